#!/bin/bash
# Sixth session's last call: finish the Panda plus parts (whole parts only), then failure reports and float32
# evaluations of the finished Panda reach plus seeds on the idle GPUs.
start=$(date +%s)
mkdir -p $OUT/w $OUT/x
nvidia-smi --query-gpu=index,name --format=csv,noheader > $OUT/gpus.txt
(python -m tools.experiments run sac-fast/ur5e-reach-avoid-plus sac-fast/panda-reach-plus sac-fast/panda-reach-avoid-plus \
   --parallel --max-seeds 1 --time-limit 450 --no-build --worker-logs $OUT/w --whole-parts > $OUT/driver.log 2>&1) & P=$!
wait $P
R=runs/experiments/sac-fast
left=$(( 560 - ($(date +%s) - start) )); echo "left for the reports: $left s" >> $OUT/driver.log
if [ $left -gt 60 ]; then
  (CUDA_VISIBLE_DEVICES=0 timeout $left python -m tools.failure_report --checkpoint $R/panda-reach-plus/seeds-3-3 --num-envs 4096 --json $OUT/x/failures_panda-reach-plus_s3.json > $OUT/x/failures_panda-reach-plus_s3.log 2>&1) & A=$!
  (CUDA_VISIBLE_DEVICES=1 timeout $left python -m tools.failure_report --checkpoint $R/panda-reach-avoid-plus/seeds-3-3 --num-envs 4096 --json $OUT/x/failures_panda-reach-avoid-plus_s3.json > $OUT/x/failures_panda-reach-avoid-plus_s3.log 2>&1) & B=$!
  (CUDA_VISIBLE_DEVICES=2 timeout $left python eval.py --checkpoint $R/panda-reach-plus/seeds-3-3 --compute-dtype float32 --json $OUT/x/eval_f32_panda-reach-plus_s3.json > $OUT/x/eval_f32_panda-reach-plus_s3.log 2>&1) & C=$!
  (CUDA_VISIBLE_DEVICES=3 timeout $left python eval.py --checkpoint $R/panda-reach-plus/seeds-4-4 --compute-dtype float32 --json $OUT/x/eval_f32_panda-reach-plus_s4.json > $OUT/x/eval_f32_panda-reach-plus_s4.log 2>&1) & D=$!
  wait $A $B $C $D
fi
tar czf $OUT/rec.tgz $OUT/w $OUT/x $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $OUT/gpus.txt; tail -30 $OUT/driver.log; ls -la $OUT/x; echo "call done $(date) elapsed $(( $(date +%s) - start ))"
