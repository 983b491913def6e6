#!/bin/sh
# Fuzzes every target for SECONDS each (one after another, one core each; JOBS targets at
# once, default 1) and exits non-zero if any found a crash (a panic, abort or signal), a hang
# (over 10 s) or an allocation over 2 GiB (the fuzzer's memory limit makes it a crash).
# Needs cargo-afl (`cargo install cargo-afl`, then `cargo afl config --build`).
# Usage: fuzz/run.sh SECONDS [TARGET...]     (targets: ply obj stl gltf env scene pbrt)
# Findings land in fuzz/out/<target>/default/{crashes,hangs}; a summary per target is printed
# (executions, rate, coverage as the fuzzer's bitmap share and edges found).
set -eu
secs=${1:?usage: fuzz/run.sh SECONDS [TARGET...]}
shift
here=$(cd "$(dirname "$0")" && pwd)
cd "$here"
targets=${*:-ply obj stl gltf env scene pbrt}
cargo afl build --release
if [ ! -d seeds ]; then
    (cd .. && cargo build --release -p megaray)
    python3 seeds.py ../target/release/megaray
fi
export AFL_NO_UI=1 AFL_SKIP_CPUFREQ=1 AFL_I_DONT_CARE_ABOUT_MISSING_CRASHES=1 AFL_QUIET=1
failed=0
for t in $targets; do
    mkdir -p out
    # Resume a corpus from an earlier run (-i -), else start from the seeds.
    input=seeds/$t
    [ -f out/$t/default/fuzzer_stats ] && input=-
    cargo afl fuzz -i "$input" -o out/$t -m 2048 -t 10000 -V "$secs" -- target/release/$t > out/$t.log 2>&1 || {
        echo "$t: the fuzzer failed to run (see fuzz/out/$t.log)"
        failed=1
        continue
    }
    s=out/$t/default/fuzzer_stats
    get() { sed -n "s/^$1 *: *//p" "$s"; }
    crashes=$(find out/$t/default/crashes -type f ! -name README.txt | wc -l)
    hangs=$(find out/$t/default/hangs -type f | wc -l)
    echo "$t: $(get execs_done) executions in $(get run_time) s ($(get execs_per_sec)/s), coverage $(get bitmap_cvg) ($(get edges_found) edges), corpus $(get corpus_count), crashes $crashes, hangs $hangs"
    if [ "$crashes" -gt 0 ] || [ "$hangs" -gt 0 ]; then
        failed=1
    fi
done
exit $failed
