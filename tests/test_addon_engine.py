"""The SDL_RAYTRACER render engine: rays exactly as Blender's camera projects (lens, sensor size and fit,
shift, pixel aspect, resolution %, border, orthographic), the same pixels as tracer.render, blocks coarse to
fine, samples, cancel, hide_render, animation, and the viewport's rays from its projection matrix."""
from __future__ import annotations

import itertools
import time

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector

import tracer
from addon import engine, object_cache
from addon.pure import blocks, raycam
from addon.scene_build import matrix_np
from blender_scripts.addon_env import SCENES, fresh, import_sdl, render_rgba, set_resolution, shape_objects


@pytest.fixture(autouse=True)
def _fresh():
    fresh()


def _camera(**data) -> bpy.types.Object:
    cam_data = bpy.data.cameras.new("cam")
    for key, value in data.items():
        setattr(cam_data, key, value)
    cam = bpy.data.objects.new("cam", cam_data)
    bpy.context.scene.collection.objects.link(cam)
    cam.location = (1.0, -7.0, 2.5)
    cam.rotation_euler = (1.3, 0.05, 0.2)
    bpy.context.scene.camera = cam
    bpy.context.view_layer.update()
    return cam


CAMERAS = [
    dict(),
    dict(lens=35.0, sensor_fit="VERTICAL", sensor_height=20.0),
    dict(lens=80.0, sensor_fit="HORIZONTAL", sensor_width=30.0, shift_x=0.2, shift_y=-0.15),
    dict(lens=24.0, sensor_fit="AUTO", shift_y=0.3),
    dict(type="ORTHO", ortho_scale=5.0, shift_x=-0.1),
    dict(type="ORTHO", ortho_scale=3.0, sensor_fit="VERTICAL"),
]
FRAMES = [(64, 48, 100, 1.0, 1.0), (40, 90, 50, 1.0, 1.0), (60, 40, 100, 2.0, 1.0), (50, 50, 100, 1.0, 1.5)]


@pytest.mark.parametrize("camera, frame", list(itertools.product(CAMERAS, FRAMES)),
                         ids=lambda v: str(v).replace(" ", ""))
