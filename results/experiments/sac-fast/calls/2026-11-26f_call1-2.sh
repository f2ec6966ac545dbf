#!/bin/bash
# Sixth session's calls (4 GPUs, one tools.experiments driver over all). Usage: bash .devcall/s6.sh LIMIT [--whole-parts]
LIMIT=$1; WHOLE=$2
start=$(date +%s)
mkdir -p $OUT/w
nvidia-smi --query-gpu=index,name --format=csv,noheader > $OUT/gpus.txt
git log -1 --format=%h >> $OUT/gpus.txt 2>/dev/null
(python -m tools.experiments run sac-fast/ur5e-reach-avoid-plus sac-fast/panda-reach-plus sac-fast/panda-reach-avoid-plus \
   --parallel --max-seeds 1 --time-limit $LIMIT --no-build --worker-logs $OUT/w $WHOLE > $OUT/driver.log 2>&1) & P=$!
wait $P
tar czf $OUT/rec.tgz $OUT/w $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $OUT/gpus.txt; tail -30 $OUT/driver.log; echo "call done $(date) elapsed $(( $(date +%s) - start ))"
