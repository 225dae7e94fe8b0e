"""The engine rebuilds only what changed (addon/object_cache.py): moving a light or the mesh, or editing a
material, converts no mesh from Blender again and builds no BVH again; editing the geometry does both;
deleted objects leave the cache; a file load empties it.  Counted through the two places the work happens
(meshes.triangle_meshes, tracer.intersect.mesh.TriangleMesh), not timed; each kept render is compared with
a render that rebuilt everything."""
from __future__ import annotations

import gc
import types

import bpy
import numpy as np

import tracer.intersect.mesh as mesh_module
from addon import engine, meshes, object_cache
from blender_scripts.addon_env import fresh, render_rgba, set_resolution

WIDTH, HEIGHT = 48, 36
GRID = 100  # 10,000 quads


class Counts:
    """How often a Blender mesh was converted and a triangle mesh (its BVH) was built."""

    def __init__(self, monkeypatch):
        # Built meshes are shared by content while any compiled scene holds them, and compiled scenes are
        # freed by the cycle collector: collect now, so that no earlier test's mesh is found again.
        gc.collect()
        self.converted = self.built = 0
        convert, counts = meshes.triangle_meshes, self

        def counted_convert(*args, **kwargs):
            counts.converted += 1
            return convert(*args, **kwargs)

        class CountedMesh(mesh_module.TriangleMesh):
            def __init__(self, *args, **kwargs):
                counts.built += 1
                super().__init__(*args, **kwargs)

        monkeypatch.setattr(meshes, "triangle_meshes", counted_convert)
        monkeypatch.setattr(mesh_module, "TriangleMesh", CountedMesh)

    def since(self, before: tuple) -> tuple:
        return self.converted - before[0], self.built - before[1]

    def now(self) -> tuple:
        return self.converted, self.built


def _bumps(count: int) -> np.ndarray:
    """Heights of a GRID x GRID grid's vertices: a few bumps, so that light and geometry changes show."""
    co = np.empty(count * 3, dtype=np.float32)
    bpy.context.scene.objects["Grid"].data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    co[:, 2] = 0.3 * np.sin(3.0 * co[:, 0]) * np.cos(2.0 * co[:, 1])
    return co


def _scene() -> bpy.types.Object:
    """A bumpy 10,000-quad grid under a point light, seen from above, with a grey Principled material that
    has no specular layer."""
    fresh()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=GRID, y_subdivisions=GRID, size=4)
    grid = bpy.context.active_object
    grid.name = "Grid"
    mesh = grid.data
    mesh.vertices.foreach_set("co", _bumps(len(mesh.vertices)).ravel())
    mesh.update()
    material = bpy.data.materials.new("Grey")
    material.use_nodes = True
    specular = material.node_tree.nodes["Principled BSDF"].inputs
    specular["Specular IOR Level" if "Specular IOR Level" in specular else "Specular"].default_value = 0.0
    mesh.materials.append(material)  # (without its white highlight, a red or green grid is only red or green)
    bpy.ops.object.light_add(type="POINT", location=(-1.0, 0.0, 2.0))
    bpy.context.active_object.name = "Lamp"
    bpy.context.active_object.data.energy = 1000.0
    bpy.ops.object.camera_add(location=(0.0, -5.0, 6.0), rotation=(0.6, 0.0, 0.0))
    bpy.context.scene.camera = bpy.context.active_object
    set_resolution(WIDTH, HEIGHT)
    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    scene.sdl_render.block_size = 1
    return grid


def _move_light(grid):
    bpy.data.objects["Lamp"].location = (1.5, 0.5, 1.5)


def _make_red(grid):
    grid.data.materials[0].node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (1, 0, 0, 1)


def _move_grid(grid):
    grid.location.x += 0.5


def _edit_geometry(grid):
    co = _bumps(len(grid.data.vertices))
    co[:, 2] *= -1.0
    grid.data.vertices.foreach_set("co", co.ravel())
    grid.data.update()


#: Changes made one after the other, with the (conversions, BVH builds) a kept engine makes for each.
CHANGES = ((_move_light, (0, 0)), (_make_red, (0, 0)), (_move_grid, (0, 0)), (_edit_geometry, (1, 1)))


def _f12_after_each_change(monkeypatch, persistent: bool) -> tuple[list, list]:
    """The images and the (conversions, builds) of a first render and of one after each of CHANGES."""
    grid = _scene()
    bpy.context.scene.render.use_persistent_data = persistent
    counts = Counts(monkeypatch)
    images, made = [], []
    try:
        for change in (None,) + tuple(c for c, _ in CHANGES):
            before = counts.now()
            if change is not None:
                change(grid)
            images.append(render_rgba(engine.ENGINE_ID))
            made.append(counts.since(before))
    finally:
        bpy.context.scene.render.use_persistent_data = False
    return images, made


