#!/bin/bash
# Fifteenth session's calls (four GPUs, or two; PPO only). Usage: bash .devcall/s20.sh CALL LIMIT [last]
#  (copy it first: mkdir -p .devcall && cp results/experiments/sac-fast/calls/2026-11-27c_next_s20.sh .devcall/s20.sh;
#  ignored folders do not outlive a session)
#  call 1: the install line first, carry .whl .devcall; calls 2..: the /tmp/site line, carry .devcall (the machine
#  keeps runs/).
#  One driver per GPU, three seeds a part; with `last` (the machine's last call): --whole-parts, three-seed parts,
#  then one-seed parts in the time left.
#  GPU 0: reach-avoid-front (ur5e seeds 3-4, panda), relative-step (seeds 1-2), reach-avoid-joint-margin; GPU 1:
#  reach-avoid-observation, joint-penalties; GPU 2: reward (the absolute rows), reach-observation; GPU 3: network-size,
#  obstacle-size-ur5e.
#  With two GPUs, GPU 2's rows follow GPU 0's and GPU 3's follow GPU 1's. The reach rows (one seed ~225 s) come last
#  on GPUs 0-2 so that the last call's one-seed pass can fill the time the three-seed parts leave.
CALL=$1; LIMIT=$2; LAST=$3; start=$(date +%s)
L=/tmp/calllogs; rm -rf $L; mkdir -p $L/w_g0 $L/w_g1 $L/w_g2 $L/w_g3
tl() { echo $(( LIMIT - ($(date +%s) - start) - 45 )); }  # the drivers' limit: 45 s kept for exports and packing
nvidia-smi --query-gpu=index,name --format=csv,noheader > $L/gpus.txt
NG=$(wc -l < $L/gpus.txt)
ROWS0=${ROWS0:-"reach-avoid-front/ur5e reach-avoid-front/panda reach-avoid-joint-margin relative-step"}
ROWS1=${ROWS1:-"reach-avoid-observation joint-penalties"}
ROWS2=${ROWS2:-"reward reach-observation"}
ROWS3=${ROWS3:-"network-size obstacle-size-ur5e"}
if [ "$NG" -lt 4 ]; then ROWS0="$ROWS0 $ROWS2"; ROWS1="$ROWS1 $ROWS3"; fi
ppo() {  # ppo GPU NAME ROWS...: PPO rows on one GPU until the limit
  local gpu=$1 name=$2; shift 2
  if [ "$LAST" = last ]; then
    CUDA_VISIBLE_DEVICES=$gpu python -m tools.experiments run "$@" --parallel --max-seeds 3 --whole-parts \
      --time-limit $(tl) --no-build --worker-logs $L/w_$name > $L/driver_$name.log 2>&1
    [ $(tl) -gt 150 ] || return 0
    CUDA_VISIBLE_DEVICES=$gpu python -m tools.experiments run "$@" --parallel --max-seeds 1 --whole-parts \
      --time-limit $(tl) --no-build --worker-logs $L/w_$name > $L/driver_${name}_1.log 2>&1
  else
    CUDA_VISIBLE_DEVICES=$gpu python -m tools.experiments run "$@" --parallel --max-seeds 3 \
      --time-limit $(tl) --no-build --worker-logs $L/w_$name > $L/driver_$name.log 2>&1
  fi
}
ppo 0 g0 $ROWS0 & ppo 1 g1 $ROWS1 &
if [ "$NG" -ge 4 ]; then ppo 2 g2 $ROWS2 & ppo 3 g3 $ROWS3 & fi
wait
tar czf $OUT/rec.tgz $L $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $L/gpus.txt; for d in $L/driver*.log; do echo "== $d"; tail -5 $d; done
for f in $L/w_*/*; do echo "== $f"; grep "steps/s" $f | tail -1; tail -2 $f; done
ls -la $OUT
echo "call $CALL done $(date) elapsed $(( $(date +%s) - start ))"
