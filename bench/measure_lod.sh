#!/bin/bash
# Issue 34's level-of-detail figures on one scene (built with levels of detail, the default):
#   1. warm frame time of the default (whole-model) view: no budget at full detail
#      (--lod-error 0) against --mem $MEM at --lod-error 1, bytes read per warm frame;
#   2. the first image from a cold start (page cache dropped: needs root) with --mem $MEM;
#   3. a 100-frame orbit with --mem $MEM --deadline 100: frame times (median, p99),
#      unfinished (black) and approximate pixels;
#   4. image quality: 16 frames accumulated at --lod-error 1 against full detail (EXR with
#      depth): mean absolute difference / mean, hit-mask difference, FLIP, and the images.
# Needs python3 with numpy, OpenEXR, pillow and flip-evaluator (pip) for step 4.
#
#   SCENE=plant300M.mray MEM=2G OUT=/tmp/lod bench/measure_lod.sh
set -u
root=$(cd "$(dirname "$0")/.." && pwd)
SCENE=${SCENE:?set SCENE to a .mray file}
MEM=${MEM:-2G}
RES=${RES:-1024x768}
OUT=${OUT:-/tmp/measure_lod}
mkdir -p "$OUT"
M=${MEGARAY:-$root/target/release/megaray}
[ -x "$M" ] || cargo build --release -q -p megaray --manifest-path "$root/Cargo.toml" || exit 1
drop() { sync; echo 3 > /proc/sys/vm/drop_caches 2>/dev/null || echo "(could not drop caches: cold figures are warm)"; }
frames() { grep -o '"frame":[0-9]*,[^}]*' "$1" | sed 's/"read_bytes"/read/; s/"seconds"/s/' | cut -c1-160; }
echo "scene $SCENE: $($M info "$SCENE" | grep -E 'triangles|levels of detail' | tr -s ' ' | tr '\n' ';')"

echo "== 1. warm frames, default view"
$M render "$SCENE" -o "$OUT/full.png" --res "$RES" --lod-error 0 --orbit 4:0 --json > "$OUT/full.jsonl"
frames "$OUT/full.jsonl"
$M render "$SCENE" -o "$OUT/lod.png" --res "$RES" --lod-error 1 --mem "$MEM" --orbit 6:0 --json > "$OUT/lod.jsonl"
frames "$OUT/lod.jsonl"

echo "== 2. first image, cold, --mem $MEM (stand-ins while tiles load)"
drop
/usr/bin/time -f "process %e s, peak RSS %M kB" $M render "$SCENE" -o "$OUT/cold.png" --res "$RES" --mem "$MEM" \
  --deadline 1000 --json > "$OUT/cold.json"
grep -o '"seconds":[0-9.]*\|"pixels_unfinished":[0-9]*' "$OUT/cold.json" | tr '\n' ' '; echo

echo "== 3. orbit: 100 frames over 90 degrees, --mem $MEM --deadline 100"
drop
$M render "$SCENE" -o "$OUT/orbit.png" --res "$RES" --mem "$MEM" --deadline 100 --orbit 100:90 --json > "$OUT/orbit.jsonl"
python3 - "$OUT/orbit.jsonl" <<'EOF'
import json, sys
lines = [json.loads(l) for l in open(sys.argv[1])]
fr = [l for l in lines if "frame" in l]
t = sorted(l["seconds"] for l in fr)
med, p99 = t[len(t) // 2], t[min(len(t) - 1, round(0.99 * (len(t) - 1)))]
print(f"frames {len(fr)}: median {med:.3f} s, p99 {p99:.3f} s (p99/median {p99 / med:.2f}); "
      f"black pixels {sum(l['black_pixels'] for l in fr)} (unfinished {sum(l['unfinished'] for l in fr)}, filled from neighbours {sum(l['filled_pixels'] for l in fr)}), approximate pixels {sum(l.get('approx_pixels', 0) for l in fr)}, "
      f"read {sum(l['read_bytes'] for l in fr) / 1e6:.0f} MB; lod error {min(l['lod_error'] for l in fr)}..{max(l['lod_error'] for l in fr)}")
EOF

echo "== 4. quality: 16 frames, --lod-error 1 against full detail"
$M render "$SCENE" -o "$OUT/q_full.exr" --res "$RES" --lod-error 0 --frames 16 --aov depth -q
$M render "$SCENE" -o "$OUT/q_full.png" --res "$RES" --lod-error 0 --frames 16 -q
$M render "$SCENE" -o "$OUT/q_lod.exr" --res "$RES" --lod-error 1 --mem "$MEM" --frames 16 --aov depth -q
$M render "$SCENE" -o "$OUT/q_lod.png" --res "$RES" --lod-error 1 --mem "$MEM" --frames 16 -q
python3 "$root/bench/compare_images.py" "$OUT/q_full.exr" "$OUT/q_lod.exr" --png "$OUT/q_full.png" "$OUT/q_lod.png" \
  --diff "$OUT/q_diff.png"
echo "images in $OUT: q_full.png q_lod.png q_diff.png"
