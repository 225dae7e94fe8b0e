"""The ``SDL_RAYTRACER`` render engine: final renders in blocks, and the viewport's Rendered mode.

Final render: the depsgraph becomes a tracer scene (scene_build), rays come from Blender's camera exactly
(raycam: lens, sensor size and fit, shift, pixel aspect, resolution %, border, orthographic), or, for
a camera the importer made and nobody changed, from the SDL file's own camera as the tracer's are; the
image is traced coarse to fine (blocks); after each finished tile the film goes to the render result
(``update_result``), so the Image Editor shows it sharpening.  Esc is checked between chunks of rays, so
it stops the render within a block.  Colours are the tracer's linear values, written as they are.

Viewport: each redraw traces for a short time slice with the viewport's own view and projection
matrices, draws the film so far as a texture over the region, and asks for another redraw until the
image is finished; any change to the scene or the view starts again.

Both keep what they made of each object's geometry (object_cache) and rebuild only the objects that
``depsgraph.updates`` says changed: the viewport for as long as it shows Rendered, final renders while the
scene's Persistent Data is on (Blender then keeps the engine between renders, as for Cycles).  The last
compiled scene is kept too, so that the meshes' BVHs, found again by content, are not built anew.
"""
from __future__ import annotations

import math
import time
import traceback
from typing import Optional

import bpy
import numpy as np

from . import live_scene, object_cache
from .importer import CAM_EXACT, CAM_SHOWN
from .pure import blocks, convert, passes, raycam
from .scene_build import SceneBuilder, flat, matrix_np
from .tracer.camera import CameraFrame
from .tracer.compile import compile_scene
from .tracer.errors import TracerError
from .tracer.model import Camera

ENGINE_ID = "SDL_RAYTRACER"
#: Statistics of the last final render (for scripts and tests): rays, seconds, size, passes, cancelled; "scene":
#: how its scene was made ("full": built; "edit": the kept scene edited; "none": the kept scene as it was).
LAST_RENDER: dict = {}
#: The viewport's last change: seconds from view_update to the first block drawn ("first_block"), of which
#: reading Blender's updates ("updates"), Blender's wait before it asked for the draw ("until_view_draw") and
#: making the scene ("sync"; "scene" as in LAST_RENDER), and when it was drawn ("drawn_at", time.perf_counter).
LAST_VIEW: dict = {}
#: Seconds of tracing per viewport redraw.
VIEWPORT_SLICE = 0.08
#: Shortest pause between two updates of the render result during a final render.
UPDATE_INTERVAL = 0.25
#: Shortest pause between two progress messages.
STATUS_INTERVAL = 0.1
#: Showing the film may take at most this share of a final render's time.
UPDATE_SHARE = 0.05


