"""The NumPy path's batches (tracer/batches.py) against asking objects one by one, by rays per call.  CPU seconds of trace.first_hits and trace.occluded, each way,
interleaved in one run; the results are the same bits either way (tests/test_batches.py).

    python bench/numpy_batches.py                 # prints a table; --json FILE writes it
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import tracer  # noqa: E402
from tracer import batches  # noqa: E402
from tracer.compile import compile_scene  # noqa: E402
from tracer.trace import first_hits, occluded  # noqa: E402

SCENES = {
    # every ray meets every sphere, at t that differ by their rounding (ties)
    "2,048 coincident spheres": "\n".join(f"push rotate {i % 360} 1 2 3 sphere pop" for i in range(2048)),
    # each ray meets a few of them
    "4,096 scattered spheres": "\n".join(f"push translate {x} {y} 0 scale 0.1 0.1 0.1 sphere pop"
                                         for x in range(-32, 32) for y in range(-32, 32)),
    "64 planes": "\n".join(f"push translate 0 0 {-k} plane pop" for k in range(64)),
}


def _rays(count: int, rng) -> tuple[np.ndarray, np.ndarray]:
    origins = np.column_stack([rng.uniform(-3, 3, (count, 2)), np.full(count, 5.0)])
    return origins, np.tile([0.0, 0.0, -1.0], (count, 1))


def _cpu(call) -> float:
    start = time.process_time()
    call()
    return time.process_time() - start


def measure(counts: list[int]) -> list[dict]:
    rows = []
    rng = np.random.default_rng(1)
    for name, text in SCENES.items():
        compiled = compile_scene(tracer.parse_sdl("light 0 9 9 1 1 1\n" + text))
        for count in counts:
            origins, directions = _rays(count, rng)
            row = {"scene": name, "rays": count}
            for way, minimum in (("batched", 8), ("one by one", 10 ** 9)):
                batches.BATCH_MIN = minimum
                compiled.objects.forget_batches()
                row[f"first_hits {way}"] = round(_cpu(lambda: first_hits(compiled, origins, directions)), 3)
                row[f"occluded {way}"] = round(_cpu(lambda: occluded(compiled, origins, directions, 10.0)), 3)
            rows.append(row)
            print(row, flush=True)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--counts", default="64,256,1024,4096,16384")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    rows = measure([int(c) for c in args.counts.split(",")])
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
