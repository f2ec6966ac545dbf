#!/bin/bash
# Fifteenth session's calls (four GPUs, or two; PPO only), from the repository root:
#   bash results/experiments/sac-fast/calls/2026-11-27c_next_s20.sh CALL LIMIT [last]
# call 1: the install line first, carrying .whl; later calls: the /tmp/site line, carrying nothing (the machine
# keeps runs/). GPU 0: reach-avoid-front (ur5e seeds 3-4, panda), reach-avoid-joint-margin, relative-step (seeds
# 1-2); GPU 1: reach-avoid-observation, joint-penalties; GPU 2: reward (the absolute rows), reach-observation;
# GPU 3: network-size, obstacle-size-ur5e. With two GPUs, GPU 2's rows follow GPU 0's and GPU 3's follow GPU 1's
# (tools/gpu_rows.sh). The reach rows (one seed ~225 s) come last on GPUs 0-2 so that the last call's one-seed
# pass can fill the time the three-seed parts leave.
export ROWS0="reach-avoid-front/ur5e reach-avoid-front/panda reach-avoid-joint-margin relative-step"
export ROWS1="reach-avoid-observation joint-penalties"
export ROWS2="reward reach-observation"
export ROWS3="network-size obstacle-size-ur5e"
exec bash tools/gpu_rows.sh "$@"