def test_f12_with_persistent_data_rebuilds_only_what_changed(monkeypatch):
    images, made = _f12_after_each_change(monkeypatch, persistent=True)
    assert made == [(1, 1)] + [expected for _, expected in CHANGES]
    first, moved, red, shifted, edited = images
    assert np.abs(moved - first).max() > 0.1  # lit from the light's new place
    lit = red[..., 0] > 0.05
    assert lit.mean() > 0.3 and red[lit][:, 1:3].max() < 0.02 < moved[lit][:, 1].max()  # red: ambient only
    assert np.abs(shifted - red).max() > 0.1 and np.abs(edited - shifted).max() > 0.1
    # Without Persistent Data Blender gives each render a new engine: every mesh is converted again (its BVH
    # too, unless the last render's compiled scene is still waiting for the cycle collector), and the images
    # are the same.
    afresh, made_afresh = _f12_after_each_change(monkeypatch, persistent=False)
    assert [converted for converted, _ in made_afresh] == [1] * (len(CHANGES) + 1)
    for kept, rebuilt in zip(images, afresh):
        np.testing.assert_array_equal(kept, rebuilt)


class _Viewport:
    """view_update/view_draw of the engine, driven as Blender drives them: view_update from the depsgraph's
    update (where ``depsgraph.updates`` holds what changed; read later it is empty), then redraws until the
    image is finished.  GPU drawing is replaced: there is none in background mode."""

    _view, _view_dirty, _view_scene, _draw_seconds = None, True, None, 0.0
    view_draw = engine.SDLRenderEngine.__dict__["view_draw"]
    view_update = engine.SDLRenderEngine.__dict__["view_update"]

    def __init__(self):
        engine.SDLRenderEngine._start(self)
        self.info, self.image = "", None
        camera = bpy.context.scene.camera
        depsgraph = bpy.context.evaluated_depsgraph_get()
        persp = camera.calc_matrix_camera(depsgraph, x=WIDTH, y=HEIGHT) @ camera.matrix_world.inverted()
        self.context = type("Context", (), {
            "region": type("Region", (), {"width": WIDTH, "height": HEIGHT}),
            "region_data": type("RegionView3D", (), {"perspective_matrix": persp})})

    def __enter__(self):
        bpy.app.handlers.depsgraph_update_post.append(self._updated)
        return self

    def __exit__(self, *exc):
        handlers = bpy.app.handlers.depsgraph_update_post
        if self._updated in handlers:  # (a file load removes it)
            handlers.remove(self._updated)

    def _updated(self, scene, depsgraph):
        self.view_update(self.context, depsgraph)

    def tag_redraw(self):
        pass

    def update_stats(self, stats, info):
        self.info = info

    def _draw(self, scene, rgba, width, height):
        self.image = rgba.copy()

    def show(self) -> np.ndarray:
        """Evaluate the changes (view_update), then redraw until done."""
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for _ in range(100):
            self.view_draw(self.context, depsgraph)
            if self.info.endswith("done"):
                return self.image
        raise AssertionError(f"the viewport did not finish: {self.info}")


def test_viewport_rebuilds_only_what_changed(monkeypatch):
    grid = _scene()
    counts = Counts(monkeypatch)
    monkeypatch.setattr(engine, "VIEWPORT_SLICE", 10.0)
    with _Viewport() as view:
        first = view.show()
        assert counts.now() == (1, 1) and len(view._geometry) == 1

        before = counts.now()
        _move_light(grid)
        moved = view.show()
        assert counts.since(before) == (0, 0) and np.abs(moved - first).max() > 0.1

        before = counts.now()
        grid.data.materials[0].node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0, 1, 0, 1)
        green = view.show()
        assert counts.since(before) == (0, 0)
        lit = green[..., 1] > 0.05  # (the background has no green)
        assert lit.mean() > 0.3 and green[lit][:, [0, 2]].max() < 0.02 < moved[lit][:, 0].max()  # ambient only

        before = counts.now()
        _move_grid(grid)
        shifted = view.show()
        assert counts.since(before) == (0, 0) and np.abs(shifted - green).max() > 0.1

        before = counts.now()
        _edit_geometry(grid)
        edited = view.show()
        assert counts.since(before) == (1, 1) and np.abs(edited - shifted).max() > 0.1

        # A deleted object leaves the cache at the next build, and the image.
        background = first[0, 0]
        bpy.data.objects.remove(grid)
        empty = view.show()
        assert len(view._geometry) == 0 and np.all(empty == background)


