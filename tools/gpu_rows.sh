#!/bin/bash
# One device call of experiment rows, one `tools.experiments` driver per local GPU, from the repository root:
#   ROWS0="exp exp/run ..." ROWS1="..." [ROWS2=... ROWS3=...] bash tools/gpu_rows.sh CALL LIMIT [last]
# GPU i trains ROWS<i>, three seeds a part, until LIMIT seconds after the start less REC_SECONDS (for the packing
# below); with fewer GPUs than row groups, group i follows group i mod (number of GPUs); the GPU of an empty group
# i >= 2 joins group i - 2's driver, which then trains that group's parts side by side (`--parallel`, a part per GPU: a
# run's seeds in two parts use both). Without `last`, the parts that do not finish stay on the machine for the next
# call, so the drivers keep a 20 s reserve for the last checkpoint and exit: a part that finishes late ends its
# evaluation inside the REC_SECONDS kept for packing. With `last` (the machine's last call: it keeps no runs/ after
# it), every pass ends PACK_SECONDS earlier: --whole-parts, the three-seed parts predicted to finish, then one-seed
# parts; then, with time still left, the next one-seed part trains to the limit, and after rec.tgz is written every
# unfinished part of the rows is packed learner-only into $OUT/carry (`tools.carry_parts pack`, its limits: what a
# call brings back; cut off 10 s before LIMIT) for the next machine, so a GPU whose parts are all predicted too long
# still trains. A folder .carry in the repository (carried into the call: a bundle that pack wrote) is unpacked into
# runs/ first.
# Logs go to $CALL_LOGS (default /tmp/calllogs);
# $OUT/rec.tgz gets them and every part's config, eval and metrics files (`python -m tools.experiments record`
# takes them after the lease).
CALL=$1; LIMIT=$2; LAST=$3; start=$(date +%s)
if [ -z "$CALL" ] || [ -z "$LIMIT" ] || [ -z "$ROWS0" ] || [ -z "$OUT" ]; then
  echo "usage: ROWS0=... [ROWS1=... ROWS2=... ROWS3=...] OUT=dir bash tools/gpu_rows.sh CALL LIMIT [last]" >&2
  exit 2
fi
L=${CALL_LOGS:-/tmp/calllogs}; rm -rf $L; mkdir -p $L
REC_SECONDS=45  # rec.tgz, and the slack for a part whose evaluation ends past the drivers' limit
PACK_SECONDS=60  # the last call's learner-only saves of up to four unfinished parts
# (timed in results/experiments/sac-fast/calls)
KEEP=0; [ "$LAST" = last ] && KEEP=$PACK_SECONDS
tl() { echo $(( LIMIT - ($(date +%s) - start) - REC_SECONDS - KEEP )); }  # the drivers' limit
if [ -d .carry ]; then
  JAX_PLATFORMS=cpu python -m tools.carry_parts unpack --from .carry --runs-dir runs/experiments > $L/unpack.log 2>&1
fi
nvidia-smi --query-gpu=index,name --format=csv,noheader > $L/gpus.txt
NG=$(wc -l < $L/gpus.txt)
GROUPS_=("$ROWS0" "$ROWS1" "$ROWS2" "$ROWS3")
ROWS=()
for i in 0 1 2 3; do ROWS[$(( i % NG ))]="${ROWS[$(( i % NG ))]} ${GROUPS_[$i]}"; done
GPUS=()  # each driver's GPUs: its own, and that of the group two above it when that group has no rows
for (( g = 0; g < NG && g < 4; g++ )); do GPUS[$g]=$g; done
for (( g = NG - 1; g >= 2; g-- )); do
  (( g < 4 )) && [ -z "${ROWS[$g]// /}" ] && GPUS[$(( g - 2 ))]="${GPUS[$(( g - 2 ))]},$g" && GPUS[$g]=""
done
for (( g = 0; g < NG && g < 4; g++ )); do [ -n "${GPUS[$g]}" ] && echo "GPU ${GPUS[$g]}:"${ROWS[$g]}; done > $L/plan.txt
rows_on() {  # rows_on GPUS NAME ROWS...: the rows on these GPUs (a comma list: parts side by side) until the limit
  local gpu=$1 name=$2; shift 2
  local rows="$*"
  mkdir -p $L/w_$name
  drive() {  # drive LOG FLAGS...: one driver over the rows with FLAGS, its output to $L/LOG
    local log=$1; shift
    CUDA_VISIBLE_DEVICES=$gpu python -m tools.experiments run $rows --parallel "$@" --time-limit $(tl) --no-build \
      --worker-logs $L/w_$name > $L/$log 2>&1
  }
  if [ "$LAST" = last ]; then
    drive driver_$name.log --max-seeds 3 --whole-parts
    [ $(tl) -gt 150 ] || return 0
    drive driver_${name}_1.log --max-seeds 1 --whole-parts
    [ $(tl) -gt 120 ] || return 0
    drive driver_${name}_2.log --max-seeds 1 --reserve 20
  else
    drive driver_$name.log --max-seeds 3 --reserve 20
  fi
}
for (( g = 0; g < NG && g < 4; g++ )); do
  [ -n "${ROWS[$g]// /}" ] && [ -n "${GPUS[$g]}" ] && rows_on ${GPUS[$g]} g$g ${ROWS[$g]} &
done
wait
tar czf $OUT/rec.tgz $L $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
left=$(( LIMIT - ($(date +%s) - start) - 10 ))
if [ "$LAST" = last ] && [ $left -gt 0 ]; then  # after rec.tgz: a pack cut off cannot cost the results
  # Every unfinished part of the rows for the next machine, within `tools.carry_parts`' limits (bundles a call
  # without the wheels can carry, 7 pieces at most: rec.tgz is the 8th file back).
  timeout $left env JAX_PLATFORMS=cpu python -m tools.carry_parts pack --runs-dir runs/experiments --to $OUT/carry \
    $ROWS0 $ROWS1 $ROWS2 $ROWS3 > $L/pack.log 2>&1
fi
cat $L/gpus.txt $L/plan.txt; for d in $L/unpack.log $L/pack.log $L/driver*.log; do [ -f $d ] || continue; echo "== $d"; tail -5 $d; done
for f in $L/w_*/*; do echo "== $f"; grep "steps/s" $f | tail -1; tail -2 $f; done
ls -la $OUT
echo "call $CALL done $(date) elapsed $(( $(date +%s) - start ))"
