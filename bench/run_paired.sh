#!/bin/sh
# The standard suite (shared/BENCH.md) with the Embree peer and megaray interleaved: scene by
# scene, the peer's harness and then megaray's bench (the order swapped every other round),
# ROUNDS times, so that both sides of a row are measured minutes apart at most. On a shared
# VM whose speed drifts by 10-30% from one minute to the next, run_all.sh followed by
# run_suite.sh (every peer figure first, every megaray figure ~5 minutes later) compares two
# different machines; here each side's row keeps its best median over the rounds.
#
#   bench/run_paired.sh                     2 rounds, all scenes (about 15 minutes)
#   ROUNDS=3 ONLY="bunny bunny_close" bench/run_paired.sh
#   python3 bench/median_rounds.py OUT_DIR   the median of per-round ratios per row
#
# Needs the peer built: make -C ../shared/peers/embree (Embree 3 and TBB from apt:
# libembree-dev libtbb-dev), or PEER=/path/to/embree_bench. Output: $OUT_DIR/peer.jsonl and
# $OUT_DIR/megaray.jsonl (each row's best round, as the harnesses print them), then the
# comparison by shared/bench/compare.py.
set -e
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
SHARED=${SHARED:-$root/../shared}
MODELS=${MODELS:-$SHARED/models}
PEER=${PEER:-$SHARED/peers/embree/embree_bench}
OUT_DIR=${OUT_DIR:-$root/bench/results/paired}
ROUNDS=${ROUNDS:-2}
RES=${RES:-1024x1024}
REPS=${REPS:-5}
MIN_MS=${MIN_MS:-200}
TRACE=primary_1,primary_16,shadow_1,diffuse_1
[ -x "$PEER" ] || { echo "no peer harness at $PEER (make -C $SHARED/peers/embree, or set PEER)" >&2; exit 2; }

cargo build --profile dist -p megaray
bin=$root/target/dist/megaray
mkdir -p "$OUT_DIR/rounds"
rm -f "$OUT_DIR"/rounds/*.jsonl

peer() { # name args...
  "$PEER" "$@" --res "$RES" --reps "$REPS" --min-ms "$MIN_MS" >> "$OUT_DIR/rounds/peer.$round.jsonl"
}
ours() { # name args...
  "$bin" bench "$@" --res "$RES" --reps "$REPS" --min-ms "$MIN_MS" --json >> "$OUT_DIR/rounds/megaray.$round.jsonl"
}
pair() { # name 'peer args' 'megaray args'
  if [ -n "$ONLY" ] && ! echo " $ONLY " | grep -q " $1 "; then return 0; fi
  echo "== round $round: $1" >&2
  if [ $((round % 2)) -eq 1 ]; then peer $2; ours $3; else ours $3; peer $2; fi
}

round=1
while [ "$round" -le "$ROUNDS" ]; do
  pair grid1000 "--gen grid:1000" "grid:1000"
  pair sphereflake4 "--gen sphereflake:4" "sphereflake:4"
  pair bunny "$MODELS/stanford-bunny.obj --name stanford-bunny.obj" "$MODELS/stanford-bunny.obj --name stanford-bunny.obj"
  pair grid1000_close "--gen grid:1000 --cam-offset 0,0.3,0.6 --kinds $TRACE --name grid:1000@close" \
    "grid:1000 --cam close --kinds $TRACE"
  pair sphereflake4_close "--gen sphereflake:4 --cam-offset 0,0.3,0.6 --kinds $TRACE --name sphereflake:4@close" \
    "sphereflake:4 --cam close --kinds $TRACE"
  pair bunny_close "$MODELS/stanford-bunny.obj --cam-offset 0,0.3,0.6 --kinds $TRACE --name stanford-bunny.obj@close" \
    "$MODELS/stanford-bunny.obj --name stanford-bunny.obj --cam close --kinds $TRACE"
  round=$((round + 1))
done

# Each side's best round per row (scene, kind, threads): the figure of its fastest minute.
ls "$OUT_DIR"/rounds/*.jsonl > /dev/null 2>&1 || { echo "nothing measured (ONLY=\"$ONLY\" names no scene of the suite?)" >&2; exit 2; }
for side in peer megaray; do
  python3 - "$OUT_DIR"/rounds/$side.*.jsonl > "$OUT_DIR/$side.jsonl" <<'PY'
import json, sys
best = {}
for path in sys.argv[1:]:
    for line in open(path):
        if not line.startswith("{"):
            continue
        r = json.loads(line)
        metric = "mtris_s" if str(r.get("kind")).startswith("build") else "mrays_s"
        key = (r.get("scene"), r.get("kind"), r.get("threads"))
        if metric in r and (key not in best or r[metric] > best[key][metric]):
            best[key] = r
for r in best.values():
    print(json.dumps(r))
PY
done
echo "best of $ROUNDS interleaved rounds: $OUT_DIR/peer.jsonl, $OUT_DIR/megaray.jsonl" >&2
python3 "$SHARED/bench/compare.py" "$OUT_DIR/peer.jsonl" -- "$OUT_DIR/megaray.jsonl"
