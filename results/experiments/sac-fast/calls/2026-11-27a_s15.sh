#!/bin/bash
# Twelfth session's calls (four GPUs, one machine). Usage: bash .devcall/s15.sh CALL LIMIT   (CALL: 1, 2 or 3)
#  call 1 (the install line first; carry .whl .devcall): PPO on all four GPUs (GPUs 2-3 the moving-obstacle rows
#         of issue 29 first; their finished parts' best seeds come back in $OUT/ship.tgz).
#  call 2 (carry .devcall .carry_sac_b): GPU 0 sac-reach/panda from .carry_sac_b (27.2M of 40M); GPU 1 PPO,
#         whole parts only (it trains SAC in call 3); GPUs 2-3 PPO.
#  call 3 (carry .devcall .carry_sac): GPU 0 sac-reach/panda to the end (on this machine since call 2), then
#         PPO whole parts; GPU 1 sac-reach/ur5e-limited from .carry_sac (32.0M) to the end; GPUs 2-3 PPO whole
#         parts. The SAC drivers pack what they leave into $OUT/carry_sac_panda and $OUT/carry_sac_ur5e (30 MiB
#         bundles, one folder each: a pack clears its folder first).
# PPO: three seeds a part; where a GPU's runs will not come back (its last PPO call), --whole-parts, first
# three-seed parts and then, in the time left, one-seed parts.
CALL=$1; LIMIT=$2; start=$(date +%s)
L=/tmp/calllogs; rm -rf $L; mkdir -p $L/w_g0 $L/w_g1 $L/w_g2 $L/w_g3 $L/w_sac_panda $L/w_sac_ur5e .carry_sac .carry_sac_b
left() { echo $(( LIMIT - ($(date +%s) - start) )); }
tl() { echo $(( $(left) - 45 )); }  # the drivers' limit: 45 s kept for shipping policies and packing the logs
nvidia-smi --query-gpu=index,name --format=csv,noheader > $L/gpus.txt
ROWS0=${ROWS0:-"joint-penalties relative-step"}
ROWS1=${ROWS1:-"reach-observation"}
ROWS2=${ROWS2:-"obstacles-moving3/panda-moving obstacles-moving3/panda-static network-size"}
ROWS3=${ROWS3:-"obstacles-moving3/ur5e-moving obstacles-moving3/ur5e-static reward"}
ppo() {  # ppo GPU NAME WHOLE ROWS...: PPO rows on one GPU until the limit (WHOLE=1: whole parts only)
  local gpu=$1 name=$2 whole=$3; shift 3
  if [ "$whole" = 1 ]; then
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
sac() {  # sac GPU NAME CARRY_IN RUN [last]: a paper-setting SAC part, packed into $OUT/carry_NAME where unfinished
  local co=""; [ "$5" = last ] && co="--carry-out $OUT/carry_$2 --carry-max-mb 30"  # one folder a driver: a pack clears its own
  CUDA_VISIBLE_DEVICES=$1 python -m tools.experiments run $4 --parallel --time-limit $(tl) --no-build \
    --worker-logs $L/w_$2 --carry-in $3 $co > $L/driver_$2.log 2>&1
}
case $CALL in
1) ppo 0 g0 1 $ROWS0 & ppo 1 g1 0 $ROWS1 & ppo 2 g2 0 $ROWS2 & ppo 3 g3 0 $ROWS3 & ;;
2) sac 0 sac_panda .carry_sac_b sac-reach/panda & ppo 1 g1 1 $ROWS1 & ppo 2 g2 0 $ROWS2 & ppo 3 g3 0 $ROWS3 & ;;
3) ( sac 0 sac_panda .carry_sac_b sac-reach/panda last; [ $(tl) -gt 150 ] && ppo 0 g0 1 $ROWS1 $ROWS0 ) &
   sac 1 sac_ur5e .carry_sac sac-reach/ur5e-limited last & ppo 2 g2 1 $ROWS2 & ppo 3 g3 1 $ROWS3 & ;;
*) echo "CALL must be 1, 2 or 3"; exit 2 ;;
esac
wait
# Issue 29's shipped policies: the best seed of every finished part of the moving-obstacle rows (one picked here).
for part in runs/experiments/obstacles-moving3/*-moving/seeds-*; do
  [ -f $part/eval.json ] || continue
  python -m tools.ship_checkpoint $part ship/$(basename $(dirname $part))/$(basename $part) --best-from $part/eval.json >> $L/ship.log 2>&1
done
[ -d ship ] && tar czf $OUT/ship.tgz ship
tar czf $OUT/rec.tgz $L $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $L/gpus.txt; for d in $L/driver*.log; do echo "== $d"; tail -5 $d; done
for f in $L/w_*/*; do echo "== $f"; grep "steps/s" $f | tail -1; tail -2 $f; done
ls -laR $OUT | head -30
echo "call $CALL done $(date) elapsed $(( $(date +%s) - start ))"
