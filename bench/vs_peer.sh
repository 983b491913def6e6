#!/bin/bash
# Megaray against the Embree peer (shared/BENCH.md), paired and interleaved: per row (scene and
# camera) and ray kind, the peer's harness then megaray's bench, the order swapped every round,
# ROUNDS times, so both sides of a figure are measured seconds apart (this VM drifts 10-30% in
# minutes). In turn, not at once one per core as bench/ab.sh does: the two harnesses would share
# the L3 and memory unevenly.
#
#   bench/vs_peer.sh [OPTIONS] [ROW...]      ROW: grid1000 sphereflake4 bunny grid1000_close
#                                            sphereflake4_close bunny_close (default: all six)
#   bench/vs_peer.sh                         the standard suite, 2 rounds (about 20 minutes)
#   bench/vs_peer.sh -n 4 -t 1 -k primary_1,diffuse_1 bunny_close
#   bench/vs_peer.sh -n 4 -t 1 -k shadow_1,diffuse_1 --row "--gen sphereflake:2" sphereflake:2
#
#   --row PEER_ARGS MEGARAY_ARGS  a row of your own: each harness's scene arguments (word-split)
#   -n N (ROUNDS, 2)   -t T,T (THREADS, 1,2)   -o DIR (OUT_DIR, bench/results/vs_peer)
#   -k K,K (KINDS, default the row's; build = megaray's build+build_high, the peer's build)
#   --split row (SPLIT=row): one run per row with all its kinds, quicker, sides minutes apart
#   --stored (STORED=1): no peer run; megaray (1 round) against $PEER_RESULTS/*.jsonl, fair
#       only if the peer's run_all.sh ran minutes before on an idle machine
# Env: RES (1024x1024) REPS (5) MIN_MS (200) PER_CPU=1 ONLY="ROW..." SHARED (../shared) MODELS
# PEER_RESULTS, PEER (../shared/peers/embree/embree_bench: make -C ../shared/peers/embree, with
# apt's libembree-dev libtbb-dev), MEGARAY (default: cargo build --profile dist, target/dist).
# Output in OUT_DIR: rounds/{peer,megaray}.N.jsonl (lines tagged with "row"), {peer,megaray}.jsonl
# (each side's best round). Prints bench/jsonl.py rounds OUT_DIR (per-round ratios: the fair
# reading), then shared/bench/compare.py on the best rounds (checksums). A failing side stops
# the run with a message naming it and quoting its last error line.
set -u
root=$(cd "$(dirname "$0")/.." && pwd)
here=$root/bench
usage() { awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit "${1:-2}"; }

SHARED=${SHARED:-$root/../shared}
MODELS=${MODELS:-$SHARED/models}
PEER=${PEER:-$SHARED/peers/embree/embree_bench}
PEER_RESULTS=${PEER_RESULTS:-$SHARED/peers/embree/results}
OUT_DIR=${OUT_DIR:-$root/bench/results/vs_peer}
ROUNDS=${ROUNDS:-}
KINDS=${KINDS:-}
THREADS=${THREADS:-1,2}
RES=${RES:-1024x1024}
REPS=${REPS:-5}
MIN_MS=${MIN_MS:-200}
SPLIT=${SPLIT:-kind}
STORED=${STORED:-0}
ALL=build,primary_1,primary_16,shadow_1,diffuse_1
TRACE=primary_1,primary_16,shadow_1,diffuse_1

