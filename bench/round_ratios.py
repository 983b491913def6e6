#!/usr/bin/env python3
"""Per-round ratios of two sides' bench figures, for bench/ab.sh and bench/vs_peer.sh.

    round_ratios.py DIR ROUNDS BASE NEW [PER_CPU]

reads the JSON lines of DIR/BASE.1 .. DIR/BASE.ROUNDS and DIR/NEW.1 .. (one file per side and
round, as `megaray bench --json` and the peer's harness print them) and prints, per kind, each
side's median figure (Mrays/s, or Mtris/s for build kinds), and the median and the geometric
mean of the per-round ratios NEW/BASE, with every round's. With PER_CPU = 1 each figure is
divided by its run's cpu_util (CPU seconds per wall second): per CPU second rather than per
wall second, which takes out the time a busy host stole from the VM.
"""
import json
import statistics as st
import sys


def main():
    tmp, rounds, base, new = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
    per_cpu = len(sys.argv) > 5 and sys.argv[5] == "1"
    figs = {}
    for side in (base, new):
        for i in range(1, rounds + 1):
            for line in open(f"{tmp}/{side}.{i}"):
                if line.startswith("{"):
                    r = json.loads(line)
                    # Rays per second, or triangles per second for the build kinds.
                    fig = r.get("mrays_s", r.get("mtris_s"))
                    if fig is not None and per_cpu and r.get("cpu_util", 0) > 0:
                        fig /= r["cpu_util"]
                    if fig is not None:
                        figs.setdefault((r["kind"], side), []).append(fig)
    for kind in sorted({k for k, _ in figs}):
        a, b = figs.get((kind, base), []), figs.get((kind, new), [])
        if not a or len(a) != len(b):
            print(f"{kind}: a side failed ({len(a)} against {len(b)} rounds)")
            continue
        ratios = [y / x for x, y in zip(a, b)]
        # The geometric mean too: where one core is slower than the other for a while and the
        # sides swap cores (or order) every round, the rounds alternate high and low, and over
        # an even number of rounds the geometric mean cancels that where the median need not.
        gm = st.geometric_mean(ratios)
        print(
            f"{kind:12} {base} {st.median(a):8.3f}  {new} {st.median(b):8.3f}  {new}/{base} "
            f"{st.median(ratios):.3f}  geomean {gm:.3f}  rounds {[round(r, 3) for r in ratios]}"
        )


if __name__ == "__main__":
    main()
