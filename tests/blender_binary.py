"""Running a real ``blender`` binary from the tests (shared by test_addon_blender_cli and
test_addon_render_script)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

BLENDER = shutil.which("blender")


def blender_numpy_path(blender: str, tmp_path) -> str:
    """A folder to put on Blender's sys.path ("" if none is needed): Debian's blender runs the system
    Python, which has no NumPy unless python3-numpy is installed; this interpreter's NumPy serves when both
    are the same Python version."""
    probe = subprocess.run([blender, "-b", "--factory-startup", "--python-expr",
                            "import sys\ntry:\n import numpy; print('NUMPY-OK')\nexcept ImportError:\n"
                            " print('PYVER', sys.version_info[0], sys.version_info[1])"],
                           capture_output=True, text=True, timeout=120)
    if "NUMPY-OK" in probe.stdout:
        return ""
    import numpy

    version = f"PYVER {sys.version_info[0]} {sys.version_info[1]}"
    assert version in probe.stdout, f"Blender's Python has no NumPy and is not this Python ({version}): " \
                                    "install NumPy for it (Debian: apt-get install python3-numpy)"
    site = tmp_path / "site"
    site.mkdir()
    source = os.path.dirname(os.path.dirname(numpy.__file__))
    for name in os.listdir(source):
        if name == "numpy" or name.startswith("numpy.libs") or name.startswith("numpy-"):
            os.symlink(os.path.join(source, name), site / name)
    return str(site)