# Rows: parallel arrays of label (the "row" of each line), peer args, megaray args, kinds.
labels=(); pargs=(); margs=(); rkinds=()
add() { labels+=("$1"); pargs+=("$2"); margs+=("$3"); rkinds+=("$4"); }
suite_row() { # NAME
  local bunny=$MODELS/stanford-bunny.obj close="--cam-offset 0,0.3,0.6"
  case $1 in
    grid1000) add grid:1000 "--gen grid:1000" "grid:1000" $ALL ;;
    sphereflake4) add sphereflake:4 "--gen sphereflake:4" "sphereflake:4" $ALL ;;
    bunny) add stanford-bunny.obj "$bunny --name stanford-bunny.obj" "$bunny --name stanford-bunny.obj" $ALL ;;
    grid1000_close) add grid:1000@close "--gen grid:1000 $close --name grid:1000@close" "grid:1000 --cam close" $TRACE ;;
    sphereflake4_close)
      add sphereflake:4@close "--gen sphereflake:4 $close --name sphereflake:4@close" "sphereflake:4 --cam close" $TRACE ;;
    bunny_close) add stanford-bunny.obj@close "$bunny $close --name stanford-bunny.obj@close" \
      "$bunny --name stanford-bunny.obj --cam close" $TRACE ;;
    *) echo "vs_peer.sh: no row $1 in the suite (grid1000 sphereflake4 bunny grid1000_close" \
      "sphereflake4_close bunny_close; --row PEER_ARGS MEGARAY_ARGS for another)" >&2; exit 2 ;;
  esac
}
while [ $# -gt 0 ]; do
  case $1 in
    -h|--help) usage 0 ;;
    -n) ROUNDS=${2:?-n needs a number}; shift 2 ;;
    -k) KINDS=${2:?-k needs kinds}; shift 2 ;;
    -t) THREADS=${2:?-t needs thread counts}; shift 2 ;;
    -o) OUT_DIR=${2:?-o needs a directory}; shift 2 ;;
    --split) SPLIT=${2:?--split needs row or kind}; shift 2 ;;
    --stored) STORED=1; shift ;;
    --row) [ $# -ge 3 ] || usage; add "$3" "$2" "$3" $ALL; shift 3 ;;
    -*) echo "vs_peer.sh: unknown option $1" >&2; usage ;;
    *) suite_row "$1"; shift ;;
  esac
done
if [ ${#labels[@]} -eq 0 ]; then
  for n in ${ONLY:-grid1000 sphereflake4 bunny grid1000_close sphereflake4_close bunny_close}; do suite_row "$n"; done
fi
[ -n "$ROUNDS" ] || { [ "$STORED" = 1 ] && ROUNDS=1 || ROUNDS=2; }
case $ROUNDS in ''|*[!0-9]*|0) echo "vs_peer.sh: ROUNDS must be a positive number, not $ROUNDS" >&2; exit 2 ;; esac
case $SPLIT in row|kind) ;; *) echo "vs_peer.sh: SPLIT is row or kind, not $SPLIT" >&2; exit 2 ;; esac

