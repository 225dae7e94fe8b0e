"""Scenes built in Blender as a user builds them, rendered by SDL_RAYTRACER and by Cycles set up as a Whitted
tracer, and compared object by object (tests/test_addon_cycles.py; bench/blender_cycles.py at a larger size).

Cycles as a Whitted tracer: no diffuse bounces, reflective and refractive caustics off, no denoising, no
adaptive sampling, the lights' own radius and angle (0 in the point-light scene); glossy and transmission
bounces as Blender's defaults.  Both engines render to linear EXR; colours are compared as Blender's Standard
view shows them (the sRGB curve, 0..255), the mean over each object's pixels (found by rendering each object
alone with Workbench, shrunk by two pixels so that edges, which the two engines anti-alias differently, do
not count) and over the background's.
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from blender_scripts.addon_env import fresh, render_rgba, set_resolution


def _material(name: str, **inputs):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    node = material.node_tree.nodes["Principled BSDF"]
    names = {"Transmission": ("Transmission Weight", "Transmission")}
    for key, value in inputs.items():
        socket = next(node.inputs[n] for n in names.get(key, (key,)) if n in node.inputs)
        socket.default_value = value
    return material


def _add(obj, material):
    obj.data.materials.append(material)
    return obj


def _objects_and_camera(world_color) -> dict:
    """Floor, glass and mirror spheres (Principled, smooth-shaded), a red cube, a camera and the world."""
    scene = bpy.context.scene
    objects = {}
    bpy.ops.mesh.primitive_plane_add(size=30)
    objects["floor"] = _add(bpy.context.object, _material("floor", **{"Base Color": (0.8, 0.8, 0.8, 1.0)}))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(-1.3, 0.6, 1.0), segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    objects["glass"] = _add(bpy.context.object, _material("glass", **{"Base Color": (1.0, 1.0, 1.0, 1.0),
                                                                      "Transmission": 1.0, "IOR": 1.45,
                                                                      "Roughness": 0.0}))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(1.4, 1.4, 1.0), segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    objects["mirror"] = _add(bpy.context.object, _material("mirror", **{"Base Color": (0.9, 0.9, 0.9, 1.0),
                                                                        "Metallic": 1.0, "Roughness": 0.0}))
    bpy.ops.mesh.primitive_cube_add(size=1.2, location=(0.9, -1.3, 0.6), rotation=(0, 0, 0.5))
    objects["cube"] = _add(bpy.context.object, _material("cube", **{"Base Color": (0.8, 0.05, 0.05, 1.0)}))
    bpy.ops.object.camera_add(location=(0.0, -8.5, 4.2), rotation=(math.radians(68), 0.0, 0.0))
    scene.camera = bpy.context.object
    world = bpy.data.worlds.new("dark")
    world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (*world_color, 1.0)
    background.inputs["Strength"].default_value = 1.0
    scene.world = world
    return objects


def point_light_scene() -> dict:
    """The issue's scene: floor, Principled glass and mirror spheres, a red diffuse cube, a 1000 W point light
    of radius 0, a dark world."""
    fresh()
    objects = _objects_and_camera((0.02, 0.02, 0.025))
    bpy.ops.object.light_add(type="POINT", location=(1.5, -3.0, 6.0))
    light = bpy.context.object.data
    light.energy, light.shadow_soft_size = 1000.0, 0.0
    return objects


def soft_lights_scene() -> dict:
    """The same objects lit by a sun (angle 3 degrees), a spot (radius 0.2, blend 0.3) and a 2 x 1 m area
    light, whose soft shadows Cycles draws."""
    fresh()
    objects = _objects_and_camera((0.01, 0.01, 0.012))
    bpy.ops.object.light_add(type="SUN", rotation=(math.radians(40), math.radians(15), 0.0))
    sun = bpy.context.object.data
    sun.energy, sun.angle = 1.5, math.radians(3.0)
    bpy.ops.object.light_add(type="SPOT", location=(-3.0, -3.0, 5.0))
    spot = bpy.context.object
    direction = np.array([1.0, 1.2, -1.0]) / np.linalg.norm([1.0, 1.2, -1.0])
    spot.rotation_euler = _pointing(direction)
    spot.data.energy, spot.data.shadow_soft_size = 800.0, 0.2
    spot.data.spot_size, spot.data.spot_blend = math.radians(60.0), 0.3
    bpy.ops.object.light_add(type="AREA", location=(3.0, -1.0, 4.0))
    area = bpy.context.object
    area.rotation_euler = _pointing(np.array([-0.5, 0.3, -1.0]) / np.linalg.norm([-0.5, 0.3, -1.0]))
    area.data.energy, area.data.shape, area.data.size, area.data.size_y = 300.0, "RECTANGLE", 2.0, 1.0
    return objects


def mirrored_lights_scene(watts: float, radius: float, strength: float, angle_degrees: float) -> None:
    """A mirror plane (Principled, Metallic 1, Roughness 0, white) seen from 2.5 above by a camera looking
    straight down, a point light of ``watts`` and ``radius`` 2 above it to the left, a sun of ``strength`` and
    ``angle_degrees`` tilted 12 degrees to the right, no world: the mirror shows the light's sphere in the
    picture's left half and the sun's disk in its right half, on black."""
    fresh()
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=20)
    _add(bpy.context.object, _material("mirror", **{"Base Color": (1.0, 1.0, 1.0, 1.0), "Metallic": 1.0,
                                                    "Roughness": 0.0}))
    bpy.ops.object.light_add(type="POINT", location=(-0.8, 0.0, 2.0))
    point = bpy.context.object.data
    point.energy, point.shadow_soft_size = watts, radius
    bpy.ops.object.light_add(type="SUN", rotation=(0.0, math.radians(12.0), 0.0))
    sun = bpy.context.object.data
    sun.energy, sun.angle = strength, math.radians(angle_degrees)
    bpy.ops.object.camera_add(location=(0.0, 0.0, 2.5))
    scene.camera = bpy.context.object
    scene.world = None


def _pointing(direction):
    """Euler angles that turn a light's -Z to ``direction``."""
    from mathutils import Vector

    return Vector(tuple(-direction)).to_track_quat("Z", "Y").to_euler()


