"""Blender-built scenes by SDL_RAYTRACER against Cycles set up as a Whitted tracer, at a size and sample count
beyond the test's (tests/test_addon_cycles.py runs 160 x 120 at 32 samples):

    python bench/blender_cycles.py [--size 640x480] [--samples 128] [--out DIR]

For each scene of tests/blender_scripts/cycles_scenes.py (the issue-23 point-light scene; sun, spot and area
lights): each object's and the background's mean colour as Blender's Standard view shows it (0..255) by
both engines and the largest channel difference, the rays traced, and each engine's render time (CPU
seconds of this process: both render here).  Writes DIR/blender_cycles.json (default bench/results) and
DIR/SCENE.png: Cycles' picture left, the tracer's right.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", default="640x480")
    parser.add_argument("--samples", type=int, default=128)
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    import bpy
    import numpy as np

    from addon import engine
    from blender_scripts import cycles_scenes
    from blender_scripts.addon_env import render_rgba

    args.out.mkdir(parents=True, exist_ok=True)
    results = {"size": [width, height], "samples": args.samples, "blender": bpy.app.version_string, "scenes": {}}
    for name, make, mirrors in (("point light", cycles_scenes.point_light_scene, ()),
                                ("sun, spot, area", cycles_scenes.soft_lights_scene, ("mirror",))):
        objects = make()
        started = time.process_time()
        result = cycles_scenes.compare(objects, width, height, args.samples, lights_unseen=mirrors)
        result["seconds_cpu_both"] = round(time.process_time() - started, 1)
        # the two pictures, side by side (rendered again: compare keeps only the means)
        cycles_scenes.set_up_cycles(args.samples)
        started = time.process_time()
        left = cycles_scenes.shown(render_rgba("CYCLES")[..., :3])
        result["seconds_cpu_cycles"] = round(time.process_time() - started, 1)
        started = time.process_time()
        right = cycles_scenes.shown(render_rgba(engine.ENGINE_ID)[..., :3])
        result["seconds_cpu_tracer"] = round(time.process_time() - started, 1)
        picture = np.concatenate([left, right], axis=1).round().astype(np.uint8)
        _save_png(picture, args.out / f"blender_cycles_{name.replace(', ', '_').replace(' ', '_')}.png")
        results["scenes"][name] = result
        print(name, {k: v["difference"] for k, v in result["regions"].items()}, flush=True)
    text = json.dumps(results, indent=1)
    (args.out / "blender_cycles.json").write_text(text + "\n")
    print(text)


def _save_png(rgb, path: Path) -> None:
    from addon.tracer.imageio import save_image

    save_image(rgb, path)  # (uint8: written as they are)


if __name__ == "__main__":
    main()
