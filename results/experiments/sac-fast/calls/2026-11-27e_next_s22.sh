#!/bin/bash
# Seventeenth session's calls (four GPUs, or two; PPO only), from the repository root:
#   bash results/experiments/sac-fast/calls/2026-11-27e_next_s22.sh CALL LIMIT [last]
# call 1: the install line first, carrying .whl; later calls: the /tmp/site line, carrying nothing (the machine
# keeps runs/). GPU 0: the last reach rows (reach-observation/prev-action; joint-penalties' acc-1e-3 seed 2,
# vel-1e-3, vel-1e-2 seeds 1-2: ~1,450 s at this session's H200 speeds), then obstacle-size-ur5e r0.3. GPU 1:
# reach-avoid-observation/link-dist-size, then obstacle-size-ur5e r0.3. GPUs 2 and 3: obstacle-size-ur5e r0.025 and
# r0.05, then r0.2. The planner guesses ~610 s for a three-seed reach-avoid part with its evaluation and ~485 s for
# a two-seed one (H200 speeds give ~530 and ~440 s): the last call's --whole-parts fits the seeds-3-4 parts. Our own studies (reach-avoid-reward/dense-penalty-10,
# reach-avoid-joint-margin) and sac-workspaces wait for the paper's rows. With two GPUs, GPU 2's rows follow
# GPU 0's and GPU 3's follow GPU 1's (tools/gpu_rows.sh).
export ROWS0="reach-observation/prev-action joint-penalties obstacle-size-ur5e/r0.3"
export ROWS1="reach-avoid-observation/link-dist-size obstacle-size-ur5e/r0.3"
export ROWS2="obstacle-size-ur5e/r0.025 obstacle-size-ur5e/r0.2"
export ROWS3="obstacle-size-ur5e/r0.05 obstacle-size-ur5e/r0.2"
exec bash tools/gpu_rows.sh "$@"
