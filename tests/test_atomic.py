"""tracer.atomic.replacing: the target is all new or all old, never half; files get the user's permissions."""
from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from tracer.atomic import replacing, writing
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


def test_a_name_of_any_valid_length_can_be_written(tmp_path):
    """A temporary name adds some 30 characters: a target already near the limit on a name (255 bytes) gets
    a temporary file whose name is cut short, never a "File name too long"."""
    limit = os.pathconf(tmp_path, "PC_NAME_MAX")
    for name in ("a" * (limit - 4) + ".png", "é" * ((limit - 4) // 2) + ".png"):
        target = tmp_path / name
        save_image(np.zeros((2, 2, 3)), target)
        with replacing(target, ".usda") as temp:
            assert len(os.fsencode(temp.name)) <= limit
            temp.write_text("usd")
        assert target.read_text() == "usd"
    assert len(list(tmp_path.iterdir())) == 2


def test_a_file_being_written_has_no_name_until_it_is_complete(tmp_path):
    target = tmp_path / "mesh.3vn"
    with writing(target, "w") as handle:
        handle.write("0 0 0\n")
        handle.flush()
        assert list(tmp_path.iterdir()) == []  # (on Linux: O_TMPFILE; elsewhere a named temporary file)
    assert target.read_text() == "0 0 0\n"
    assert list(tmp_path.iterdir()) == [target]


def test_a_killed_writers_temporary_file_is_removed_by_the_next_write(tmp_path):
    """A run killed between creating its named temporary file and renaming it leaves the file: the next write
    of the same target removes it (its process is gone), and leaves a live process's alone."""
    import subprocess
    import sys

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    target = tmp_path / "scene.usda"
    with replacing(target, ".usda") as temp:
        host = temp.name.split("@")[1]  # (this host's tag, and the suffix)
        temp.write_text("new")
    stale = tmp_path / f".scene.usda.0badf00d-{dead_pid}@{host}"
    live = tmp_path / f".scene.usda.0badf00d-{os.getppid()}@{host}"
    foreign = tmp_path / f".scene.usda.0badf00d-{dead_pid}@ffffff.usda"  # (another host's: its pid means nothing here)
    for path in (stale, live, foreign):
        path.write_text("half")
    with replacing(target, ".usda") as temp:
        temp.write_text("newer")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([target.name, live.name, foreign.name])
    assert target.read_text() == "newer"


def test_write_errors_name_the_file_written(tmp_path):
    from tracer.reporting import error_message

    target = tmp_path / "out.png"
    with pytest.raises(OSError) as caught:
        with writing(target) as handle:
            handle.write(b"x")
            raise OSError(28, "No space left on device")
    assert error_message(caught.value, "scene.sdl") == f"{target}: no space left on the device"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usd"])
def test_a_usd_write_killed_as_usd_core_finishes_leaves_only_the_old_file(tmp_path, suffix):
    """SIGKILL just after usd-core has written its file (the moment whose name it holds is fullest): the
    user's folder holds the old file and nothing else (usd-core names its file and a temporary of its own
    beside it, so they are made in a private folder elsewhere), and the next write removes that folder."""
    import signal
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    pytest.importorskip("pxr")
    target = tmp_path / f"scene{suffix}"
    target.write_text("old")
    code = ("import os, signal, sys\n"
            "from pxr import Sdf\n"
            "import tracer\n"
            "from tracer.usd import save_usd\n"
            "real_export, real_text = Sdf.Layer.Export, Sdf.Layer.ExportToString\n"
            "def export(self, *args, **kwargs):\n"
            "    real_export(self, *args, **kwargs)\n"
            "    os.kill(os.getpid(), signal.SIGKILL)\n"
            "def text(self):\n"
            "    real_text(self)\n"
            "    os.kill(os.getpid(), signal.SIGKILL)\n"
            "Sdf.Layer.Export, Sdf.Layer.ExportToString = export, text\n"
            "save_usd(tracer.parse_sdl('camera 0 0 6 0 0 0 0 1 0 40 sphere'), sys.argv[1])\n")
    child = subprocess.Popen([sys.executable, "-c", code, str(target)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    _, stderr = child.communicate(timeout=120)
    assert child.returncode == -signal.SIGKILL, stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name] and target.read_text() == "old"
    from tracer.atomic import PRIVATE_FOLDER, _process_gone
    import tracer
    from tracer.usd import save_usd

    def dead_folders():  # (the killed run's: another test run on this machine may have its own meanwhile)
        return [p for p in Path(tempfile.gettempdir()).iterdir()
                if PRIVATE_FOLDER.fullmatch(p.name) and int(PRIVATE_FOLDER.fullmatch(p.name)["pid"]) == child.pid
                and _process_gone(child.pid)]

    assert suffix == ".usda" or dead_folders()  # (the killed run's crate file: outside the user's folder)
    save_usd(tracer.parse_sdl("camera 0 0 6 0 0 0 0 1 0 40 sphere"), target)
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name] and target.read_bytes() != b"old"
    assert dead_folders() == []
