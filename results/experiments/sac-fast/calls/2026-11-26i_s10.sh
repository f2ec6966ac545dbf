#!/bin/bash
# Tenth session, call 1 (two GPUs): the Panda reach-avoid 200M row (seed 3 carried in .carry at 168M, seed 4 new);
# once seed 3 is done, its GPU profiles Brax's SAC (4 epochs of 256 vector steps after the 800-step prefill; the
# second epoch traced alone). Usage: bash .devcall/s10.sh LIMIT
LIMIT=$1
start=$(date +%s)
L=/tmp/calllogs; rm -rf $L /tmp/tr; mkdir -p $L/w $L/brax
nvidia-smi --query-gpu=index,name --format=csv,noheader > $L/gpus.txt
python -m tools.experiments run sac-fast/panda-reach-avoid-plus-200m --parallel --round-robin --max-seeds 1 \
  --time-limit $LIMIT --no-build --worker-logs $L/w --carry-in .carry > $L/driver.log 2>&1 &
A=$!
( while ! grep -q "seeds-3-3 exited" $L/driver.log 2>/dev/null; do kill -0 $A 2>/dev/null || exit 0; sleep 5; done
  gpu=$(grep -o "GPU [0-9]*: sac-fast/panda-reach-avoid-plus-200m seeds-3-3 exited" $L/driver.log | grep -o "^GPU [0-9]*" | cut -d' ' -f2)
  left=$(( LIMIT - 30 - ($(date +%s) - start) ))
  echo "Brax profile on GPU $gpu with $left s left" > $L/brax/run.log
  [ $left -gt 240 ] || exit 0
  CUDA_VISIBLE_DEVICES=$gpu timeout $left python -m benchmarks.brax_reference --preset ur5e-reach-sac --skip ours \
    --evals 4 --updates-per-eval 456 --eval-envs 128 --trace /tmp/tr --out $L/brax/brax_sac >> $L/brax/run.log 2>&1
  echo "brax rc $? at $(( $(date +%s) - start )) s" >> $L/brax/run.log
  python -m benchmarks.trace_summary /tmp/tr/brax --top 25 --detail 5 --json $L/brax/trace_summary.json > $L/brax/trace_summary.txt 2>&1
  f=$(find /tmp/tr/brax -name perfetto_trace.json.gz | head -1)
  [ -n "$f" ] && [ $(stat -c %s "$f") -lt 16000000 ] && cp "$f" $OUT/brax_perfetto_trace.json.gz ) &
B=$!
wait $A $B
tar czf $OUT/rec.tgz $L $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $L/gpus.txt; tail -12 $L/driver.log; tail -6 $L/brax/run.log; head -45 $L/brax/trace_summary.txt; ls -la $OUT
echo "call done $(date) elapsed $(( $(date +%s) - start ))"