if [ "$STORED" = 1 ]; then
  ls "$PEER_RESULTS"/*.jsonl > /dev/null 2>&1 ||
    { echo "vs_peer.sh: no stored peer figures in $PEER_RESULTS (the peer's run_all.sh, or set PEER_RESULTS)" >&2; exit 2; }
else
  [ -x "$PEER" ] || { echo "vs_peer.sh: no peer harness at $PEER (make -C $SHARED/peers/embree, or set PEER)" >&2; exit 2; }
fi
if [ -z "${MEGARAY:-}" ]; then
  cargo build --profile dist -p megaray --manifest-path "$root/Cargo.toml" || exit 1
  MEGARAY=$root/target/dist/megaray
fi
[ -x "$MEGARAY" ] || { echo "vs_peer.sh: no megaray at $MEGARAY (set MEGARAY)" >&2; exit 2; }
mkdir -p "$OUT_DIR/rounds" || exit 1
rm -f "$OUT_DIR"/rounds/*.jsonl "$OUT_DIR"/peer.jsonl "$OUT_DIR"/megaray.jsonl

# The kinds each harness is asked for: megaray's build is its build and build_high, the
# peer's build makes both of its builds (build_high, build_medium); duplicates dropped.
side_kinds() { # SIDE K,K
  local k out="" IFS=,
  for k in $2; do
    case $1:$k in megaray:build) k=build,build_high ;; peer:build_high) k=build ;; esac
    case ",$out," in *",$k,"*) ;; *) out=${out:+$out,}$k ;; esac
  done
  echo "$out"
}
# The runs of a row: one per kind (build_high goes with build), or one with every kind.
units() { # K,K
  if [ "$SPLIT" = row ]; then echo "$1"; return; fi
  side_kinds peer "$1" | tr , '\n'
}
# The last line of a failed run's stderr that names an error or a panic, else its last line.
last_error() { grep -iE 'error|panicked' "$1" | tail -n 1 | grep . || tail -n 1 "$1"; }
failed() { # SIDE
  echo "vs_peer.sh: the $1 side failed in round $round (row $label, kinds $kinds): $(last_error "$OUT_DIR/$1.err")" >&2
  exit 1
}
run_side() { # SIDE: runs it on row $r's kinds $kinds, its lines tagged and added to the round's file
  # shellcheck disable=SC2086  # the scene arguments are word-split on purpose: several arguments
  if [ "$1" = peer ]; then
    "$PEER" ${pargs[$r]} --res "$RES" --reps "$REPS" --min-ms "$MIN_MS" --threads "$THREADS" \
      --kinds "$(side_kinds peer "$kinds")" > "$OUT_DIR/peer.out" 2> "$OUT_DIR/peer.err" || failed peer
  else
    "$MEGARAY" bench ${margs[$r]} --res "$RES" --reps "$REPS" --min-ms "$MIN_MS" --threads "$THREADS" \
      --kinds "$(side_kinds megaray "$kinds")" --json -q > "$OUT_DIR/megaray.out" 2> "$OUT_DIR/megaray.err" ||
      failed megaray
  fi
  python3 "$here/jsonl.py" tag "$label" < "$OUT_DIR/$1.out" >> "$OUT_DIR/rounds/$1.$round.jsonl" || exit 1
}

round=1
while [ "$round" -le "$ROUNDS" ]; do
  for r in "${!labels[@]}"; do
    label=${labels[$r]}
    for kinds in $(units "${KINDS:-${rkinds[$r]}}"); do
      echo "== round $round/$ROUNDS: $label $kinds (loadavg $(cut -d' ' -f1-3 /proc/loadavg))" >&2
      if [ "$STORED" = 1 ]; then run_side megaray
      elif [ $((round % 2)) -eq 1 ]; then run_side peer; run_side megaray
      else run_side megaray; run_side peer
      fi
    done
  done
  round=$((round + 1))
done
rm -f "$OUT_DIR/peer.out" "$OUT_DIR/megaray.out"

compare=$SHARED/bench/compare.py
[ -f "$compare" ] || { echo "vs_peer.sh: no $compare to compare with" >&2; exit 1; }
python3 "$here/jsonl.py" best "$OUT_DIR"/rounds/megaray.*.jsonl > "$OUT_DIR/megaray.jsonl" || exit 1
if [ "$STORED" = 1 ]; then
  echo "== megaray's best of $ROUNDS rounds ($OUT_DIR/megaray.jsonl) against the stored $PEER_RESULTS/*.jsonl"
  python3 "$compare" "$PEER_RESULTS"/*.jsonl -- "$OUT_DIR/megaray.jsonl"
  exit
fi
python3 "$here/jsonl.py" best "$OUT_DIR"/rounds/peer.*.jsonl > "$OUT_DIR/peer.jsonl" || exit 1
echo "== per-round ratios megaray/peer, $ROUNDS rounds (bench/jsonl.py rounds $OUT_DIR)"
per_cpu=(); [ "${PER_CPU:-0}" = 1 ] && per_cpu=(--per-cpu)
python3 "$here/jsonl.py" rounds "$OUT_DIR" --base peer --new megaray ${per_cpu[@]+"${per_cpu[@]}"} || exit 1
echo "== each side's best round ($OUT_DIR/peer.jsonl, megaray.jsonl; shared/bench/compare.py)"
python3 "$compare" "$OUT_DIR/peer.jsonl" -- "$OUT_DIR/megaray.jsonl" ||
  echo "(compare.py pairs rows by scene name: with --row, give both sides the same --name)"
