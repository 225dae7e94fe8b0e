"""How many threads a render uses unless told: $SDL_TRACER_THREADS if set, else every core this process may
run on.  Its own module, so that asking (the add-on's settings, a Dask worker) loads no C core."""
from __future__ import annotations

import os

#: The environment variable that sets the default.
THREADS_VARIABLE = "SDL_TRACER_THREADS"


def default_threads() -> int:
    """$SDL_TRACER_THREADS if set (and a number), else every core this process may run on."""
    env = os.environ.get(THREADS_VARIABLE)
    if env:
        try:
            return max(1, int(env))
        except ValueError:
            pass
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)
