#!/bin/bash
# Next session's calls (any number of GPUs). Usage: bash .devcall/next.sh LIMIT [last]
# One driver over every GPU, --round-robin: parts with a checkpoint first, then a seed of each row.
# .carry/ (git-ignored, carried): the previous machine's pieces, put into runs/ by --carry-in (a part newer here is kept);
# CARRY_IN=.carry_b for a second bundle (--carry-out's $OUT/carry/more-1), carried by another call of the same machine.
# last: --carry-out packs the unfinished parts into $OUT/carry (the runner stops training early enough for it).
# $OUT ends with rec.tgz (logs and records) and the carry pieces only: a call brings back at most 8 files.
LIMIT=$1; LAST=$2
start=$(date +%s)
CARRY_IN=${CARRY_IN:-.carry}  # the bundle this call carries (name it in the call's carry list)
L=/tmp/calllogs; rm -rf $L; mkdir -p $L/w $CARRY_IN
nvidia-smi --query-gpu=index,name --format=csv,noheader > $L/gpus.txt
CARRY="--carry-in $CARRY_IN"; [ "$LAST" = last ] && CARRY="$CARRY --carry-out $OUT/carry"
ROWS=${ROWS:-"sac-fast/panda-reach-plus-200m sac-fast/panda-reach-avoid-plus-200m relative-step/step-0.6 reach-avoid-joint-margin/margin-0.25"}
python -m tools.experiments run $ROWS --parallel --round-robin --max-seeds 1 --time-limit $LIMIT --no-build \
  --worker-logs $L/w $CARRY $EXTRA > $L/driver.log 2>&1
tar czf $OUT/rec.tgz $L $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $L/gpus.txt; tail -30 $L/driver.log; ls -laR $OUT 2>/dev/null | head -30
echo "call done $(date) elapsed $(( $(date +%s) - start ))"
