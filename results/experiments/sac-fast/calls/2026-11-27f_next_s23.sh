#!/bin/bash
# Eighteenth session's calls (four GPUs, or two), from the repository root:
#   bash results/experiments/sac-fast/calls/2026-11-27f_next_s23.sh CALL LIMIT [last]
# call 1: the install line first, carrying .whl; later calls: the /tmp/site line, carrying nothing (the machine
# keeps runs/). GPU 0: obstacle-size-ur5e/r0.2 (three seeds ~535 s, two ~455 s on an H200), then
# reach-avoid-joint-margin/margin-0.25. GPU 1: obstacle-size-ur5e/r0.3 seeds 3-4, reach-avoid-reward/dense-penalty-10,
# joint-penalties/vel-1e-2 seed 2 (~250 s), then sac-workspaces/upper. GPUs 2 and 3: sac-workspaces/pandagym and
# front, a three-seed part of the paper-setting SAC each (40M steps a seed; ~920-1,565 s from a five-seed part
# that shared its H200 with another: at most a GPU's three calls), then full-range and upper. In the last call, a part that cannot finish trains to the limit
# and the call packs the unfinished ones into $OUT/carry (`tools/gpu_rows.sh`; learner-only, a PPO seed ~3-5 MiB,
# a paper-setting SAC seed ~6 MiB: a three-seed SAC part ~18 MiB, in bundles of 24 MiB). With two GPUs, GPU 2's rows
# follow GPU 0's and GPU 3's follow GPU 1's.
export ROWS0="obstacle-size-ur5e/r0.2 reach-avoid-joint-margin/margin-0.25"
export ROWS1="obstacle-size-ur5e/r0.3 reach-avoid-reward/dense-penalty-10 joint-penalties/vel-1e-2 sac-workspaces/upper"
export ROWS2="sac-workspaces/pandagym sac-workspaces/full-range"
export ROWS3="sac-workspaces/front sac-workspaces/upper"
exec bash tools/gpu_rows.sh "$@"
