#!/usr/bin/env python3
"""Writes the failure-case suite, data/scenes/failure/*.json, and its small meshes.

    tools/make_failure_scenes.py [--variant N] [--out DIR]

Scenes of the kinds voxel methods are known to fail on, none of them used to choose voxcone's
defaults (metres, +y up, 256x256, 16 spp, the project's JSON format):
  two-rooms-door    two rooms sharing a 5.5 mm wall with a doorway; the only light is in the
                    far room, so everything the camera's room receives came through the door
  two-rooms-closed  the same with the doorway walled up: the camera's room must be black
  sunlit-hall       a 4 m high hall with columns under a 40 mm roof slab; a small, bright
                    "sun" (an emitting quad) 4 m above an opening in the slab
  small-objects     a 5.5 m room with red and green walls; a cup, a knot and a cube (each under
                    2% of the room) on a table, seen from 0.6 m
  sky-room          a closed room with 0.15 m walls in the open, lit only through one window by
                    a constant sky and a sun (a directional light), a ground outside
  many-lights       a closed room lit only by 16 small lights (45 mm) of different colours and
                    powers: on the ceiling, hanging, on three walls; four boxes on the floor
  glossy-room       a Cornell-like room whose back wall is rough aluminium (GGX alpha 0.25), whose
                    floor is a black polished rough dielectric (alpha 0.2), with a mirror ball and
                    an Oren-Nayar block

--variant N (N > 0) writes scenes of the same kinds with other dimensions, wall thickness,
light and camera placements, drawn from N (for checks on scenes the defaults were not tuned on;
not committed). The committed suite is variant 0."""
import argparse
import json
import math
import os
import random

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

WHITE = [0.75, 0.75, 0.75]
RED = [0.63, 0.065, 0.05]
GREEN = [0.14, 0.45, 0.091]
BLUE = [0.1, 0.2, 0.6]


def quad(name, material, v):
    return {"type": "quad", "name": name, "material": material, "vertices": [[round(c, 6) for c in p] for p in v]}


def box(name, material, lo, hi):
    """An axis-aligned box, its six faces wound outwards."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    faces = {
        "xm": [[x0, y0, z0], [x0, y0, z1], [x0, y1, z1], [x0, y1, z0]],
        "xp": [[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]],
        "ym": [[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]],
        "yp": [[x0, y1, z0], [x0, y1, z1], [x1, y1, z1], [x1, y1, z0]],
        "zm": [[x0, y0, z0], [x0, y1, z0], [x1, y1, z0], [x1, y0, z0]],
        "zp": [[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]],
    }
    return [quad("%s_%s" % (name, k), material, v) for k, v in faces.items()]


def room(name, lo, hi, materials, skip=()):
    """The inside faces of a room (wound inwards): materials per face xm, xp, ym (floor), yp
    (ceiling), zm, zp; faces in `skip` are left out (another shape closes them)."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    faces = {
        "xm": [[x0, y0, z0], [x0, y1, z0], [x0, y1, z1], [x0, y0, z1]],
        "xp": [[x1, y0, z0], [x1, y0, z1], [x1, y1, z1], [x1, y1, z0]],
        "ym": [[x0, y0, z0], [x0, y0, z1], [x1, y0, z1], [x1, y0, z0]],
        "yp": [[x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]],
        "zm": [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]],
        "zp": [[x0, y0, z1], [x0, y1, z1], [x1, y1, z1], [x1, y0, z1]],
    }
    return [quad("%s_%s" % (name, k), materials.get(k, "white"), v) for k, v in faces.items() if k not in skip]


def ceiling_light(name, centre, size, y):
    """A square emitter at height y facing down (-y)."""
    cx, cz = centre
    h = 0.5 * size
    return quad(name, "light", [[cx + h, y, cz - h], [cx + h, y, cz + h], [cx - h, y, cz + h], [cx - h, y, cz - h]])


