#!/usr/bin/env python3
"""Writes a Y-up glTF scene for the "device's up is the scene's up" checks (issue 33): a flat
4 x 4 x 0.5 cm plate ("plate", its top at Y = 0) and a 1 cm cube probe ("probe", no rotation)
above it, as OUT/plate.gltf (one embedded buffer), and OUT/plate.json, the scene description
that names the probe as the tool. Usage: make_plate_scene.py OUT_DIR [--tool-rotation-deg A]
(the probe's node turned A degrees about the scene's X axis: the device's up must not follow)."""
import base64
import json
import math
import os
import struct
import sys


def box(hx, hy, hz):
    """A box's 24 vertices (4 per face, flat normals) and 36 indices, counter-clockwise outside."""
    pos, nrm, idx = [], [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = [0.0, 0.0, 0.0]
            n[axis] = sign
            u, v = (axis + 1) % 3, (axis + 2) % 3
            base = len(pos)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0.0, 0.0, 0.0]
                p[axis] = sign * (hx, hy, hz)[axis]
                p[u] = a * (hx, hy, hz)[u]
                p[v] = b * (hx, hy, hz)[v]
                pos.append(p)
                nrm.append(n)
            quad = [0, 1, 2, 0, 2, 3] if sign > 0 else [0, 2, 1, 0, 3, 2]
            idx += [base + q for q in quad]
    return pos, nrm, idx


def main():
    out = sys.argv[1]
    angle = 0.0
    if len(sys.argv) > 3 and sys.argv[2] == "--tool-rotation-deg":
        angle = float(sys.argv[3])
    os.makedirs(out, exist_ok=True)
    blob = b""
    views, accessors, meshes = [], [], []
    for name, (hx, hy, hz) in (("plate", (0.02, 0.0025, 0.02)), ("probe", (0.005, 0.005, 0.005))):
        pos, nrm, idx = box(hx, hy, hz)
        for data, target, fmt, typ, comp in ((pos, 34962, "3f", "VEC3", 5126),
                                             (nrm, 34962, "3f", "VEC3", 5126),
                                             (idx, 34963, "I", "SCALAR", 5125)):
            raw = b"".join(struct.pack("<" + fmt, *(d if isinstance(d, list) else [d]))
                           for d in data)
            views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(raw),
                          "target": target})
            acc = {"bufferView": len(views) - 1, "componentType": comp, "count": len(data),
                   "type": typ}
            if typ == "VEC3":
                acc["min"] = [min(p[i] for p in data) for i in range(3)]
                acc["max"] = [max(p[i] for p in data) for i in range(3)]
            accessors.append(acc)
            blob += raw
        a = len(accessors)
        meshes.append({"name": name, "primitives": [{"attributes": {"POSITION": a - 3,
                                                                     "NORMAL": a - 2},
                                                      "indices": a - 1}]})
    half = math.radians(angle) / 2
    probe = {"name": "probe", "mesh": 1, "translation": [0.0, 0.03, 0.0]}
    if angle != 0.0:
        probe["rotation"] = [math.sin(half), 0.0, 0.0, math.cos(half)]
    gltf = {
        "asset": {"version": "2.0", "generator": "tests/make_plate_scene.py"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"name": "plate", "mesh": 0, "translation": [0.0, -0.0025, 0.0]}, probe],
        "meshes": meshes,
        "buffers": [{"byteLength": len(blob),
                     "uri": "data:application/octet-stream;base64," +
                            base64.b64encode(blob).decode()}],
        "bufferViews": views,
        "accessors": accessors,
    }
    with open(os.path.join(out, "plate.gltf"), "w") as f:
        json.dump(gltf, f)
    with open(os.path.join(out, "plate.json"), "w") as f:
        json.dump({"scene": "plate.gltf", "tool": "probe",
                   "defaults": {"texture_size": 128, "coarse_triangles": 100}}, f)


main()
