#!/usr/bin/env bash
# Ranks against threads: frames/s of one image rendered by 1 process x 1 thread, 2 MPI ranks x
# 1 thread, 1 process x 2 threads, and the machine's ceiling for two processes (two
# independent 1-thread renders at once, their frames/s summed). Prints one line per run.
#
#   bench/mpi.sh SCENE.mray [ROUNDS] -- RENDER ARGS...
#   bench/mpi.sh ~/.cache/megaray/plant-3M.mray 3 -- --res 1280x960 --shader env --frames 8
#
# Needs the MPI build (cargo build --release --features mpi) and mpirun.
set -euo pipefail
scene=$1; rounds=${2:-3}; shift 2; [ "${1:-}" = "--" ] && shift
bin=${BIN:-$(dirname "$0")/../target/release/megaray}
out=$(mktemp -d); trap 'rm -rf "$out"' EXIT
fps() { python3 -c 'import json,sys; d=json.load(sys.stdin); c=d.get("cluster") or {}; print("%.3f fps  %.2f s  sent %.0f KB/frame  received %.0f KB/frame  rank-0 wait %.1f ms/frame" % (d["fps"], d["seconds"], c.get("bytes_sent_per_frame",0)/1e3, c.get("bytes_received_per_frame",0)/1e3, 1e3*c.get("root_wait_seconds_per_frame",0)))'; }
mpi="mpirun --oversubscribe --allow-run-as-root --bind-to none -n 2"
for r in $(seq "$rounds"); do
  echo "round $r"
  echo -n "  1 process x 1 thread : "; "$bin" render "$scene" -o "$out/a.png" -q --json --threads 1 "$@" | fps
  echo -n "  2 ranks   x 1 thread : "; $mpi "$bin" render "$scene" -o "$out/b.png" -q --json --threads 1 "$@" | fps
  echo -n "  1 process x 2 threads: "; "$bin" render "$scene" -o "$out/c.png" -q --json --threads 2 "$@" | fps
  echo -n "  2 processes at once  : "
  "$bin" render "$scene" -o "$out/d.png" -q --json --threads 1 "$@" > "$out/d.json" &
  "$bin" render "$scene" -o "$out/e.png" -q --json --threads 1 "$@" > "$out/e.json"; wait
  python3 -c 'import json,sys; a,b=(json.load(open(f)) for f in sys.argv[1:]); print("%.3f fps summed (%.3f + %.3f)" % (a["fps"]+b["fps"], a["fps"], b["fps"]))' "$out/d.json" "$out/e.json"
  cmp -s "$out/a.png" "$out/b.png" && echo "  2-rank image equals the 1-process one" || echo "  2-rank image DIFFERS from the 1-process one"
done