def scene(camera, materials, shapes, emission, photons=None):
    mats = {"white": {"type": "lambertian", "albedo": WHITE}, "red": {"type": "lambertian", "albedo": RED},
            "green": {"type": "lambertian", "albedo": GREEN}, "blue": {"type": "lambertian", "albedo": BLUE},
            "light": {"type": "lambertian", "albedo": [0, 0, 0], "emission": emission}}
    mats.update(materials)
    render = {"width": 256, "height": 256, "spp": 16, "max_depth": 16, "seed": 0, "method": "voxcone"}
    if photons:
        render["photons"] = photons
    return {"camera": camera, "render": render, "materials": mats, "shapes": shapes}


def two_rooms(rng, closed):
    """Room A (the camera's) at x < 0, room B (lit) at x > wall; the shared wall at x in [0, t]."""
    t = 0.0055 if rng is None else rng.choice([0.002, 0.004, 0.008, 0.012])
    w_a = 4.0 if rng is None else rng.uniform(3.0, 5.0)
    w_b = 4.0 if rng is None else rng.uniform(3.0, 5.0)
    depth = 4.0 if rng is None else rng.uniform(3.0, 5.0)
    height = 2.5 if rng is None else rng.uniform(2.3, 3.2)
    door_z = (1.5, 2.4) if rng is None else (lambda z: (z, z + rng.uniform(0.8, 1.1)))(rng.uniform(0.8, depth - 2.0))
    door_h = 2.0 if rng is None else min(height - 0.2, rng.uniform(1.9, 2.2))
    shapes = room("room_a", [-w_a, 0, 0], [0, height, depth], {"zp": "blue"}, skip=("xp",))
    shapes += room("room_b", [t, 0, 0], [t + w_b, height, depth], {"xp": "red", "zp": "green"}, skip=("xm",))
    if closed:
        shapes += box("wall", "white", [0, 0, 0], [t, height, depth])
    else:
        shapes += box("wall_front", "white", [0, 0, 0], [t, height, door_z[0]])
        shapes += box("wall_back", "white", [0, 0, door_z[1]], [t, height, depth])
        shapes += box("wall_lintel", "white", [0, door_h, door_z[0]], [t, height, door_z[1]])
        # The threshold: the floor under the doorway, between the rooms' floors.
        shapes.append(quad("threshold", "white", [[0, 0, door_z[0]], [0, 0, door_z[1]], [t, 0, door_z[1]], [t, 0, door_z[0]]]))
    lx = t + 0.5 * w_b if rng is None else t + rng.uniform(0.3, 0.7) * w_b
    lz = 0.55 * depth if rng is None else rng.uniform(0.3, 0.7) * depth
    shapes.append(ceiling_light("light", (lx, lz), 0.5, height - 0.001))
    # The camera in room A's corner, looking at the shared wall and through the doorway.
    cam = {"position": [-w_a + 0.4, 1.5, 0.3], "target": [0.0, 1.0, 0.5 * (door_z[0] + door_z[1])],
           "up": [0, 1, 0], "fov_y_deg": 60}
    return scene(cam, {}, shapes, [40, 36, 30])


