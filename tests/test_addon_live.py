"""The engine's live scene (addon/live_scene.py): each kind of change Blender reports becomes its own edit of
the compiled scene (counted through LiveScene.done, not timed), converts only what it must (ObjectCache.made),
and the image after it is, byte for byte, the image of the scene built from scratch."""
from __future__ import annotations

import bpy
import numpy as np
import pytest

from addon import engine, live_scene
from addon.pure import blocks
from addon.scene_build import SceneBuilder
from blender_scripts.addon_env import SCENES, fresh, import_sdl, shape_objects
from tracer.compile import compile_scene

WIDTH, HEIGHT = 40, 30


class Live:
    """A LiveScene fed as the engine feeds it: take_updates from each depsgraph update, then compiled()."""

    def __init__(self, mode: str = "VIEWPORT"):
        self.live = live_scene.LiveScene()
        self.mode = mode

    def __enter__(self):
        # (Blender calls view_update, or RenderEngine.update before each frame of an animation, after both)
        for handlers in (bpy.app.handlers.depsgraph_update_post, bpy.app.handlers.frame_change_post):
            handlers.append(self._updated)
        return self

    def __exit__(self, *exc):
        for handlers in (bpy.app.handlers.depsgraph_update_post, bpy.app.handlers.frame_change_post):
            if self._updated in handlers:
                handlers.remove(self._updated)

    def _updated(self, scene, depsgraph):
        self.live.take_updates(depsgraph)

    def image(self, backend: str = "c") -> np.ndarray:
        depsgraph = bpy.context.evaluated_depsgraph_get()  # (evaluates the change: the handler runs)
        compiled, _ = self.live.compiled(depsgraph, self.mode)
        return _render(compiled, depsgraph, backend)


def _render(compiled, depsgraph, backend: str = "c") -> np.ndarray:
    camera = bpy.context.scene.camera.evaluated_get(depsgraph)
    params = engine.camera_params(camera)
    rays_for = engine.camera_rays(camera, None, params, WIDTH, HEIGHT, 0, 0, 1.0, 1.0)
    renderer = blocks.BlockRenderer(compiled, rays_for, WIDTH, HEIGHT, backend=backend)
    renderer.run()
    return renderer.rgba().copy()


def _from_scratch(mode: str = "VIEWPORT", backend: str = "c") -> np.ndarray:
    depsgraph = bpy.context.evaluated_depsgraph_get()
    builder = SceneBuilder(depsgraph, mode=mode)
    return _render(compile_scene(builder.build(depsgraph.scene)), depsgraph, backend)


def _lecture():
    fresh()
    import_sdl(SCENES / "lecture.sdl")
    return {o.name: o for o in shape_objects()}


def _biggest_sphere(objects):
    return max((o for o in objects.values() if o["sdl_kind"] == "sphere"), key=lambda o: o.matrix_world.median_scale)


def _move(objects):
    _biggest_sphere(objects).location.x += 0.4


def _sdl_colour(objects):
    _biggest_sphere(objects).active_material.sdl.diffuse = (0.1, 0.7, 0.2)


def _principled_colour(objects):
    material = _biggest_sphere(objects).active_material
    material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.2, 0.3, 0.9, 1.0)


def _other_material(objects):
    spheres = [o for o in objects.values() if o["sdl_kind"] == "sphere"]
    spheres[0].material_slots[0].material = spheres[-1].material_slots[0].material


def _geometry(objects):
    sphere = _biggest_sphere(objects)
    sphere.data = sphere.data.copy()  # (its own mesh, edited: traced as a mesh now)
    sphere.data.vertices[0].co.z += 0.5
    sphere.data.update()


def _add(objects):
    copy = _biggest_sphere(objects).copy()
    copy.location.x -= 1.5
    bpy.context.scene.collection.objects.link(copy)


def _delete(objects):
    bpy.data.objects.remove(_biggest_sphere(objects))


def _hide(objects):
    _biggest_sphere(objects).hide_set(True)


def _light(objects):
    lamp = next(o for o in bpy.data.objects if o.type == "LIGHT")
    lamp.location.z += 2.0
    lamp.data.energy *= 0.5


def _world(objects):
    bpy.context.scene.world.sdl.background = (0.5, 0.1, 0.1)


