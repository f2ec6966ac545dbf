#!/usr/bin/env bash
# Trains registered runs on a GPU host that takes one command of limited length (see README.md):
#
#   REACH_AVOID_CODE_VERSION=<commit> bash dev/train_within.sh SECONDS EXPERIMENT/RUN [EXPERIMENT/RUN ...]
#   TRAIN_GPU=1 bash dev/train_within.sh ...   # this GPU alone, its own folders and archive
#   TRAIN_MAX_SEEDS=2 bash dev/train_within.sh ...   # seeds trained together in one process (default 1)
#
# TRAIN_GPU=N gives each GPU its own list of runs (one launch per GPU, started side by side), where one launch would
# hand its parts to the GPUs in a single order. A part resumes only under the TRAIN_GPU it started with.
#
# Installs the wheels of .whl/, copies the tree to /tmp/x/repo (/tmp/x-gpuN/repo) and runs `tools.experiments launch
# ... --executor local --max-seeds 1` there (one seed per process; TRAIN_MAX_SEEDS=N for N), recording into the
# copy's results/experiments: the parts the tree already holds are not trained again. It shows the launch's first output after at most 30 s (a refused
# launch ends the command then, with its exit status), waits until the launch ends or SECONDS have passed since the
# script started, and packs the parts finished since it started (their runs/ files under results/experiments/), their
# newest policy exports (exports/<experiment>/<run>/<part>/: for eval.py and tools.failure_report on a CPU), the job
# logs and the launch log into $OUT/experiments.tgz (experiments-gpuN.tgz with TRAIN_GPU=N): `tar xzf ARCHIVE results`
# in the tree puts the parts in place. Give SECONDS about 30 less than the command's limit; the script exits 3 when
# the deadline came first. Parts still training then stop with the command (the host ends its processes); the same
# call in a later command on the warm host resumes them from their last checkpoint, since the runs folder is kept.
set -u
gpu="${TRAIN_GPU:-}"
max_seeds="${TRAIN_MAX_SEEDS:-1}"
if ! [[ $max_seeds =~ ^[1-9][0-9]*$ ]]; then
  echo "TRAIN_MAX_SEEDS=$max_seeds is invalid: a number of seeds >= 1" >&2
  exit 2
fi
if [ -n "$gpu" ] && ! [[ $gpu =~ ^[0-9]+$ ]]; then
  echo "TRAIN_GPU=$gpu is invalid: one GPU index (0, 1, ...)" >&2
  exit 2
fi
work=/tmp/x${gpu:+-gpu$gpu}
site=/tmp/site${gpu:+-gpu$gpu}  # each launch imports from its own copy, which no other install replaces under it
archive="experiments${gpu:+-gpu$gpu}.tgz"

exports() {  # the policy export of each part evaluated since the launch started, as exports/<exp>/<run>/<part>/
  rm -rf "$work/exports"
  mkdir -p "$work/exports"
  (cd "$work/runs" 2>/dev/null && find . -name eval.json -newer "$work/started") | while read -r done; do
    part=$(dirname "$done")
    step=$(ls "$work/runs/$part/checkpoints" 2>/dev/null | grep -E '^[0-9]+$' | sort -n | tail -n 1)
    policy="$work/runs/$part/checkpoints/$step/policy"
    if [ -n "$step" ] && [ -f "$policy/policy.json" ]; then
      mkdir -p "$work/exports/$part" && cp "$policy"/policy.* "$work/exports/$part/"
    fi
  done
}

pack() {  # the parts recorded since the launch started, with their policy exports and the job and launch logs
  (cd "$work/repo" && find results/experiments -path '*/runs/*' -type f -newer "$work/started" -print0) \
    > "$work/parts.list"
  exports
  tar czf "$OUT/$archive" -C "$work/repo" --null -T "$work/parts.list" -C "$work" jobs launch.log exports
  echo "packed $(tr -cd '\0' < "$work/parts.list" | wc -c) files of finished parts and" \
    "$(find "$work/exports" -name policy.json | wc -l) policy exports (eval.py --checkpoint exports/EXP/RUN/PART)"
}

: "${OUT:?the folder that comes back}"
if [ $# -lt 2 ] || ! [[ $1 =~ ^[0-9]+$ ]]; then
  echo "usage: REACH_AVOID_CODE_VERSION=<commit> bash dev/train_within.sh SECONDS EXPERIMENT/RUN [...]" >&2
  exit 2
fi
deadline=$(( $(date +%s) + $1 ))
shift
: "${REACH_AVOID_CODE_VERSION:?set it to the commit the tree holds (the copy has no .git)}"
mkdir -p "$work"
exec 9> "$work.lock"
if command -v flock > /dev/null && ! flock -n 9; then
  echo "another launch holds $work (TRAIN_GPU=${gpu:-unset}); wait for it" >&2
  exit 2
fi
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$site" .whl/*.whl \
  || exit 1
# A fresh copy of the tree and job logs; the runs' folders ($work/runs: a part stopped early resumes from its
# checkpoint) and the compilation cache ($work/jc) are kept.
rm -rf "$work/repo" "$work/jobs"
mkdir -p "$work/jobs"
cp -r . "$work/repo"
cd "$work/repo" || exit 1
touch "$work/started"
export PYTHONPATH="$site:$PWD" PYTHONUNBUFFERED=1 REACH_AVOID_CODE_VERSION
nvidia-smi -L
[ -n "$gpu" ] && export CUDA_VISIBLE_DEVICES="$gpu"
python3 -m tools.experiments launch "$@" --executor local --max-seeds "$max_seeds" --runs-dir "$work/runs" \
  --jobs-dir "$work/jobs" --compilation-cache "$work/jc" > "$work/launch.log" 2>&1 &
launch=$!
for _ in $(seq 30); do
  kill -0 "$launch" 2>/dev/null || break
  sleep 1
done
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