def sunlit_hall(rng):
    """A 4 m wide, 4 m high, 12 m long hall under a 40 mm slab with an opening; the sun is a
    small, very bright quad 4 m above the opening, facing down."""
    width = 4.0 if rng is None else rng.uniform(3.5, 6.0)
    height = 4.0 if rng is None else rng.uniform(3.0, 5.0)
    length = 12.0 if rng is None else rng.uniform(10.0, 16.0)
    slab = 0.04 if rng is None else rng.uniform(0.02, 0.08)
    hole = (1.5, 1.5) if rng is None else (rng.uniform(1.0, 2.0), rng.uniform(1.0, 2.5))
    hole_z = 0.35 * length if rng is None else rng.uniform(0.25, 0.6) * length
    sun_height = 4.0 if rng is None else rng.uniform(3.0, 6.0)
    shapes = room("hall", [0, 0, 0], [width, height, length], {"xm": "red", "zp": "green"}, skip=("yp",))
    # The roof slab as four boxes around the opening (centred in x at hole_z).
    hx0, hx1 = 0.5 * (width - hole[0]), 0.5 * (width + hole[0])
    hz0, hz1 = hole_z - 0.5 * hole[1], hole_z + 0.5 * hole[1]
    y0, y1 = height, height + slab
    shapes += box("slab_front", "white", [0, y0, 0], [width, y1, hz0])
    shapes += box("slab_back", "white", [0, y0, hz1], [width, y1, length])
    shapes += box("slab_left", "white", [0, y0, hz0], [hx0, y1, hz1])
    shapes += box("slab_right", "white", [hx1, y0, hz0], [width, y1, hz1])
    # Columns along both long walls.
    col = 0.3
    n = 4 if rng is None else rng.randint(3, 6)
    for i in range(n):
        z = (i + 0.5) * length / n
        for side, x in (("l", 0.6), ("r", width - 0.6)):
            shapes += box("column_%s%d" % (side, i), "white", [x - col / 2, 0, z - col / 2], [x + col / 2, height, z + col / 2])
    sun = 0.25
    sx = 0.5 * width + (0.0 if rng is None else rng.uniform(-0.3, 0.3))
    shapes.append(ceiling_light("sun", (sx, hole_z + (0.0 if rng is None else rng.uniform(-0.3, 0.3))), sun,
                                height + slab + sun_height))
    # Irradiance at the floor about what a 4 m sun-lit patch would get from a much brighter sun:
    # the quad's power is what matters.
    cam = {"position": [0.5 * width, 1.6, length - 0.3], "target": [0.5 * width, 1.2, 0.0], "up": [0, 1, 0],
           "fov_y_deg": 60}
    return scene(cam, {}, shapes, [3000, 2800, 2400])


