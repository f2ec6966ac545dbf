#!/bin/bash
# Eleventh session's calls (four GPUs). Usage: bash .devcall/s13.sh LIMIT [last]
# GPU $RA_GPU (0): Panda reach-avoid 200M (seed 4 carried in .carry at 56M; --carry-in .carry), then, once that
#   driver exits (at once when the row is done), PPO rows $PPO_ROWS_B (--max-seeds 3, run after run).
# GPUs $SAC_GPUS (1,2): the paper-setting SAC rows (sac-reach), one five-seed part a GPU.
# GPUs $PPO_GPUS (3): PPO rows $PPO_ROWS (--max-seeds 3, run after run).
# last: the Panda and SAC drivers pack their unfinished parts: $OUT/carry (Panda; none if seed 4 is done),
#   $OUT/carry_sac (30 MiB bundles: one five-seed SAC part each, 2 pieces). The PPO drivers train only the parts
#   that finish (--whole-parts): a 3-seed PPO part is 9-14 MiB and the 64 MiB a call brings back hold the SAC parts.
LIMIT=$1; LAST=$2
start=$(date +%s)
RA_GPU=${RA_GPU-0}; SAC_GPUS=${SAC_GPUS-1,2}; PPO_GPUS=${PPO_GPUS-3}
PPO_ROWS=${PPO_ROWS:-"action-space/absolute reward"}; PPO_ROWS_B=${PPO_ROWS_B:-"joint-penalties"}
L=/tmp/calllogs; rm -rf $L; mkdir -p $L/w $L/w3 $L/w4 $L/w5 .carry
left() { echo $(( LIMIT - ($(date +%s) - start) )); }
nvidia-smi --query-gpu=index,name --format=csv,noheader > $L/gpus.txt
co() { [ "$LAST" = last ] && echo "--carry-out $OUT/$1 $2"; }
wp() { [ "$LAST" = last ] && echo "--whole-parts"; }  # PPO in the last call: only parts that finish (no room to carry them)
P=""; S=""; Q=""; R=""
if [ -n "$RA_GPU" ]; then
( CUDA_VISIBLE_DEVICES=$RA_GPU python -m tools.experiments run sac-fast/panda-reach-avoid-plus-200m --parallel \
    --round-robin --max-seeds 1 --time-limit $LIMIT --no-build --worker-logs $L/w --carry-in .carry $(co carry) > $L/driver.log 2>&1
  [ $(left) -gt 120 ] || exit 0
  CUDA_VISIBLE_DEVICES=$RA_GPU python -m tools.experiments run $PPO_ROWS_B --parallel --max-seeds 3 \
    --time-limit $(left) --no-build --worker-logs $L/w5 $(wp) > $L/driver_ppo_b.log 2>&1 ) &
P=$!; fi
if [ -n "$SAC_GPUS" ]; then
CUDA_VISIBLE_DEVICES=$SAC_GPUS python -m tools.experiments run sac-reach --parallel --time-limit $LIMIT --no-build \
  --worker-logs $L/w3 $(co carry_sac "--carry-max-mb 30") > $L/driver_sac.log 2>&1 &
S=$!; fi
if [ -n "$PPO_GPUS" ]; then
CUDA_VISIBLE_DEVICES=$PPO_GPUS python -m tools.experiments run $PPO_ROWS --parallel --max-seeds 3 \
  --time-limit $LIMIT --no-build --worker-logs $L/w4 $(wp) > $L/driver_ppo.log 2>&1 &
Q=$!; fi
wait $P $S $Q
tar czf $OUT/rec.tgz $L $(find runs/experiments \( -name config.json -o -name eval.json -o -name 'cross-*.json' -o -name metrics.csv \) -not -path '*/checkpoints/*' 2>/dev/null)
cat $L/gpus.txt; for d in $L/driver*.log; do echo "== $d"; tail -6 $d; done
for f in $L/w*/*; do echo "== $f"; grep "steps/s" $f | tail -1; tail -2 $f; done
ls -laR $OUT | head -40
echo "call done $(date) elapsed $(( $(date +%s) - start ))"