def render_size(render) -> tuple[int, int]:
    """Blender's pixel size of the frame: resolution times percentage, rounded down as Blender does."""
    return (max(1, render.resolution_x * render.resolution_percentage // 100),
            max(1, render.resolution_y * render.resolution_percentage // 100))


def camera_params(cam_obj, matrix: Optional[np.ndarray] = None) -> raycam.CameraParams:
    """The camera of an object.  Blender renders through any object made the scene camera: one that is not
    a camera has its defaults with a 35 mm lens, a light a lens from its spot size
    (``BKE_camera_params_from_object``)."""
    matrix = matrix_np(cam_obj.matrix_world) if matrix is None else matrix
    data = cam_obj.data
    if cam_obj.type != "CAMERA":
        lens = 35.0
        if cam_obj.type == "LIGHT":  # Blender's spot size, 45 degrees by default, on every light
            lens = 16.0 / math.tan(0.5 * float(getattr(data, "spot_size", math.radians(45.0)))) or 35.0
        return raycam.CameraParams(matrix=matrix, lens=lens)
    if data.type not in ("PERSP", "ORTHO"):
        raise ValueError(f"{cam_obj.name}: panoramic cameras are not supported")
    return raycam.CameraParams(
        matrix=matrix, ortho=data.type == "ORTHO", lens=float(data.lens), sensor_width=float(data.sensor_width),
        sensor_height=float(data.sensor_height), sensor_fit=data.sensor_fit, ortho_scale=float(data.ortho_scale),
        shift_x=float(data.shift_x), shift_y=float(data.shift_y), clip_start=float(data.clip_start))


def stored_sdl_camera(cam_obj, matrix: Optional[np.ndarray] = None):
    """The SDL camera the importer made ``cam_obj`` from, as (eye, look, up, view angle) in Blender's axes,
    while Blender still shows that camera as the import left it: its matrix (``matrix``, else its world
    matrix), lens and sensor height equal the snapshot taken at import to float32 rounding, the sensor fit is
    vertical and there is no shift.  None otherwise (an edited or a Blender-made camera)."""
    if cam_obj.type != "CAMERA" or cam_obj.data.type != "PERSP":
        return None
    data = cam_obj.data
    # Custom properties from the original: the evaluated copy holds them as of its last evaluation.
    original = getattr(cam_obj, "original", cam_obj)
    exact, shown = original.get(CAM_EXACT), original.get(CAM_SHOWN)
    if exact is None or shown is None or data.sensor_fit != "VERTICAL" or data.shift_x or data.shift_y:
        return None
    now = flat(cam_obj.matrix_world if matrix is None else matrix) + [float(data.lens), float(data.sensor_height)]
    if not convert.unchanged(now, list(shown)):
        return None
    values = [float(v) for v in exact]
    return (np.array(values[0:3]), np.array(values[3:6]), np.array(values[6:9]), values[9])


def camera_rays(cam_obj, matrix, params: raycam.CameraParams, winx: int, winy: int, x0: int, y0: int,
                aspx: float, aspy: float):
    """``rays_for(rows, cols, dy, dx)`` of a final render (rows and columns within the render border at
    (x0, y0)).  A camera the importer made, still as it left it, traces the SDL file's own camera, as the
    tracer does: Blender's float32 matrix and lens move rays by ~1e-7, enough to put a pixel whose centre
    lies that close to an edge on the edge's other side.  Otherwise Blender's camera (raycam)."""
    stored = stored_sdl_camera(cam_obj, matrix) if aspx == aspy else None
    if stored is None:
        def rays_for(rows, cols, dy=0.5, dx=0.5):
            return raycam.pixel_rays(params, winx, winy, rows + y0, cols + x0, aspx, aspy, dy, dx)
        return rays_for
    frame = CameraFrame.from_camera(Camera(*stored), winx / winy)

    def exact_rays_for(rows, cols, dy=0.5, dx=0.5):
        directions = frame.directions(np.asarray(rows) + y0, np.asarray(cols) + x0, winy, winx, dy=dy, dx=dx)
        # Start on the near clipping plane, as Blender draws nothing nearer (t = 1 is at distance 1).
        return frame.eye + params.clip_start * directions, directions
    return exact_rays_for


def build_scene(depsgraph, mode: str, cache: Optional[object_cache.ObjectCache] = None):
    builder = SceneBuilder(depsgraph, mode=mode, cache=cache)
    scene = builder.build(depsgraph.scene)
    return scene, builder.warnings


def render_settings(scene) -> dict:
    """BlockRenderer keyword arguments from the scene's SDL render settings (registered before the engine,
    unregistered after it: see addon._MODULES)."""
    s = scene.sdl_render
    return dict(block_size=s.block_size, progressive=s.progressive, threads=s.threads, samples=s.samples,
                sampling=s.sampling.lower())


def blocky_warning(block_size: int) -> str:
    """What a final render without Progressive Refinement says when it traces blocks, not pixels."""
    return (f"Progressive Refinement is off with Block Size {block_size}: the image is one ray per "
            f"{block_size} x {block_size} block (set Block Size 1, or tick Progressive Refinement)")


def displayed() -> bool:
    """Whether anyone sees a final render while it is traced: not under ``blender -b`` nor in the bpy module."""
    return not bpy.app.background


def write_pass(render_pass, pixels: np.ndarray) -> None:
    """Copy a (height, width, channels) float32 film into a render pass at memory speed.

    ``RenderPass.rect`` is a (pixels, channels) float array.  Blender 4.x/5.0 take a flat buffer of every
    float in ``foreach_set``; Blender 3.x counts the first dimension only and takes the (pixels, channels)
    array itself.  Both read the NumPy buffer directly; assigning ``rect`` from Python lists instead costs
    seconds per frame at 1080p."""
    height, width, channels = pixels.shape
    rows = np.ascontiguousarray(pixels, dtype=np.float32).reshape(height * width, channels)
    try:
        render_pass.rect.foreach_set(rows.reshape(-1))
    except TypeError:  # Blender 3.x: "expected sequence size <pixels>"
        render_pass.rect.foreach_set(rows)


def write_first_hit_passes(layer, names, tracer, compiled, rays_for, params, scene, chunk: int = 1 << 16) -> None:
    """Depth, Normal, Diffuse Color, Position and Mist (those in ``names``) of the ray through each pixel's
    centre, into the render layer's passes (addon/pure/passes.py says what each holds)."""
    height, width = tracer.height, tracer.width
    matrix = np.asarray(params.matrix, dtype=np.float64)
    eye, forward = matrix[:3, 3], -matrix[:3, 2] / np.linalg.norm(matrix[:3, 2])
    mist = None
    if scene.world is not None:
        m = scene.world.mist_settings
        mist = (float(m.start), float(m.depth), m.falloff)
    backend = tracer.backend_tracer()
    films = {}
    rows_all, cols_all = np.divmod(np.arange(height * width), width)  # film order: bottom row first
    for start in range(0, height * width, chunk):
        rows, cols = rows_all[start:start + chunk], cols_all[start:start + chunk]
        origins, directions = rays_for(rows, cols)
        origins = np.ascontiguousarray(np.broadcast_to(origins, directions.shape), dtype=np.float64)
        directions = np.ascontiguousarray(directions, dtype=np.float64)
        values = passes.compute(names, backend, compiled, origins, directions, eye, forward, mist)
        for name, value in values.items():
            film = films.setdefault(name, np.empty((height * width, value.shape[1]), dtype=np.float32))
            film[start:start + len(value)] = value
    for name, film in films.items():
        render_pass = layer.passes.find_pass(name, "") if hasattr(layer.passes, "find_pass") else None
        render_pass = render_pass or layer.passes.get(name)
        if render_pass is not None:
            write_pass(render_pass, film.reshape(height, width, -1))


class FilmUpdates:
    """When a final render shows its film so far: at the end of each pass and every UPDATE_INTERVAL, but
    spaced so that copying the film (a whole 1080p frame costs tens of milliseconds) stays within
    UPDATE_SHARE of the time; never without a window to show it in (``blender -b``, the bpy module)."""

    def __init__(self, show, enabled: bool = True):
        self.show, self.enabled = show, enabled
        self.last = time.perf_counter()
        self.cost = 0.0

    def offer(self, pass_done: bool) -> bool:
        if not self.enabled:
            return False
        now = time.perf_counter()
        since = now - self.last
        if since < self.cost / UPDATE_SHARE or (since < UPDATE_INTERVAL and not pass_done):
            return False
        self.show()
        self.last = time.perf_counter()
        self.cost = self.last - now
        return True


class SDLRenderEngine(bpy.types.RenderEngine):
    bl_idname = ENGINE_ID
    bl_label = "SDL Ray Tracer"
    bl_use_preview = True  # material previews traced too (small, one ray per pixel: well under a second)
    bl_use_postprocess = True
    bl_use_eevee_viewport = True  # Material Preview mode draws with EEVEE
    _draw_seconds = 0.0  # what the last viewport draw took

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._start()

    def _start(self) -> None:
        """The engine's own state (the tests drive view_update and view_draw on stand-ins that start so)."""
        self._view = None  # viewport state
        self._view_dirty = True
        self._view_scene = None
        self._geometry = object_cache.ObjectCache()  # what each object's geometry became, between builds
        # the compiled scene, edited as Blender's updates say (the viewport's; F12's with Persistent Data)
        self._live = live_scene.LiveScene(self._geometry)
        self._changed_at: Optional[float] = None  # when the viewport was told of a change not yet drawn
        self._draw_stride = 1  # (see _draw)

    def update(self, data, depsgraph):
        """Before each final render: what changed since the last one (everything, unless Persistent Data
        kept this engine and its depsgraph)."""
        self._live.take_updates(depsgraph)

    # -- final render ---------------------------------------------------------------------------------

    def cancelled(self) -> bool:
        """Esc pressed (asked between chunks of rays, so a render stops within a block)."""
        return bool(self.test_break())

    def render(self, depsgraph):
        scene = depsgraph.scene
        render = scene.render
        winx, winy = render_size(render)
        x0, y0, x1, y1 = raycam.border_rect(winx, winy, render.use_border,
                                            (render.border_min_x, render.border_max_x,
                                             render.border_min_y, render.border_max_y))
        width, height = x1 - x0, y1 - y0
        stats = {"width": width, "height": height, "frame": scene.frame_current, "cancelled": False,
                 "view_layer": depsgraph.view_layer.name}
        LAST_RENDER.clear()
        LAST_RENDER.update(stats)
        # Blender calls render() once per view layer, with that layer's depsgraph (its own visible
        # collections); the result must name the layer, else every layer's image lands in the first.
        result = self.begin_result(0, 0, width, height, layer=depsgraph.view_layer.name)
        try:
            layer = result.layers[0].passes["Combined"]
            cam_obj, matrix, params = self._camera(depsgraph)
            tracer_scene, compiled, warnings = self._compiled(depsgraph)
            rays_for = camera_rays(cam_obj, matrix, params, winx, winy, x0, y0, render.pixel_aspect_x,
                                   render.pixel_aspect_y)
            tracer = blocks.BlockRenderer(compiled, rays_for, width, height, alpha=render.film_transparent,
                                          seed=scene.frame_current, **self._settings(scene, warnings))
            estimate = self._trace(tracer, scene, layer, result)
            write_pass(layer, tracer.rgba())
            wanted = passes.enabled(depsgraph.view_layer)
            if wanted and not LAST_RENDER["cancelled"]:
                self.update_stats("", "SDL Ray Tracer | passes")
                write_first_hit_passes(result.layers[0], wanted, tracer, compiled, rays_for, params, scene)
            LAST_RENDER["passes_written"] = wanted if not LAST_RENDER["cancelled"] else []
            self._report_render(tracer, tracer_scene, warnings, estimate)
        except Exception as exc:  # noqa: BLE001 - a render must end with a message, not a traceback
            LAST_RENDER["error"] = str(exc)
            self.report({"ERROR"}, f"SDL Ray Tracer: {exc}")
            if not isinstance(exc, (TracerError, ValueError)):
                traceback.print_exc()  # (the scene's own problems are said in one line; a bug shows where)
        finally:
            self.end_result(result)

    def _camera(self, depsgraph):
        """The final render's camera object (evaluated), its model matrix and its CameraParams."""
        scene = depsgraph.scene
        cam_obj = self.camera_override or scene.camera
        if cam_obj is None:
            raise ValueError("the scene has no camera")
        cam_obj = cam_obj.evaluated_get(depsgraph)
        try:
            matrix = matrix_np(self.camera_model_matrix(cam_obj))
        except (AttributeError, TypeError):
            matrix = None
        return cam_obj, matrix, camera_params(cam_obj, matrix)

    def _compiled(self, depsgraph):
        """(tracer scene, compiled scene, warnings) of the final render: the live scene, kept and edited, where
        Blender keeps this engine for the next render (Persistent Data); else built anew."""
        render = depsgraph.scene.render
        self.update_stats("", "SDL Ray Tracer | building the scene")
        if render.use_persistent_data and not self.is_preview:
            # Blender keeps this engine for the next render: the scene is kept, and edited as it changes
            compiled, warnings = self._live.compiled(depsgraph, "RENDER")
            tracer_scene = self._live.editable.scene
            LAST_RENDER["scene"] = self._live.last_sync[0]
        else:
            tracer_scene, warnings = build_scene(depsgraph, "RENDER", self._geometry)
            compiled = compile_scene(tracer_scene)
            self._live.clear()
            self._geometry.clear()
            LAST_RENDER["scene"] = "full"
        if self.is_preview:
            # A preview's scene is Blender's own (its hidden floor has a Checker Texture and a Math node this
            # engine does not evaluate): nothing there for the user to act on, so nothing is said.
            warnings = []
        for message in warnings:
            self.report({"WARNING"}, message)
        return tracer_scene, compiled, warnings

    def _settings(self, scene, warnings: list) -> dict:
        """The BlockRenderer settings of a final render (a preview's, or the panel's), warning of blocks."""
        settings = render_settings(scene)
        if self.is_preview:  # a material or light preview: one pass, one ray per pixel, at once
            settings.update(block_size=1, progressive=False, samples=1)
        elif not settings["progressive"] and settings["block_size"] > 1:
            warnings.append(blocky_warning(settings["block_size"]))
            self.report({"WARNING"}, warnings[-1])
        if settings["progressive"] and not displayed():
            # Coarse passes only show the image sharpening, and nothing is shown here; every pixel gets
            # the same rays either way, so the image is the same without them.
            settings["block_size"] = 1
        return settings

    def _trace(self, tracer: blocks.BlockRenderer, scene, layer, result):
        """Trace the film (to the panel's error target when it sets one: then its ErrorEstimate is returned),
        showing it and the progress as it goes; Esc stops it (LAST_RENDER["cancelled"])."""
        shown = FilmUpdates(lambda: (write_pass(layer, tracer.rgba()), self.update_result(result)),
                            enabled=displayed())
        status_shown = [0.0]

        def on_item(item):
            pass_done = tracer.done == len(tracer.items) or \
                tracer.items[min(tracer.done, len(tracer.items) - 1)].pass_index != item.pass_index
            shown.offer(pass_done)
            now = time.perf_counter()
            if pass_done or now - status_shown[0] >= STATUS_INTERVAL:  # (blender -b prints each one)
                status_shown[0] = now
                self.update_progress(tracer.fraction)
                self.update_stats("", f"SDL Ray Tracer | pass {item.pass_index + 1}/{tracer.pass_count} "
                                      f"(block {item.stride}) | tile {tracer.done}/{len(tracer.items)}")

        target = 0.0 if self.is_preview else float(scene.sdl_render.target_error)
        try:
            if target > 0.0:
                self.update_stats("", f"SDL Ray Tracer | sampling to an error of {target:g}")
                return tracer.run_to_error(target, cancel=self.cancelled)
            tracer.run(cancel=self.cancelled, on_item=on_item)
        except blocks.Cancelled:
            LAST_RENDER["cancelled"] = True
        return None

    def _report_render(self, tracer: blocks.BlockRenderer, tracer_scene, warnings: list, estimate) -> None:
        """What the render did, in LAST_RENDER and Blender's status line."""
        counts = tracer.counts().as_dict()
        LAST_RENDER.update({"rays": counts, "seconds": round(tracer.seconds, 6), "passes": tracer.passes,
                            "tiles_done": tracer.done, "tiles_total": len(tracer.items),
                            "backend": tracer.backend_name, "objects": len(tracer_scene.objects),
                            "lights": len(tracer_scene.lights), "warnings": list(warnings),
                            # (the meshes traced, each held once whatever its instances; how many of those
                            # are instance rows: docs/tracer.md, "Instance rows")
                            "meshes": len(tracer.compiled.table.meshes),
                            "instance_rows": int((getattr(tracer.compiled.table, "slot", np.zeros(0)) < 0).sum())})
        total = sum(counts.values())
        reached = ""
        if estimate is not None:
            LAST_RENDER["error_estimate"] = estimate.as_dict()
            reached = (f" | estimated error {estimate.rms:.3g} (worst pixel {estimate.worst:.3g}, "
                       f"{estimate.samples_mean:.1f} samples per pixel)")
            self.report({"INFO"}, "SDL Ray Tracer:" + reached[2:])
        self.update_stats("", f"SDL Ray Tracer | {total} rays in {tracer.seconds:.2f} s" + reached
                              + (" | cancelled" if LAST_RENDER["cancelled"] else ""))

    def update_render_passes(self, scene=None, renderlayer=None):
        """The passes this engine writes, for the Render Layers node and the render result."""
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        for name in passes.enabled(renderlayer):
            _, channels, kind = passes.PASSES[name]
            self.register_pass(scene, renderlayer, name, len(channels), channels, kind)

    # -- viewport -------------------------------------------------------------------------------------

    def view_update(self, context, depsgraph):
        told = time.perf_counter()
        self._live.take_updates(depsgraph)
        self._view_dirty = True
        if self._changed_at is None:
            self._changed_at = told
        self._updates_seconds = time.perf_counter() - told

    def view_draw(self, context, depsgraph):
        region = context.region
        rv3d = context.region_data
        width, height = region.width, region.height
        if width < 1 or height < 1:
            return
        entered = time.perf_counter()
        persp = matrix_np(rv3d.perspective_matrix)
        settings = render_settings(depsgraph.scene)
        settings["progressive"] = True  # the viewport always refines while the user waits
        key = (width, height, persp.tobytes(), tuple(sorted(settings.items())))
        try:
            if self._view_dirty or self._view_scene is None:
                compiled, _ = self._live.compiled(depsgraph, "VIEWPORT")
                self._view_dirty = False
                if not self._live.changed and compiled is self._view_scene:
                    self._changed_at = None  # (the image being refined is still the scene's: a selection, say)
                elif self._view is not None and self._view[1].compiled is compiled:
                    self._view[1].restart()  # (the scene was edited in place)
                else:
                    self._view = None
                self._view_scene = compiled
            if self._view is None or self._view[0] != key:
                def rays_for(rows, cols, dy=0.5, dx=0.5, persp=persp, width=width, height=height):
                    return raycam.projection_rays(persp, width, height, rows, cols, dy, dx)

                renderer = blocks.BlockRenderer(self._view_scene, rays_for, width, height, **settings)
                self._view = (key, renderer, sum(1 for item in renderer.items if item.pass_index == 0))
            renderer, coarse_items = self._view[1], self._view[2]
            if not renderer.finished:
                # After a change, one work item (the first block of the coarsest pass) is drawn at once; then
                # slices at least as long as drawing takes (slow on software OpenGL), so that tracing keeps
                # half the time.
                renderer.run_for(0.0 if renderer.done == 0 else max(VIEWPORT_SLICE, self._draw_seconds))
        except Exception as exc:  # noqa: BLE001
            self.update_stats("", f"SDL Ray Tracer: {exc}")
            return
        started = time.perf_counter()
        # While the film is all blocks of the first pass, one pixel of each block is enough to draw it.
        self._draw_stride = renderer.passes[0] if renderer.done <= coarse_items else 1
        self._draw(depsgraph.scene, renderer.rgba(), width, height)
        drawn = time.perf_counter()
        self._draw_seconds = drawn - started
        if self._changed_at is not None:  # the first block since Blender said the scene changed
            what, seconds = self._live.last_sync
            LAST_VIEW.update({"first_block": drawn - self._changed_at, "sync": seconds, "scene": what,
                              "drawn_at": drawn, "until_view_draw": entered - self._changed_at,
                              "updates": getattr(self, "_updates_seconds", 0.0)})
            self._changed_at = None
        first = f" | first block {LAST_VIEW['first_block']:.3f} s after the change" if LAST_VIEW else ""
        self.update_stats("", "SDL Ray Tracer" + first + " | " + (
            "done" if renderer.finished else f"pass {renderer.current_pass() + 1}/{renderer.pass_count}"))
        if not renderer.finished:
            self.tag_redraw()
            if not bpy.app.timers.is_registered(_redraw_rendered_viewports):
                bpy.app.timers.register(_redraw_rendered_viewports, first_interval=0.0)

    def _draw(self, scene, rgba: np.ndarray, width: int, height: int) -> None:
        """Draw the film over the region: with ``_draw_stride`` s > 1 (a film of s x s blocks, anchored at
        the bottom left) one texel per block, stretched: s² times less to upload (tens of milliseconds for a
        whole viewport in software OpenGL)."""
        import gpu
        from gpu_extras.presets import draw_texture_2d

        stride = getattr(self, "_draw_stride", 1)
        film = rgba[::stride, ::stride] if stride > 1 else rgba
        rows, cols = film.shape[:2]
        data = np.ascontiguousarray(film, dtype=np.float32).reshape(-1)
        buffer = gpu.types.Buffer("FLOAT", data.size, data)
        texture = gpu.types.GPUTexture((cols, rows), format="RGBA16F", data=buffer)
        gpu.state.blend_set("ALPHA_PREMULT")
        self.bind_display_space_shader(scene)
        draw_texture_2d(texture, (0, 0), cols * stride, rows * stride)
        self.unbind_display_space_shader()
        gpu.state.blend_set("NONE")


def _redraw_rendered_viewports() -> None:
    """Draw the Rendered viewports again, to trace their next slice.  A one-shot timer, because Blender 3.4
    does not honour ``tag_redraw`` asked from inside ``view_draw``: the image stopped refining there."""
    for window in bpy.context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D" and area.spaces.active.shading.type == "RENDERED":
                area.tag_redraw()
    return None


def compatible_panels():
    """Blender's own panels that work with this engine (they list the engines they support)."""
    wanted = {"RENDER_PT_format", "RENDER_PT_frame_range", "RENDER_PT_output", "RENDER_PT_dimensions",
              "RENDER_PT_stamp", "RENDER_PT_post_processing", "DATA_PT_lens", "DATA_PT_camera",
              "DATA_PT_camera_display", "DATA_PT_context_light", "DATA_PT_light", "DATA_PT_context_camera",
              "MATERIAL_PT_preview", "MATERIAL_PT_context_material", "WORLD_PT_context_world",
              "EEVEE_MATERIAL_PT_context_material",  # the slot list and New (3.4-5.0 give it this name)
              "DATA_PT_preview",
              "RENDER_PT_format_presets", "RENDER_PT_film", "OBJECT_PT_visibility",
              "VIEWLAYER_PT_layer", "DATA_PT_camera_dof"}
    found = []
    for name in dir(bpy.types):
        cls = getattr(bpy.types, name, None)
        engines = getattr(cls, "COMPAT_ENGINES", None)
        if isinstance(engines, set) and ("BLENDER_RENDER" in engines or name in wanted):
            found.append(cls)
    return found


_added_to: list = []


def register() -> None:
    bpy.utils.register_class(SDLRenderEngine)
    for cls in compatible_panels():
        if ENGINE_ID not in cls.COMPAT_ENGINES:
            cls.COMPAT_ENGINES.add(ENGINE_ID)
            _added_to.append(cls)


def unregister() -> None:
    if bpy.app.timers.is_registered(_redraw_rendered_viewports):
        bpy.app.timers.unregister(_redraw_rendered_viewports)
    for cls in _added_to:
        cls.COMPAT_ENGINES.discard(ENGINE_ID)
    _added_to.clear()
    if SDLRenderEngine.is_registered:
        bpy.utils.unregister_class(SDLRenderEngine)