def sky_room(rng):
    """A 5 x 2.7 x 4 m room (x, y, z) closed on every side but a window in its +z wall, in the
    open under a constant sky and a sun: a ground outside, walls 0.15 m thick. Everything the
    room receives comes through the window: sky light, the sun's patch on the floor, and the
    ground's light. Returns the scene and the same scene with the window walled up (nothing
    reaches the room then: it must render black)."""
    w = 5.0 if rng is None else rng.uniform(3.5, 6.0)
    h = 2.7 if rng is None else rng.uniform(2.4, 3.2)
    d = 4.0 if rng is None else rng.uniform(3.0, 5.5)
    t = 0.15 if rng is None else rng.choice([0.01, 0.05, 0.15, 0.3])
    win_w = 1.6 if rng is None else rng.uniform(0.8, 2.2)
    win_h = 1.2 if rng is None else rng.uniform(0.8, 1.5)
    win_x = 0.5 * w if rng is None else rng.uniform(0.3, 0.7) * w
    sill = 0.9 if rng is None else rng.uniform(0.5, 1.0)
    sill = min(sill, h - win_h - 0.2)
    shapes = room("room", [0, 0, 0], [w, h, d], {"xm": "red", "xp": "green"}, skip=("zp",))
    # The window wall, z in [d, d + t], as four boxes around the opening; its inside face is the
    # boxes' -z faces.
    x0, x1 = win_x - 0.5 * win_w, win_x + 0.5 * win_w
    shapes += box("wall_left", "white", [0, 0, d], [x0, h, d + t])
    shapes += box("wall_right", "white", [x1, 0, d], [w, h, d + t])
    shapes += box("wall_below", "white", [x0, 0, d], [x1, sill, d + t])
    shapes += box("wall_above", "white", [x0, sill + win_h, d], [x1, h, d + t])
    # The room's shell from outside: the other walls', the roof's and the floor's outer faces
    # (a slab of the same thickness), so that the sky lights them as it would a house.
    shapes += box("shell_left", "white", [-t, -t, -t], [0, h + t, d + t])
    shapes += box("shell_right", "white", [w, -t, -t], [w + t, h + t, d + t])
    shapes += box("shell_back", "white", [0, -t, -t], [w, h + t, 0])
    shapes += box("shell_roof", "white", [0, h, 0], [w, h + t, d])
    shapes += box("shell_floor", "white", [0, -t, 0], [w, 0, d])
    # The ground in front of the window, 8 m out, a little below the floor's top.
    g = 8.0
    shapes.append(quad("ground", "ground", [[-t - 2, -t, d + t], [-t - 2, -t, d + t + g], [w + t + 2, -t, d + t + g],
                                            [w + t + 2, -t, d + t]]))
    elev = 40.0 if rng is None else rng.uniform(25.0, 60.0)
    az = 20.0 if rng is None else rng.uniform(-35.0, 35.0)
    e, a = math.radians(elev), math.radians(az)
    # The direction the sunlight travels: down and into the room (-z), turned by az about +y.
    direction = [round(-math.cos(e) * math.sin(a), 6), round(-math.sin(e), 6), round(-math.cos(e) * math.cos(a), 6)]
    sky = [0.5, 0.65, 1.0] if rng is None else [round(v * rng.uniform(0.6, 1.5), 3) for v in (0.5, 0.65, 1.0)]
    lights = [{"type": "environment", "radiance": sky},
              {"type": "directional", "direction": direction, "irradiance": [12.0, 11.0, 9.6]}]
    cam = {"position": [0.25 * w, 1.5, 0.3], "target": [0.6 * w, 0.6, d], "up": [0, 1, 0], "fov_y_deg": 65}
    out = scene(cam, {"ground": {"type": "lambertian", "albedo": [0.3, 0.28, 0.22]}}, shapes, [0, 0, 0])
    del out["materials"]["light"]
    out["lights"] = lights
    closed = json.loads(json.dumps(out))
    closed["shapes"] += box("window_shut", "white", [x0, sill, d], [x1, sill + win_h, d + t])
    return out, closed


LIGHT_COLOURS = [[1.0, 0.35, 0.2], [0.3, 1.0, 0.35], [0.3, 0.45, 1.0], [1.0, 0.85, 0.4], [0.9, 0.3, 1.0],
                 [0.3, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, 0.6, 0.2]]


