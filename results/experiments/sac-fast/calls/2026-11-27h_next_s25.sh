#!/bin/bash
# Twentieth session's calls (two GPUs, or four), from the repository root:
#   bash results/experiments/sac-fast/calls/2026-11-27h_next_s25.sh CALL LIMIT [last]
# The nineteenth session's last call packed two parts: sac-workspaces/upper seed 0 at 30.4M of 40M steps (5.9 MiB)
# and sac-workspaces/pandagym seeds 0-2 at 34.4M (17.6 MiB). Call 1 carries [".whl", ".carry"] with only upper's
# bundle in .carry (the tree, slimmed wheels and it: ~57 of the 64 MiB); call 2 carries [".carry"] with only
# pandagym's (~49 MiB); call 3 carries nothing. Rows whose bundle has not arrived stay out of a call (they would
# start afresh), so the rows change with the call.
# Two GPUs (group i on GPU i mod 2): GPU 0 finishes upper seed 0 (~355 s at 32.9k env steps/s) and starts upper
# seeds 1-2 in call 1; in calls 2-3 it finishes pandagym (~290 s at 26.4k a seed), then trains upper seeds 1-2.
# GPU 1 trains front's three seeds (~1,650 s with a start-up and compilation per call: it comes back packed, with
# upper seeds 1-2). Four GPUs: the same, with full-range (not started yet) on GPU 3, and upper on GPUs 0 and 2 in
# call 1 (group 2 is empty, so its GPU joins group 0: seed 0 and seeds 1-2 side by side), on GPU 2 from call 2.
case "$1" in
  1) export ROWS0="sac-workspaces/upper" ROWS2="" ;;
  *) export ROWS0="sac-workspaces/pandagym" ROWS2="sac-workspaces/upper" ;;
esac
export ROWS1="sac-workspaces/front" ROWS3="sac-workspaces/full-range"
exec bash tools/gpu_rows.sh "$@"
