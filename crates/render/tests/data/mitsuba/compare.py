#!/usr/bin/env python3
"""The `path` shader against Mitsuba 3 (a renderer no one here wrote) on the same scene.

Writes the scene's geometry (OBJ + MTL) and its sky (a Radiance .hdr: constant, or a map with a
sun), builds and renders it with megaray (`--shader path`), renders it with Mitsuba 3
(`scalar_rgb`, the `path` integrator, a `constant` or `envmap` emitter, box pixel filter; the
glossy material as a BSDF written here, `blinn_phong_bsdf`), and compares the two linear images:
the mean absolute difference as a fraction of Mitsuba's mean pixel value, and the mean FLIP
error of the tone-mapped images when flip-evaluator is installed. One JSON line per scene.

    python3 compare.py [--megaray BIN] [--res 160x120] [--frames 1024] [--spp 4096]
                       [--scene all|box,glass,sun,glossy,staircase] [--save-reference] [--check 0.03] [--keep DIR]

--save-reference writes Mitsuba's image beside this script (`<scene>-mitsuba.exr`) with the
scene as megaray reads it (`<scene>.obj`, `.mtl`, `-sky.hdr`): the reference the Rust test
`crates/cli/tests/mitsuba.rs` compares megaray with, Mitsuba or not. Needs `pip install mitsuba` (and numpy, which it brings).
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def box_scene():
    """An open box (floor, back and side walls, albedo 0.7 / 0.6 / 0.3 tints) with a diffuse
    sphere (albedo 0.5) inside, under a constant sky of radiance 1; camera looking in."""
    quads = {
        "floor": ([(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)], (0.7, 0.7, 0.7)),
        "back": ([(-1, 0, -1), (-1, 2, -1), (1, 2, -1), (1, 0, -1)], (0.7, 0.7, 0.7)),
        "left": ([(-1, 0, -1), (-1, 0, 1), (-1, 2, 1), (-1, 2, -1)], (0.7, 0.25, 0.2)),
        "right": ([(1, 0, -1), (1, 2, -1), (1, 2, 1), (1, 0, 1)], (0.2, 0.3, 0.7)),
    }
    meshes = []
    for name, (q, kd) in quads.items():
        # Both sides: the walls are seen from inside and lit from outside.
        meshes.append((name, kd, q, [(0, 1, 2), (0, 2, 3), (0, 2, 1), (0, 3, 2)]))
    # A UV sphere, centre (0.2, 0.45, 0.1), radius 0.45.
    verts, faces = [], []
    n_lat, n_lon = 24, 48
    for i in range(n_lat + 1):
        th = math.pi * i / n_lat
        for j in range(n_lon):
            ph = 2 * math.pi * j / n_lon
            verts.append((0.2 + 0.45 * math.sin(th) * math.cos(ph), 0.45 + 0.45 * math.cos(th),
                          0.1 + 0.45 * math.sin(th) * math.sin(ph)))
    for i in range(n_lat):
        for j in range(n_lon):
            a, b = i * n_lon + j, i * n_lon + (j + 1) % n_lon
            c, d = a + n_lon, b + n_lon
            if i > 0:
                faces.append((a, b, c))
            if i < n_lat - 1:
                faces.append((b, d, c))
    meshes.append(("sphere", (0.5, 0.5, 0.5), verts, faces))
    camera = {"eye": (0.0, 1.3, 4.2), "at": (0.0, 0.8, 0.0), "fov": 40.0}
    return meshes, camera, 1.0


def glass_scene():
    """The open box with the sphere made of clear glass (index 1.5)."""
    meshes, camera, radiance = box_scene()
    name, _, verts, faces = meshes[-1]
    meshes[-1] = ("glass", "glass", verts, faces)
    return meshes, camera, radiance


def sun_scene():
    """The open box with the diffuse sphere under a sky map with a sun: radiance 0.5 everywhere
    and 2,000 in a 2x2-pixel patch of a 64x32 map (about 45 degrees up), so that shadows and
    the importance sampling of a small bright source are compared too."""
    meshes, camera, _ = box_scene()
    sky = [[0.5] * 64 for _ in range(32)]
    for y in (8, 9):
        for x in (20, 21):
            sky[y][x] = 2000.0
    return meshes, camera, sky


def glossy_scene():
    """The open box with a glossy sphere: diffuse 0.3 under a normalized Blinn-Phong lobe of
    0.4 and exponent 40 (OBJ `Ks`, `Ns`; megaray's model, given to Mitsuba as a BSDF written
    in Python here, `BlinnPhong`: Mitsuba's integrator, sampling and light transport, our
    material), under the sky with a sun, so that the lobe's highlight is compared too."""
    meshes, camera, sky = sun_scene()
    name, _, verts, faces = meshes[-1]
    meshes[-1] = ("glossy", {"kd": (0.3, 0.3, 0.3), "ks": (0.4, 0.4, 0.4), "ns": 40.0}, verts, faces)
    return meshes, camera, sky