def many_lights(rng):
    """A closed 6 x 2.8 x 5 m room (x, y, z) lit only by 16 small lights, 45 mm squares of
    different colours and powers: six on the ceiling facing down, four hanging as small glowing
    cubes, two on each of three walls facing into the room; four boxes on the floor."""
    w = 6.0 if rng is None else rng.uniform(4.5, 8.0)
    h = 2.8 if rng is None else rng.uniform(2.5, 3.4)
    d = 5.0 if rng is None else rng.uniform(4.0, 7.0)
    r = random.Random(7) if rng is None else rng
    s = 0.045 if rng is None else rng.uniform(0.03, 0.06)
    n_ceiling, n_hanging, n_wall = (6, 4, 2) if rng is None else (rng.randint(4, 8), rng.randint(2, 5), rng.randint(1, 3))
    shapes = room("room", [0, 0, 0], [w, h, d], {"xm": "red", "xp": "blue"})
    mats = {}
    count = [0]

    def light_material(scale):
        c = r.choice(LIGHT_COLOURS)
        name = "lamp%d" % count[0]
        count[0] += 1
        mats[name] = {"type": "lambertian", "albedo": [0, 0, 0], "emission": [round(v * scale, 3) for v in c]}
        return name

    for i in range(n_ceiling):
        cx, cz = r.uniform(0.15, 0.85) * w, r.uniform(0.15, 0.85) * d
        q = ceiling_light("ceiling%d" % i, (cx, cz), s, h - 0.001)
        q["material"] = light_material(r.uniform(300, 900))
        shapes.append(q)
    for i in range(n_hanging):
        cx, cy, cz = r.uniform(0.2, 0.8) * w, r.uniform(1.2, h - 0.6), r.uniform(0.2, 0.8) * d
        shapes += box("hanging%d" % i, light_material(r.uniform(100, 300)), [cx - s / 2, cy - s / 2, cz - s / 2],
                      [cx + s / 2, cy + s / 2, cz + s / 2])
    # Wall lights: on the -x, +x and -z walls, 1 mm off the wall, facing into the room.
    for wall in ("xm", "xp", "zm"):
        for i in range(n_wall):
            y = r.uniform(0.8, h - 0.5)
            m = light_material(r.uniform(300, 900))
            hs = s / 2
            if wall == "zm":
                x = r.uniform(0.2, 0.8) * w
                v = [[x - hs, y - hs, 0.001], [x + hs, y - hs, 0.001], [x + hs, y + hs, 0.001], [x - hs, y + hs, 0.001]]
            else:
                z = r.uniform(0.2, 0.8) * d
                x = 0.001 if wall == "xm" else w - 0.001
                v = [[x, y - hs, z - hs], [x, y + hs, z - hs], [x, y + hs, z + hs], [x, y - hs, z + hs]]
                if wall == "xp":
                    v = v[::-1]
            shapes.append(quad("wall_%s%d" % (wall, i), m, v))
    for i in range(4):
        bw, bh = r.uniform(0.3, 0.7), r.uniform(0.3, 1.1)
        bx, bz = r.uniform(0.15, 0.85) * w, r.uniform(0.3, 0.8) * d
        shapes += box("box%d" % i, r.choice(["white", "green", "white"]), [bx - bw / 2, 0, bz - bw / 2],
                      [bx + bw / 2, bh, bz + bw / 2])
    cam = {"position": [0.5 * w, 1.6, d - 0.2], "target": [0.5 * w, 1.0, 0.0], "up": [0, 1, 0], "fov_y_deg": 70}
    out = scene(cam, mats, shapes, [0, 0, 0])
    del out["materials"]["light"]
    return out


def glossy_room(rng):
    """A 2 m Cornell-like room (red and green side walls, a white ceiling with a light): its back
    wall rough aluminium, its floor a black polished floor (a rough dielectric with nothing
    under it), a mirror ball and an Oren-Nayar block on the floor."""
    size = 2.0 if rng is None else rng.uniform(1.6, 3.0)
    a_wall = 0.25 if rng is None else rng.uniform(0.12, 0.4)
    a_floor = 0.2 if rng is None else rng.uniform(0.08, 0.35)
    shapes = room("room", [-size / 2, 0, -size / 2], [size / 2, size, size / 2],
                  {"xm": "red", "xp": "green", "zm": "metal", "ym": "floor"}, skip=("zp",))
    ball_r = 0.2 * size if rng is None else rng.uniform(0.15, 0.25) * size
    bx = -0.2 * size if rng is None else rng.uniform(-0.3, 0.0) * size
    shapes.append({"type": "sphere", "name": "ball", "material": "mirror", "center": [bx, ball_r, -0.1 * size],
                   "radius": ball_r, "subdivisions": 5})
    b = 0.25 * size
    cx = 0.22 * size if rng is None else rng.uniform(0.1, 0.3) * size
    cz = 0.1 * size if rng is None else rng.uniform(-0.1, 0.25) * size
    shapes += box("block", "clay", [cx - b / 2, 0, cz - b / 2], [cx + b / 2, 1.6 * b, cz + b / 2])
    shapes.append(ceiling_light("light", (0.0, 0.0), 0.25 * size, size - 0.001))
    mats = {"metal": {"type": "rough_conductor", "eta": [1.657, 0.880, 0.521], "k": [9.224, 6.270, 4.837],
                      "roughness": round(a_wall, 3), "distribution": "ggx"},
            "floor": {"type": "rough_dielectric", "ior": 1.5, "roughness": round(a_floor, 3), "distribution": "ggx"},
            "mirror": {"type": "mirror"},
            "clay": {"type": "oren_nayar", "albedo": [0.7, 0.55, 0.4], "sigma_deg": 25}}
    cam = {"position": [0.0, 0.5 * size, 1.9 * size], "target": [0.0, 0.45 * size, 0.0], "up": [0, 1, 0],
           "fov_y_deg": 40}
    return scene(cam, mats, shapes, [17, 12, 4])


