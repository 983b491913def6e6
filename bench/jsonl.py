#!/usr/bin/env python3
"""Reads the JSON lines of `megaray bench --json` and of the Embree peer's harness (one object
per figure, shared/BENCH.md); every bench script goes through it.

    jsonl.py rounds DIR... [--base peer] [--new megaray] [--metric median|best] [--per-cpu]
        Per row (scene or driver's row label, kind, threads) of DIR/BASE.N.jsonl and
        DIR/NEW.N.jsonl (N = round; DIR/rounds/ is read when it exists, so a vs_peer.sh OUT_DIR
        will do): each side's median and maximum over the rounds, the median and the geometric
        mean of the per-round ratios NEW/BASE, the ratio of the two maxima, checksum agreement,
        every round's ratio; then how many tracing rows are at or above 1.0 and the worst.
        Several DIRs: their rounds are pooled. Figures: Mrays/s, Mtris/s for build kinds;
        --metric best takes each run's best repetition (mrays_s_best, build_ms_best) instead of
        its median; --per-cpu divides each figure by its run's cpu_util (CPU seconds per wall
        second), which takes out time a busy host stole from the VM.
    jsonl.py best FILE...
        Each row's (scene, kind, threads; row label first when there is one) line with the
        highest figure over the files, as JSON lines: one side's best round, for
        shared/bench/compare.py.
    jsonl.py tag LABEL < LINES > LINES
        Adds "row": LABEL to every JSON line (other lines are dropped); rows are paired by this
        label rather than by scene name when it is there (the two harnesses may name a scene
        differently, or two scenes are compared).
    jsonl.py get FIELD FILE...
        The first value of FIELD in the JSON lines of the files (e.g. `rays`); exit 1 if none.

The peer's build_medium is read as kind build (the build that megaray's `build` is held
against, as compare.py pairs them).
"""
import glob
import json
import os
import re
import statistics as st
import sys

KIND_ORDER = ["build", "build_high", "primary_1", "primary_8", "primary_16", "shadow_1", "diffuse_1"]


def records(path):
    """The JSON objects of a file's lines that start with '{' (notes and tables are skipped)."""
    with open(path) as f:
        for n, line in enumerate(f, 1):
            line = line.strip()
            if not line.startswith("{"):
                continue
            try:
                yield json.loads(line)
            except json.JSONDecodeError as e:
                sys.exit(f"jsonl.py: {path}:{n}: not JSON: {e}")


def kind_of(r):
    k = str(r.get("kind"))
    return "build" if k == "build_medium" else k


def key_of(r):
    return (r.get("row", r.get("scene")), kind_of(r), r.get("threads"))


def figure(r, metric="median", per_cpu=False):
    """Mrays/s, or Mtris/s for the build kinds; None when the line has no such figure."""
    if kind_of(r).startswith("build"):
        if metric == "best" and r.get("build_ms_best") and r.get("tris"):
            fig = r["tris"] / r["build_ms_best"] / 1000.0
        else:
            fig = r.get("mtris_s")
    else:
        fig = r.get("mrays_s_best") if metric == "best" else None
        if fig is None:
            fig = r.get("mrays_s")
    if fig is not None and per_cpu and r.get("cpu_util", 0) > 0:
        fig /= r["cpu_util"]
    return fig


def checksum(a, b):
    """As shared/bench/compare.py: hits within 0.01 %, sum_t within 1e-4 relative."""
    if "hits" not in a or "hits" not in b:
        return "-"
    ha, hb = a["hits"], b["hits"]
    if abs(ha - hb) > max(1, 1e-4 * max(ha, hb)):
        return "DIFFERS"
    sa, sb = a.get("sum_t", 0.0), b.get("sum_t", 0.0)
    return "agrees" if abs(sa - sb) <= 1e-4 * max(abs(sa), abs(sb), 1e-9) else "DIFFERS"


def sort_key(order):
    def k(key):
        row, kind, thr = key
        ki = KIND_ORDER.index(kind) if kind in KIND_ORDER else len(KIND_ORDER)
        return (order.get(row, 1 << 30), ki, kind, thr if isinstance(thr, int) else 0)
    return k


def take(args, flag, default):
    if flag in args:
        i = args.index(flag)
        if i + 1 >= len(args):
            sys.exit(f"jsonl.py: {flag} needs a value")
        value = args[i + 1]
        del args[i:i + 2]
        return value
    return default