STAIRCASE = os.path.join(HERE, "../../../../../../shared/models/pbrt-staircase/staircase.pbrt")


def staircase_scene():
    """The pbrt-v4 staircase (a third party's scene: 262,663 triangles in 773 PLY meshes, 24
    materials, lit by one area light). megaray builds the .pbrt itself; Mitsuba is given the
    same meshes, camera and light, with the materials as megaray's importer maps them (so that
    the light transport is compared, not two material models): diffuse and textured diffuse
    as they are, coateddiffuse as megaray's Blinn-Phong lobe (`blinnphong`, specular 0.04,
    exponent 2 / roughness^2) over the diffuse, conductors as mirrors of their normal-incidence
    reflectance, dielectrics as glass of index 1.5. Textures missing from the copy are drawn in
    the material's colour by both."""
    return "pbrt", None, None


SCENES = {"box": box_scene, "glass": glass_scene, "sun": sun_scene, "glossy": glossy_scene,
          "staircase": staircase_scene}


def pbrt_tokens(path):
    """The tokens of a pbrt file: words, numbers, quoted strings, brackets."""
    import re
    text = open(path).read()
    text = re.sub(r"#[^\n]*", "", text)
    for m in re.finditer(r'"([^"]*)"|(\[|\])|([^\s\[\]"]+)', text):
        yield m.group(1) if m.group(1) is not None else (m.group(2) or m.group(3)), m.group(1) is not None


def read_pbrt(path):
    """The staircase's shapes, materials, textures, area light and camera: the subset of
    pbrt-v4 it uses (world shapes without transforms, named materials, one Transform and
    Camera), read into plain Python."""
    toks = list(pbrt_tokens(path))
    i, out = 0, {"textures": {}, "materials": {}, "shapes": [], "lights": []}
    cur, area, mat = None, None, None

    def params(i):
        ps = {}
        while i < len(toks) and toks[i][1] and " " in toks[i][0]:
            ty, name = toks[i][0].split()
            i += 1
            vals = []
            if toks[i][0] == "[":
                i += 1
                while toks[i][0] != "]":
                    vals.append(toks[i][0])
                    i += 1
                i += 1
            else:
                vals.append(toks[i][0])
                i += 1
            conv = (lambda v: float(v)) if ty in ("float", "rgb", "point3", "point2", "normal", "integer") else \
                (lambda v: v == "true") if ty == "bool" else (lambda v: v)
            ps[name] = (ty, [conv(v) for v in vals])
        return ps, i

    xform = None
    while i < len(toks):
        w, quoted = toks[i]
        i += 1
        if w == "Transform":
            i += 1
            xform = [float(toks[i + k][0]) for k in range(16)]
            i += 17
        elif w == "Camera":
            i += 1
            ps, i = params(i)
            out["camera"] = (xform, ps["fov"][1][0])
        elif w == "Texture":
            name = toks[i][0]
            i += 3
            ps, i = params(i)
            out["textures"][name] = os.path.join(os.path.dirname(path), ps["filename"][1][0])
        elif w == "MakeNamedMaterial":
            name = toks[i][0]
            ps, i = params(i + 1)
            out["materials"][name] = ps
        elif w == "NamedMaterial":
            cur = toks[i][0]
            i += 1
        elif w == "Material":
            ps, i = params(i + 1)
            ps["type"] = ("string", [toks[i - 1][0]])
            mat = ps
        elif w == "AreaLightSource":
            ps, i = params(i + 1)
            area = ps["L"][1]
        elif w == "Shape":
            kind = toks[i][0]
            ps, i = params(i + 1)
            if area is not None:
                out["lights"].append((ps["P"][1], [int(v) for v in ps["indices"][1]], area))
            elif kind == "plymesh":
                out["shapes"].append((os.path.join(os.path.dirname(path), ps["filename"][1][0]), cur))
        elif w in ("AttributeBegin", "WorldBegin"):
            pass
        elif w == "AttributeEnd":
            area, mat = None, None
        elif not quoted and w not in ("[", "]"):
            # Integrator, Sampler, PixelFilter, Film: read past their parameters.
            if i < len(toks) and toks[i][1]:
                i += 1
            _, i = params(i)
    return out