def torus_knot(p=2, q=3, radius=1.0, tube=0.28, seg=160, ring=12):
    """A (p, q) torus knot tube: vertices and quads (wound outwards)."""
    def curve(s):
        a = 2 * math.pi * s
        r = radius * (0.6 + 0.4 * math.cos(q * a))
        return [r * math.cos(p * a), 0.4 * radius * math.sin(q * a), r * math.sin(p * a)]

    def sub(a, b):
        return [a[i] - b[i] for i in range(3)]

    def cross(a, b):
        return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]

    def norm(a):
        length = math.sqrt(sum(c * c for c in a))
        return [c / length for c in a]

    verts, quads = [], []
    for i in range(seg):
        c = curve(i / seg)
        tangent = norm(sub(curve((i + 1) / seg), curve((i - 1) / seg)))
        n1 = norm(cross(tangent, [0, 1, 0]))
        n2 = cross(n1, tangent)
        for j in range(ring):
            a = 2 * math.pi * j / ring
            verts.append([c[k] + tube * radius * (math.cos(a) * n1[k] + math.sin(a) * n2[k]) for k in range(3)])
    for i in range(seg):
        for j in range(ring):
            i1, j1 = (i + 1) % seg, (j + 1) % ring
            quads.append([i * ring + j, i1 * ring + j, i1 * ring + j1, i * ring + j1])
    return verts, quads


def cup(radius=1.0, height=2.2, wall=0.08, seg=32):
    """An open cylinder with a bottom and a thickness: outer wall, inner wall, rim, bottom."""
    verts, quads = [], []
    ring = lambda r, y: [[r * math.cos(2 * math.pi * i / seg), y, r * math.sin(2 * math.pi * i / seg)] for i in range(seg)]
    rings = [ring(radius, 0), ring(radius, height), ring(radius - wall, height), ring(radius - wall, wall)]
    for r in rings:
        verts += r
    for a in range(3):
        for i in range(seg):
            i1 = (i + 1) % seg
            quads.append([a * seg + i, a * seg + i1, (a + 1) * seg + i1, (a + 1) * seg + i])
    # Inner floor and outer bottom as fans around centre vertices.
    verts.append([0, wall, 0])
    verts.append([0, 0, 0])
    ci, co = len(verts) - 2, len(verts) - 1
    tris = []
    for i in range(seg):
        i1 = (i + 1) % seg
        tris.append([3 * seg + i, 3 * seg + i1, ci])
        tris.append([co, i1, i])
    return verts, quads, tris


def write_obj(path, verts, quads, tris=()):
    with open(path, "w") as f:
        f.write("# written by tools/make_failure_scenes.py\n")
        for v in verts:
            f.write("v %.6f %.6f %.6f\n" % tuple(v))
        for q in quads:
            f.write("f %d %d %d\n" % (q[0] + 1, q[1] + 1, q[2] + 1))
            f.write("f %d %d %d\n" % (q[0] + 1, q[2] + 1, q[3] + 1))
        for t in tris:
            f.write("f %d %d %d\n" % (t[0] + 1, t[1] + 1, t[2] + 1))


