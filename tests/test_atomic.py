"""tracer.atomic.replacing: the target is all new or all old, never half; files get the user's permissions."""
from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from tracer.atomic import replacing
from tracer.imageio import save_image


def test_success_replaces_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "scene.sdl"
    target.write_text("old")
    with replacing(target) as temp:
        assert temp.parent == tmp_path and temp.exists() and temp != target
        temp.write_text("new")
        assert target.read_text() == "old"  # not visible until the block ends
    assert target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.sdl"]


def test_failure_keeps_the_old_file_and_removes_the_temporary(tmp_path):
    target = tmp_path / "scene.sdl"
    target.write_text("old")
    with pytest.raises(KeyboardInterrupt):  # a cancel is an error too
        with replacing(target) as temp:
            temp.write_text("half")
            raise KeyboardInterrupt
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.sdl"]


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_new_files_get_the_umask_permissions_not_private_ones(tmp_path, umask):
    previous = os.umask(umask)
    try:
        save_image(np.zeros((2, 2, 3)), tmp_path / "x.png")
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / "x.png").stat().st_mode) == 0o666 & ~umask


def test_a_missing_folder_is_named_not_the_temporary(tmp_path):
    from tracer.errors import TracerError

    with pytest.raises(TracerError, match=r"x\.sdl: folder .*nowhere.* does not exist"):
        with replacing(tmp_path / "nowhere" / "x.sdl"):
            pass
