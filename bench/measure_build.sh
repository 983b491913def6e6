#!/bin/bash
# Issue 2's out-of-core figures: generate a plant, build it at two memory budgets with caches
# dropped, report wall time, peak RSS and bytes; the disk's own speed for comparison; scene
# size by section; a cold then warm render. Needs root (drop_caches) and ~25 GB free in $DIR.
#
#   bench/measure_build.sh                  plant:100M in ./big
#   TRIS=10M MEMS="256M 1G" DIR=/tmp/m bench/measure_build.sh
set -u
root=$(cd "$(dirname "$0")/.." && pwd)
TRIS=${TRIS:-100M}
MEMS=${MEMS:-"1G 4G"}
DIR=${DIR:-$root/big}
cargo build --profile dist -q -p megaray --manifest-path "$root/Cargo.toml" || exit 1
M=$root/target/dist/megaray
mkdir -p "$DIR" && cd "$DIR" || exit 1
drop() { sync; echo 3 > /proc/sys/vm/drop_caches 2>/dev/null || echo "(could not drop caches: figures are warm)"; }
ply=plant$TRIS.ply
[ -f "$ply" ] || /usr/bin/time -f "gen: %e s, peak RSS %M KiB" $M gen plant:$TRIS -o "$ply" -q
for mem in $MEMS; do
  drop
  echo "== build --build-mem $mem (loadavg $(cut -d' ' -f1-3 /proc/loadavg))"
  /usr/bin/time -v $M build "$ply" -o "plant$TRIS-$mem.mray" --build-mem "$mem" --json -q 2> "build-$mem.time"
  grep -E "Elapsed|Maximum resident|File system" "build-$mem.time"
done
last=$(echo $MEMS | awk '{print $1}')
$M info "plant$TRIS-$last.mray"
echo "== disk: 10 GiB written with fdatasync, then read cold"
dd if=/dev/zero of=ddtest bs=4M count=2560 conv=fdatasync 2>&1 | tail -1
drop
dd if=ddtest of=/dev/null bs=4M 2>&1 | tail -1
rm -f ddtest
echo "== render 1024x1024, default camera: cold, then warm"
drop
for i in 1 2 3; do /usr/bin/time -f "  wall %e s, peak RSS %M KiB" $M render "plant$TRIS-$last.mray" -o render.png --res 1024x1024; done
