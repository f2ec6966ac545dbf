#!/usr/bin/env bash
# Trains registered runs on a GPU host that takes one command of limited length (see README.md):
#
#   REACH_AVOID_CODE_VERSION=<commit> bash dev/train_within.sh SECONDS EXPERIMENT/RUN [EXPERIMENT/RUN ...]
#
# Installs the wheels of .whl/, copies the tree to /tmp/x/repo and runs `tools.experiments launch ... --executor
# local --max-seeds 1` there (one seed per GPU). It shows the launch's first output after 30 s (a refused launch ends
# the command then, with its exit status), waits until the launch ends or SECONDS have passed since the script
# started, and packs the finished parts, job logs and launch log into $OUT/experiments.tgz. Give SECONDS about 30
# less than the command's limit; the script exits 3 when the deadline came first. Parts still training at the
# deadline keep running on a host that stays warm: a later command can pack them with `tar czf $OUT/experiments.tgz
# -C /tmp/x out jobs launch.log`.
set -u
if [ $# -lt 2 ]; then
  echo "usage: REACH_AVOID_CODE_VERSION=<commit> bash dev/train_within.sh SECONDS EXPERIMENT/RUN [...]" >&2
  exit 2
fi
deadline=$(( $(date +%s) + $1 ))
shift
: "${REACH_AVOID_CODE_VERSION:?set it to the commit the tree holds (the copy has no .git)}"
: "${OUT:?the folder that comes back}"
work=/tmp/x
pack() { tar czf "$OUT/experiments.tgz" -C "$work" out jobs launch.log 2>/dev/null; ls -l "$OUT"; }

python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
  || exit 1
mkdir -p "$work/out" "$work/jobs"
rm -rf "$work/repo"
cp -r . "$work/repo"
cd "$work/repo" || exit 1
export PYTHONPATH="/tmp/site:$PWD" PYTHONUNBUFFERED=1 REACH_AVOID_CODE_VERSION
nvidia-smi -L
python3 -m tools.experiments launch "$@" --executor local --max-seeds 1 --runs-dir "$work/runs" --out "$work/out" \
  --jobs-dir "$work/jobs" --compilation-cache "$work/jc" > "$work/launch.log" 2>&1 &
launch=$!
sleep 30
cat "$work/launch.log"
if ! kill -0 "$launch" 2>/dev/null; then
  wait "$launch"
  status=$?
  echo "the launch ended within 30 s (exit $status)"
  pack
  exit "$status"
fi
while kill -0 "$launch" 2>/dev/null && [ "$(date +%s)" -lt "$deadline" ]; do
  sleep 5
done
status=0
if kill -0 "$launch" 2>/dev/null; then
  echo "deadline reached with the launch still running; packing what finished"
  status=3
else
  wait "$launch"
  status=$?
  echo "the launch ended (exit $status)"
fi
tail -n 20 "$work/launch.log"
pack
exit "$status"
