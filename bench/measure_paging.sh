#!/bin/bash
# Issue 4's out-of-core rendering figures: a scene much larger than the budget rendered
# with no budget and with --mem, cold then warm (the same view three times: --orbit 3:0),
# images compared, peak RSS; then a 100-frame camera path (a quarter orbit) with frame times
# and bytes read. About 40 minutes for plant:300M on a 2-core machine (the default-view path
# is disk-bound). PART=budget runs only issue 32's sequence instead: an unbudgeted render
# (the page cache then holds the file as a mapped read leaves it), then renders with each
# budget of MEMS, their peak RSS (the process's, from time -v) and frame times.
# Needs root (drop_caches) and a built scene:
#
#   megaray gen plant:300M -o plant300M.ply && megaray build plant300M.ply -o plant300M.mray
#   SCENE=plant300M.mray MEM=2G bench/measure_paging.sh
set -u
root=$(cd "$(dirname "$0")/.." && pwd)
SCENE=${SCENE:?set SCENE to a .mray file}
MEM=${MEM:-2G}
RES=${RES:-1024x768}
OUT=${OUT:-$(dirname "$SCENE")}
cargo build --profile dist -q -p megaray --manifest-path "$root/Cargo.toml" || exit 1
M=$root/target/dist/megaray
drop() { sync; echo 3 > /proc/sys/vm/drop_caches 2>/dev/null || echo "(could not drop caches: figures are warm)"; }
echo "scene $(ls -la "$SCENE" | awk '{print $5}') bytes; loadavg $(cut -d' ' -f1-3 /proc/loadavg)"
if [ "${PART:-all}" = budget ]; then
  drop
  echo "== no budget, cold (reads the file through the map)"
  /usr/bin/time -v $M render "$SCENE" -o "$OUT/budget-none.png" --res "$RES" --orbit 2:0 --json 2> "$OUT/budget-none.time"
  grep -E "Elapsed|Maximum resident" "$OUT/budget-none.time"
  grep -E "FileHugePages" /proc/meminfo
  for mem in ${MEMS:-64M 256M 2G}; do
    echo "== --mem $mem after it (frame 0 from the page cache as it was left, then warm)"
    /usr/bin/time -v $M render "$SCENE" -o "$OUT/budget-$mem.png" --res "$RES" --orbit 3:0 --json --mem "$mem" \
      > "$OUT/budget-$mem.jsonl" 2> "$OUT/budget-$mem.time"
    cat "$OUT/budget-$mem.jsonl"
    grep -E "Elapsed|Maximum resident" "$OUT/budget-$mem.time"
  done
  exit 0
fi
# Two views: the default camera (the whole plant: a frame needs several times a 2G budget)
# and one inside the plant (INSIDE, a --cam-offset; its frames fit the budget).
INSIDE=${INSIDE:-0.015,0.005,0.025}
for view in default inside; do
  cam=(); [ $view = inside ] && cam=(--cam-offset "$INSIDE")
  for mode in unlimited budget; do
    drop
    extra=(); [ $mode = budget ] && extra=(--mem "$MEM")
    echo "== $view view, $mode: the same view three times (frame 0 cold)"
    /usr/bin/time -v $M render "$SCENE" -o "$OUT/paging-$view-$mode.png" --res "$RES" --orbit 3:0 --json \
      "${cam[@]}" "${extra[@]}" > "$OUT/paging-$view-$mode.jsonl" 2> "$OUT/paging-$view-$mode.time"
    cat "$OUT/paging-$view-$mode.jsonl"
    grep -E "Elapsed|Maximum resident" "$OUT/paging-$view-$mode.time"
  done
  cmp "$OUT/paging-$view-unlimited.png" "$OUT/paging-$view-budget.png" && echo "$view: images identical"
done
# 100-frame paths over 90 degrees: the default view with a deadline (frames end on time,
# pixels left are counted) and without one (every pixel finished, frames as long as their
# reads), and the inside view without one.
for run in "deadline:$RES:${DEADLINE:-500}:" "full:$RES:none:" "inside:$RES:none:$INSIDE"; do
  IFS=: read -r name res dl off <<< "$run"
  drop
  extra=(); [ "$dl" != none ] && extra=(--deadline "$dl")
  [ -n "$off" ] && extra+=(--cam-offset "$off")
  echo "== camera path: 100 frames over 90 degrees at $res, --mem $MEM, deadline $dl ms"
  /usr/bin/time -v $M render "$SCENE" -o "$OUT/path-$name.png" --res "$res" --orbit 100:90 --json --mem "$MEM" "${extra[@]}" \
    > "$OUT/path-$name.jsonl" 2> "$OUT/path-$name.time"
  tail -1 "$OUT/path-$name.jsonl"
  grep -E "Elapsed|Maximum resident" "$OUT/path-$name.time"
done
