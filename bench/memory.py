"""Peak memory of a render against the size of one full frame (``make bench`` runs it).

Each size is rendered by the command line in a fresh Python process that reports its own peak resident set
size; a process that only imports the tracer gives the baseline.  The command line keeps each tile's 8-bit
values (3 bytes a pixel) and hands their rows to Pillow's image (4 bytes a pixel) as it writes, so the peak
above the baseline should stay near 4 bytes a pixel, a third of one float32 frame (12 bytes a pixel),
however large the image is.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SIZES = ((960, 540), (1920, 1080), (3840, 2160))

_CHILD = """
import resource, sys
import numpy, PIL.Image, tracer, tracer.cli, tracer.native
if sys.argv[1:]:
    status = tracer.cli.main(sys.argv[1:])
    if status:
        raise SystemExit(status)
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
"""


def peak_bytes(args: list[str]) -> int:
    done = subprocess.run([sys.executable, "-c", _CHILD, *args], cwd=ROOT, capture_output=True, text=True,
                          check=True)
    return int(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="scenes/lecture.sdl")
    parser.add_argument("--output", default=str(ROOT / "bench" / "results" / "memory.json"))
    args = parser.parse_args()

    baseline = peak_bytes([])
    rows = []
    for width, height in SIZES:
        image = Path("/tmp") / f"sdl-tracer-memory-{width}x{height}.png"
        peak = peak_bytes(["render", args.scene, "-o", str(image), "--width", str(width), "--height", str(height),
                           "-q"])
        image.unlink(missing_ok=True)
        frame = width * height * 3 * 4  # one float32 RGB film
        rows.append({"width": width, "height": height, "peak_mib": peak / 2**20,
                     "above_baseline_mib": (peak - baseline) / 2**20, "frame_mib": frame / 2**20,
                     "frames": (peak - baseline) / frame})
        print(f"{width}x{height}: peak {peak / 2**20:.0f} MiB, {(peak - baseline) / 2**20:.0f} MiB above the "
              f"imports ({baseline / 2**20:.0f} MiB) = {rows[-1]['frames']:.2f} float32 frames of "
              f"{frame / 2**20:.0f} MiB")
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    Path(args.output).write_text(json.dumps({"scene": args.scene, "baseline_mib": baseline / 2**20,
                                             "sizes": rows}, indent=2) + "\n")


if __name__ == "__main__":
    main()
