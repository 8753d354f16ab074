#!/usr/bin/env python3
"""A sky-lit room as glTF 2.0, for checking the glTF loader, textures and the sky against an
independent renderer (Blender's Cycles through its own glTF importer).

    tools/make_gltf_room.py OUTDIR [--held-out | --held-out-2 | --held-out-3 | --held-out-4]

Writes OUTDIR/room.glb (textured diffuse walls and floor as 0.15 m slabs, a window in the +z
wall, a textured block, an emissive lamp under the ceiling, a perspective camera; the textures
are PNGs embedded in the .glb) and OUTDIR/room.json (voxcone: the .glb as a {"type": "gltf"}
shape, the same camera, a constant sky [0.6, 0.7, 1.0] and a ground outside). Nothing here is
committed output: the files are small and made on demand.

--held-out writes the room voxcone's defaults were not chosen on, for checking them: 5 x 2.8 x
3.6 m, the window off centre (0.2 to 1.6 m across, 0.6 to 2.2 m high), the lamp 0.1 m under the
ceiling at the other end, a lower block, a 20 m ground and the camera in the other corner.
--held-out-2 another: 3.5 x 2.5 x 4.5 m, a small window by a corner (0.5 to 1.5 m across, 1.0
to 2.1 m high), the lamp 0.3 m under the ceiling and in view, a taller block, a 24 m ground.
--held-out-3 a third, made after the emission guide's bound was chosen on the first three: 6 x
3 x 4 m, a wide low window at one end (-2.6 to -0.4 m across, 0.4 to 1.4 m high), the lamp 5 cm
under the ceiling at the far end, a low wide block, a 20 m ground, the camera by the far wall.
--held-out-4 a fourth, made after the indirect filter's reach and the cone hits' shadow rays were
chosen on the first four: 3 x 3.4 x 5 m, tall and narrow, a high narrow window (-0.9 to -0.1 m
across, 1.6 to 3.0 m high), the lamp 0.15 m under the ceiling in the middle and in view, a
cabinet 1.6 m tall against a side wall, a 12 m ground, the camera low and looking up.
"""

import json
import math
import os
import struct
import sys
import zlib

SKY = [0.6, 0.7, 1.0]
# The room's layout: half width (x), height, half depth (z), the window's x and y span, the
# block's and the lamp's boxes (the lamp's top `lamp_gap` under the ceiling), the ground's half
# size, the camera.
ROOM = {"W": 2.0, "H": 2.6, "D": 2.0, "window_x": (-0.6, 0.6), "window_y": (0.9, 2.0),
        "block": ([-1.2, 0, 0.2], [-0.5, 0.7, 0.9]), "lamp_xz": ((0.3, -1.0), (0.9, -0.4)), "lamp_gap": 0.02,
        "ground": 8,
        "camera": {"position": [0.6, 1.3, -1.6], "target": [-0.1, 0.8, 1.2], "fov_y_deg": 60.0}}
HELD_OUT = {"W": 2.5, "H": 2.8, "D": 1.8, "window_x": (0.2, 1.6), "window_y": (0.6, 2.2),
            "block": ([0.6, 0, -0.9], [1.4, 0.5, -0.2]), "lamp_xz": ((-1.2, 0.3), (-0.7, 0.8)), "lamp_gap": 0.1,
            "ground": 10,
            "camera": {"position": [-1.9, 1.6, -1.4], "target": [1.0, 0.9, 1.3], "fov_y_deg": 55.0}}
HELD_OUT_2 = {"W": 1.75, "H": 2.5, "D": 2.25, "window_x": (0.5, 1.5), "window_y": (1.0, 2.1),
              "block": ([-1.4, 0, 0.5], [-0.6, 0.9, 1.5]), "lamp_xz": ((-0.5, -1.0), (0.0, -0.5)), "lamp_gap": 0.3,
              "ground": 12,
              "camera": {"position": [1.2, 1.4, -1.9], "target": [-0.6, 1.0, 1.5], "fov_y_deg": 65.0}}
HELD_OUT_3 = {"W": 3.0, "H": 3.0, "D": 2.0, "window_x": (-2.6, -0.4), "window_y": (0.4, 1.4),
              "block": ([0.2, 0, -0.2], [1.6, 0.45, 0.8]), "lamp_xz": ((1.8, -1.2), (2.4, -0.6)), "lamp_gap": 0.05,
              "ground": 10,
              "camera": {"position": [2.6, 1.7, -1.7], "target": [-1.2, 0.8, 1.6], "fov_y_deg": 70.0}}
HELD_OUT_4 = {"W": 1.5, "H": 3.4, "D": 2.5, "window_x": (-0.9, -0.1), "window_y": (1.6, 3.0),
              "block": ([-1.5, 0, -0.5], [-0.9, 1.6, 0.7]), "lamp_xz": ((-0.3, -0.3), (0.3, 0.3)), "lamp_gap": 0.15,
              "ground": 12,
              "camera": {"position": [1.0, 1.0, -2.2], "target": [-0.5, 1.9, 2.0], "fov_y_deg": 62.0}}


