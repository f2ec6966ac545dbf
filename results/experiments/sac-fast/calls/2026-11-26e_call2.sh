#!/bin/bash
start=$(date +%s); deadline=$((start + 540))
left() { echo $((deadline - $(date +%s))); }
mkdir -p $OUT/w0 $OUT/w1 $OUT/w2 $OUT/w3
drive() { local g=$1 d=$2; shift 2
  CUDA_VISIBLE_DEVICES=$g python -m tools.experiments run "$@" --parallel --max-seeds 1 --time-limit $(left) --no-build --worker-logs $d; }
(drive 0 $OUT/w0 sac-fast/panda-reach-plus > $OUT/d0.log 2>&1) & P0=$!
(drive 1 $OUT/w1 sac-fast/panda-reach-avoid-plus > $OUT/d1.log 2>&1) & P1=$!
(drive 2 $OUT/w2 sac-fast/ur5e-reach-avoid-plus > $OUT/d2.log 2>&1) & P2=$!
(drive 3 $OUT/w3 reward/relative-semi-sparse reward/relative-sparse > $OUT/d3.log 2>&1) & P3=$!
wait $P0 $P1 $P2 $P3
tar czf $OUT/rec.tgz results/experiments $(find runs/experiments \( -name '*.csv' -o -name '*.json' \) 2>/dev/null | grep -v checkpoints)
echo "call done $(date) elapsed $(( $(date +%s) - start ))"
