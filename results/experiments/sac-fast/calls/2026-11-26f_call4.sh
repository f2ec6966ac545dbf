#!/bin/bash
# Sixth session, call 4 (63 s, after call 3 on the same machine): float32 evaluations of the Panda reach-avoid plus
# seeds 3-4 and failure reports of Panda reach plus seed 4 and UR5e reach-avoid plus seed 1, one GPU each.
R=runs/experiments/sac-fast; mkdir -p $OUT/x
(CUDA_VISIBLE_DEVICES=0 timeout 150 python eval.py --checkpoint $R/panda-reach-avoid-plus/seeds-3-3 --compute-dtype float32 --json $OUT/x/eval_f32_panda-reach-avoid-plus_s3.json > $OUT/x/e3.log 2>&1) &
(CUDA_VISIBLE_DEVICES=1 timeout 150 python eval.py --checkpoint $R/panda-reach-avoid-plus/seeds-4-4 --compute-dtype float32 --json $OUT/x/eval_f32_panda-reach-avoid-plus_s4.json > $OUT/x/e4.log 2>&1) &
(CUDA_VISIBLE_DEVICES=2 timeout 150 python -m tools.failure_report --checkpoint $R/panda-reach-plus/seeds-4-4 --num-envs 4096 --json $OUT/x/failures_panda-reach-plus_s4.json > $OUT/x/f4.log 2>&1) &
(CUDA_VISIBLE_DEVICES=3 timeout 150 python -m tools.failure_report --checkpoint $R/ur5e-reach-avoid-plus/seeds-1-1 --num-envs 4096 --json $OUT/x/failures_ur5e-reach-avoid-plus_s1.json > $OUT/x/fu1.log 2>&1) &
wait; cd $OUT && tar czf x4.tgz x && rm -rf x