def set_up_cycles(samples: int) -> None:
    scene = bpy.context.scene
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = samples
    cycles.use_denoising = False
    cycles.use_adaptive_sampling = False
    cycles.diffuse_bounces = 0
    cycles.caustics_reflective = cycles.caustics_refractive = False
    cycles.seed = 1


def masks(objects: dict) -> dict:
    """Each object's pixels (rendered alone by Workbench, shrunk by two pixels) and the background's (no
    object, shrunk alike)."""
    scene = bpy.context.scene
    scene.render.film_transparent = True
    scene.display.render_aa = "OFF"
    shown = {name: obj.hide_render for name, obj in objects.items()}
    out = {}
    for name, obj in objects.items():
        for other in objects.values():
            other.hide_render = other is not obj
        out[name] = render_rgba("BLENDER_WORKBENCH")[..., 3] > 0.5
    for name, obj in objects.items():
        obj.hide_render = shown[name]
    out["background"] = ~np.logical_or.reduce([m for m in out.values()])
    everything = render_rgba("BLENDER_WORKBENCH")[..., 3] > 0.5
    out["background"] &= ~everything
    scene.render.film_transparent = False
    return {name: _shrink(mask, 2) for name, mask in out.items()}


def _shrink(mask: np.ndarray, pixels: int) -> np.ndarray:
    kept = mask.copy()
    for _ in range(pixels):
        inner = kept.copy()
        inner[1:] &= kept[:-1]
        inner[:-1] &= kept[1:]
        inner[:, 1:] &= kept[:, :-1]
        inner[:, :-1] &= kept[:, 1:]
        kept = inner
    return kept


def shown(linear: np.ndarray) -> np.ndarray:
    """Linear colours as Blender's Standard view shows them, 0..255 (the sRGB curve, clipped)."""
    c = np.clip(linear, 0.0, 1.0)
    return 255.0 * np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1.0 / 2.4) - 0.055)


def cycles_without_lights_in_mirrors(samples: int) -> np.ndarray:
    """Cycles' picture with the lights hidden from glossy rays: what a mirror shows without the images of the
    lights themselves (the book's Whitted rays do not see lights; a Cycles mirror, as the tracer's now, shows
    an area light, a sphere light or the sun's disk): how much of a mirror's difference those images are."""
    lights = [obj for obj in bpy.data.objects if obj.type == "LIGHT"]
    for light in lights:
        light.visible_glossy = False
    try:
        set_up_cycles(samples)
        return shown(render_rgba("CYCLES")[..., :3])
    finally:
        for light in lights:
            light.visible_glossy = True


def compare(objects: dict, width: int, height: int, samples: int, depth: int = 8,
            lights_unseen: tuple = ()) -> dict:
    """Mean shown colour per object (and background) by Cycles and by SDL_RAYTRACER, and their difference.
    The objects named in ``lights_unseen`` (mirrors) are compared with cycles_without_lights_in_mirrors."""
    from addon import engine

    set_resolution(width, height)
    regions = masks(objects)
    scene = bpy.context.scene
    unseen = cycles_without_lights_in_mirrors(samples) if lights_unseen else None
    set_up_cycles(samples)
    cycles = shown(render_rgba("CYCLES")[..., :3])
    s = scene.sdl_render
    s.block_size, s.progressive, s.samples, s.sampling, s.max_recursion_depth = 1, False, 4, "JITTERED", depth
    traced = shown(render_rgba(engine.ENGINE_ID)[..., :3])
    stats = dict(engine.LAST_RENDER)
    result = {"regions": {}, "error": stats.get("error"), "rays": stats.get("rays"),
              "warnings": stats.get("warnings")}
    for name, mask in regions.items():
        a, b = cycles[mask].mean(axis=0), traced[mask].mean(axis=0)
        entry = result["regions"][name] = {"pixels": int(mask.sum()), "cycles": [round(float(v), 1) for v in a],
                                           "traced": [round(float(v), 1) for v in b],
                                           "difference": round(float(np.abs(a - b).max()), 2)}
        if name in lights_unseen:
            c = unseen[mask].mean(axis=0)
            entry.update(cycles_lights_unseen=[round(float(v), 1) for v in c],
                         difference_lights_unseen=round(float(np.abs(c - b).max()), 2))
    return result
