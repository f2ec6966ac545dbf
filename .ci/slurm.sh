#!/usr/bin/env bash
# Single-node Slurm "cluster" on this machine, for CI and the submitit/requeue tests.
#
# Idempotent: when munged, slurmctld and slurmd run with this configuration and the node answers,
# it does nothing; otherwise it (re)starts what is missing, also after the daemons were killed.
# Needs root and the Debian packages slurm-wlm + munge. No systemd, no cgroups, no accounting DB
# (so `sacct` does not work: use `scontrol show job` / `squeue`).
# Timers are short so that a job past its time limit is signalled, killed or requeued promptly.
set -euo pipefail

STATE=${SLURM_CI_STATE:-/var/spool/slurm-ci}  # state, spool, pid and log files
CONF=/etc/slurm/slurm.conf   # the default path: sbatch, sinfo, submitit need no SLURM_CONF
MARK="# Written by .ci/slurm.sh"  # we only ever overwrite a slurm.conf that carries this line
NODE=$(hostname -s 2>/dev/null || true); NODE=${NODE:-localhost}

die() { echo "slurm.sh: ERROR: $*" >&2; exit 1; }
log() { echo "slurm.sh: $*"; }
# Does the daemon of pid file $STATE/$1.pid run? (A killed daemon can linger as a zombie where
# PID 1 does not reap, as in some containers; that counts as dead.)
alive() {
  local p c st; p=$(cat "$STATE/$1.pid" 2>/dev/null) || return 1
  { read -r _ c st _ < "/proc/$p/stat"; } 2>/dev/null && [ "$c" = "($1)" ] && [ "$st" != Z ]
}
# Compact node state: idle, mix, alloc, idle* (not responding), down*, drain, ...
node_state() { timeout 10 sinfo -h -N -n "$NODE" -o %t 2>/dev/null | head -n1; }
munge_ok() { munge -n 2>/dev/null | unmunge >/dev/null 2>&1; }

[ "$(id -u)" -eq 0 ] || die "must run as root"
for c in munged munge slurmctld slurmd sinfo scontrol sbatch srun; do
  command -v "$c" >/dev/null || die "'$c' not found: apt-get install slurm-wlm munge"
done
# One run at a time (parallel test workers may call us together); a waiting run then finds the
# cluster healthy. Every daemon below is started with 9>&- so that none keeps this lock.
mkdir -p "$STATE/ctld" "$STATE/d"
exec 9>"$STATE/.lock"; flock -w 120 9 || die "another run of slurm.sh holds $STATE/.lock"

# --- munge, Slurm's authentication: create a key if missing; run munged as user munge (as
# systemd would). --force: ignore a stale socket left by a killed munged.
if ! munge_ok; then
  install -d -o munge -g munge -m 0755 /run/munge
  install -d -o munge -g munge -m 0700 /etc/munge /var/lib/munge /var/log/munge
  if [ ! -s /etc/munge/munge.key ]; then
    log "creating /etc/munge/munge.key"
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
  fi
  chown munge:munge /etc/munge/munge.key; chmod 0400 /etc/munge/munge.key
  log "starting munged"; runuser -u munge -- munged --force 9>&-
  for _ in $(seq 20); do munge_ok && break; sleep 0.5; done
  munge_ok || die "munged does not answer, see /var/log/munge/munged.log"
fi

# --- slurm.conf. Node size from `slurmd -C`, i.e. what slurmd will report itself (a node that
# reports less than configured is drained); else nproc and /proc/meminfo.
HW=$(slurmd -C 2>/dev/null | head -n1 | grep -oE '(CPUs|RealMemory)=[0-9]+' | paste -sd' ' || true)
[[ "$HW" == *CPUs=*RealMemory=* ]] \
  || HW="CPUs=$(nproc) RealMemory=$(awk '/MemTotal/ {print int($2 / 1024)}' /proc/meminfo)"
