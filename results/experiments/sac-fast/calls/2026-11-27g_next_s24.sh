#!/bin/bash
# Nineteenth session's calls (four GPUs, or two), from the repository root:
#   bash results/experiments/sac-fast/calls/2026-11-27g_next_s24.sh CALL LIMIT [last]
# call 1: the install line first, carrying [".whl", ".carry"] (.carry: the bundle the eighteenth session's last
# call packed, sac-workspaces/upper seed 0 at 3.2M of 40M steps, 5.9 MiB; the tree, wheels and bundle are ~60 MiB
# of the 64); later calls: the /tmp/site line, carrying nothing (the machine keeps runs/; its .carry is unpacked
# again and kept out, being older). Every row is a paper-setting SAC row but margin-0.25's (PPO).
# GPU 0: reach-avoid-joint-margin/margin-0.25 seeds 1-2 (~455 s with two seeds, ~314 s with one on an H200), then
# sac-workspaces/upper seed 0 from 3.2M (~1,150 s at the 32.9k env steps/s it trained at alone on an H200; likely
# carried again near its end), then upper seeds 1-2. GPUs 1-3: sac-workspaces/pandagym, front and full-range, a
# three-seed part each (~1,400-1,575 s: 40M steps at 26k a seed with five seeds, 32.9k with one; each call
# recompiles), against ~1,550 s of driver time in three calls. A part that cannot finish trains to the limit in the
# last call and comes back packed in $OUT/carry (a three-seed SAC part ~18 MiB learner-only, bundles of 24 MiB).
# With two GPUs, GPU 2's rows follow GPU 0's and GPU 3's follow GPU 1's.
export ROWS0="reach-avoid-joint-margin/margin-0.25 sac-workspaces/upper"
export ROWS1="sac-workspaces/pandagym"
export ROWS2="sac-workspaces/front"
export ROWS3="sac-workspaces/full-range"
exec bash tools/gpu_rows.sh "$@"