def test_a_mesh_shared_by_two_objects_is_built_once_and_an_edit_reaches_both(monkeypatch):
    grid = _scene()
    twin = grid.copy()  # the same mesh datablock
    bpy.context.scene.collection.objects.link(twin)
    twin.location.x += 1.0
    counts = Counts(monkeypatch)
    with _Viewport() as view:
        view.show()
        # Each object converts its own evaluated mesh (modifiers may differ), but one BVH serves both.
        assert counts.now() == (2, 1)
        before = counts.now()
        _edit_geometry(grid)
        view.show()
        assert counts.since(before) == (2, 1)
        assert len(view._geometry) == 2


def test_the_cache_forgets_on_file_load_and_for_another_scene():
    _scene()
    with _Viewport() as view:
        view.show()
    assert len(view._geometry) == 1
    other = bpy.data.scenes.new("Other")
    view._geometry.begin_build(types.SimpleNamespace(scene=other, view_layer=other.view_layers[0]))
    assert len(view._geometry) == 0  # a build for another scene starts empty
    with _Viewport() as view:
        view.show()
        assert len(view._geometry) == 1
        bpy.ops.wm.read_factory_settings(use_empty=True)  # load_post: datablocks may reuse the addresses
        assert len(view._geometry) == 0
    fresh()


def test_the_engine_blender_kept_goes_with_its_cache():
    """What a kept engine holds (its cache, its last compiled scene) is freed with it: when Persistent Data
    is turned off, and on a file load."""
    for release in (lambda: setattr(bpy.context.scene.render, "use_persistent_data", False),
                    lambda: bpy.ops.wm.read_factory_settings(use_empty=True)):
        _scene()
        bpy.context.scene.render.use_persistent_data = True
        render_rgba(engine.ENGINE_ID)
        gc.collect()
        assert [len(cache) for cache in object_cache._LIVE] == [1]
        release()
        gc.collect()
        assert len(object_cache._LIVE) == 0
    fresh()


def test_the_render_panel_offers_persistent_data():
    """Blender shows Persistent Data in Cycles' panels only: the engine's own render panel offers it."""
    from addon import ui

    shown = []

    class Layout:
        use_property_split = False

        def column(self):
            return self

        def row(self):
            return self

        def prop(self, owner, name, **_kwargs):
            shown.append((owner, name))

    fresh()
    scene = bpy.context.scene
    ui.SDL_PT_render.draw(types.SimpleNamespace(layout=Layout()), types.SimpleNamespace(scene=scene))
    assert (scene.render, "use_persistent_data") in shown


def _triangles_as_blender_gives_them(mesh) -> dict:
    """Per material index, each triangle's corner positions and corner normals, asked of Blender one
    triangle at a time (the slow way the add-on used to read them)."""
    mesh.calc_loop_triangles()
    positions = np.array([v.co[:] for v in mesh.vertices])
    normals = meshes._corner_normals(mesh)
    out: dict = {}
    for tri in mesh.loop_triangles:
        out.setdefault(tri.material_index, []).append((positions[list(tri.vertices)], normals[list(tri.loops)]))
    return out


def test_meshes_read_as_arrays_are_blenders_triangles_and_normals():
    """triangle_meshes reads positions, triangles, materials and normals as whole arrays (normals from the
    domain Blender keeps them in): the same triangles, corner positions and corner normals as Blender's."""
    fresh()
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=7)
    sphere = bpy.context.active_object
    mesh = sphere.data
    for name in ("a", "b", "c"):
        mesh.materials.append(bpy.data.materials.new(name))
    bpy.ops.mesh.primitive_circle_add(vertices=9, fill_type="NGON")
    ngon = bpy.context.active_object.data

    def smooth(value):
        mesh.polygons.foreach_set("use_smooth", [value] * len(mesh.polygons))

    def sharpen():
        mesh.edges[3].use_edge_sharp = mesh.edges[10].use_edge_sharp = True
        if hasattr(mesh, "use_auto_smooth"):  # Blender < 4.1
            mesh.use_auto_smooth = True

    def materials():
        mesh.polygons.foreach_set("material_index", [p % 3 for p in range(len(mesh.polygons))])

    cases = [(ngon, None), (mesh, lambda: smooth(False)), (mesh, lambda: smooth(True)), (mesh, materials),
             (mesh, lambda: smooth(False)), (mesh, lambda: (smooth(True), sharpen()))]
    for target, change in cases:
        if change is not None:
            change()
            target.update()
        parts = meshes.triangle_meshes(target, "x")
        expected = _triangles_as_blender_gives_them(target)
        assert sorted(parts) == sorted(expected)
        for index, triangles in expected.items():
            tri_v, tri_n = parts[index].triangles()
            np.testing.assert_array_equal(np.asarray(parts[index].vertices)[tri_v], [p for p, _ in triangles])
            np.testing.assert_array_equal(np.asarray(parts[index].normals)[tri_n], [n for _, n in triangles])
