#!/bin/bash
# Sixteenth session's calls (four GPUs, or two; PPO only), from the repository root:
#   bash results/experiments/sac-fast/calls/2026-11-27d_next_s21.sh CALL LIMIT [last]
# call 1: the install line first, carrying .whl; later calls: the /tmp/site line, carrying nothing (the machine
# keeps runs/). GPU 0: the reach-observation rows of relative control, then relative-step's seeds 1-2 (one-seed
# parts, ~225 s each on an H100, to fill a last call's tail). GPU 1: reach-avoid-reward/dense-penalty (the test of
# why our dense reward collides more: results/experiments/README.md), then joint-penalties. GPU 2: the
# reach-observation rows of absolute control, then reach-avoid-observation/link-dist-size. GPU 3: network-size's
# 3x512 rows (~1.5x slower per step than 3x256: 2026-11-27d_calls.md), then obstacle-size-ur5e. With two GPUs,
# GPU 2's rows follow GPU 0's and GPU 3's follow GPU 1's (tools/gpu_rows.sh).
export ROWS0="reach-observation/ee-pos reach-observation/velocities reach-observation/prev-action relative-step"
export ROWS1="reach-avoid-reward/dense-penalty joint-penalties"
export ROWS2="reach-observation/absolute-no-prev-action reach-observation/absolute-velocities reach-avoid-observation/link-dist-size"
export ROWS3="network-size obstacle-size-ur5e"
exec bash tools/gpu_rows.sh "$@"
