#!/bin/bash
# Call 1: four GPUs, one driver each. Usage: bash .devcall/call1.sh (from the repo root, after install)
start=$(date +%s); deadline=$((start + 535))
left() { echo $((deadline - $(date +%s))); }
nvidia-smi --query-gpu=index,name --format=csv,noheader
mkdir -p $OUT/w0 $OUT/w1 $OUT/w2 $OUT/w3
drive() { # gpu, logdir, names...
  local g=$1 d=$2; shift 2
  CUDA_VISIBLE_DEVICES=$g python -m tools.experiments run "$@" --parallel --max-seeds 1 --time-limit $(left) --no-build --worker-logs $d
}
(drive 0 $OUT/w0 sac-fast/panda-reach-plus > $OUT/d0.log 2>&1) & P0=$!
(drive 1 $OUT/w1 sac-fast/panda-reach-avoid-plus > $OUT/d1.log 2>&1) & P1=$!
(drive 2 $OUT/w2 sac-fast/ur5e-reach-avoid-plus > $OUT/d2.log 2>&1) & P2=$!
(
  export CUDA_VISIBLE_DEVICES=3
  timeout 200 python -m benchmarks.train_throughput --preset panda-reach-sac --seeds 1 2 3 5 --updates 500 --rounds 2 --skip-env-only --out $OUT/tp
  echo "tp rc=$?"
  timeout 200 python -m benchmarks.brax_reference --preset ur5e-reach-sac --evals 2 --updates-per-eval 1024 --eval-envs 128 --trace $OUT/tr --out $OUT/brax_sac
  echo "brax rc=$?"
  python -m benchmarks.trace_summary $OUT/tr/ours; python -m benchmarks.trace_summary $OUT/tr/brax
  echo "summary done $(date)"
  drive 3 $OUT/w3 reward/relative-semi-sparse reward/relative-sparse
) > $OUT/g3.log 2>&1 & P3=$!
wait $P0 $P1 $P2 $P3
du -sh $OUT/tr 2>/dev/null
tar czf $OUT/rec.tgz results/experiments $(find runs/experiments \( -name '*.csv' -o -name '*.json' \) 2>/dev/null | grep -v checkpoints)
echo "call done $(date) elapsed $(( $(date +%s) - start ))"
