#!/bin/sh
# Compares two megaray builds (or two scenes) by running both at the same time, one process per
# core, swapping the cores each round: both sides then see the same machine (this project's VMs
# move 10-15% from run to run, so interleaved single runs cannot tell +5% from noise).
#
#   A=old/megaray B=target/release/megaray bench/ab.sh ROUNDS SCENE [bench args...]
#   SA=one.mray SB=other.mray bench/ab.sh 6 x --cam close --kinds diffuse_1   # two scenes, one binary
#
# A and B default to target/release/megaray; SA and SB, when set, replace SCENE for that side.
# Each side runs `megaray bench SCENE --threads 1 --reps 3 --json ARGS`. Prints, per ray kind,
# the median Mrays/s (Mtris/s for build kinds) of each side and the median and geometric mean of the
# per-round ratios B/A (with every round's; use an even number of rounds: see the geometric mean's note).
# With PER_CPU=1 each figure is divided by the run's cpu_util (CPU seconds per wall second):
# per CPU second rather than per wall second, which takes out the time a busy host stole
# from the VM (its steal time is not the process's CPU time).
# Needs two cores and taskset (util-linux).
set -e
[ $# -ge 2 ] || { sed -n '2,12p' "$0"; exit 2; }
rounds=$1; scene=$2; shift 2
root=$(cd "$(dirname "$0")/.." && pwd)
A=${A:-$root/target/release/megaray}
B=${B:-$root/target/release/megaray}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
i=1
while [ "$i" -le "$rounds" ]; do
  if [ $((i % 2)) = 1 ]; then ca=0; cb=1; else ca=1; cb=0; fi
  taskset -c $ca "$A" bench "${SA:-$scene}" --threads 1 --reps 3 --json "$@" > "$tmp/A.$i" 2>/dev/null &
  taskset -c $cb "$B" bench "${SB:-$scene}" --threads 1 --reps 3 --json "$@" > "$tmp/B.$i" 2>/dev/null &
  wait
  i=$((i + 1))
done
python3 "$root/bench/round_ratios.py" "$tmp" "$rounds" A B "${PER_CPU:-0}"
