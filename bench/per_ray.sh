#!/bin/sh
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
# so that loading, building and the warm-up cancel. Output files: $OUT (default /tmp/per_ray).
set -e
TAG=$1; shift
OUT=${OUT:-/tmp/per_ray}
mkdir -p "$OUT"
for r in 1 3; do
  valgrind --tool=cachegrind --cache-sim=yes --branch-sim=yes --cachegrind-out-file="$OUT/$TAG.$r" \
    "$@" --reps $r > "$OUT/$TAG.$r.out" 2> "$OUT/$TAG.$r.err"
done
python3 - "$OUT/$TAG" <<'PY'
import sys, json
def totals(f):
    ev = None
    for l in open(f):
        if l.startswith('events:'): ev = l.split()[1:]
        if l.startswith('summary:'): return dict(zip(ev, map(int, l.split()[1:])))
a, b = totals(sys.argv[1] + '.1'), totals(sys.argv[1] + '.3')
rays = next(json.loads(l)['rays'] for l in open(sys.argv[1] + '.1.out') if l.startswith('{') and '"rays"' in l)
print(sys.argv[1], 'rays', rays, ' '.join(f"{k}={(b[k] - a[k]) / 2 / rays:.2f}" for k in ['Ir', 'Dr', 'D1mr', 'Bc', 'Bcm'] if k in a))
PY
