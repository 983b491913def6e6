#!/bin/sh
# Compares megaray builds by their best figures: each binary runs in turn on one core (cores
# alternating by round), and per ray kind the best `mrays_s_best` of each run is kept. On a
# shared VM, whose speed drifts by 10-30% from minute to minute, the best of several runs is
# steadier than a median; bench/ab.sh (both at once, one per core) is the other way.
#
#   bench/best.sh ROUNDS SCENE BIN... -- [bench args...]
#   bench/best.sh 6 bunny.mray old/megaray target/release/megaray -- --cam close --kinds diffuse_1 --reps 3
#
# Prints per kind and binary the maximum and median over the rounds, and every round's figure.
set -e
[ $# -ge 3 ] || { sed -n '2,9p' "$0"; exit 2; }
rounds=$1; scene=$2; shift 2
bins=""
while [ $# -gt 0 ] && [ "$1" != "--" ]; do bins="$bins $1"; shift; done
[ "$1" = "--" ] && shift
i=1
while [ "$i" -le "$rounds" ]; do
  for b in $bins; do
    taskset -c $((i % 2)) "$b" bench "$scene" --threads 1 --json "$@" 2>/dev/null | grep '^{' | sed "s|^|$b |"
  done
  i=$((i + 1))
done | python3 -c '
import collections, json, sys
best = collections.defaultdict(list)
for line in sys.stdin:
    b, j = line.split(" ", 1)
    r = json.loads(j)
    if "mrays_s_best" in r:
        best[(r["kind"], b)].append(r["mrays_s_best"])
for (k, b), v in sorted(best.items()):
    v.sort()
    print("%-11s %-36s max %7.3f  med %7.3f  all %s" % (k, b, v[-1], v[len(v) // 2], v))
'
