"""Run add-on test files inside a real Blender (``blender -b``), with this interpreter's packages:

    blender -b --factory-startup --python run_tests.py -- ROOT SITE_PACKAGES TEST_FILE...

The add-on tests are written for the bpy module; here the same files run in Debian's Blender 3.4 (whose
Python has the same minor version, so the test environment's pytest, NumPy and Pillow load in it).
Prints ``PYTEST-EXIT <status>``.
"""
import sys

argv = sys.argv[sys.argv.index("--") + 1:]
root, site, files = argv[0], argv[1], argv[2:]
sys.path[:0] = [site, root, root + "/tests"]

import pytest  # noqa: E402

status = int(pytest.main(["-q", "-p", "no:cacheprovider", *files]))
print(f"PYTEST-EXIT {status}")
