#!/usr/bin/env python3
"""Writes the seed corpora of the fuzz targets into fuzz/seeds/<target>/: tiny files written
here by hand (every feature each reader has), the heads of ../shared/models, and files the
megaray binary writes (a scene file, an EXR). Usage: seeds.py MEGARAY_BINARY"""
import base64, json, os, struct, subprocess, sys, tempfile

here = os.path.dirname(os.path.abspath(__file__))
models = os.path.join(here, "..", "..", "shared", "models")
megaray = sys.argv[1]
out = os.path.join(here, "seeds")


def put(target, name, data):
    d = os.path.join(out, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())


def head(name, n):
    p = os.path.join(models, name)
    if os.path.exists(p):
        with open(p, "rb") as f:
            return f.read(n)
    return None


V = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0.5)]
F = [(0, 1, 2), (1, 3, 2), (0, 1), (0, 1, 3, 2)]

# PLY: ascii, binary both ways, with normals, colours and texture coordinates.
def ply(fmt):
    hdr = f"ply\nformat {fmt} 1.0\ncomment seed\nelement vertex {len(V)}\nproperty float x\nproperty float y\nproperty float z\n" \
          "property float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n" \
          "property float u\nproperty float v\n" \
          f"element face {len(F)}\nproperty list uchar int vertex_indices\nelement other 1\nproperty int q\nend_header\n"
    if fmt == "ascii":
        body = "".join(f"{x} {y} {z} 0 0 1 255 128 0 {x} {y}\n" for x, y, z in V)
        body += "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in F) + "7\n"
        return (hdr + body).encode()
    e = "<" if fmt == "binary_little_endian" else ">"
    b = b"".join(struct.pack(e + "6f3B2f", x, y, z, 0, 0, 1, 255, 128, 0, x, y) for x, y, z in V)
    b += b"".join(struct.pack(e + "B" + "i" * len(f), len(f), *f) for f in F) + struct.pack(e + "i", 7)
    return hdr.encode() + b

for fmt in ["ascii", "binary_little_endian", "binary_big_endian"]:
    put("ply", fmt + ".ply", ply(fmt))
if head("horse.ply", 16384):
    put("ply", "horse-head.ply", head("horse.ply", 16384))

# OBJ (+ its material library after '#MTL').
obj = "mtllib m.mtl\no thing\nv 0 0 0\nv 1 0 0 1 0 0\nv 0 1 0\nv 1 1 0.5\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n" \
      "g side\nusemtl red\nf 1/1/1 2/2/1 3/3/1\nf -1 -2 -3\nf 1 2\nl 1 2 3\np 1\nusemtl none\nf 1//1 2//1 3//1 4//1\n"
mtl = "newmtl red\nKd 1 0 0\nKs 0.5 0.5 0.5\nNs 32\nd 0.5\nTr 0.2\nmap_Kd -s 1 1 1 tex.png\n"
put("obj", "features.obj", obj + "#MTL\n" + mtl)
for m in ["teapot.obj", "spot.obj"]:
    h = head(m, 8192)
    if h:
        put("obj", m, h)

# STL: ascii and binary.
stl = "solid s\n" + "".join(
    f"facet normal 0 0 1\nouter loop\n" + "".join(f"vertex {x} {y} {z}\n" for x, y, z in (V[a], V[b], V[c])) + "endloop\nendfacet\n"
    for a, b, c in [F[0], F[1]]) + "endsolid s\n"
put("stl", "ascii.stl", stl)
bin_stl = b"binary seed".ljust(80, b" ") + struct.pack("<I", 2)
for a, b, c in [F[0], F[1]]:
    bin_stl += struct.pack("<12fH", 0, 0, 1, *V[a], *V[b], *V[c], 0)
put("stl", "binary.stl", bin_stl)
h = head("dog_ribcage.stl", 4096)
if h:
    put("stl", "ribcage-head.stl", h)

# glTF: JSON with the buffer as a data URI, and GLB; two nodes share the mesh, one scaled.
pos = b"".join(struct.pack("<3f", *v) for v in V)
idx = struct.pack("<6H", 0, 1, 2, 1, 3, 2)
buf = pos + idx
def gltf(uri):
    g = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}],
         "nodes": [{"mesh": 0, "name": "a"}, {"mesh": 0, "scale": [2, 1, -1], "translation": [1, 2, 3], "children": [2]},
                   {"mesh": 0, "rotation": [0, 0.7071, 0, 0.7071]}],
         "meshes": [{"name": "m", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0},
                                                {"attributes": {"POSITION": 0}, "mode": 1}]}],
         "materials": [{"name": "red", "pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 1], "metallicFactor": 0.5}}],
         "buffers": [{"byteLength": len(buf)} | ({"uri": uri} if uri else {})],
         "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(pos)},
                         {"buffer": 0, "byteOffset": len(pos), "byteLength": len(idx)}],
         "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0.5]},
                       {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}]}
    return json.dumps(g)
put("gltf", "embedded.gltf", gltf("data:application/octet-stream;base64," + base64.b64encode(buf).decode()))
j = gltf(None).encode()
j += b" " * (-len(j) % 4)
b = buf + b"\0" * (-len(buf) % 4)
glb = struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(j) + 8 + len(b)) + struct.pack("<I4s", len(j), b"JSON") + j + struct.pack("<I4s", len(b), b"BIN\0") + b
put("gltf", "tiny.glb", glb)
h = head("2CylinderEngine.glb", 32768)
if h:
    put("gltf", "engine-head.glb", h)