#: Each change, and what the live scene must have done for it (beside nothing else: no full build).
CHANGES = {
    "move": (_move, {"moved": 1}),
    "sdl colour": (_sdl_colour, {"materials": 1}),
    "principled colour": (_principled_colour, {"materials": 1}),
    "another material": (_other_material, {"replaced": 1}),
    "geometry": (_geometry, {"replaced": 1}),
    "add": (_add, {"added": 1, "replaced": 1}),
    "delete": (_delete, {"removed": 1}),
    "hide": (_hide, {"removed": 1}),
    "light": (_light, {"lights": 1}),
}


@pytest.mark.parametrize("name", list(CHANGES))
def test_each_change_is_its_own_edit_and_the_image_is_a_full_builds(name):
    change, expected = CHANGES[name]
    objects = _lecture()
    with Live() as live:
        before = live.image()
        made_before = live.live.cache.made.copy()
        change(objects)
        after = live.image()
        done = {k: v for k, v in live.live.done.items() if k != "full"}
        assert live.live.done["full"] == 1, live.live.done  # the first build only
        assert {k: done.get(k, 0) for k in expected} == expected and set(done) <= set(expected) | {"lights"}, done
        assert live.live.last_sync[0] == "edit"
    assert np.abs(after - before).max() > 0.02  # the change shows
    np.testing.assert_array_equal(after, _from_scratch())
    # meshes read out of Blender (beside "generic": a generic shape's mesh hashed, to see it is unedited)
    converted = {kind: n for kind, n in (live.live.cache.made - made_before).items() if "mesh" in kind}
    assert converted == ({"evaluated mesh VIEWPORT": 1} if name == "geometry" else {}), converted


def test_the_world_builds_the_scene_again():
    objects = _lecture()
    with Live() as live:
        before = live.image()
        _world(objects)
        after = live.image()
        assert live.live.done["full"] == 2 and live.live.last_sync[0] == "full"
    assert np.abs(after - before).max() > 0.1
    np.testing.assert_array_equal(after, _from_scratch())


def test_edits_in_a_row_end_where_a_full_build_does_on_both_backends():
    objects = _lecture()
    with Live() as live:
        live.image()
        for name in ("move", "sdl colour", "another material", "add", "light", "geometry", "hide"):
            CHANGES[name][0](objects)
            live.image()
        assert live.live.done["full"] == 1
        for backend in ("c", "numpy"):
            np.testing.assert_array_equal(live.image(backend), _from_scratch(backend=backend))


def test_moving_a_boolean_operand_remakes_its_owner():
    fresh()
    import_sdl(SCENES / "csg.sdl")
    cutter = next(o for o in shape_objects() if o.get("sdl_cutter"))
    with Live() as live:
        before = live.image()
        cutter.location.x += 0.3
        after = live.image()
        assert live.live.done["full"] == 1 and live.live.done["replaced"] >= 1
    assert np.abs(after - before).max() > 0.02
    np.testing.assert_array_equal(after, _from_scratch())


def test_an_animation_converts_no_mesh_after_its_first_frame():
    """Frames whose objects' transforms change: every frame after the first moves objects, and reads no mesh
    out of Blender (counted in the object cache) and builds nothing anew."""
    objects = _lecture()
    scene = bpy.context.scene
    animated = list(objects.values())[:6]
    for frame in (1, 10):
        scene.frame_set(frame)
        for i, obj in enumerate(animated):
            obj.location.z += 0.05 * (i + 1) * (1 if frame == 10 else 0)
            obj.keyframe_insert("location", frame=frame)
    scene.frame_set(1)
    with Live(mode="RENDER") as live:
        live.image()
        made = live.live.cache.made.copy()
        for frame in (2, 3, 4):
            scene.frame_set(frame)
            image = live.image()
            assert live.live.last_sync[0] == "edit"
        assert live.live.cache.made == made and live.live.done["full"] == 1
        assert live.live.done["moved"] == 3 * len(animated)
    np.testing.assert_array_equal(image, _from_scratch("RENDER"))


def test_f12_with_persistent_data_edits_the_scene_it_kept():
    from blender_scripts.addon_env import render_rgba, set_resolution

    objects = _lecture()
    set_resolution(WIDTH, HEIGHT)
    scene = bpy.context.scene
    scene.render.use_persistent_data = True
    try:
        render_rgba(engine.ENGINE_ID)
        assert engine.LAST_RENDER["scene"] == "full"
        _move(objects)
        moved = render_rgba(engine.ENGINE_ID)
        assert engine.LAST_RENDER["scene"] == "edit"
    finally:
        scene.render.use_persistent_data = False
    np.testing.assert_array_equal(moved, render_rgba(engine.ENGINE_ID))  # a new engine, a full build
    assert engine.LAST_RENDER["scene"] == "full"