NEW=$(cat <<EOF
$MARK -- single-node test cluster; rerun the script to regenerate.
ClusterName=ci
# 127.0.0.1, so that it works even where \`hostname -s\` does not resolve.
SlurmctldHost=$NODE(127.0.0.1)
SlurmUser=root
AuthType=auth/munge
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/d
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=$STATE/slurmctld.log
SlurmdLogFile=$STATE/slurmd.log
# No cgroups (containers, no systemd): find a job's processes through /proc, no containment.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
# No accounting DB, so no sacct; scontrol shows a finished job for MinJobAge seconds.
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MinJobAge=600
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
MailProg=/bin/true
# Batch jobs may be requeued (submitit runs \`scontrol requeue\` on its timeout signal).
JobRequeue=1
# slurmctld tests time limits and sends --signal warnings every 30 s (compiled in): a job is
# killed 0-30 s after its limit, SIGTERM first, SIGKILL KillWait seconds later.
KillWait=5
OverTimeLimit=0
MessageTimeout=10
InactiveLimit=0
# A requeued job may start again cred_expire+1 s after the requeue (default 120 s, minimum 5).
AuthInfo=cred_expire=10
# Full scheduling pass every 2 s (default 60), so a requeued job starts once it is eligible.
SchedulerType=sched/backfill
SchedulerParameters=sched_interval=2
# A node marked down (its slurmd was killed) returns to service when slurmd registers again.
ReturnToService=2
SlurmdTimeout=120
NodeName=$NODE NodeAddr=127.0.0.1 $HW State=UNKNOWN
PartitionName=debug Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
)

# --- nothing to do when all runs with this configuration (sinfo only once the daemons run:
# with slurmctld down it takes ~10 s to give up).
if munge_ok && [ "$(cat "$CONF" 2>/dev/null)" = "$NEW" ] && alive slurmctld && alive slurmd \
  && [[ "$(node_state)" =~ ^(idle|mix|alloc)$ ]]; then
  log "already running, node $NODE is $(node_state)"; exit 0
fi
if [ -e "$CONF" ] && ! grep -qF "$MARK" "$CONF"; then
  die "$CONF exists and was not written by this script; not touching it (move it away first)"
fi
if [ "$(cat "$CONF" 2>/dev/null)" != "$NEW" ]; then
  log "writing $CONF ($HW)"
  mkdir -p "$(dirname "$CONF")"; printf '%s\n' "$NEW" > "$CONF"
  # The configuration changed: stop our daemons (through their pid files) so they reread it.
  for d in slurmd slurmctld; do if alive $d; then kill "$(cat "$STATE/$d.pid")"; fi; done
  for _ in $(seq 20); do alive slurmctld || alive slurmd || break; sleep 0.5; done
fi

# --- daemons; they fork into the background. slurmctld reloads its job state from $STATE.
if ! alive slurmctld; then
  log "starting slurmctld"; slurmctld 9>&- || die "slurmctld did not start, see $STATE/slurmctld.log"
fi
if ! alive slurmd; then
  log "starting slurmd"; slurmd -N "$NODE" 9>&- || die "slurmd did not start, see $STATE/slurmd.log"
fi

# --- wait (60 s at most) until the node is usable; resume it once if it was left down/drained.
resumed=0; end=$((SECONDS + 60)); st=""
while [ $SECONDS -lt $end ]; do
  st=$(node_state)
  if [[ "$st" =~ ^(idle|mix|alloc)$ ]]; then log "ready: node $NODE is $st"; exit 0; fi
  if [[ "$st" =~ ^(down|drain|drng|fail) ]] && [ $resumed -eq 0 ]; then
    scontrol update NodeName="$NODE" State=RESUME 2>/dev/null && resumed=1 || true
  fi
  sleep 1
done
die "node $NODE is not idle after 60 s (state: '${st:-no answer}'), see $STATE/slurmctld.log" \
  "and $STATE/slurmd.log"
