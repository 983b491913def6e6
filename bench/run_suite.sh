#!/bin/sh
# Runs megaray's standard benchmark suite (shared/BENCH.md) and compares it with the peer's.
#
#   bench/run_suite.sh                       all scenes, 1024x1024, 5 repetitions, 1 and 2 threads
#   ONLY="bunny grid1000" bench/run_suite.sh  a subset (names as in the peer's results/*.jsonl)
#   REPS=3 MIN_MS=100 bench/run_suite.sh      quicker, noisier
#
# Output: bench/results/megaray.jsonl (one JSON object per figure, as the peer harness prints),
# then the ratios against shared/peers/embree/results/*.jsonl (shared/bench/compare.py).
# Run it within minutes of the peer's run_all.sh, on an otherwise idle machine.
set -e
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
SHARED=${SHARED:-$root/../shared}
MODELS=${MODELS:-$SHARED/models}
PEER_RESULTS=${PEER_RESULTS:-$SHARED/peers/embree/results}
OUT=${OUT:-$root/bench/results/megaray.jsonl}
RES=${RES:-1024x1024}
REPS=${REPS:-5}
MIN_MS=${MIN_MS:-200}
THREADS=${THREADS:-1,2}
TRACE=primary_1,primary_16,shadow_1,diffuse_1

cargo build --profile dist -p megaray
bin=$root/target/dist/megaray
mkdir -p "$(dirname "$OUT")"
: > "$OUT"

run() { # name args...   (ONLY="a b" runs just those names)
  name=$1; shift
  if [ -n "$ONLY" ] && ! echo " $ONLY " | grep -q " $name "; then return 0; fi
  echo "== $name  (loadavg before: $(cut -d' ' -f1-3 /proc/loadavg))" >&2
  "$bin" bench "$@" --res "$RES" --reps "$REPS" --min-ms "$MIN_MS" --threads "$THREADS" --json >> "$OUT"
}
run grid1000 grid:1000
run sphereflake4 sphereflake:4
run bunny "$MODELS/stanford-bunny.obj" --name stanford-bunny.obj
# the closer camera (about half the image covered), tracing only, as the peer's run_all.sh
run grid1000_close grid:1000 --cam close --kinds $TRACE
run sphereflake4_close sphereflake:4 --cam close --kinds $TRACE
run bunny_close "$MODELS/stanford-bunny.obj" --name stanford-bunny.obj --cam close --kinds $TRACE
echo "wrote $OUT ($(wc -l < "$OUT") lines)" >&2

compare=$SHARED/bench/compare.py
if [ -f "$compare" ] && ls "$PEER_RESULTS"/*.jsonl > /dev/null 2>&1; then
  python3 "$compare" "$PEER_RESULTS"/*.jsonl -- "$OUT"
else
  echo "no peer figures to compare with ($compare, $PEER_RESULTS)" >&2
fi
