#!/bin/bash
# Ninth session's last call: GPU 0 runs the Panda reach-avoid row's driver; GPU 1 profiles Brax's SAC first,
# then runs the Panda reach row's driver for what is left. Both pack their unfinished parts.
LIMIT=$1
start=$(date +%s)
L=/tmp/calllogs; rm -rf $L; mkdir -p $L/w $L/w2 $L/brax
nvidia-smi --query-gpu=index,name --format=csv,noheader > $L/gpus.txt
CUDA_VISIBLE_DEVICES=0 python -m tools.experiments run sac-fast/panda-reach-avoid-plus-200m --parallel --round-robin \
  --max-seeds 1 --time-limit $LIMIT --no-build --worker-logs $L/w --carry-out $OUT/carry > $L/driver.log 2>&1 &
A=$!
( CUDA_VISIBLE_DEVICES=1 timeout 300 python -m benchmarks.brax_reference --preset ur5e-reach-sac --skip ours --evals 4 \
    --updates-per-eval 256 --eval-envs 128 --trace /tmp/tr --out $L/brax/brax_sac > $L/brax/run.log 2>&1
  echo "brax rc $? at $(( $(date +%s) - start )) s" >> $L/brax/run.log
  CUDA_VISIBLE_DEVICES=1 python -m benchmarks.trace_summary /tmp/tr/brax > $L/brax/trace_summary.txt 2>&1
  left=$(( LIMIT - ($(date +%s) - start) ))
  echo "driver B limit $left" >> $L/brax/run.log
  if [ $left -gt 200 ]; then
    CUDA_VISIBLE_DEVICES=1 python -m tools.experiments run sac-fast/panda-reach-plus-200m --parallel --round-robin \
      --max-seeds 1 --time-limit $left --no-build --worker-logs $L/w2 --carry-out $OUT/carry2 > $L/driver2.log 2>&1
  fi ) &
B=$!
wait $A $B
tar czf $OUT/rec.tgz $L $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $L/gpus.txt; tail -12 $L/driver.log; tail -12 $L/driver2.log; tail -5 $L/brax/run.log; head -40 $L/brax/trace_summary.txt; ls -laR $OUT 2>/dev/null | head -30
echo "call done $(date) elapsed $(( $(date +%s) - start ))"