# Environment maps: Radiance HDR (flat and run-length encoded rows) and OpenEXR.
def hdr(w, h, rle):
    out = f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=1.0\n\n-Y {h} +X {w}\n".encode()
    for y in range(h):
        px = [(128 + x % 100, 64, 32, 129) for x in range(w)]
        if rle:
            out += bytes([2, 2, w >> 8, w & 255])
            for c in range(4):
                vals = [p[c] for p in px]
                out += bytes([128 + w // 2, vals[0]]) + bytes([w - w // 2]) + bytes(vals[w // 2:])
        else:
            out += b"".join(bytes(p) for p in px)
    return out
put("env", "flat.hdr", hdr(4, 2, False))
put("env", "rle.hdr", hdr(16, 2, True))

# pbrt-v4 scenes (+ an included file after '#INC', a PLY after '#PLY'): every statement read.
pbrt = """LookAt 0 3 12  0 0 0  0 1 0
Camera "perspective" "float fov" [ 40 ]
Film "rgb" "integer xresolution" [ 64 ] "integer yresolution" [ 48 ] "string filename" "x.exr"
Sampler "zsobol" "integer pixelsamples" 16
CoordinateSystem "cam"
WorldBegin
LightSource "distant" "point3 from" [ 1 2 1 ] "point3 to" [ 0 0 0 ] "blackbody L" [ 5500 ]
LightSource "infinite" "string filename" "sky.exr"
Texture "wood" "spectrum" "imagemap" "string filename" "wood.png"
MakeNamedMaterial "gold" "string type" "conductor" "spectrum eta" "metal-Au-eta" "float roughness" 0.1
Material "diffuse" "texture reflectance" "wood"
Include "inc.pbrt"
ObjectBegin "quad"
  Shape "bilinearmesh" "point3 P" [ -1 -1 0  1 -1 0  -1 1 0  1 1 0 ] "point2 uv" [ 0 0 1 0 0 1 1 1 ]
ObjectEnd
ObjectBegin "row"
  Translate -3 0 0  ObjectInstance "quad"
  Translate 3 0 0   ObjectInstance "quad"
ObjectEnd
AttributeBegin
  Transform [ 1 0 0 0  0 1 0 0  0 0 1 0  0 2 0 1 ]
  ConcatTransform [ 1 0 0 0  0 1 0 0  0 0 -1 0  0 0 0 1 ]
  NamedMaterial "gold"
  ObjectInstance "row"
AttributeEnd
AttributeBegin
  Rotate 30 0 1 0  Scale 1 -2 1  ReverseOrientation
  Material "coateddiffuse" "rgb reflectance" [ 0.2 0.3 0.4 ]
  AreaLightSource "diffuse" "rgb L" [ 4 4 4 ]
  Shape "trianglemesh" "point3 P" [ -6 -4 -1  6 -4 -1  0 -4 -8 ] "integer indices" [ 0 1 2 ]
    "normal N" [ 0 1 0 0 1 0 0 1 0 ] "point2 uv" [ 0 0 1 0 0 1 ]
AttributeEnd
CoordSysTransform "cam"
Material "dielectric" "float eta" 1.5
Shape "plymesh" "string filename" "m.ply"
Shape "sphere" "float radius" 2
Shape "curve" "point3 P" [ 0 0 0 1 1 1 2 2 2 3 3 3 ]
"""
inc = """# included
AttributeBegin
  Translate 0 -1 0
  Shape "trianglemesh" "point3 P" [ 0 0 0  1 0 0  0 1 0 ] "integer indices" [ 0 1 2 ]
AttributeEnd
"""
put("pbrt", "features.pbrt", pbrt + "#INC\n" + inc + "#PLY\n" + ply("ascii").decode())
put("pbrt", "binary-ply.pbrt", pbrt.encode() + b"#INC\n" + inc.encode() + b"#PLY\n" + ply("binary_little_endian"))
stairs = head(os.path.join("pbrt-staircase", "staircase.pbrt"), 16384)
if stairs:
    put("pbrt", "staircase-head.pbrt", stairs)

with tempfile.TemporaryDirectory() as t:
    o = os.path.join(t, "s.obj")
    with open(o, "w") as f:
        f.write(obj)
    with open(os.path.join(t, "m.mtl"), "w") as f:
        f.write(mtl)
    scene = os.path.join(t, "s.mray")
    subprocess.run([megaray, "build", o, "-o", scene, "-q"], check=True)
    put("scene", "tiny.mray", open(scene, "rb").read())
    subprocess.run([megaray, "build", o, "-o", scene, "-q", "--no-lod"], check=True)
    put("scene", "tiny-nolod.mray", open(scene, "rb").read())
    subprocess.run([megaray, "build", o, "-o", scene, "-q", "--plain"], check=True)
    put("scene", "tiny-plain.mray", open(scene, "rb").read())
    # A scene file with instances (objects, nested groups, materials): the pbrt seed built.
    for name, data in [("scene.pbrt", pbrt), ("inc.pbrt", inc), ("m.ply", ply("ascii"))]:
        with open(os.path.join(t, name), "wb") as f:
            f.write(data if isinstance(data, bytes) else data.encode())
    inst = os.path.join(t, "inst.mray")
    subprocess.run([megaray, "build", os.path.join(t, "scene.pbrt"), "-o", inst, "-q"], check=True)
    put("scene", "instanced.mray", open(inst, "rb").read())
    exr = os.path.join(t, "e.exr")
    subprocess.run([megaray, "render", scene, "-o", exr, "--res", "4x2", "-q"], check=True)
    put("env", "tiny.exr", open(exr, "rb").read())
print("seeds in", out)