def staircase_camera(cam):
    """eye, at, up of the pbrt camera (the inverse of its world-to-camera Transform), as
    megaray's importer computes them, and pbrt's fov (of the shorter image axis)."""
    import numpy as np
    xform, fov = cam
    m = np.array(xform).reshape(4, 4).T
    inv = np.linalg.inv(m)
    eye = inv @ [0, 0, 0, 1]
    at = inv @ [0, 0, 1, 1]
    up = inv @ [0, 1, 0, 0]
    return {"eye": tuple(eye[:3]), "at": tuple(at[:3]), "up": tuple(up[:3] / np.linalg.norm(up[:3])), "fov": fov}


def staircase_mitsuba(scene, res, spp):
    """The staircase as a Mitsuba scene dictionary."""
    import mitsuba as mi
    blinn_phong_bsdf()
    p = read_pbrt(STAIRCASE)
    c = staircase_camera(p["camera"])
    w, h = map(int, res.split("x"))
    scene.update({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 64},
        "camera": {
            "type": "perspective", "fov": c["fov"], "fov_axis": "smaller",
            "to_world": mi.ScalarTransform4f().look_at(origin=c["eye"], target=c["at"], up=c["up"]),
            "film": {"type": "hdrfilm", "width": w, "height": h, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": spp},
        },
    })

    def reflectance(ps):
        tex = ps.get("reflectance")
        if tex and tex[0] == "texture":
            f = p["textures"].get(tex[1][0])
            if f and os.path.isfile(f):
                # megaray: nearest texel, repeat, sRGB decoded, v = 0 the bottom row.
                return {"type": "bitmap", "filename": f, "filter_type": "nearest", "wrap_mode": "repeat",
                        "to_uv": mi.ScalarTransform3f().translate([0, 1]).scale([1, -1])}
            return {"type": "rgb", "value": [0.5] * 3}
        if tex and tex[0] == "rgb":
            return {"type": "rgb", "value": tex[1]}
        return {"type": "rgb", "value": [0.5] * 3}

    def bsdf(ps):
        kind = ps["type"][1][0]
        rough = ps.get("roughness", ps.get("uroughness", ("float", [None])))[1][0]
        if kind in ("diffuse", "diffusetransmission"):
            b = {"type": "diffuse", "reflectance": reflectance(ps)}
        elif kind == "coateddiffuse":
            ns = 2.0 / max(rough if rough is not None else 0.05, 0.01) ** 2
            b = {"type": "blinnphong", "kd": reflectance(ps), "ks": [0.04] * 3, "ns": ns}
        elif kind in ("conductor", "coatedconductor"):
            eta = ps.get("eta", ("rgb", [0.2, 0.92, 1.1]))[1]
            k = ps.get("k", ("rgb", [3.9, 2.45, 2.14]))[1]
            f0 = [((e - 1) ** 2 + kk * kk) / ((e + 1) ** 2 + kk * kk) for e, kk in zip(eta, k)]
            b = {"type": "conductor", "material": "none", "specular_reflectance": {"type": "rgb", "value": f0}}
            return b
        elif kind in ("dielectric", "thindielectric"):
            return {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}
        else:
            b = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5] * 3}}
        return {"type": "twosided", "bsdf": b}

    bsdfs = {name: bsdf(ps) for name, ps in p["materials"].items()}
    for k, (f, m) in enumerate(p["shapes"]):
        scene[f"shape{k}"] = {"type": "ply", "filename": f, "bsdf": bsdfs[m]}
    for k, (pts, idx, l) in enumerate(p["lights"]):
        verts = [pts[3 * j:3 * j + 3] for j in range(len(pts) // 3)]
        scene[f"light{k}"] = {"type": "obj", "filename": write_light_obj(verts, idx),
                              "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}},
                              "emitter": {"type": "area", "radiance": {"type": "rgb", "value": l}}}
    return scene


def write_light_obj(verts, idx):
    f = tempfile.NamedTemporaryFile("w", suffix=".obj", delete=False)
    for v in verts:
        f.write("v %.9g %.9g %.9g\n" % tuple(v))
    for t in range(0, len(idx), 3):
        f.write("f %d %d %d\n" % (idx[t] + 1, idx[t + 1] + 1, idx[t + 2] + 1))
    f.close()
    return f.name


def blinn_phong_bsdf():
    """Registers `blinnphong` with Mitsuba: megaray's glossy model (`path` shader), a diffuse
    term plus a normalized Blinn-Phong lobe, kd / pi + ks (ns + 8) / (8 pi) (n.h)^ns, sampled
    by the cosine (as megaray's bounce is)."""
    import drjit as dr
    import mitsuba as mi

    # Each call of a BSDF written in Python takes the interpreter's lock: one thread renders
    # 3.6 times faster than two fighting for it (measured on the staircase).
    dr.set_thread_count(1)

    class BlinnPhong(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            kd = props["kd"]
            # A colour, or a texture (the staircase's textured coated wood).
            self.kd = kd if isinstance(kd, mi.Texture) else mi.Color3f(kd)
            self.ks, self.ns = mi.Color3f(props["ks"]), props["ns"]
            self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]

        def f(self, si, wi, wo):
            h = dr.normalize(wi + wo)
            kd = self.kd.eval(si) if isinstance(self.kd, mi.Texture) else self.kd
            return kd / math.pi + self.ks * ((self.ns + 8) / (8 * math.pi) * dr.maximum(h.z, 0) ** self.ns)

        def sample(self, ctx, si, sample1, sample2, active=True):
            bs = mi.BSDFSample3f()
            bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            bs.eta, bs.sampled_component = 1.0, 0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
            ok = mi.Frame3f.cos_theta(si.wi) > 0 and bs.pdf > 0
            return bs, (self.f(si, si.wi, bs.wo) * math.pi if ok else mi.Color3f(0))

        def eval(self, ctx, si, wo, active=True):
            ci, co = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
            return self.f(si, si.wi, wo) * co if ci > 0 and co > 0 else mi.Color3f(0)

        def pdf(self, ctx, si, wo, active=True):
            return mi.warp.square_to_cosine_hemisphere_pdf(wo) if mi.Frame3f.cos_theta(si.wi) > 0 else 0.0

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def to_string(self):
            return "BlinnPhong"

    mi.register_bsdf("blinnphong", lambda props: BlinnPhong(props))


def write_obj(meshes, path):
    """One OBJ with a material per mesh (megaray), and one OBJ per mesh (Mitsuba)."""
    mtl = path[:-4] + ".mtl"
    with open(mtl, "w") as m:
        for name, kd, _, _ in meshes:
            if kd == "glass":
                # Opacity below 1 is megaray's glass (index 1.5).
                m.write(f"newmtl {name}\nKd 1 1 1\nd 0\n")
            elif isinstance(kd, dict):
                d, k = kd["kd"], kd["ks"]
                m.write(f"newmtl {name}\nKd {d[0]} {d[1]} {d[2]}\nKs {k[0]} {k[1]} {k[2]}\nNs {kd['ns']}\n")
            else:
                m.write(f"newmtl {name}\nKd {kd[0]} {kd[1]} {kd[2]}\n")
    parts = []
    with open(path, "w") as o:
        o.write(f"mtllib {os.path.basename(mtl)}\n")
        base = 1
        for name, kd, verts, faces in meshes:
            o.write(f"o {name}\nusemtl {name}\n")
            for v in verts:
                o.write("v %.9g %.9g %.9g\n" % v)
            for f in faces:
                o.write("f %d %d %d\n" % (f[0] + base, f[1] + base, f[2] + base))
            base += len(verts)
            one = path[:-4] + f"-{name}.obj"
            with open(one, "w") as s:
                for v in verts:
                    s.write("v %.9g %.9g %.9g\n" % v)
                for f in faces:
                    s.write("f %d %d %d\n" % (f[0] + 1, f[1] + 1, f[2] + 1))
            parts.append((one, kd))
    return parts


def rgbe(v):
    m, e = math.frexp(v)
    return bytes([int(m * 256)] * 3 + [e + 128])


def write_sky_hdr(path, sky):
    """A lat-long Radiance map (flat RGBE pixels, grey): `sky` is a constant radiance (an
    8x4 map) or rows of radiances. Row 0 is straight up; column u looks along
    (cos 2 pi u, ., sin 2 pi u), megaray's convention (`EnvMap::eval`)."""
    rows = [[sky] * 8 for _ in range(4)] if isinstance(sky, (int, float)) else sky
    with open(path, "wb") as f:
        f.write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % (len(rows), len(rows[0])))
        for row in rows:
            f.write(b"".join(rgbe(v) for v in row))


def write_sky_hdr_for_mitsuba(path, sky, factor=16):
    """The sky map as Mitsuba's `envmap` must be given it to show megaray's: Mitsuba reads a
    map's rows as samples at the poles and between (row j at theta = pi j / (h - 1)) and
    interpolates bilinearly, where megaray reads row j as constant over theta in
    [pi j / h, pi (j + 1) / h) (columns agree: both centre column i at 2 pi (i + 0.5) / w).
    Resampled `factor` times finer, Mitsuba's rows sample megaray's map where they lie, and
    its blur is a sixteenth of a pixel wide. (Read as is, the sun moves about a third of a
    row toward the horizon, which made the sun scene's mean 1.2 % low.)"""
    rows = [[sky] * 8 for _ in range(4)] if isinstance(sky, (int, float)) else sky
    h, w = len(rows), len(rows[0])
    hh, ww = h * factor, w * factor
    out = [[rows[min(j * h // (hh - 1), h - 1)][(i * w) // ww] for i in range(ww)] for j in range(hh)]
    write_sky_hdr(path, out)


def render_megaray(binary, tmp, obj, hdr, camera, res, frames):
    scene = os.path.join(tmp, "scene.mray")
    subprocess.run([binary, "build", obj, "-o", scene, "-q"], check=True)
    out = os.path.join(tmp, "megaray.exr")
    c = camera
    args = [binary, "render", scene, "-o", out, "-q", "--json", "--shader", "path", "--env", hdr,
            "--res", res, "--frames", str(frames), "--max-depth", "64", "--fov", str(c["fov"]),
            "--eye", ",".join(map(str, c["eye"])), "--at", ",".join(map(str, c["at"]))]
    t = time.time()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
    return out, time.time() - t


def render_mitsuba(parts, camera, res, spp, radiance, out, sky_file=None):
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    w, h = map(int, res.split("x"))
    c = camera
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 64},
        "sky": ({"type": "constant", "radiance": {"type": "rgb", "value": [radiance] * 3}}
                if isinstance(radiance, (int, float)) else
                # The same map, turned so that Mitsuba's (atan2(x, -z), acos y) mapping reads it
                # as megaray's (atan2(z, x), acos y) does.
                {"type": "envmap", "filename": sky_file,
                 "to_world": mi.ScalarTransform4f([[0, 0, -1, 0], [0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1]])}),
        "camera": {
            "type": "perspective", "fov": c["fov"], "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(origin=c["eye"], target=c["at"], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": w, "height": h, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": spp},
        },
    }
    for k, (path, kd) in enumerate(parts):
        if kd == "glass":
            bsdf = {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}
        elif isinstance(kd, dict):
            blinn_phong_bsdf()
            bsdf = {"type": "twosided", "bsdf": {"type": "blinnphong", "kd": list(kd["kd"]), "ks": list(kd["ks"]),
                                                 "ns": kd["ns"]}}
        else:
            diffuse = {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(kd)}}
            bsdf = {"type": "twosided", "bsdf": diffuse}
        scene[f"shape{k}"] = {"type": "obj", "filename": path, "face_normals": True, "bsdf": bsdf}
    t = time.time()
    img = mi.render(mi.load_dict(scene))
    secs = time.time() - t
    write_exr(img, out)
    return secs


def write_exr(img, path):
    """Writes a Mitsuba image as EXR. OpenEXR's writer waits on a thread pool that Mitsuba
    sizes from Dr.Jit's: with the one thread the Python BSDF asks for, the write never ends."""
    import drjit as dr
    import mitsuba as mi
    dr.set_thread_count(max(2, os.cpu_count() or 2))
    mi.Bitmap(img).write(path)


def read_exr(path):
    import mitsuba as mi
    import numpy as np
    mi.set_variant("scalar_rgb")
    return np.array(mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, False))


def compare(ref_path, test_path):
    import numpy as np
    ref, test = read_exr(ref_path).astype(np.float64), read_exr(test_path).astype(np.float64)
    out = {"mean_abs_diff_rel": float(np.abs(ref - test).mean() / max(ref.mean(), 1e-12)),
           "mean_ref": float(ref.mean()), "mean_test": float(test.mean())}
    try:
        import flip_evaluator as flip
        tone = lambda x: np.clip(x, 0, 1) ** (1 / 2.2)
        _, mean, _ = flip.evaluate(tone(ref).astype(np.float32), tone(test).astype(np.float32), "LDR")
        out["flip"] = float(mean)
    except ImportError:
        pass
    return out


def run_staircase(a):
    """megaray builds and renders the .pbrt (its camera, its area light, no sky); Mitsuba
    renders `staircase_mitsuba`."""
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    with tempfile.TemporaryDirectory() as tmp:
        scene = os.path.join(tmp, "staircase.mray")
        subprocess.run([a.megaray, "build", STAIRCASE, "-o", scene, "-q"], check=True)
        ours = os.path.join(tmp, "megaray.exr")
        t = time.time()
        subprocess.run([a.megaray, "render", scene, "-o", ours, "-q", "--json", "--shader", "path", "--res", a.res,
                        "--frames", str(a.frames), "--max-depth", "64", "--lod-error", "0"], check=True,
                       stdout=subprocess.DEVNULL)
        ours_s = time.time() - t
        ref = os.path.join(HERE, "staircase-mitsuba.exr") if a.save_reference else os.path.join(tmp, "mitsuba.exr")
        t = time.time()
        img = mi.render(mi.load_dict(staircase_mitsuba({}, a.res, a.spp)))
        mi_s = time.time() - t
        write_exr(img, ref)
        r = compare(ref, ours)
        r.update({"scene": "staircase", "res": a.res, "megaray_frames": a.frames, "megaray_s": round(ours_s, 2),
                  "mitsuba_spp": a.spp, "mitsuba_s": round(mi_s, 2)})
        print(json.dumps(r))
        if a.keep:
            for f, to in ((ours, "staircase-megaray.exr"), (ref, "staircase-mitsuba.exr")):
                with open(f, "rb") as src, open(os.path.join(a.keep, to), "wb") as dst:
                    dst.write(src.read())
        if a.check is not None and r["mean_abs_diff_rel"] > a.check:
            print(f"staircase: megaray and Mitsuba differ by {100 * r['mean_abs_diff_rel']:.2f} % of the mean",
                  file=sys.stderr)
            return True
    return False


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--megaray", default=os.path.join(HERE, "../../../../../target/release/megaray"))
    ap.add_argument("--res", default="160x120")
    ap.add_argument("--frames", type=int, default=1024)
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--scene", default="all", help="all, or scenes separated by commas: " + ", ".join(SCENES))
    ap.add_argument("--save-reference", action="store_true")
    ap.add_argument("--keep", metavar="DIR", help="copy the staircase's two images into DIR")
    ap.add_argument("--check", type=float, metavar="FRACTION",
                    help="exit 1 if a scene's mean absolute difference is above FRACTION of the mean")
    a = ap.parse_args()
    failed = False
    names = list(SCENES) if a.scene == "all" else a.scene.split(",")
    for name in names:
        if name == "staircase":
            failed |= run_staircase(a)
            continue
        meshes, camera, radiance = SCENES[name]()
        with tempfile.TemporaryDirectory() as tmp:
            obj = os.path.join(tmp, f"{name}.obj")
            parts = write_obj(meshes, obj)
            hdr = os.path.join(tmp, "sky.hdr")
            write_sky_hdr(hdr, radiance)
            ours, ours_s = render_megaray(a.megaray, tmp, obj, hdr, camera, a.res, a.frames)
            if a.save_reference:
                # The scene as megaray reads it, for the Rust test.
                for f, to in ((obj, None), (obj[:-4] + ".mtl", None), (hdr, f"{name}-sky.hdr")):
                    with open(f, "rb") as src, open(os.path.join(HERE, to or os.path.basename(f)), "wb") as dst:
                        dst.write(src.read())
            ref = os.path.join(HERE, f"{name}-mitsuba.exr") if a.save_reference else os.path.join(tmp, "mitsuba.exr")
            mi_hdr = os.path.join(tmp, "sky-mitsuba.hdr")
            write_sky_hdr_for_mitsuba(mi_hdr, radiance)
            mi_s = render_mitsuba(parts, camera, a.res, a.spp, radiance, ref, mi_hdr)
            r = compare(ref, ours)
            r.update({"scene": name, "res": a.res, "megaray_frames": a.frames, "megaray_s": round(ours_s, 2),
                      "mitsuba_spp": a.spp, "mitsuba_s": round(mi_s, 2)})
            print(json.dumps(r))
            if a.check is not None and r["mean_abs_diff_rel"] > a.check:
                print(f"{name}: megaray and Mitsuba differ by {100 * r['mean_abs_diff_rel']:.2f} % of the mean", file=sys.stderr)
                failed = True
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
