#!/usr/bin/env python3
"""Compares a render with a reference render of the same view (EXR files as `megaray render
-o X.exr --aov depth` writes them): the mean absolute difference of the linear RGB as a
fraction of the reference's mean pixel value, the fraction of pixels whose hit/miss (finite
depth) differs, and the mean FLIP error (NVIDIA's flip-evaluator, LDR, on the tone-mapped
PNGs beside the EXRs when given). Writes a difference image when asked. One JSON line.

    python3 bench/compare_images.py REF.exr TEST.exr [--png REF.png TEST.png] [--diff diff.png]

Needs numpy, OpenEXR and, for FLIP, flip-evaluator (pip install numpy OpenEXR flip-evaluator).
"""
import json
import sys

import numpy as np
import OpenEXR


def read(path):
    with OpenEXR.File(path) as f:
        ch = f.channels()
        if "RGB" in ch:
            rgb = ch["RGB"].pixels.astype(np.float64)
        else:
            rgb = np.stack([ch[c].pixels.astype(np.float64) for c in ("R", "G", "B")], axis=-1)
        depth = next((ch[k].pixels for k in ch if k.endswith("Z")), None)
    return rgb, depth


def main():
    args = sys.argv[1:]
    if len(args) < 2:
        sys.exit(__doc__)
    ref, test = read(args[0]), read(args[1])
    out = {"reference": args[0], "test": args[1]}
    a, b = ref[0], test[0]
    out["mad_fraction"] = float(np.abs(a - b).mean() / max(a.mean(), 1e-12))
    out["mean_pixel"] = float(a.mean())
    if ref[1] is not None and test[1] is not None:
        ha, hb = np.isfinite(ref[1]), np.isfinite(test[1])
        out["mask_differs_fraction"] = float((ha != hb).mean())
        out["hit_fraction"] = float(ha.mean())
        # The same over the pixels that show the model in either image (the sky can dwarf
        # it): the difference as a fraction of the model's mean pixel, the mask's share.
        m = ha | hb
        if m.any():
            out["mad_fraction_model"] = float(np.abs(a - b)[m].mean() / max(a[m].mean(), 1e-12))
            out["mask_differs_fraction_model"] = float((ha != hb)[m].mean())
    if "--png" in args:
        i = args.index("--png")
        import flip_evaluator as flip
        from PIL import Image

        pa = np.asarray(Image.open(args[i + 1]).convert("RGB")).astype(np.float32) / 255
        pb = np.asarray(Image.open(args[i + 2]).convert("RGB")).astype(np.float32) / 255
        _, mean, _ = flip.evaluate(pa, pb, "LDR", applyMagma=False)
        out["flip_mean"] = float(mean)
    if "--diff" in args:
        from PIL import Image

        d = np.abs(a - b).sum(axis=-1)
        d = np.clip(d / max(float(np.percentile(d, 99.5)), 1e-12), 0, 1)
        Image.fromarray((d * 255).astype(np.uint8)).save(args[args.index("--diff") + 1])
    print(json.dumps(out))


if __name__ == "__main__":
    main()
