#!/usr/bin/env python3
"""bench/mitsuba_speed.py megaray|mitsuba [DIR]: time to 1 % RMSE against each renderer's own converged image, on the staircase (90x160).
megaray: images after n frames are prefixes of the converged N-frame one (same sample
sequence), so MSE = s2 (1/n - 1/N). Mitsuba: a different seed, MSE = s2 (1/n + 1/N).
The samples needed for 1 % relative RMSE: n = s2 / (0.01 mean)^2; the time per sample
from two runs (16 and 64) so that loading is left out. DIR holds the converged images
that `compare.py --scene staircase --res 90x160 --frames 1024 --spp 2048 --keep DIR` kept."""
import json, os, subprocess, sys, time
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "../crates/render/tests/data/mitsuba"))
import compare as C
import numpy as np
import mitsuba as mi
mi.set_variant("scalar_rgb")
BIN = os.environ.get("BIN", os.path.join(HERE, "../target/release/megaray"))
KEEP = sys.argv[2] if len(sys.argv) > 2 else "/tmp/cmp"  # compare.py --keep DIR
RES = "90x160"
which = sys.argv[1]
out = {}
if which == "megaray":
    scene = os.path.join(KEEP, "stair.mray")
    if not os.path.exists(scene):
        subprocess.run([BIN, "build", C.STAIRCASE, "-o", scene, "-q"], check=True)
    ref = C.read_exr(os.path.join(KEEP, "staircase-megaray.exr")).astype(np.float64); N = 1024
    ts = {}
    for n in (16, 64):
        o = os.path.join(KEEP, f"m{n}.exr")
        t = time.time()
        subprocess.run([BIN, "render", scene, "-o", o, "-q", "--shader", "path", "--res", RES, "--frames", str(n),
                        "--max-depth", "64", "--lod-error", "0"], check=True, stdout=subprocess.DEVNULL)
        ts[n] = time.time() - t
        img = C.read_exr(o).astype(np.float64)
        mse = ((img - ref) ** 2).mean()
        s2 = mse / (1 / n - 1 / N)
        out[n] = {"s": round(ts[n], 2), "rmse_rel": float(np.sqrt(mse) / ref.mean()), "s2_over_mean2": s2 / ref.mean() ** 2}
    per = (ts[64] - ts[16]) / 48
else:
    ref = C.read_exr(os.path.join(KEEP, "staircase-mitsuba.exr")).astype(np.float64); N = 2048
    ts = {}
    for n in (16, 64):
        d = C.staircase_mitsuba({}, RES, n)
        t0 = time.time()
        sc = mi.load_dict(d)
        t = time.time()
        img = np.array(mi.render(sc, seed=12345 + n)).astype(np.float64)
        ts[n] = time.time() - t
        mse = ((img - ref) ** 2).mean()
        s2 = mse / (1 / n + 1 / N)
        out[n] = {"s": round(ts[n], 2), "load_s": round(t - t0, 2), "rmse_rel": float(np.sqrt(mse) / ref.mean()), "s2_over_mean2": s2 / ref.mean() ** 2}
    per = (ts[64] - ts[16]) / 48
k = out[64]["s2_over_mean2"]
n1 = k / 0.01 ** 2
out["per_sample_s"] = per
out["samples_to_1pct"] = n1
out["time_to_1pct_s"] = n1 * per
print(which, json.dumps(out))