def png(width, height, rgb_rows):
    """8-bit RGB PNG bytes from rows of (r, g, b) codes, top row first."""
    raw = b"".join(b"\x00" + bytes(c for px in row for c in px) for row in rgb_rows)

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def checker(n, a, b, cells):
    return png(n, n, [[a if ((x * cells // n) + (y * cells // n)) % 2 == 0 else b for x in range(n)] for y in range(n)])


def bricks(n):
    rows = []
    for y in range(n):
        row = []
        for x in range(n):
            course = y * 8 // n
            shift = (n // 8) if course % 2 else 0
            mortar = (y % (n // 8)) < 2 or ((x + shift) % (n // 4)) < 2
            row.append((200, 196, 188) if mortar else (168, 74, 52))
        rows.append(row)
    return png(n, n, rows)


class Glb:
    def __init__(self):
        self.bin = bytearray()
        self.doc = {"asset": {"version": "2.0", "generator": "voxcone tools/make_gltf_room.py"},
                    "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [], "materials": [],
                    "accessors": [], "bufferViews": [], "buffers": [], "images": [], "textures": [],
                    "samplers": [{"magFilter": 9729, "minFilter": 9729}], "cameras": [],
                    "extensionsUsed": ["KHR_materials_emissive_strength"]}

    def view(self, data):
        while len(self.bin) % 4:
            self.bin.append(0)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)})
        self.bin += data
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, values, kind, comps, ctype=5126):
        fmt = "<" + ("f" if ctype == 5126 else "I") * len(values)
        v = self.view(struct.pack(fmt, *values))
        acc = {"bufferView": v, "componentType": ctype, "count": len(values) // comps, "type": kind}
        if kind == "VEC3":
            acc["min"] = [min(values[i::3]) for i in range(3)]
            acc["max"] = [max(values[i::3]) for i in range(3)]
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def texture(self, png_bytes):
        v = self.view(png_bytes)
        self.doc["images"].append({"bufferView": v, "mimeType": "image/png"})
        self.doc["textures"].append({"source": len(self.doc["images"]) - 1, "sampler": 0})
        return len(self.doc["textures"]) - 1

    def material(self, colour, texture=None, emission=None):
        m = {"pbrMetallicRoughness": {"baseColorFactor": colour + [1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}}
        if texture is not None:
            m["pbrMetallicRoughness"]["baseColorTexture"] = {"index": texture}
        if emission is not None:
            peak = max(emission)
            m["emissiveFactor"] = [e / peak for e in emission]
            m["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": peak}}
        self.doc["materials"].append(m)
        return len(self.doc["materials"]) - 1

    def mesh(self, quads, material, name):
        """quads: lists of 4 corners (counter-clockwise seen from the front) with their uvs."""
        pos, uv, idx = [], [], []
        for corners, uvs in quads:
            base = len(pos) // 3
            for c in corners:
                pos += c
            for t in uvs:
                uv += t
            idx += [base, base + 1, base + 2, base, base + 2, base + 3]
        prim = {"attributes": {"POSITION": self.accessor(pos, "VEC3", 3), "TEXCOORD_0": self.accessor(uv, "VEC2", 2)},
                "indices": self.accessor(idx, "SCALAR", 1, 5125), "material": material}
        self.doc["meshes"].append({"name": name, "primitives": [prim]})
        self.doc["nodes"].append({"name": name, "mesh": len(self.doc["meshes"]) - 1})
        self.doc["scenes"][0]["nodes"].append(len(self.doc["nodes"]) - 1)

    def camera(self, position, target, fov_y_deg):
        f = [t - p for t, p in zip(target, position)]
        n = math.sqrt(sum(x * x for x in f))
        f = [x / n for x in f]
        up = [0.0, 1.0, 0.0]
        r = [f[1] * up[2] - f[2] * up[1], f[2] * up[0] - f[0] * up[2], f[0] * up[1] - f[1] * up[0]]
        n = math.sqrt(sum(x * x for x in r))
        r = [x / n for x in r]
        u = [r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]]
        back = [-x for x in f]
        matrix = r + [0.0] + u + [0.0] + back + [0.0] + list(position) + [1.0]
        self.doc["cameras"].append({"type": "perspective", "perspective": {"yfov": math.radians(fov_y_deg), "znear": 0.01,
                                                                            "aspectRatio": 1.0}})
        self.doc["nodes"].append({"name": "camera", "camera": 0, "matrix": matrix})
        self.doc["scenes"][0]["nodes"].append(len(self.doc["nodes"]) - 1)

    def write(self, path):
        while len(self.bin) % 4:
            self.bin.append(0)
        self.doc["buffers"] = [{"byteLength": len(self.bin)}]
        text = json.dumps(self.doc, separators=(",", ":")).encode()
        while len(text) % 4:
            text += b" "
        total = 12 + 8 + len(text) + 8 + len(self.bin)
        with open(path, "wb") as f:
            f.write(struct.pack("<III", 0x46546C67, 2, total))
            f.write(struct.pack("<II", len(text), 0x4E4F534A) + text)
            f.write(struct.pack("<II", len(self.bin), 0x004E4942) + bytes(self.bin))


def box(lo, hi, scale=1.0):
    """The 6 outward faces of an axis-aligned box, uvs in metres times `scale`."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    faces = [
        ([[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], (x1 - x0, y1 - y0)),  # +z
        ([[x1, y0, z0], [x0, y0, z0], [x0, y1, z0], [x1, y1, z0]], (x1 - x0, y1 - y0)),  # -z
        ([[x1, y0, z1], [x1, y0, z0], [x1, y1, z0], [x1, y1, z1]], (z1 - z0, y1 - y0)),  # +x
        ([[x0, y0, z0], [x0, y0, z1], [x0, y1, z1], [x0, y1, z0]], (z1 - z0, y1 - y0)),  # -x
        ([[x0, y1, z1], [x1, y1, z1], [x1, y1, z0], [x0, y1, z0]], (x1 - x0, z1 - z0)),  # +y
        ([[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]], (x1 - x0, z1 - z0)),  # -y
    ]
    # glTF uv: v = 0 at the image's top; the face's bottom edge gets v = height.
    return [(c, [[0, s[1] * scale], [s[0] * scale, s[1] * scale], [s[0] * scale, 0], [0, 0]]) for c, s in faces]


def main():
    layouts = {"--held-out": HELD_OUT, "--held-out-2": HELD_OUT_2, "--held-out-3": HELD_OUT_3,
               "--held-out-4": HELD_OUT_4}
    args = sys.argv[1:]
    chosen = [a for a in args if a in layouts]
    args = [a for a in args if a not in layouts]
    if len(args) != 1 or args[0].startswith("-") or len(chosen) > 1:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    out = args[0]
    room = layouts[chosen[0]] if chosen else ROOM
    CAMERA = room["camera"]
    os.makedirs(out, exist_ok=True)
    g = Glb()
    floor_tex = g.texture(checker(64, (186, 140, 92), (120, 82, 50), 8))
    wall_tex = g.texture(bricks(64))
    block_tex = g.texture(checker(32, (60, 110, 170), (220, 220, 210), 4))
    floor = g.material([1.0, 1.0, 1.0], floor_tex)
    wall = g.material([1.0, 1.0, 1.0], wall_tex)
    white = g.material([0.75, 0.75, 0.72])
    block = g.material([1.0, 1.0, 1.0], block_tex)
    lamp = g.material([0.8, 0.8, 0.8], emission=[12.0, 10.5, 8.0])
    ground = g.material([0.35, 0.33, 0.3])
    t = 0.15
    W, H, D = room["W"], room["H"], room["D"]
    (wx0, wx1), (wy0, wy1) = room["window_x"], room["window_y"]
    (lx0, lz0), (lx1, lz1) = room["lamp_xz"]
    gap, G = room["lamp_gap"], room["ground"]
    # Floor and ceiling slabs, the four walls; the +z wall around the window.
    g.mesh(box([-W - t, -t, -D - t], [W + t, 0.0, D + t], 1.0), floor, "floor")
    g.mesh(box([-W - t, H, -D - t], [W + t, H + t, D + t]), white, "ceiling")
    g.mesh(box([-W - t, 0, -D - t], [-W, H, D + t], 0.5) + box([W, 0, -D - t], [W + t, H, D + t], 0.5) +
           box([-W, 0, -D - t], [W, H, -D], 0.5), wall, "walls")
    g.mesh(box([-W, 0, D], [wx0, H, D + t], 0.5) + box([wx1, 0, D], [W, H, D + t], 0.5) +
           box([wx0, 0, D], [wx1, wy0, D + t], 0.5) + box([wx0, wy1, D], [wx1, H, D + t], 0.5), wall, "window-wall")
    g.mesh(box(room["block"][0], room["block"][1], 1.0), block, "block")
    g.mesh(box([lx0, H - gap - 0.04, lz0], [lx1, H - gap, lz1]), lamp, "lamp")
    y = -t - 0.01
    g.mesh([([[-G, y, G], [G, y, G], [G, y, -G], [-G, y, -G]], [[0, 0], [1, 0], [1, 1], [0, 1]])], ground, "ground")
    g.camera(CAMERA["position"], CAMERA["target"], CAMERA["fov_y_deg"])
    g.write(os.path.join(out, "room.glb"))
    scene = {
        "camera": {"position": CAMERA["position"], "target": CAMERA["target"], "up": [0, 1, 0],
                   "fov_y_deg": CAMERA["fov_y_deg"]},
        "render": {"width": 256, "height": 256, "spp": 16, "max_depth": 16},
        "materials": {},
        "shapes": [{"type": "gltf", "file": "room.glb"}],
        "lights": [{"type": "environment", "radiance": SKY}],
    }
    with open(os.path.join(out, "room.json"), "w") as f:
        json.dump(scene, f, indent=2)
    print("wrote", os.path.join(out, "room.glb"), "and room.json")


if __name__ == "__main__":
    main()
