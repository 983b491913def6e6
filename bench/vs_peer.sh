#!/bin/sh
# Megaray against the Embree peer, row by row: for one scene and camera, the peer's harness and
# megaray's bench in turn (the order swapped every round), on one thread, a few ray kinds, ROUNDS
# times. The two sides of a row are measured seconds apart (run_paired.sh runs every kind of a
# scene on one side, then on the other: minutes apart on a VM that drifts 10-30% in minutes).
# Prints, per kind, each side's median and the median and geometric mean of the per-round
# ratios megaray/peer (bench/round_ratios.py).
# (Not at the same time, one per core, as bench/ab.sh runs two megaray builds: the two
# harnesses then share the L3 and memory unevenly, and the ratios come out different from the
# suite's.)
#
#   bench/vs_peer.sh ROUNDS PEER_SCENE_ARGS MEGARAY_SCENE_ARGS KINDS
#   bench/vs_peer.sh 4 "../shared/models/stanford-bunny.obj --cam-offset 0,0.3,0.6" \
#       "bunny.mray --cam close" primary_1,shadow_1,diffuse_1
#   bench/vs_peer.sh 3 "--gen sphereflake:2" "sphereflake:2" shadow_1,diffuse_1
#
# PEER (default ../shared/peers/embree/embree_bench) and MEGARAY (default target/dist/megaray,
# built by `cargo build --profile dist -p megaray`) name the two binaries.
set -e
[ $# -eq 4 ] || { sed -n '2,18p' "$0"; exit 2; }
rounds=$1; peer_args=$2; ours_args=$3; kinds=$4
root=$(cd "$(dirname "$0")/.." && pwd)
PEER=${PEER:-$root/../shared/peers/embree/embree_bench}
MEGARAY=${MEGARAY:-$root/target/dist/megaray}
[ -x "$PEER" ] || { echo "no peer harness at $PEER (make -C ../shared/peers/embree, or set PEER)" >&2; exit 2; }
[ -x "$MEGARAY" ] || { echo "no megaray at $MEGARAY (cargo build --profile dist -p megaray, or set MEGARAY)" >&2; exit 2; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# A side that fails stops the script with its own last error line (its stderr is kept apart
# from the figures on stdout).
failed() { # side
  echo "vs_peer.sh: the $1 side failed in round $i: $(tail -n 1 "$tmp/$1.err")" >&2
  exit 1
}
peer() { # $peer_args is word-split on purpose: it holds several arguments
  # shellcheck disable=SC2086
  "$PEER" $peer_args --threads 1 --reps 3 --kinds "$kinds" > "$tmp/peer.$i" 2> "$tmp/peer.err" || failed peer
}
ours() {
  # shellcheck disable=SC2086
  "$MEGARAY" bench $ours_args --threads 1 --reps 3 --json --kinds "$kinds" > "$tmp/megaray.$i" 2> "$tmp/megaray.err" ||
    failed megaray
}
i=1
while [ "$i" -le "$rounds" ]; do
  if [ $((i % 2)) = 1 ]; then peer; ours; else ours; peer; fi
  i=$((i + 1))
done
python3 "$root/bench/round_ratios.py" "$tmp" "$rounds" peer megaray
