#!/usr/bin/env python3
"""Writes data/scenes/*.json from the numbers of docs/scenes/SPEC.md (run from anywhere).

The scene files are committed; this script documents where every number comes from and
regenerates them if the format changes."""
import json
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "data", "scenes")

WHITE = [0.725, 0.71, 0.68]
RED = [0.63, 0.065, 0.05]
GREEN = [0.14, 0.45, 0.091]

ROOM = [
    ("floor", "white", [[552.8, 0, 0], [0, 0, 0], [0, 0, 559.2], [549.6, 0, 559.2]]),
    ("ceiling", "white", [[556, 548.8, 0], [556, 548.8, 559.2], [0, 548.8, 559.2], [0, 548.8, 0]]),
    ("back_wall", "white", [[549.6, 0, 559.2], [0, 0, 559.2], [0, 548.8, 559.2], [556, 548.8, 559.2]]),
    ("right_wall", "green", [[0, 0, 559.2], [0, 0, 0], [0, 548.8, 0], [0, 548.8, 559.2]]),
    ("left_wall", "red", [[552.8, 0, 0], [549.6, 0, 559.2], [556, 548.8, 559.2], [556, 548.8, 0]]),
    ("light", "light", [[343, 548.7, 227], [343, 548.7, 332], [213, 548.7, 332], [213, 548.7, 227]]),
]
SHORT = [
    [[130, 165, 65], [82, 165, 225], [240, 165, 272], [290, 165, 114]],
    [[290, 0, 114], [290, 165, 114], [240, 165, 272], [240, 0, 272]],
    [[130, 0, 65], [130, 165, 65], [290, 165, 114], [290, 0, 114]],
    [[82, 0, 225], [82, 165, 225], [130, 165, 65], [130, 0, 65]],
    [[240, 0, 272], [240, 165, 272], [82, 165, 225], [82, 0, 225]],
]
TALL = [
    [[423, 330, 247], [265, 330, 296], [314, 330, 456], [472, 330, 406]],
    [[423, 0, 247], [423, 330, 247], [472, 330, 406], [472, 0, 406]],
    [[472, 0, 406], [472, 330, 406], [314, 330, 456], [314, 0, 456]],
    [[314, 0, 456], [314, 330, 456], [265, 330, 296], [265, 0, 296]],
    [[265, 0, 296], [265, 330, 296], [423, 330, 247], [423, 0, 247]],
]

# Dragon placement (SPEC.md): bounding box in the file, scaled to span 300 mm in x, centred at
# x = 278, z = 279.6, standing on the floor (min y = 0).
DRAGON_LO = [-0.108324, 0.0527295, -0.0504143]
DRAGON_HI = [0.0965662, 0.197173, 0.0412075]
DRAGON_SCALE = 300.0 / 0.2048902
DRAGON_TRANSLATE = [
    278.0 - DRAGON_SCALE * 0.5 * (DRAGON_LO[0] + DRAGON_HI[0]),
    0.0 - DRAGON_SCALE * DRAGON_LO[1],
    279.6 - DRAGON_SCALE * 0.5 * (DRAGON_LO[2] + DRAGON_HI[2]),
]


def base(materials):
    mats = {
        "white": {"type": "lambertian", "albedo": WHITE},
        "red": {"type": "lambertian", "albedo": RED},
        "green": {"type": "lambertian", "albedo": GREEN},
        "light": {"type": "lambertian", "albedo": [0, 0, 0], "emission": [17, 12, 4]},
    }
    mats.update(materials)
    return {
        "camera": {"position": [278, 273, -800], "target": [278, 273, 0], "up": [0, 1, 0], "fov_y_deg": 39.3077},
        "render": {"width": 256, "height": 256, "spp": 16, "max_depth": 16, "seed": 0, "method": "voxcone"},
        "materials": mats,
        "shapes": [{"type": "quad", "name": n, "material": m, "vertices": v} for n, m, v in ROOM],
    }


def dragon(material):
    return {
        "type": "mesh", "name": "dragon", "material": material,
        "file": "../models/dragon_vrip.ply",
        "transform": {"scale": round(DRAGON_SCALE, 6), "translate": [round(x, 6) for x in DRAGON_TRANSLATE]},
    }


def write(name, scene):
    path = os.path.join(OUT, name + ".json")
    with open(path, "w") as f:
        json.dump(scene, f, indent=2)
        f.write("\n")
    print("wrote", path)


def main():
    os.makedirs(OUT, exist_ok=True)
    box = base({})
    for i, q in enumerate(SHORT):
        box["shapes"].append({"type": "quad", "name": "short_block_%d" % i, "material": "white", "vertices": q})
    for i, q in enumerate(TALL):
        box["shapes"].append({"type": "quad", "name": "tall_block_%d" % i, "material": "white", "vertices": q})
    write("cornell-box", box)

    s = base({})
    s["shapes"].append(dragon("white"))
    write("cornell-dragon", s)

    s = base({"glass": {"type": "dielectric", "ior": 1.5}})
    s["shapes"].append(dragon("glass"))
    write("cornell-dragon-glass", s)

    gold_eta, gold_k = [0.143, 0.374, 1.442], [3.983, 2.385, 1.603]
    s = base({"gold": {"type": "conductor", "eta": gold_eta, "k": gold_k}})
    s["shapes"].append(dragon("gold"))
    write("cornell-dragon-gold", s)

    s = base({"gold_rough": {"type": "rough_conductor", "eta": gold_eta, "k": gold_k, "roughness": 0.2,
                             "distribution": "ggx"}})
    s["shapes"].append(dragon("gold_rough"))
    write("cornell-dragon-gold-rough", s)

    s = base({"glass": {"type": "dielectric", "ior": 1.5}, "mirror": {"type": "mirror", "specular": [1, 1, 1]}})
    for shape in s["shapes"]:
        if shape["name"] == "back_wall":
            shape["material"] = "mirror"
    s["shapes"].append(dragon("glass"))
    write("cornell-mirror-glass", s)


if __name__ == "__main__":
    main()