def small_objects(rng, mesh_dir):
    size = 5.5 if rng is None else rng.uniform(4.5, 8.0)
    height = 3.0 if rng is None else rng.uniform(2.6, 3.6)
    shapes = room("room", [0, 0, 0], [size, height, size], {"xm": "red", "xp": "green"})
    # The table: a top and four legs, near the room's centre.
    tx = 0.5 * size if rng is None else rng.uniform(0.35, 0.65) * size
    tz = 0.5 * size if rng is None else rng.uniform(0.35, 0.65) * size
    top_y = 0.75
    shapes += box("table_top", "white", [tx - 0.6, top_y - 0.04, tz - 0.4], [tx + 0.6, top_y, tz + 0.4])
    for i, (dx, dz) in enumerate(((-0.55, -0.35), (0.55, -0.35), (-0.55, 0.35), (0.55, 0.35))):
        shapes += box("table_leg%d" % i, "white", [tx + dx - 0.025, 0, tz + dz - 0.025], [tx + dx + 0.025, top_y - 0.04, tz + dz + 0.025])
    s = 0.04 if rng is None else rng.uniform(0.03, 0.05)
    rel = os.path.relpath(mesh_dir, os.path.join(ROOT, "data", "scenes", "failure"))
    shapes.append({"type": "mesh", "name": "cup", "material": "white", "file": rel + "/cup.obj",
                   "transform": {"scale": s, "translate": [tx - 0.15, top_y, tz]}})
    shapes.append({"type": "mesh", "name": "knot", "material": "yellow", "file": rel + "/knot.obj",
                   "transform": {"scale": 0.05, "translate": [tx + 0.05, top_y + 0.028, tz + 0.02]}})
    c = 0.06
    shapes += box("cube", "white", [tx + 0.22 - c / 2, top_y, tz - 0.1 - c / 2], [tx + 0.22 + c / 2, top_y + c, tz - 0.1 + c / 2])
    lsize = 0.8
    shapes.append(ceiling_light("light", (0.5 * size, 0.5 * size), lsize, height - 0.001))
    cam = {"position": [tx, top_y + 0.3, tz - 0.6], "target": [tx + 0.03, top_y + 0.03, tz], "up": [0, 1, 0],
           "fov_y_deg": 40}
    return scene(cam, {"yellow": {"type": "lambertian", "albedo": [0.7, 0.6, 0.2]}}, shapes, [20, 18, 15])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variant", type=int, default=0)
    ap.add_argument("--out", default=os.path.join(ROOT, "data", "scenes", "failure"))
    args = ap.parse_args()
    rng = random.Random(args.variant) if args.variant else None
    os.makedirs(args.out, exist_ok=True)
    mesh_dir = os.path.join(ROOT, "data", "meshes")
    verts, quads = torus_knot()
    write_obj(os.path.join(mesh_dir, "knot.obj"), verts, quads)
    verts, quads, tris = cup()
    write_obj(os.path.join(mesh_dir, "cup.obj"), verts, quads, tris)
    scenes = {"two-rooms-door": two_rooms(rng, False), "two-rooms-closed": two_rooms(rng, True),
              "sunlit-hall": sunlit_hall(rng), "small-objects": small_objects(rng, mesh_dir)}
    scenes["sky-room"], scenes["sky-room-closed"] = sky_room(rng)
    scenes["many-lights"] = many_lights(rng)
    scenes["glossy-room"] = glossy_room(rng)
    if args.variant:
        # Mesh paths relative to the output folder.
        for s in scenes.values():
            for sh in s["shapes"]:
                if sh["type"] == "mesh":
                    sh["file"] = os.path.join(mesh_dir, os.path.basename(sh["file"]))
    for name, s in scenes.items():
        path = os.path.join(args.out, name + ".json")
        with open(path, "w") as f:
            json.dump(s, f, indent=1)
            f.write("\n")
        print("wrote", path)


if __name__ == "__main__":
    main()
