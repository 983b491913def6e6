#!/usr/bin/env python3
"""Bake N placed copies of an OBJ model into one binary PLY (a real model no generator made,
at any size): copies on a square grid, each turned about the vertical axis and scaled by
0.8-1.2 at random (seeded), spaced so that no two overlap.

    python3 bench/bake_copies.py ../shared/models/stanford-bunny.obj 1500 bunnies.ply
    megaray build bunnies.ply -o bunnies.mray --build-mem 4G

Needs numpy (pip install numpy). Streams one copy at a time: memory is a few copies'.
"""
import math
import struct
import sys

import numpy as np


def read_obj(path):
    verts, faces = [], []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                verts.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) for t in line.split()[1:]]
                idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
                for k in range(1, len(idx) - 1):
                    faces.append([idx[0], idx[k], idx[k + 1]])
    return np.array(verts, dtype=np.float64), np.array(faces, dtype=np.int64)


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    src, n, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    v, f = read_obj(src)
    v -= (v.min(0) + v.max(0)) / 2
    radius = np.linalg.norm(v, axis=1).max()
    spacing = 2.6 * radius * 1.2  # the largest copy's bounding sphere, and a gap
    side = math.ceil(math.sqrt(n))
    rng = np.random.default_rng(7)
    nv, nf = len(v), len(f)
    with open(out, "wb") as o:
        o.write(
            (
                "ply\nformat binary_little_endian 1.0\n"
                f"comment {n} copies of {src}\n"
                f"element vertex {nv * n}\nproperty float x\nproperty float y\nproperty float z\n"
                f"element face {nf * n}\nproperty list uchar int vertex_indices\nend_header\n"
            ).encode()
        )
        for c in range(n):
            a, s = rng.uniform(0, 2 * math.pi), rng.uniform(0.8, 1.2)
            rot = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
            at = np.array([(c % side) * spacing, 0.0, (c // side) * spacing])
            o.write(((v @ rot.T) * s + at).astype("<f4").tobytes())
        rec = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
        for c in range(n):
            faces = np.empty(nf, dtype=rec)
            faces["n"] = 3
            faces["i"] = f + c * nv
            o.write(faces.tobytes())
    print(f"wrote {out}: {nv * n} vertices, {nf * n} triangles ({n} copies)")


if __name__ == "__main__":
    main()
