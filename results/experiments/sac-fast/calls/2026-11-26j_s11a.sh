#!/bin/bash
# Tenth session, call 1 (four GPUs). Usage: bash .devcall/s11a.sh LIMIT
# GPUs 0,1: Panda reach-avoid 200M (seed 3 carried in .carry at 168M, seed 4 new); once seed 3 exits, its GPU
#           trains Panda reach 200M seed 4 (new). GPU 2: Panda reach 200M seed 3 (new). Panda reach seed 2 waits
#           for its carried copy (.carry_b, call 2). GPU 3: the paper-setting SAC rows (sac-reach), two five-seed
#           parts side by side on one GPU (--workers-per-gpu 2, measured here).
LIMIT=$1
start=$(date +%s)
L=/tmp/calllogs; rm -rf $L; mkdir -p $L/w $L/w3
left() { echo $(( LIMIT - ($(date +%s) - start) )); }
nvidia-smi --query-gpu=index,name --format=csv,noheader > $L/gpus.txt
CUDA_VISIBLE_DEVICES=0,1 python -m tools.experiments run sac-fast/panda-reach-avoid-plus-200m --parallel --round-robin \
  --max-seeds 1 --time-limit $LIMIT --no-build --worker-logs $L/w --carry-in .carry > $L/driver.log 2>&1 &
A=$!
CUDA_VISIBLE_DEVICES=2 python -m tools.experiments run sac-fast/panda-reach-plus-200m --only-part seeds-3-3 \
  --max-seeds 1 --time-limit $LIMIT --no-build > $L/w/reach-seed3.log 2>&1 &
C=$!
CUDA_VISIBLE_DEVICES=3 python -m tools.experiments run sac-reach --parallel --workers-per-gpu 2 --time-limit $LIMIT \
  --no-build --worker-logs $L/w3 > $L/driver_sac.log 2>&1 &
D=$!
( while ! grep -q "seeds-3-3 exited" $L/driver.log 2>/dev/null; do kill -0 $A 2>/dev/null || exit 0; sleep 5; done
  gpu=$(grep -o "GPU [0-9]*: sac-fast/panda-reach-avoid-plus-200m seeds-3-3 exited" $L/driver.log | grep -o "^GPU [0-9]*" | cut -d' ' -f2)
  echo "Panda reach seed 4 on GPU $gpu with $(left) s left" > $L/w/reach-seed4.log
  [ $(left) -gt 150 ] || exit 0
  CUDA_VISIBLE_DEVICES=$gpu python -m tools.experiments run sac-fast/panda-reach-plus-200m --only-part seeds-4-4 \
    --max-seeds 1 --time-limit $(left) --no-build >> $L/w/reach-seed4.log 2>&1 ) &
B=$!
wait $A $B $C $D
tar czf $OUT/rec.tgz $L $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $L/gpus.txt; tail -8 $L/driver.log; tail -8 $L/driver_sac.log; tail -3 $L/w/reach-seed3.log $L/w/reach-seed4.log
for f in $L/w/* $L/w3/*; do echo "== $f"; grep "steps/s" $f | tail -1; tail -2 $f; done
ls -la $OUT
echo "call done $(date) elapsed $(( $(date +%s) - start ))"
