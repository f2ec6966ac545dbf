#!/bin/bash
# Sixth session, call 5 (47 s): float32 evaluations of the UR5e reach-avoid plus seeds 1-4, one GPU each.
R=runs/experiments/sac-fast/ur5e-reach-avoid-plus; mkdir -p $OUT/x
for s in 1 2 3 4; do
  (CUDA_VISIBLE_DEVICES=$((s-1)) timeout 110 python eval.py --checkpoint $R/seeds-$s-$s --compute-dtype float32 --json $OUT/x/eval_f32_ur5e-reach-avoid-plus_s$s.json > $OUT/x/u$s.log 2>&1) &
done
wait; cd $OUT && tar czf x5.tgz x && rm -rf x
