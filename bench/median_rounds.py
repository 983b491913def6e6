#!/usr/bin/env python3
"""Per row of the standard suite, the median of the per-round megaray/peer ratios of one or
more bench/run_paired.sh runs (their OUT_DIR), and each round's ratio: on a VM whose speed
drifts between minutes, a fairer reading than each side's best round.

    python3 bench/median_rounds.py bench/results/paired [more OUT_DIRs...]
"""
import json, sys, glob, statistics as st, collections, re
rows = collections.defaultdict(list)
for d in sys.argv[1:]:
    for pf in sorted(glob.glob(f"{d}/rounds/peer.*.jsonl")):
        n = re.search(r"peer\.(\d+)\.jsonl", pf).group(1)
        mf = f"{d}/rounds/megaray.{n}.jsonl"
        def load(f, peer):
            out = {}
            for l in open(f):
                if not l.startswith("{"): continue
                r = json.loads(l)
                k = r["kind"]
                if peer and k == "build_medium": k = "build"
                if k == "primary_8": continue
                v = r.get("mtris_s") if k.startswith("build") else r.get("mrays_s")
                out[(r["scene"], k, r["threads"])] = v
            return out
        p, m = load(pf, True), load(mf, False)
        for key in p:
            if key in m and p[key]:
                rows[key].append(m[key] / p[key])
order = ["build", "build_high", "diffuse_1", "primary_1", "primary_16", "shadow_1"]
print(f"{'scene':28s} {'kind':10s} thr rounds  median (each round's ratios)")
tr = []
for key in sorted(rows, key=lambda k: (k[0], order.index(k[1]) if k[1] in order else 9, k[2])):
    v = rows[key]
    med = st.median(v)
    if not key[1].startswith("build"): tr.append(med)
    print(f"{key[0]:28s} {key[1]:10s} {key[2]:3d} {len(v):3d}   {med:5.2f}  " + " ".join(f"{x:.2f}" for x in v))
print(f"tracing rows: {len(tr)}, at or above 1.0: {sum(1 for x in tr if x >= 1.0)}, worst {min(tr):.2f}")