def test_rays_land_where_blender_projects(camera, frame):
    """Points along each pixel's ray project (by Blender's own camera view frame) to that pixel's centre."""
    width, height, percent, aspx, aspy = frame
    cam = _camera(**camera)
    render = bpy.context.scene.render
    set_resolution(width, height, percent)
    render.pixel_aspect_x, render.pixel_aspect_y = aspx, aspy
    winx, winy = engine.render_size(render)
    assert (winx, winy) == (width * percent // 100, height * percent // 100)
    rows = np.array([0, winy // 3, winy - 1, winy // 2, 0])
    cols = np.array([0, winx // 2, winx - 1, 3, winx - 1])
    origins, directions = raycam.pixel_rays(engine.camera_params(cam), winx, winy, rows, cols, aspx, aspy)
    for o, d, r, c in zip(origins, directions, rows, cols):
        for t in (1.0, 7.5):
            p = world_to_camera_view(bpy.context.scene, cam, Vector(o + t * d))
            assert p.x == pytest.approx((c + 0.5) / winx, abs=1e-5)
            assert p.y == pytest.approx((r + 0.5) / winy, abs=1e-5)


def test_render_equals_the_tracers_own_render():
    """Imported into Blender and rendered through Blender's camera, the scene gives tracer.render's pixels."""
    import_sdl(SCENES / "lecture.sdl")
    set_resolution(80, 60)
    image = render_rgba("SDL_RAYTRACER")
    expected = tracer.render(tracer.load(str(SCENES / "lecture.sdl")), 80, 60).image
    assert image.shape == (60, 80, 4)
    np.testing.assert_allclose(image[..., :3], expected, atol=1e-4)
    assert np.all(image[..., 3] == 1.0)


def test_an_imported_camera_traces_the_sdl_camera_until_it_is_edited():
    """While the imported camera is as the import left it, F12 traces the tracer's own rays (not Blender's
    float32 copy of the camera); once it is moved, Blender's camera."""
    import_sdl(SCENES / "lecture.sdl")
    scene = bpy.context.scene
    cam = scene.camera
    width, height = 64, 48
    rows, cols = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    params = engine.camera_params(cam)
    rays = engine.camera_rays(cam, None, params, width, height, 0, 0, 1.0, 1.0)
    _, directions = rays(rows.ravel(), cols.ravel())
    # The imported camera in Blender's axes (eye, look, up as the importer stored them) gives the
    # tracer's directions bit for bit; Blender's float32 camera does not.
    frame = tracer.camera.CameraFrame.from_camera(tracer.model.Camera(*engine.stored_sdl_camera(cam)), width / height)
    assert np.array_equal(directions, frame.directions(rows.ravel(), cols.ravel(), height, width))
    _, blender_directions = raycam.pixel_rays(params, width, height, rows, cols)
    assert not np.array_equal(directions, blender_directions)
    np.testing.assert_allclose(directions, blender_directions, atol=1e-5)
    cam.location.x += 1e-3
    bpy.context.view_layer.update()
    assert engine.stored_sdl_camera(cam) is None
    edited = engine.camera_rays(cam, None, engine.camera_params(cam), width, height, 0, 0, 1.0, 1.0)
    _, directions = edited(rows.ravel(), cols.ravel())
    _, blender_directions = raycam.pixel_rays(engine.camera_params(cam), width, height, rows, cols)
    assert np.array_equal(directions, blender_directions)
    cam.location.x -= 1e-3
    cam.data.lens *= 1.001
    assert engine.stored_sdl_camera(cam) is None


def test_target_error_samples_the_whole_image_and_reports_the_estimate():
    """Render Properties > Target Error: a final render sampled as ``tracer.render(target_error=E)`` does,
    with the estimate in the render's statistics; 0 renders the block plan as before."""
    import_sdl(SCENES / "lecture.sdl")
    set_resolution(32, 24)
    scene = bpy.context.scene
    scene.sdl_render.target_error = 0.02
    image = render_rgba("SDL_RAYTRACER")
    reached = engine.LAST_RENDER["error_estimate"]
    expected = tracer.render(tracer.load(str(SCENES / "lecture.sdl")), 32, 24,
                             target_error=scene.sdl_render.target_error, seed=scene.frame_current)
    np.testing.assert_allclose(image[..., :3], expected.image, atol=1e-4)
    assert reached == expected.error_estimate.as_dict()
    assert reached["target"] == pytest.approx(0.02)
    assert reached["estimated_rmse"] <= 0.02 and reached["samples_mean"] > 1.0
    assert reached["kind"] == "image"  # the image's RMSE is the target, as on the command line
    scene.sdl_render.target_error = 0.0
    render_rgba("SDL_RAYTRACER")
    assert "error_estimate" not in engine.LAST_RENDER


def test_blocks_coarse_to_fine_every_pixel_once(monkeypatch):
    import_sdl(SCENES / "shapes.sdl")
    set_resolution(96, 72)
    settings = bpy.context.scene.sdl_render
    settings.block_size, settings.progressive = 8, True
    unseen = render_rgba("SDL_RAYTRACER")  # (the bpy module shows nothing: no coarse passes to watch)
    assert engine.LAST_RENDER["passes"] == [1] and engine.LAST_RENDER["rays"]["camera"] == 96 * 72
    monkeypatch.setattr(engine, "displayed", lambda: True)
    refined = render_rgba("SDL_RAYTRACER")
    stats = engine.LAST_RENDER
    assert stats["passes"] == [8, 4, 2, 1] and stats["tiles_done"] == stats["tiles_total"]
    assert stats["rays"]["camera"] == 96 * 72
    np.testing.assert_array_equal(refined, unseen)  # the same rays through every pixel
    assert not engine.LAST_RENDER["warnings"]
    settings.progressive = False
    coarse = render_rgba("SDL_RAYTRACER")
    assert engine.LAST_RENDER["rays"]["camera"] == 12 * 9  # one ray per 8 x 8 block
    assert np.all(coarse[:8, :8] == coarse[0, 0])
    # (not what a user who unticked Progressive Refinement expects of a final render: said)
    assert engine.LAST_RENDER["warnings"] == [engine.blocky_warning(8)]


def test_samples_and_modes():
    import_sdl(SCENES / "lecture.sdl")
    set_resolution(48, 36)
    s = bpy.context.scene.sdl_render
    s.block_size, s.progressive, s.samples, s.sampling = 1, False, 4, "REGULAR"
    regular = render_rgba("SDL_RAYTRACER")
    assert engine.LAST_RENDER["rays"]["camera"] == 4 * 48 * 36
    s.sampling = "ADAPTIVE"
    adaptive = render_rgba("SDL_RAYTRACER")
    rays = engine.LAST_RENDER["rays"]["camera"]
    assert 48 * 36 < rays <= 4 * 48 * 36  # about Samples rays per pixel, never more
    # the command line's adaptive render, pixel for pixel (and near the regular grid's)
    expected = tracer.render(tracer.load(str(SCENES / "lecture.sdl")), 48, 36, samples=4, sampling_mode="adaptive",
                             seed=bpy.context.scene.frame_current)
    np.testing.assert_allclose(adaptive[..., :3], expected.image, atol=1e-4)
    assert rays == expected.rays.camera
    assert np.abs(adaptive - regular).max() < 0.5


def test_border_crop_resolution_percentage():
    import_sdl(SCENES / "lecture.sdl")
    set_resolution(100, 80, 50)
    full = render_rgba("SDL_RAYTRACER")
    assert full.shape == (40, 50, 4)
    render = bpy.context.scene.render
    render.use_border, render.use_crop_to_border = True, True
    render.border_min_x, render.border_max_x, render.border_min_y, render.border_max_y = 0.2, 0.7, 0.25, 0.75
    part = render_rgba("SDL_RAYTRACER")
    assert part.shape == (20, 25, 4)
    # the crop is the same pixels of the full frame (row 0 at the top: border y counts from the bottom)
    np.testing.assert_allclose(part, full[40 - 30:40 - 10, 10:35], atol=1e-6)
    render.use_crop_to_border = False  # the full frame, with only the border's pixels rendered
    framed = render_rgba("SDL_RAYTRACER")
    assert framed.shape == (40, 50, 4) and framed[..., 3].sum() == 20 * 25
    np.testing.assert_allclose(framed[10:30, 10:35], part, atol=1e-6)


def test_hide_render_respected():
    import_sdl(SCENES / "lecture.sdl")
    set_resolution(40, 30)
    render_rgba("SDL_RAYTRACER")
    count = engine.LAST_RENDER["objects"]
    shape_objects()[4].hide_render = True
    render_rgba("SDL_RAYTRACER")
    assert engine.LAST_RENDER["objects"] == count - 1


def test_cancel_within_a_block(monkeypatch):
    """Esc (test_break) stops the render within a work item: the engine asks between chunks of rays."""
    import_sdl(SCENES / "shapes.sdl")
    set_resolution(64, 64)
    s = bpy.context.scene.sdl_render
    s.block_size, s.progressive = 1, False  # one pass, one 64 x 64 tile: a single work item
    monkeypatch.setattr(blocks, "DEFAULT_CHUNK", 256)
    asked = []
    # (RenderEngine.test_break is Blender's own function, which a Python attribute cannot shadow; the
    # engine asks it through SDLRenderEngine.cancelled)
    monkeypatch.setattr(engine.SDLRenderEngine, "cancelled", lambda self: asked.append(1) or len(asked) > 3)
    render_rgba("SDL_RAYTRACER")
    stats = engine.LAST_RENDER
    assert asked, stats
    assert stats["cancelled"] and stats["tiles_done"] == 0 and stats["tiles_total"] == 1, stats
    assert stats["rays"]["camera"] == 3 * 256  # stopped inside the only block


def test_block_renderer_cancel_and_time_slices():
    compiled = tracer.compile.compile_scene(tracer.load(str(SCENES / "shapes.sdl")))
    cam = tracer.camera.CameraFrame.from_camera(compiled.scene.camera, 1.0)

    def rays_for(rows, cols, dy=0.5, dx=0.5):
        d = cam.directions(rows, cols, 32, 32, dy=dy, dx=dx)
        return np.broadcast_to(cam.eye, d.shape), d

    r = blocks.BlockRenderer(compiled, rays_for, 32, 32, block_size=4, progressive=True, tile=16)
    # a coarse pass's tiles are stride times wider (as many rays per item): 64, 32 and 16 pixels here
    assert [len(r.pass_items(p)) for p in range(3)] == [1, 1, 4] and r.pass_count == 3
    r.run_for(0.0)  # one item per slice at least: the viewport refines while the user waits
    assert r.done >= 1 and not r.finished
    while not r.finished:
        r.run_for(0.01)
    expected = tracer.render(compiled, 32, 32).image[::-1]
    np.testing.assert_allclose(r.color, expected, atol=1e-9)
    with pytest.raises(blocks.Cancelled):
        blocks.BlockRenderer(compiled, rays_for, 32, 32).run(cancel=lambda: True)


def test_animation_frame_by_frame(tmp_path):
    import_sdl(SCENES / "lecture.sdl")
    set_resolution(40, 30)
    scene = bpy.context.scene
    scene.render.engine = "SDL_RAYTRACER"
    ball = [o for o in shape_objects() if o["sdl_kind"] == "sphere"][-1]
    ball.location.z = 1.0
    ball.keyframe_insert("location", frame=1)
    ball.location.z = 3.0
    ball.keyframe_insert("location", frame=2)
    scene.frame_start, scene.frame_end = 1, 2
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(tmp_path / "frame_")
    scene.render.use_file_extension = True
    bpy.ops.render.render(animation=True)
    files = sorted(p.name for p in tmp_path.iterdir())
    assert files == ["frame_0001.png", "frame_0002.png"]
    assert engine.LAST_RENDER["frame"] == 2
    a, b = (bpy.data.images.load(str(tmp_path / f)) for f in files)
    assert np.abs(np.array(a.pixels[:]) - np.array(b.pixels[:])).max() > 0.2  # the ball moved


def test_viewport_rays_from_the_projection_matrix():
    """The viewport traces from a region's perspective matrix; for a camera's own matrices its rays are
    the final render's rays."""
    cam = _camera(lens=40.0)
    set_resolution(64, 48)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    window = matrix_np(cam.calc_matrix_camera(depsgraph, x=64, y=48))
    persp = window @ np.linalg.inv(matrix_np(cam.matrix_world))
    rows, cols = np.arange(48) % 48, (np.arange(48) * 7) % 64
    near, d_view = raycam.projection_rays(persp, 64, 48, rows, cols)
    o_cam, d_cam = raycam.pixel_rays(engine.camera_params(cam), 64, 48, rows, cols)
    d_cam = d_cam / np.linalg.norm(d_cam, axis=1, keepdims=True)
    np.testing.assert_allclose(d_view, d_cam, atol=1e-5)
    np.testing.assert_allclose(near, o_cam, atol=1e-4)


def test_render_errors_are_reported_not_raised():
    import_sdl(SCENES / "lecture.sdl")
    set_resolution(20, 20)
    bpy.context.scene.camera.data.type = "PANO"
    bpy.context.scene.render.engine = "SDL_RAYTRACER"
    try:
        bpy.ops.render.render()
    except RuntimeError as exc:  # Blender raises the engine's error report for a script; a user sees it
        assert "panoramic cameras are not supported" in str(exc)
    assert "panoramic cameras are not supported" in engine.LAST_RENDER["error"]


def test_viewport_refines_while_the_user_waits(monkeypatch):
    """view_draw, driven as Blender drives it (one call per redraw, another redraw asked for until the image
    is finished), traces the scene from the region's perspective matrix.  GPU drawing is not available in
    background mode, so the texture upload (_draw) is replaced by a recorder here."""
    import_sdl(SCENES / "lecture.sdl")
    width, height = 64, 48
    cam = bpy.context.scene.camera
    depsgraph = bpy.context.evaluated_depsgraph_get()
    persp = cam.calc_matrix_camera(depsgraph, x=width, y=height) @ cam.matrix_world.inverted()

    class Context:
        region = type("Region", (), {"width": width, "height": height})
        region_data = type("RegionView3D", (), {"perspective_matrix": persp})

    class Engine:
        _view, _view_dirty, _view_scene, _draw_seconds = None, True, None, 0.0
        view_draw = engine.SDLRenderEngine.__dict__["view_draw"]
        view_update = engine.SDLRenderEngine.__dict__["view_update"]

        def __init__(self):
            self.redraws, self.frames = 0, []
            engine.SDLRenderEngine._start(self)

        def tag_redraw(self):
            self.redraws += 1

        def update_stats(self, stats, info):
            self.info = info

        def _draw(self, scene, rgba, w, h):
            assert (w, h) == (width, height)
            self.frames.append(rgba.copy())

    bpy.context.scene.sdl_render.block_size = 8
    monkeypatch.setattr(engine, "VIEWPORT_SLICE", 0.0)  # one work item per redraw (the C core is quick)
    eng = Engine()
    for _ in range(200):
        eng.view_draw(Context, depsgraph)
        if eng.info.endswith("done"):
            break
    assert eng.info.endswith("done") and eng.redraws == len(eng.frames) - 1 == 3  # passes 8, 4, 2, 1
    expected = tracer.render(tracer.load(str(SCENES / "lecture.sdl")), width, height).image[::-1]
    first, last = eng.frames[0][..., :3], eng.frames[-1][..., :3]
    np.testing.assert_allclose(last, expected, atol=1e-4)  # bottom row first, as a texture wants
    assert np.abs(first - expected).max() > 0.05  # the first redraw showed a coarse image
    # an update that changes nothing traced (a selection, say) keeps the finished image
    eng.view_update(Context, depsgraph)
    eng.view_draw(Context, depsgraph)
    assert eng.info.endswith("done")
    # a change to the scene starts again (Blender calls view_update with what changed)
    def updated(scene, graph):
        eng.view_update(Context, graph)

    bpy.app.handlers.depsgraph_update_post.append(updated)
    try:
        next(o for o in bpy.data.objects if o.type == "MESH").location.x += 0.1
        depsgraph = bpy.context.evaluated_depsgraph_get()
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(updated)
    eng.view_draw(Context, depsgraph)
    assert not eng.info.endswith("done")


def test_any_object_as_the_scene_camera():
    """Blender renders through any object made the scene camera (an empty: a 35 mm lens; a light: a lens
    from its spot size); so does the engine: the same silhouette as Workbench's, not an error."""
    import math

    from blender_scripts.addon_env import iou

    bpy.ops.object.sdl_add_shape(kind="cube")
    bpy.context.object.location = (0.8, 0.0, 0.3)
    set_resolution(80, 60)
    scene = bpy.context.scene
    scene.render.film_transparent = True
    scene.display.render_aa = "OFF"
    spot = bpy.data.lights.new("spot", "SPOT")
    spot.spot_size = math.radians(30.0)
    for data in (None, spot):
        viewer = bpy.data.objects.new("viewer", data)
        scene.collection.objects.link(viewer)
        viewer.location, viewer.rotation_euler = (0.5, -7.0, 0.8), (math.radians(86.0), 0.0, 0.1)
        scene.camera = viewer
        workbench = render_rgba("BLENDER_WORKBENCH")[..., 3] > 0.5
        traced = render_rgba("SDL_RAYTRACER")[..., 3] > 0.5
        assert "error" not in engine.LAST_RENDER, engine.LAST_RENDER
        assert workbench.sum() > 200 and iou(workbench, traced) >= 0.97, (data, workbench.sum(), traced.sum())
        bpy.data.objects.remove(viewer)


def test_a_sun_is_a_sun_of_its_strength():
    """A Blender sun of strength S (W/m^2) lights a diffuse surface as Cycles does: a tracer sun of colour
    S / pi x its colour, its light travelling along the object's -Z (it was an SDL point light 10^6 away, of
    colour S)."""
    import math

    bpy.ops.object.light_add(type="SUN", rotation=(0.0, 0.0, 0.0))
    sun = bpy.context.object
    sun.data.energy, sun.data.color, sun.data.angle = 2.0, (1.0, 0.5, 0.25), 0.0
    scene, _ = engine.build_scene(bpy.context.evaluated_depsgraph_get(), "RENDER")
    (light,) = scene.lights
    assert (light.kind, light.direction, light.angle) == ("sun", (0.0, 0.0, -1.0), 0.0)
    assert light.color == pytest.approx((2.0 / math.pi, 1.0 / math.pi, 0.5 / math.pi))

def test_threads_zero_is_the_tracers_default(monkeypatch):
    compiled = tracer.compile.compile_scene(tracer.load(str(SCENES / "shapes.sdl")))
    monkeypatch.setenv("SDL_TRACER_THREADS", "3")
    assert blocks.BlockRenderer(compiled, None, 8, 8, threads=0).threads == 3
    assert blocks.BlockRenderer(compiled, None, 8, 8, threads=2).threads == 2


def test_each_imported_file_keeps_its_own_images(tmp_path):
    """Two files whose ``makePixmap 1`` names different images: each file's cube shows its own."""
    from blender_scripts.addon_env import two_files_with_their_own_pixmap_1

    for path in two_files_with_their_own_pixmap_1(tmp_path):
        import_sdl(path)
    set_resolution(60, 30)
    scene = bpy.context.scene
    rgba = render_rgba("SDL_RAYTRACER")
    assert "error" not in engine.LAST_RENDER, engine.LAST_RENDER
    colors = []
    for obj in shape_objects():
        p = world_to_camera_view(scene, scene.camera, obj.matrix_world.translation)
        colors.append(rgba[int((1.0 - p.y) * 30), int(p.x * 60), :3])
    np.testing.assert_allclose(colors, [(1, 0, 0), (0, 1, 0)], atol=0.02)


def test_film_updates_are_spaced_by_what_they_cost():
    """Showing a 1080p film costs tens of milliseconds: it may take at most UPDATE_SHARE of the render, and
    nothing is shown without a window (blender -b, the bpy module)."""
    shown = []

    def show():
        shown.append(time.perf_counter())
        time.sleep(0.02)

    updates = engine.FilmUpdates(show)
    updates.last -= 1.0  # a while into the render
    started = time.perf_counter()
    while time.perf_counter() - started < 1.0:
        updates.offer(pass_done=True)
    assert 1 <= len(shown) <= 1 + 1.0 / max(engine.UPDATE_INTERVAL, 0.02 / engine.UPDATE_SHARE)
    assert all(b - a >= 0.02 / engine.UPDATE_SHARE * 0.99 for a, b in zip(shown, shown[1:]))
    hidden = engine.FilmUpdates(show, enabled=False)
    hidden.last -= 1.0
    assert not hidden.offer(pass_done=True)


def test_a_material_preview_is_traced_and_says_nothing_of_blenders_preview_scene():
    """(In the bpy module a preview renders at once; Blender 3.4's `-b` queues it as a job.)
    The Material tab's preview is rendered by this engine in Blender's own preview scene, whose hidden
    floor uses nodes the engine does not evaluate: the preview shows the material, and no warning about
    that floor reaches the user's status bar."""
    fresh()
    bpy.context.scene.render.engine = engine.ENGINE_ID
    material = bpy.data.materials.new("Red")
    material.use_nodes = True
    material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.8, 0.02, 0.02, 1.0)
    engine.LAST_RENDER.clear()
    material.asset_generate_preview()  # (renders the preview at once, as the Material tab asks for it)
    assert engine.LAST_RENDER.get("width"), "the preview was not traced by the engine"
    assert engine.LAST_RENDER["warnings"] == []
    size = material.preview.image_size[:]
    pixels = list(material.preview.image_pixels_float)
    red, green = pixels[0::4], pixels[1::4]
    assert len(red) == size[0] * size[1] > 0
    reddish = sum(r > 2 * g + 0.05 for r, g in zip(red, green))
    assert reddish > 0.05 * len(red), "the preview does not show the red material"
