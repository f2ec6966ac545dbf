#!/bin/bash
# Thirteenth session's calls (two GPUs, one machine; PPO only). Usage: bash .devcall/s17.sh CALL LIMIT [last]
#  call 1 (the install line first; carry .whl .devcall), call 2 and 3 (the /tmp/site line; carry .devcall):
#  one driver per GPU, three seeds a part, the machine's runs/ kept between calls. With `last` (the last call
#  on this machine): --whole-parts, first three-seed parts, then one-seed parts in the time left.
#  GPU 0: obstacles-moving3's static rows (issue 29; their cross-evaluations on moving obstacles run where
#  the checkpoints are), then reach-avoid-observation; GPU 1: obstacles-moving3/ur5e-moving-plus (issue 29),
#  then reach-avoid-front, then reach-avoid-reward/dense.
CALL=$1; LIMIT=$2; LAST=$3; start=$(date +%s)
L=/tmp/calllogs; rm -rf $L; mkdir -p $L/w_g0 $L/w_g1
tl() { echo $(( LIMIT - ($(date +%s) - start) - 45 )); }  # the drivers' limit: 45 s kept for packing the logs
nvidia-smi --query-gpu=index,name --format=csv,noheader > $L/gpus.txt
ROWS0=${ROWS0:-"obstacles-moving3/ur5e-static obstacles-moving3/panda-static reach-avoid-observation"}
ROWS1=${ROWS1:-"obstacles-moving3/ur5e-moving-plus reach-avoid-front reach-avoid-reward"}
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
case $CALL in
1|2|3) ppo 0 g0 $ROWS0 & ppo 1 g1 $ROWS1 & ;;
*) echo "CALL must be 1, 2 or 3"; exit 2 ;;
esac
wait
tar czf $OUT/rec.tgz $L $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $L/gpus.txt; for d in $L/driver*.log; do echo "== $d"; tail -5 $d; done
for f in $L/w_*/*; do echo "== $f"; grep "steps/s" $f | tail -1; tail -2 $f; done
ls -la $OUT
echo "call $CALL done $(date) elapsed $(( $(date +%s) - start ))"
