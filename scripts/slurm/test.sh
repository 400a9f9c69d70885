#!/usr/bin/env bash
# A real Slurm run of a split render, on this machine: brings up a one-node
# Slurm (Debian's slurm-wlm and munge, installed with apt-get when missing;
# run as root), submits a job array of N parts and a merge job that depends on
# it (afterok), waits, and compares the merged PNG byte for byte with a
# single-machine `rothray render` of the same scene and flags.
#
#   scripts/slurm/test.sh            # N = 4 (ROTHRAY_SLURM_N overrides)
#
# Every daemon it starts (munged, slurmctld, slurmd) runs in a temporary
# folder with its own key, sockets, ports, state and logs, and is stopped by
# its pid on exit, failure included. Exit status: 0 when the images are
# identical, 1 on any difference or failure.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
N=${ROTHRAY_SLURM_N:-4}
say() { echo "slurm/test.sh: $*"; }
die() { say "FAIL: $*" >&2; exit 1; }

if [ "$(id -u)" -ne 0 ]; then
  die "run as root: the one-node Slurm runs its daemons as root (SlurmUser=root)"
fi
need=()
command -v slurmctld >/dev/null 2>&1 && command -v slurmd >/dev/null 2>&1 && command -v sbatch >/dev/null 2>&1 || need+=(slurm-wlm)
command -v munged >/dev/null 2>&1 || need+=(munge)
if [ ${#need[@]} -gt 0 ]; then
  say "installing ${need[*]} (Debian packages)"
  apt-get update -qq || true
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need[@]}" >/dev/null || die "could not install ${need[*]}"
fi

target=${CARGO_TARGET_DIR:-$root/target}
cargo build --release -q
bin=$target/release/rothray
[ -x "$bin" ] || die "no binary at $bin"
t_start=$(date +%s)  # after the build: the times below are Slurm's

tmp=$(mktemp -d /tmp/rothray-slurm.XXXXXX)
chmod 700 "$tmp"
pids=()
jobs_submitted=()
cleanup() {
  local rc=$?
  set +e
  if [ ${#jobs_submitted[@]} -gt 0 ] && [ -n "${SLURM_CONF:-}" ]; then
    scancel "${jobs_submitted[@]}" >/dev/null 2>&1
  fi
  # Stop the daemons we started, newest first, each by its pid.
  for ((k = ${#pids[@]} - 1; k >= 0; k--)); do
    kill "${pids[k]}" 2>/dev/null
  done
  for p in "${pids[@]}"; do
    for _ in $(seq 50); do kill -0 "$p" 2>/dev/null || break; sleep 0.1; done
    kill -9 "$p" 2>/dev/null
    wait "$p" 2>/dev/null
  done
  if [ $rc -ne 0 ]; then
    for f in "$tmp"/*.log "$tmp"/out/*; do
      [ -f "$f" ] && { echo "---- $f (last lines)"; tail -n 20 "$f"; }
    done
    say "FAILED after $(($(date +%s) - t_start)) s (logs above; kept in $tmp)" >&2
  else
    rm -rf "$tmp"
  fi
  exit $rc
}
trap cleanup EXIT
trap 'exit 1' INT TERM

host=$(hostname -s)
cpus=$(nproc)
# Ports of our own, away from a system Slurm's 6817/6818.
base=$((20000 + RANDOM % 20000))
mkdir -p "$tmp/state" "$tmp/spool" "$tmp/out" "$tmp/parts"

# munge: its own key, socket, pid and log files.
dd if=/dev/urandom of="$tmp/munge.key" bs=1024 count=1 status=none
chmod 400 "$tmp/munge.key"
munged --force --foreground --key-file="$tmp/munge.key" --socket="$tmp/munge.sock" \
  --pid-file="$tmp/munged.pid" --log-file="$tmp/munged.log" --seed-file="$tmp/munged.seed" \
  >"$tmp/munged.out.log" 2>&1 &
pids+=($!)
for _ in $(seq 50); do [ -S "$tmp/munge.sock" ] && break; sleep 0.1; done
[ -S "$tmp/munge.sock" ] || die "munged did not start"

export SLURM_CONF=$tmp/slurm.conf
cat >"$SLURM_CONF" <<EOF
ClusterName=rothray-test
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$tmp/munge.sock
CredType=cred/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
SlurmctldPort=$base
SlurmdPort=$((base + 1))
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/slurmctld.pid
SlurmdPidFile=$tmp/slurmd.pid
SlurmctldLogFile=$tmp/slurmctld.log
SlurmdLogFile=$tmp/slurmd.log
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
JobAcctGatherType=jobacct_gather/none
MpiDefault=none
ReturnToService=2
MinJobAge=600
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=test Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF

slurmctld -D -i >"$tmp/slurmctld.out.log" 2>&1 &
pids+=($!)
slurmd -D -N "$host" >"$tmp/slurmd.out.log" 2>&1 &
pids+=($!)

state=""
for _ in $(seq 120); do
  state=$(sinfo -h -N -n "$host" -o %t 2>/dev/null | head -n 1 || true)
  [ "$state" = idle ] && break
  for p in "${pids[@]}"; do kill -0 "$p" 2>/dev/null || die "a daemon (pid $p) exited while starting"; done
  sleep 0.5
done
[ "$state" = idle ] || die "node $host is not idle after 60 s (state: '${state:-none}')"
say "one-node Slurm up on $host ($cpus CPUs) after $(($(date +%s) - t_start)) s"

scene=$root/scenes/sampler.json
flags=(--width 320 --height 180 --spp 2)
export ROTHRAY=$bin
array=$(sbatch --parsable --chdir="$tmp" --output="$tmp/out/part-%A_%a.log" --array=0-$((N - 1)) \
  scripts/slurm/render-array.sbatch "$scene" "$tmp/parts" "${flags[@]}")
array=${array%%;*}
jobs_submitted+=("$array")
merge=$(sbatch --parsable --chdir="$tmp" --output="$tmp/out/merge-%j.log" --dependency=afterok:"$array" \
  scripts/slurm/merge.sbatch "$tmp/parts" "$tmp/merged.png")
merge=${merge%%;*}
jobs_submitted+=("$merge")
say "submitted array $array (N = $N) and merge $merge (afterok:$array)"

# The single-machine render, while Slurm works.
"$bin" render "$scene" -o "$tmp/single.png" "${flags[@]}"

job_state() { scontrol show job "$1" 2>/dev/null | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p' | head -n 1; }
for _ in $(seq 240); do
  [ -z "$(squeue -h -j "$array,$merge" 2>/dev/null)" ] && break
  sleep 0.5
done
[ -z "$(squeue -h -j "$array,$merge" 2>/dev/null)" ] || die "jobs still queued or running after 120 s: $(squeue -h -j "$array,$merge")"
ms=$(job_state "$merge")
[ "$ms" = COMPLETED ] || die "merge job $merge ended $ms"
for ((i = 0; i < N; i++)); do
  s=$(job_state "${array}_$i")
  [ "$s" = COMPLETED ] || die "array task ${array}_$i ended $s"
done
[ -f "$tmp/merged.png" ] || die "no merged PNG"
cmp "$tmp/single.png" "$tmp/merged.png" || die "merged PNG differs from the single render"
say "PASS: $N parts rendered by Slurm and merged equal the single render byte for byte ($(($(date +%s) - t_start)) s)"
