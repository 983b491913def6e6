#!/bin/bash
# A/B of two megaray builds (or of two scenes with one build), ROUNDS rounds of
# `megaray bench SCENE --threads 1 --reps $REPS --json ARGS` per side, cores swapped every round.
# By default both sides run at the same time, one process per core: both then see the same
# machine (this project's VMs move 10-15% from run to run, so runs one after the other cannot
# tell +5% from noise). With --seq they run in turn on one core (the order swapped every round
# too) and each run's best repetition is its figure (METRIC=best): on a VM whose speed drifts
# from minute to minute the best of several runs is steadier than a median.
#
#   A=old/megaray B=target/release/megaray bench/ab.sh [--seq] ROUNDS SCENE [bench args...]
#   A=old/megaray bench/ab.sh 6 grid.mray --cam close --kinds diffuse_1
#   A=old/megaray bench/ab.sh --seq 6 bunny.mray --cam close --kinds diffuse_1
#   SA=one.mray SB=other.mray bench/ab.sh 6 x --kinds diffuse_1     # two scenes, one binary
#
# A and B default to target/release/megaray; SA and SB, when set, replace SCENE for that side.
# ARGS must not repeat --threads or --reps.
# REPS (default 3); METRIC=median|best (default median, best with --seq); PER_CPU=1 divides each
# figure by its run's cpu_util (CPU seconds per wall second): per CPU second rather than per wall
# second, which takes out the time a busy host stole from the VM. OUT_DIR keeps the rounds
# (A.N.jsonl, B.N.jsonl; default: a temporary directory). Prints per kind each side's median and
# maximum (Mrays/s, Mtris/s for build kinds) and the median and geometric mean of the per-round
# ratios B/A, with every round's (bench/jsonl.py rounds; use an even number of rounds: see the
# geometric mean's note there). A side that fails stops the run with its last error line.
# Needs two cores and taskset (util-linux).
set -u
root=$(cd "$(dirname "$0")/.." && pwd)
usage() { awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit "${1:-2}"; }
case ${1:-} in -h|--help) usage 0 ;; esac
seq=0
[ "${1:-}" = --seq ] && { seq=1; shift; }
[ $# -ge 2 ] || usage
rounds=$1; scene=$2; shift 2
case $rounds in ''|*[!0-9]*|0) echo "ab.sh: ROUNDS must be a positive number, not $rounds" >&2; exit 2 ;; esac
A=${A:-$root/target/release/megaray}
B=${B:-$root/target/release/megaray}
REPS=${REPS:-3}
if [ "$seq" = 1 ]; then METRIC=${METRIC:-best}; else METRIC=${METRIC:-median}; fi
for b in "$A" "$B"; do [ -x "$b" ] || { echo "ab.sh: no megaray at $b (set A and B)" >&2; exit 2; }; done
if [ -n "${OUT_DIR:-}" ]; then
  dir=$OUT_DIR; mkdir -p "$dir" || exit 1; rm -f "$dir"/A.*.jsonl "$dir"/B.*.jsonl
else
  dir=$(mktemp -d) || exit 1; trap 'rm -rf "$dir"' EXIT
fi
# Both sides' lines carry the same row label, so that two scenes (SA, SB) pair up.
label=$scene
[ -n "${SA:-}${SB:-}" ] && label="${SA:-$scene} / ${SB:-$scene}"

# The last line of a failed run's stderr that names an error or a panic, else its last line.
last_error() { grep -iE 'error|panicked' "$1" | tail -n 1 | grep . || tail -n 1 "$1"; }
start() { # SIDE CORE ARGS...: starts one side's run in the background
  local side=$1 core=$2 bin=$A sc=${SA:-$scene}
  shift 2
  [ "$side" = B ] && { bin=$B; sc=${SB:-$scene}; }
  taskset -c "$core" "$bin" bench "$sc" --threads 1 --reps "$REPS" --json -q "$@" > "$dir/$side.out" 2> "$dir/$side.err" &
}
finish() { # SIDE PID: waits for it, then tags its lines into the round's file
  local bin=$A
  [ "$1" = B ] && bin=$B
  if ! wait "$2"; then
    wait # for the other side, if it runs
    echo "ab.sh: side $1 ($bin) failed in round $i: $(last_error "$dir/$1.err")" >&2
    exit 1
  fi
  python3 "$root/bench/jsonl.py" tag "$label" < "$dir/$1.out" > "$dir/$1.$i.jsonl" || exit 1
}
i=1
while [ "$i" -le "$rounds" ]; do
  if [ $((i % 2)) = 1 ]; then first=A; second=B; ca=0; cb=1; else first=B; second=A; ca=1; cb=0; fi
  if [ "$seq" = 1 ]; then
    start $first $((i % 2)) "$@"; finish $first $!
    start $second $((i % 2)) "$@"; finish $second $!
  else
    start A $ca "$@"; pa=$!
    start B $cb "$@"; pb=$!
    finish A $pa; finish B $pb
  fi
  i=$((i + 1))
done
per_cpu=(); [ "${PER_CPU:-0}" = 1 ] && per_cpu=(--per-cpu)
python3 "$root/bench/jsonl.py" rounds "$dir" --base A --new B --metric "$METRIC" ${per_cpu[@]+"${per_cpu[@]}"}