def cmd_rounds(args):
    base = take(args, "--base", "peer")
    new = take(args, "--new", "megaray")
    metric = take(args, "--metric", "median")
    if metric not in ("median", "best"):
        sys.exit("jsonl.py: --metric is median or best")
    per_cpu = "--per-cpu" in args
    dirs = [a for a in args if a != "--per-cpu"]
    if not dirs:
        sys.exit(__doc__)
    # The round files, in the order they were measured: DIR, round, base before new.
    files = []
    for di, d in enumerate(dirs):
        if os.path.isdir(os.path.join(d, "rounds")):
            d = os.path.join(d, "rounds")
        found = 0
        for si, side in enumerate((base, new)):
            for path in glob.glob(os.path.join(glob.escape(d), f"{side}.*.jsonl")):
                m = re.fullmatch(re.escape(side) + r"\.(\d+)\.jsonl", os.path.basename(path))
                if m:
                    files.append(((di, int(m.group(1))), si, side, path))
                    found += 1
        if not found:
            sys.exit(f"jsonl.py: no {base}.N.jsonl or {new}.N.jsonl files in {d}")
    # figs[key][side][round] = figure; lines[key][side] = a line of it (for the checksums);
    # order: rows by first appearance.
    figs, lines, order = {}, {}, {}
    for rnd, _, side, path in sorted(files):
        for r in records(path):
            fig = figure(r, metric, per_cpu)
            if fig is None:
                continue
            key = key_of(r)
            order.setdefault(key[0], len(order))
            figs.setdefault(key, {}).setdefault(side, {})[rnd] = fig
            lines.setdefault(key, {})[side] = r
    unit = "best repetition of each run" if metric == "best" else "median of each run"
    print(f"figures: Mrays/s (build kinds: Mtris/s), the {unit}{', per CPU second' if per_cpu else ''}; "
          f"ratio = {new}/{base}")
    print(f"{'row':28} {'kind':10} {'thr':>3} {'n':>2}  {base + ' med':>12} {'max':>8}  "
          f"{new + ' med':>12} {'max':>8}  {'median':>6} {'geomean':>7} {'of max':>6}  {'checksum':8} each round's ratio")
    trace, notes, one_side = [], [], {}
    for key in sorted(figs, key=sort_key(order)):
        sides = figs[key]
        a, b = sides.get(base, {}), sides.get(new, {})
        if not a or not b:  # e.g. the peer's primary_8, which the suite leaves out
            one_side.setdefault((key[1], base if a else new), []).append(key)
            continue
        both = sorted(set(a) & set(b))
        if len(a) != len(b) or len(both) != len(a):
            notes.append(f"{key[0]} {key[1]} threads {key[2]}: {base} measured {len(a)} rounds, {new} {len(b)}")
        if not both or not all(a[i] for i in both):
            continue
        ratios = [b[i] / a[i] for i in both]
        med = st.median(ratios)
        # The geometric mean too: where one core (or one order) is slower than the other for a
        # while and the sides swap every round, the rounds alternate high and low, and over an
        # even number of rounds the geometric mean cancels that where the median need not.
        gm = st.geometric_mean(ratios) if all(x > 0 for x in ratios) else float("nan")
        va, vb = [a[i] for i in both], [b[i] for i in both]
        check = checksum(lines[key][base], lines[key][new])
        print(f"{str(key[0]):28} {key[1]:10} {str(key[2]):>3} {len(both):2d}  {st.median(va):12.3f} {max(va):8.3f}  "
              f"{st.median(vb):12.3f} {max(vb):8.3f}  {med:6.3f} {gm:7.3f} {max(vb) / max(va):6.3f}  {check:8} "
              + " ".join(f"{x:.3f}" for x in ratios))
        if not key[1].startswith("build"):
            trace.append((med, key))
    for n in notes:
        print("a side missed rounds:", n)
    for (kind, side), keys in one_side.items():
        print(f"{kind} measured by {side} only ({len(keys)} rows), not compared")
    if trace:
        worst = min(trace)
        print(f"tracing rows: {len(trace)}, median ratio at or above 1.0: {sum(1 for m, _ in trace if m >= 1.0)}, "
              f"worst {worst[0]:.3f} ({worst[1][0]} {worst[1][1]} threads {worst[1][2]})")
    elif not any(len(s) == 2 for s in figs.values()):
        sys.exit("jsonl.py: no row measured by both sides")
    return 0


def cmd_best(args):
    if not args:
        sys.exit(__doc__)
    best = {}
    for path in args:
        for r in records(path):
            fig = figure(r)
            key = key_of(r)
            if fig is not None and (key not in best or fig > best[key][0]):
                best[key] = (fig, r)
    for _, r in best.values():
        print(json.dumps(r, separators=(",", ":")))
    return 0


def cmd_tag(args):
    if len(args) != 1:
        sys.exit(__doc__)
    for n, line in enumerate(sys.stdin, 1):
        line = line.strip()
        if not line.startswith("{"):
            continue
        try:
            r = json.loads(line)
        except json.JSONDecodeError as e:
            sys.exit(f"jsonl.py tag: line {n} of the input is not JSON: {e}")
        print(json.dumps({"row": args[0], **r}, separators=(",", ":")))
    return 0


def cmd_get(args):
    if len(args) < 2:
        sys.exit(__doc__)
    for path in args[1:]:
        for r in records(path):
            if args[0] in r:
                print(r[args[0]])
                return 0
    print(f"jsonl.py: no {args[0]} in {' '.join(args[1:])}", file=sys.stderr)
    return 1


def main(argv):
    cmds = {"rounds": cmd_rounds, "best": cmd_best, "tag": cmd_tag, "get": cmd_get}
    if not argv or argv[0] not in cmds:
        print(__doc__, file=sys.stderr)
        return 0 if argv and argv[0] in ("-h", "--help") else 2
    return cmds[argv[0]](argv[1:])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
