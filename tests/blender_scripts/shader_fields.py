"""Materials and worlds made as a user makes them, read by the add-on (addon/shader_nodes.py): prints
``RESULT {json}`` with the tracer Material fields of each material and the Settings of each world.

    blender -b --factory-startup --python-exit-code 1 --python shader_fields.py -- ROOT PICTURE
    python shader_fields.py ROOT PICTURE                (the bpy module)

The Principled BSDF is set through the input names of the Blender that runs it (3.x: Transmission, Specular,
Emission; 4.x/5.0: Transmission Weight, Specular IOR Level, Emission Color), so the same materials are read
in both; PICTURE is an image file for the Image Texture case.
"""
import json
import sys

import bpy

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
root, picture = argv[0], argv[1]
sys.path[:0] = [root, root + "/tests"]

import addon  # noqa: E402
from addon import props, shader_nodes  # noqa: E402
from blender_scripts.addon_env import fresh  # noqa: E402

NEW = bpy.app.version >= (4, 0, 0)


def principled(name, **inputs):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    node = material.node_tree.nodes["Principled BSDF"]
    renamed = {"transmission": "Transmission Weight" if NEW else "Transmission",
               "emission": "Emission Color" if NEW else "Emission"}
    for key, value in inputs.items():
        node.inputs[renamed.get(key, key)].default_value = value
    return material, node


def replaced(name, kind, **inputs):
    """A material whose surface is one ``kind`` node (its Principled BSDF removed)."""
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    tree = material.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    node = tree.nodes.new(kind)
    for key, value in inputs.items():
        node.inputs[key].default_value = value
    tree.links.new(node.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    return material, node


def cases() -> dict:
    made = {}
    made["glass"], _ = principled("glass", **{"transmission": 1.0, "IOR": 1.45, "Roughness": 0.0})
    made["mirror"], _ = principled("mirror", **{"Base Color": (0.9, 0.6, 0.2, 1), "Metallic": 1.0, "Roughness": 0.0})
    made["rough red"], _ = principled("rough red", **{"Base Color": (0.8, 0.05, 0.05, 1), "Roughness": 0.5,
                                                      "IOR": 1.5})
    low = ("Specular IOR Level", 0.25) if NEW else ("Specular", 0.25)
    made["low specular"], _ = principled("low specular", **{low[0]: low[1], "Roughness": 0.5, "IOR": 1.5})
    made["emitting"], _ = principled("emitting", **{"Base Color": (0, 0, 0, 1), "emission": (1.0, 0.5, 0.25, 1),
                                                    "Emission Strength": 4.0})
    made["half alpha"], _ = principled("half alpha", **{"Alpha": 0.5})
    made["diffuse node"], _ = replaced("diffuse node", "ShaderNodeBsdfDiffuse", Color=(0.2, 0.4, 0.6, 1))
    made["glossy node"], _ = replaced("glossy node", "ShaderNodeBsdfGlossy", Color=(0.9, 0.9, 0.9, 1),
                                      Roughness=0.0)
    made["glass node"], _ = replaced("glass node", "ShaderNodeBsdfGlass", IOR=1.5, Roughness=0.0)
    made["emission node"], _ = replaced("emission node", "ShaderNodeEmission", Color=(1, 1, 1, 1), Strength=3.0)
    mix, _ = replaced("mix", "ShaderNodeMixShader")
    tree = mix.node_tree
    node = tree.nodes["Mix Shader"]
    node.inputs["Fac"].default_value = 0.25
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (1, 0, 0, 1)
    glass = tree.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["Roughness"].default_value = 0.0
    tree.links.new(diffuse.outputs[0], node.inputs[1])
    tree.links.new(glass.outputs[0], node.inputs[2])
    made["mix"] = mix
    textured, base = principled("textured", Roughness=1.0)
    texture = textured.node_tree.nodes.new("ShaderNodeTexImage")
    texture.image = bpy.data.images.load(picture)
    textured.node_tree.links.new(texture.outputs["Color"], base.inputs["Base Color"])
    made["textured"] = textured
    plain = bpy.data.materials.new("no nodes")
    plain.use_nodes = False
    plain.diffuse_color, plain.metallic, plain.roughness = (0.3, 0.6, 0.9, 1.0), 0.0, 0.7
    if not plain.use_nodes:  # (Blender 5.0 has no material without nodes: use_nodes stays on)
        made["no nodes"] = plain
    return made


def worlds() -> dict:
    lit = bpy.data.worlds.new("lit")
    lit.use_nodes = True
    background = lit.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.2, 0.4, 0.8, 1.0)
    background.inputs["Strength"].default_value = 0.5
    flat = bpy.data.worlds.new("flat")
    flat.use_nodes = False
    flat.color = (0.1, 0.2, 0.3)
    return {"background node": lit, **({} if flat.use_nodes else {"no nodes": flat})}  # (as materials in 5.0)


fresh()
try:
    result = {"blender": bpy.app.version_string, "materials": {}, "worlds": {}}
    for name, material in cases().items():
        warnings = []
        tracer_material, image = props.blender_material(material, warnings)
        fields = {f: getattr(tracer_material, f) for f in ("ambient", "diffuse", "specular", "specular_exponent",
                                                           "emissive", "reflectivity", "transparency",
                                                           "speed_of_light", "fresnel", "fresnel_tint")}
        result["materials"][name] = dict(fields, image=image and image.path, srgb=image and image.srgb,
                                         warnings=warnings)
    for name, world in worlds().items():
        settings = props.world_settings(world, 3)
        result["worlds"][name] = {"background": settings.background, "ambient": settings.global_ambient}
    print("RESULT " + json.dumps(result))
finally:
    addon.unregister()
