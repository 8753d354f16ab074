"""Render a glTF scene with Blender's Cycles (CPU), as an independent check of voxcone's glTF
loading, textures and sky; run by Blender:

    blender -b --factory-startup -P tools/blender_gltf_reference.py -- SCENE.glb OUT.exr \
        --sky R,G,B --spp N [--res N] [--byte-textures]

Blender's own importer reads the file (its camera, meshes, embedded textures, emission). Its
Principled BSDFs become Cycles' Diffuse BSDF of the same base colour (texture or factor), plus
an Emission of the material's emission: glTF's metallic 0, roughness 1 is voxcone's Lambertian,
and the Principled BSDF's specular layer and Disney diffuse would differ from it by a few
percent. The world is a constant colour (the sky's radiance). Linear EXR, no denoising, no
clamping, a box filter of one pixel, light tree and thresholds off.

8-bit sRGB textures are decoded to linear floats here (the sRGB formula, in numpy) before
Cycles samples them: Cycles keeps byte images as bytes and interpolates them before decoding,
which darkens every blend between texels (the room's lamp-lit walls came out 4% darker than
with the decoded texels); glTF asks for decoding before filtering, as voxcone does. Pass
--byte-textures to keep Cycles' own handling."""

import sys

import bpy


def linearize_textures():
    """Every 8-bit sRGB image replaced by a float image of its decoded (linear) values."""
    import numpy as np
    for img in list(bpy.data.images):
        if img.source not in ("FILE", "GENERATED") and not img.packed_file:
            continue
        if img.is_float or img.colorspace_settings.name != "sRGB" or img.size[0] == 0:
            continue
        w, h = img.size
        px = np.array(img.pixels[:], dtype=np.float64).reshape(-1, 4)
        rgb = px[:, :3]
        px[:, :3] = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
        lin = bpy.data.images.new(img.name + "-linear", w, h, alpha=True, float_buffer=True)
        lin.colorspace_settings.name = "Linear"
        lin.pixels[:] = px.ravel().tolist()
        img.user_remap(lin)


def main():
    argv = sys.argv[sys.argv.index("--") + 1:]
    scene_path, out = argv[0], argv[1]
    flags = [a for a in argv[2:] if a == "--byte-textures"]
    rest = [a for a in argv[2:] if a not in flags]
    opts = dict(zip(rest[0::2], rest[1::2]))
    sky = [float(x) for x in opts.get("--sky", "0,0,0").split(",")]
    spp = int(opts.get("--spp", "256"))
    res = int(opts.get("--res", "256"))

    bpy.ops.wm.read_factory_settings(use_empty=True)
    # Debian 12's Blender 3.4 importer uses numpy.bool, which its numpy 1.24 no longer has.
    import numpy
    if not hasattr(numpy, "bool"):
        numpy.bool = bool
    bpy.ops.import_scene.gltf(filepath=scene_path)
    if not flags:
        linearize_textures()
    scn = bpy.context.scene
    cams = [o for o in scn.objects if o.type == "CAMERA"]
    if not cams:
        raise SystemExit("no camera in " + scene_path)
    scn.camera = cams[0]
    cams[0].data.sensor_fit = "VERTICAL"

    for mat in bpy.data.materials:
        if not mat.use_nodes:
            continue
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        pbr = next((n for n in nodes if n.type == "BSDF_PRINCIPLED"), None)
        out_node = next((n for n in nodes if n.type == "OUTPUT_MATERIAL"), None)
        if pbr is None or out_node is None:
            continue
        diffuse = nodes.new("ShaderNodeBsdfDiffuse")
        base = pbr.inputs["Base Color"]
        if base.is_linked:
            links.new(base.links[0].from_socket, diffuse.inputs["Color"])
        else:
            diffuse.inputs["Color"].default_value = base.default_value
        shader = diffuse.outputs["BSDF"]
        em = pbr.inputs["Emission"].default_value
        strength = pbr.inputs["Emission Strength"].default_value
        if max(em[0], em[1], em[2]) * strength > 0:
            emission = nodes.new("ShaderNodeEmission")
            emission.inputs["Color"].default_value = em
            emission.inputs["Strength"].default_value = strength
            add = nodes.new("ShaderNodeAddShader")
            links.new(diffuse.outputs["BSDF"], add.inputs[0])
            links.new(emission.outputs["Emission"], add.inputs[1])
            shader = add.outputs["Shader"]
        links.new(shader, out_node.inputs["Surface"])

    world = bpy.data.worlds.new("sky")
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (sky[0], sky[1], sky[2], 1.0)
    bg.inputs["Strength"].default_value = 1.0
    scn.world = world

    scn.render.engine = "CYCLES"
    c = scn.cycles
    c.device = "CPU"
    c.samples = spp
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = 16
    c.transparent_max_bounces = 16
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.light_sampling_threshold = 0.0
    # A box filter one pixel wide, as voxcone's: samples spread uniformly over each pixel. (Width
    # 0.01 with the default Blackman-Harris was a point sample at the pixel's centre: edges
    # aliased, and the 32x32 block holding the held-out-3 room's window edge 6% off.)
    c.filter_type = "BOX"
    c.filter_width = 1.0
    c.seed = 7
    if hasattr(c, "use_light_tree"):
        c.use_light_tree = False
    scn.render.resolution_x = scn.render.resolution_y = res
    scn.render.resolution_percentage = 100
    scn.view_settings.view_transform = "Standard"
    scn.render.image_settings.file_format = "OPEN_EXR"
    scn.render.image_settings.color_depth = "32"
    scn.render.filepath = out
    bpy.ops.render.render(write_still=True)


main()
