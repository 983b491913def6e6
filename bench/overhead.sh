#!/usr/bin/env bash
# The renderer's overhead against bench (issue 35): frames/s of `render` times a frame's rays,
# against what `megaray bench` reaches for the same rays (primary_1 and shadow_1) on the same
# scene and view. Alternates the three runs ROUNDS times (single runs scatter by 10 % on a VM)
# and prints each round's figures and the medians of the ratios.
#   usage: bench/overhead.sh SCENE [ROUNDS] [RES]     (BIN=path/to/megaray, THREADS=2)
set -euo pipefail
scene=${1:?usage: bench/overhead.sh SCENE [ROUNDS] [RES]}
rounds=${2:-7}
res=${3:-640x480}
bin=${BIN:-target/dist/megaray}
thr=${THREADS:-2}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
fps() { python3 -c "import json,sys; print(json.load(sys.stdin)['fps'])"; }
for i in $(seq 1 "$rounds"); do
  b=$("$bin" bench "$scene" --res "$res" --kinds primary_1,shadow_1 --threads "$thr" --json 2>/dev/null |
    python3 -c "import json,sys; print(1000/sum(json.loads(l)['ms_median'] for l in sys.stdin if l.strip()))")
  r=$("$bin" render "$scene" --res "$res" --frames 240 --threads "$thr" --lod-error 0 --json -o "$out/a.png" 2>/dev/null | fps)
  d=$("$bin" render "$scene" --res "$res" --frames 240 --threads "$thr" --lod-error 0 --deadline 1000 --json -o "$out/b.png" 2>/dev/null | fps)
  echo "$b $r $d"
done | python3 -c "
import sys, statistics as st
rows = [list(map(float, l.split())) for l in sys.stdin]
for b, r, d in rows:
    print(f'bench {b:7.1f} frames/s-equivalent   render {r:7.1f} ({r/b:.2f}x)   render --deadline {d:7.1f} ({d/b:.2f}x)')
print(f'median of {len(rows)}: render {st.median(r/b for b, r, d in rows):.2f}x of bench, with a deadline (the viewers) {st.median(d/b for b, r, d in rows):.2f}x')
"
