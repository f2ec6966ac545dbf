#!/bin/bash
# Seventh session's calls (2 GPUs). Usage: bash .devcall/s7.sh LIMIT "DRIVER_GPUS" [--whole-parts] [TT_GPU]
# DRIVER_GPUS: one driver over the Panda screening rows (jl, ent14), one seed a part.
# TT_GPU (optional): the paper-setting SAC's speed with and without loops in command buffers (+WHILE),
# then a PPO filler (relative-step/step-0.6) to the end of the call.
LIMIT=$1; GPUS=$2; WHOLE=$3; TT_GPU=$4
start=$(date +%s); deadline=$((start + LIMIT))
left() { echo $((deadline - $(date +%s))); }
mkdir -p $OUT/w $OUT/x
nvidia-smi --query-gpu=index,name --format=csv,noheader > $OUT/gpus.txt
(CUDA_VISIBLE_DEVICES=$GPUS python -m tools.experiments run ${ROWS:-sac-fast/panda-reach-plus-jl sac-fast/panda-reach-avoid-plus-jl sac-fast/panda-reach-plus-ent14 sac-fast/panda-reach-avoid-plus-ent14} \
   --parallel --max-seeds 1 --time-limit $(left) --no-build --worker-logs $OUT/w $WHOLE > $OUT/dA.log 2>&1) & P0=$!
P3=
if [ -n "$TT_GPU" ]; then
(
  TT="python -m benchmarks.train_throughput --preset panda-reach-sac --seeds 1 5 --updates 300 --rounds 2 --skip-env-only"
  CUDA_VISIBLE_DEVICES=$TT_GPU timeout 200 $TT --out $OUT/x/tt_sac_paper_default
  CUDA_VISIBLE_DEVICES=$TT_GPU XLA_FLAGS="--xla_gpu_enable_command_buffer=+WHILE" timeout 200 $TT --out $OUT/x/tt_sac_paper_while
  CUDA_VISIBLE_DEVICES=$TT_GPU python -m tools.experiments run relative-step/step-0.6 \
    --parallel --max-seeds 1 --time-limit $(left) --no-build --worker-logs $OUT/w $WHOLE
) > $OUT/dB.log 2>&1 & P3=$!
fi
wait $P0 $P3
tar czf $OUT/rec.tgz $OUT/w $OUT/x $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $OUT/gpus.txt; tail -25 $OUT/dA.log; [ -n "$TT_GPU" ] && tail -25 $OUT/dB.log; echo "call done $(date) elapsed $(( $(date +%s) - start ))"
