#!/bin/bash
# Counts per ray under valgrind's cachegrind (instructions, data reads, L1 data misses,
# conditional branches and their mispredictions), for megaray or the Embree peer alike.
#
#   bench/per_ray.sh TAG CMD...
#
# CMD is a bench command line without --reps, e.g.
#   bench/per_ray.sh ours target/release/megaray bench grid.mray --cam close --res 128x128 \
#       --threads 1 --min-ms 1 --kinds diffuse_1 --json
#   bench/per_ray.sh peer ../shared/peers/embree/embree_bench grid.ply --cam-offset 0,0.3,0.6 \
#       --res 128x128 --threads 1 --min-ms 1 --kinds diffuse_1
# It runs CMD with --reps 1 and --reps 3 and prints (counts of 3 - counts of 1) / 2 / rays,
# so that loading, building and the warm-up cancel (rays: from CMD's JSON lines, through
# bench/jsonl.py get). Output files: $OUT (default /tmp/per_ray).
set -u
[ $# -ge 2 ] || { awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit 2; }
root=$(cd "$(dirname "$0")/.." && pwd)
TAG=$1; shift
OUT=${OUT:-/tmp/per_ray}
mkdir -p "$OUT" || exit 1
for r in 1 3; do
  valgrind --tool=cachegrind --cache-sim=yes --branch-sim=yes --cachegrind-out-file="$OUT/$TAG.$r" \
    "$@" --reps $r > "$OUT/$TAG.$r.out" 2> "$OUT/$TAG.$r.err" ||
    { echo "per_ray.sh: CMD --reps $r failed: $(tail -n 1 "$OUT/$TAG.$r.err")" >&2; exit 1; }
done
rays=$(python3 "$root/bench/jsonl.py" get rays "$OUT/$TAG.1.out") || exit 1
# cachegrind's files: an "events:" line names the counters, the "summary:" line totals them.
awk -v rays="$rays" -v tag="$OUT/$TAG" '
  /^events:/ { split($0, ev, " ") }
  /^summary:/ { f++; for (i = 2; i <= NF; i++) v[f, ev[i]] = $i }
  END {
    line = tag " rays " rays
    n = split("Ir Dr D1mr Bc Bcm", want, " ")
    for (j = 1; j <= n; j++)
      if ((1, want[j]) in v) line = line sprintf(" %s=%.2f", want[j], (v[2, want[j]] - v[1, want[j]]) / 2 / rays)
    print line
  }' "$OUT/$TAG.1" "$OUT/$TAG.3"
