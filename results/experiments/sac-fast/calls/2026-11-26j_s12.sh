#!/bin/bash
# Tenth session, after the first machine went back: both Panda 200M rows on every GPU (one seed a part,
# round-robin, --carry-in $CARRY_IN); once a part exits with >= 260 s left, its GPU profiles Brax's SAC
# (BRAX=1). Usage: bash .devcall/s12.sh LIMIT [last]   (last: --carry-out $OUT/carry)
LIMIT=$1; LAST=$2
start=$(date +%s)
CARRY_IN=${CARRY_IN:-.carry}
L=/tmp/calllogs; rm -rf $L /tmp/tr; mkdir -p $L/w $L/brax $CARRY_IN
left() { echo $(( LIMIT - ($(date +%s) - start) )); }
nvidia-smi --query-gpu=index,name --format=csv,noheader > $L/gpus.txt
CA="--carry-in $CARRY_IN"; [ "$LAST" = last ] && CA="$CA --carry-out $OUT/carry"
python -m tools.experiments run sac-fast/panda-reach-plus-200m sac-fast/panda-reach-avoid-plus-200m --parallel \
  --round-robin --max-seeds 1 --time-limit $LIMIT --no-build --worker-logs $L/w $CA > $L/driver.log 2>&1 &
A=$!
B=""
if [ "$BRAX" = 1 ]; then
( while ! grep -q "exited with status" $L/driver.log 2>/dev/null; do kill -0 $A 2>/dev/null || exit 0; sleep 5; done
  gpu=$(grep -o "GPU [0-9]*: [^ ]* seeds-[0-9-]* exited" $L/driver.log | head -1 | cut -d' ' -f2 | tr -d :)
  echo "Brax profile on GPU $gpu with $(left) s left" > $L/brax/run.log
  [ $(left) -gt 260 ] || exit 0
  CUDA_VISIBLE_DEVICES=$gpu timeout $(( $(left) - 25 )) python -m benchmarks.brax_reference --preset ur5e-reach-sac --skip ours \
    --evals 4 --updates-per-eval 456 --eval-envs 128 --trace /tmp/tr --out $L/brax/brax_sac >> $L/brax/run.log 2>&1
  echo "brax rc $? at $(( $(date +%s) - start )) s" >> $L/brax/run.log
  python -m benchmarks.trace_summary /tmp/tr/brax --top 25 --detail 5 --json $L/brax/trace_summary.json > $L/brax/trace_summary.txt 2>&1
  f=$(find /tmp/tr/brax -name perfetto_trace.json.gz | head -1)
  [ -n "$f" ] && [ $(stat -c %s "$f") -lt 16000000 ] && cp "$f" $OUT/brax_perfetto_trace.json.gz ) &
B=$!
fi
wait $A $B
tar czf $OUT/rec.tgz $L $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $L/gpus.txt; tail -12 $L/driver.log
for f in $L/w/*; do echo "== $f"; grep "steps/s" $f | tail -1; tail -2 $f; done
tail -4 $L/brax/run.log 2>/dev/null; head -30 $L/brax/trace_summary.txt 2>/dev/null
ls -laR $OUT | head -30
echo "call done $(date) elapsed $(( $(date +%s) - start ))"
