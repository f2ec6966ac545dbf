#!/bin/bash
# Twenty-first session's calls (two GPUs or more), from the repository root:
#   bash results/experiments/sac-fast/calls/2026-11-27i_next_s26.sh 1
#   bash results/experiments/sac-fast/calls/2026-11-27i_next_s26.sh 2 LIMIT
# The twentieth session's last call packed sac-workspaces/front and full-range, seeds 0-2 each at 35.2M of 40M steps
# (17.6 MiB each). The tree (~31 MiB) and the slimmed wheels (20.1 MiB) leave a first call ~13 MiB, so front's archive
# is re-split into 10 MiB pieces: call 1 carries [".whl", ".carry"] with piece .000 in .carry, installs the wheels
# and keeps the piece on the machine (/tmp/stash); call 2 carries [".carry"] with front's piece .001 and full-range's
# two pieces, puts the kept piece beside them and trains both rows to the end, one per GPU (~180 s each at 26.5k env
# steps/s a seed, plus compilation and evaluation), as the machine's last call: what does not finish is packed.
set -u
case "$1" in
  1)
    mkdir -p /tmp/stash && cp .carry/* /tmp/stash/ && ls -la /tmp/stash ;;
  2)
    cp /tmp/stash/* .carry/ || exit 4
    export ROWS0="sac-workspaces/front" ROWS1="sac-workspaces/full-range"
    exec bash tools/gpu_rows.sh 2 "$2" last ;;
  *)
    echo "usage: $0 1 | $0 2 LIMIT" >&2; exit 2 ;;
esac
