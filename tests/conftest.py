"""Shared fixtures.

``backend``: a test that takes it runs once per backend, "c" and "numpy" (named explicitly, never
"auto", so that a fallback cannot hide which one ran).  The "c" variant skips, with the loader's reason, only
where the C core cannot be built; tests/test_native.py fails where a compiler exists and it does not build.
helpers.scaled(backend, width, height) gives the NumPy variant a smaller image.
"""
import signal
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

# Tests send SIGINT to the programs they start, as a terminal's Ctrl-C would.  A test run started in the
# background (`make test &`, `nohup ... &`) has SIGINT ignored, and its children would inherit that (the
# program keeps an ignored SIGINT, as a shell's `cmd &` asks): a Python handler here makes theirs the default.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

BACKEND_NAMES = ("c", "numpy")


@pytest.fixture(params=BACKEND_NAMES)
def backend(request) -> str:
    if request.param == "c":
        from tracer import native
        if native.load_error is not None:
            pytest.skip(f"C core not available: {native.load_error}")
    return request.param

