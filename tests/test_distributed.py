"""Rendering on a Dask cluster (tracer.distributed, ``render --scheduler``), on loopback only: the same bytes as
the local render, a worker killed mid-render, an unreachable scheduler, a scene a worker cannot read, a
USD frame sequence.  Images are small; one two-worker LocalCluster serves the library-level tests."""
from __future__ import annotations

import dataclasses
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest
from PIL import Image

import tracer
from tracer import distributed as dist
from tracer.errors import TracerError

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
#: Bounds a hang, never a speed: connecting to nothing waits for Dask's connect timeout (set to 3 s here).
PROCESS_LIMIT = 120
#: (read before this module starts a cluster: Dask's nanny writes its workers' variables into this process too)
MALLOC_TRIM_AT_START = os.environ.get("MALLOC_TRIM_THRESHOLD_")


def _children() -> list:
    """This process's children, less multiprocessing's resource tracker (started with the first spawned
    process, it lives as long as this process does and leaks nothing)."""
    found = []
    for child in psutil.Process().children(recursive=True):
        try:
            if "resource_tracker" not in " ".join(child.cmdline()):
                found.append(child)
        except psutil.NoSuchProcess:
            pass
    return found


@pytest.fixture(scope="module")
def client():
    """A LocalCluster of two worker processes; afterwards no process of it may be left behind."""
    before = {p.pid for p in _children()}
    with dist.connect("local:2") as c:
        c.wait_for_workers(2, timeout=60)
        yield c
    deadline = time.monotonic() + 30
    while {p.pid for p in _children()} - before and time.monotonic() < deadline:
        time.sleep(0.2)
    assert {p.pid for p in _children()} - before == set()


def _cluster_render(client, path, job, times=(None,), on_tile=None, eight_bit=False):
    scene = dist.read_scene(path, time=times[0])
    frames = {}
    dist.render_frames(client, dist.SceneBundle.of(path, scene), job, list(times),
                       lambda i, image, rays, backend: frames.__setitem__(i, (image, rays)), on_tile,
                       eight_bit=eight_bit)
    return [frames[i] for i in range(len(times))]


def _local_render(path, job, time=None, eight_bit=False):
    return tracer.render(dist.read_scene(path, time=time), job.width, job.height, block_size=job.block_size,
                         progressive=job.progressive, tile=job.tile, samples=job.samples,
                         sampling_mode=job.sampling_mode, seed=job.seed,
                         eight_bit=eight_bit)


@pytest.mark.parametrize("eight_bit", [False, True])
@pytest.mark.parametrize("job", [
    dist.Job(64, 48, samples=4, tile=16),  # jittered
    dist.Job(64, 48, samples=4, sampling_mode="adaptive", tile=16),
    dist.Job(50, 30, block_size=8, progressive=True, tile=16),
])
def test_cluster_render_equals_local_bytes(client, job, eight_bit):
    """The float image, or (as the command line keeps it) its 8-bit values with each tile converted as it
    arrives, is the local render's."""
    [(image, rays)] = _cluster_render(client, SCENES / "glass.sdl", job, eight_bit=eight_bit)
    local = _local_render(SCENES / "glass.sdl", job, eight_bit=eight_bit)
    assert image.dtype == (np.uint8 if eight_bit else np.float32)
    assert image.any() and np.array_equal(image, local.image)
    assert rays == local.rays  # each pixel traced once (no tile lost or doubled), the same rays skipped


def test_every_file_the_scene_reads_goes_to_the_workers(client, tmp_path):
    """textures.sdl reads pixmaps (and a copy of the scene elsewhere still finds them through the bundle)."""
    job = dist.Job(40, 30, samples=1, tile=16)
    scene = tracer.load(SCENES / "textures.sdl")
    bundle = dist.SceneBundle.of(SCENES / "textures.sdl", scene)
    assert bundle.scene == "textures.sdl" and len(bundle.files) == 1 + len(set(scene.pixmaps.values()))
    [(image, _)] = _cluster_render(client, SCENES / "textures.sdl", job)
    assert np.array_equal(image, _local_render(SCENES / "textures.sdl", job).image)


def test_a_worker_killed_mid_render_loses_nothing(client):
    job = dist.Job(96, 72, samples=16, tile=8)
    pids = client.run(os.getpid)
    victim = sorted(pids.values())[0]
    arrived_after_kill = []

    def on_tile(update):
        if arrived_after_kill or update.tiles_done == 1:
            if not arrived_after_kill:
                os.kill(victim, signal.SIGKILL)
            arrived_after_kill.append(update.tiles_done)

    [(image, rays)] = _cluster_render(client, SCENES / "glass.sdl", job, on_tile=on_tile)
    local = _local_render(SCENES / "glass.sdl", job)
    assert len(arrived_after_kill) > 10  # the render went on after the kill, for most of its tiles
    assert not psutil.pid_exists(victim) or psutil.Process(victim).status() == psutil.STATUS_ZOMBIE
    assert np.array_equal(image, local.image)
    assert rays.camera == local.rays.camera


def test_local_workers_keep_glibcs_adaptive_allocator(client):
    """Dask's nanny puts MALLOC_TRIM_THRESHOLD_ into its workers' environment (and its own), which turns off
    glibc's adaptive mmap threshold: every temporary array of a tile's rays is then mapped and faulted in
    anew, and a worker spent a fifth of its time in the kernel.  A local:N cluster leaves the variable as this
    process had it before any cluster started."""
    def workers(name):  # (a lambda: a bound os.environ.get would travel with this process's environment)
        return set(client.run(lambda: os.environ.get(name)).values())

    assert workers("MALLOC_TRIM_THRESHOLD_") == {MALLOC_TRIM_AT_START}
    assert os.environ.get("MALLOC_TRIM_THRESHOLD_") == MALLOC_TRIM_AT_START
    assert workers("OMP_NUM_THREADS") == {"1"}  # (the rest of Dask's list stays)


def test_a_scene_a_worker_cannot_read_is_reported_once(client):
    path = SCENES / "glass.sdl"
    bundle = dist.SceneBundle.of(path, tracer.load(path))
    broken = dataclasses.replace(bundle, files={**bundle.files, bundle.scene: b"sphere sphere 12 {"},
                                 digest="broken-" + bundle.digest)
    with pytest.raises(TracerError) as caught:
        dist.render_frames(client, broken, dist.Job(32, 24, tile=8), [None], lambda *a: None)
    message = str(caught.value)
    assert message.startswith("worker tcp://127.0.0.1:") and "glass.sdl:1:" in message
    assert "\n" not in message and "sdl-scene-" not in message  # the user's file name, not the worker's copy
    assert client.submit(sum, [1, 2]).result(timeout=30) == 3  # the cluster is not left jammed


def _run(*args, env=None):
    return subprocess.run([sys.executable, "-m", "tracer", *map(str, args)], capture_output=True, text=True,
                          timeout=PROCESS_LIMIT, env={**os.environ, **(env or {})}, cwd=ROOT)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_unreachable_scheduler_is_one_line_and_exit_2(tmp_path):
    out = tmp_path / "x.png"
    done = _run("render", SCENES / "lecture.sdl", "-o", out, "--width", 16, "--height", 12,
                "--scheduler", f"tcp://127.0.0.1:{_free_port()}",
                env={"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "3s"})
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith("error: --scheduler tcp://127.0.0.1:") and done.stderr.count("\n") == 1
    assert "cannot reach the scheduler" in done.stderr and not out.exists()


def test_a_scheduler_without_workers_is_one_line_not_a_wait(tmp_path):
    address = f"tcp://127.0.0.1:{_free_port()}"
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", address.rsplit(":", 1)[1], "--no-dashboard"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        done = _run("render", SCENES / "lecture.sdl", "-o", tmp_path / "x.png", "--width", 16, "--height", 12,
                    "--scheduler", address, env={"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "20s"})
    finally:
        scheduler.terminate()
        scheduler.wait(timeout=30)
    assert done.returncode == 2, done.stderr
    assert done.stderr == f"error: --scheduler {address}: no worker joined the scheduler within 20s\n"
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("address, what", [("local:0", "local:N"), ("nonsense", "tcp://HOST:8786")])
def test_bad_scheduler_addresses(tmp_path, address, what):
    done = _run("render", SCENES / "lecture.sdl", "-o", tmp_path / "x.png", "--scheduler", address)
    assert done.returncode == 2 and done.stderr.startswith("error: --scheduler") and what in done.stderr


def test_without_dask_scheduler_says_how_to_install_it(tmp_path):
    code = ("import sys; sys.modules['distributed'] = None\n"  # what an environment without it gives
            "from tracer.cli import main\n"
            f"sys.exit(main(['render', {str(SCENES / 'lecture.sdl')!r}, '-o', {str(tmp_path / 'x.png')!r}, "
            "'--scheduler', 'local:2']))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=PROCESS_LIMIT)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "pip install 'sdl-raytracer[distributed]'" in done.stderr


ANIMATED_STAGE = """#usda 1.0
(
    defaultPrim = "World"
    upAxis = "Y"
    subLayers = [@motion.usda@]
    startTimeCode = 1
    endTimeCode = 3
)

def Xform "World"
{
    def Sphere "Ball"
    {
        double radius = 0.5
        color3f[] primvars:displayColor = [(0.9, 0.3, 0.1)]
    }

    def Cube "Box"
    {
        double size = 1
        double3 xformOp:translate = (-1.2, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }

    def SphereLight "Lamp"
    {
        float inputs:intensity = 1
        double3 xformOp:translate = (3, 4, 5)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }

    def Camera "Camera"
    {
        float focalLength = 35
        float verticalAperture = 24
        double3 xformOp:translate = (0, 0.5, 6)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
}
"""

MOTION_LAYER = """#usda 1.0

over "World"
{
    over "Ball"
    {
        double3 xformOp:translate.timeSamples = {
            1: (0.5, 0, 0),
            3: (1.5, 1, 0),
        }
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
}
"""


def test_a_frame_sequence_on_the_cluster_equals_the_local_frames(tmp_path):
    """--frames on a stage whose motion is in a sublayer: one image per frame, the ball moves, and the
    cluster (which gets the sublayer in the bundle) writes the local bytes."""
    stage = tmp_path / "stage" / "shot.usda"
    stage.parent.mkdir()
    stage.write_text(ANIMATED_STAGE)
    (stage.parent / "motion.usda").write_text(MOTION_LAYER)
    assert sorted(dist.SceneBundle.of(stage, dist.read_scene(stage)).files) == ["motion.usda", "shot.usda"]
    (tmp_path / "local").mkdir()
    (tmp_path / "cluster").mkdir()
    common = ["--width", 40, "--height", 30, "--samples", 4, "--frames", "1-3", "-q"]
    local = _run("render", stage, "-o", tmp_path / "local" / "f.png", *common)
    assert local.returncode == 0, local.stderr
    cluster = _run("render", stage, "-o", tmp_path / "cluster" / "f.png", *common, "--scheduler", "local:2")
    assert cluster.returncode == 0, cluster.stderr
    names = ["f_0001.png", "f_0002.png", "f_0003.png"]
    assert sorted(p.name for p in (tmp_path / "local").iterdir()) == names
    assert sorted(p.name for p in (tmp_path / "cluster").iterdir()) == names
    images = [np.asarray(Image.open(tmp_path / "local" / n)) for n in names]
    for name in names:
        assert (tmp_path / "local" / name).read_bytes() == (tmp_path / "cluster" / name).read_bytes()
    assert np.abs(images[0].astype(int) - images[2]).max() > 100  # the ball moved between frames 1 and 3
    assert not np.array_equal(images[0], images[1]) and not np.array_equal(images[1], images[2])


def test_frames_need_a_usd_stage(tmp_path):
    done = _run("render", SCENES / "lecture.sdl", "-o", tmp_path / "x.png", "--frames", "1-2")
    assert done.returncode == 2 and "frames need a USD stage" in done.stderr and done.stderr.count("\n") == 1
    done = _run("render", SCENES / "lecture.sdl", "-o", tmp_path / "x.png", "--frames", "3-1")
    assert done.returncode == 2 and "--frames 3-1" in done.stderr


def _certificates(folder: Path) -> dict:
    """A CA and one certificate for 127.0.0.1 signed by it (scheduler, worker and client share it)."""
    (folder / "ext.cnf").write_text("subjectAltName = IP:127.0.0.1, DNS:localhost\n")

    def openssl(*args):
        subprocess.run(["openssl", *args], cwd=folder, check=True, capture_output=True, timeout=PROCESS_LIMIT)

    openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out", "ca.pem", "-days", "2",
            "-subj", "/CN=test-ca")
    openssl("req", "-newkey", "rsa:2048", "-nodes", "-keyout", "node.key", "-out", "node.csr", "-subj", "/CN=localhost")
    openssl("x509", "-req", "-in", "node.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
            "-out", "node.pem", "-days", "2", "-extfile", "ext.cnf")
    return {name: str(folder / name) for name in ("ca.pem", "node.pem", "node.key")}


@pytest.mark.skipif(shutil.which("openssl") is None, reason="makes its certificates with the openssl command")
def test_tls_scheduler_with_dasks_own_security_settings(tmp_path):
    """A scheduler and a worker that speak only TLS: render reads the client's certificate from Dask's
    configuration (here its environment variables) and gets the local bytes; without it, one line."""
    certs = _certificates(tmp_path)
    tls = ["--tls-ca-file", certs["ca.pem"], "--tls-cert", certs["node.pem"], "--tls-key", certs["node.key"]]
    address = f"tls://127.0.0.1:{_free_port()}"
    port = address.rsplit(":", 1)[1]
    started = []
    try:
        started.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--protocol", "tls",
                                         "--host", "127.0.0.1", "--port", port, "--no-dashboard", *tls],
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        started.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads",
                                         "1", "--no-dashboard", *tls],
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        settings = {"DASK_DISTRIBUTED__COMM__TLS__CA_FILE": certs["ca.pem"],
                    "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT": certs["node.pem"],
                    "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY": certs["node.key"],
                    "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "60s"}  # (the scheduler may still be starting)
        args = ["render", SCENES / "glass.sdl", "--width", 40, "--height", 30, "--samples", 4, "-q"]
        done = _run(*args, "-o", tmp_path / "tls.png", "--scheduler", address, env=settings)
        assert done.returncode == 0, done.stderr
        assert _run(*args, "-o", tmp_path / "local.png").returncode == 0
        assert (tmp_path / "tls.png").read_bytes() == (tmp_path / "local.png").read_bytes()
        plain = _run(*args, "-o", tmp_path / "x.png", "--scheduler", address)
        assert plain.returncode == 2 and "TLS needs Dask's TLS settings" in plain.stderr
        assert plain.stderr.count("\n") == 1 and not (tmp_path / "x.png").exists()
    finally:
        for process in reversed(started):
            process.terminate()
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


def test_ctrl_c_to_the_process_group_is_one_line_and_exit_130(tmp_path):
    """A terminal's Ctrl-C reaches every process of the group, the LocalCluster's workers too: the render must
    still stop with its one line, no worker's traceback or log, no image and no process left behind."""
    out = tmp_path / "big.png"
    command = [sys.executable, "-m", "tracer", "render", str(SCENES / "glass.sdl"), "-o", str(out), "--width",
               "3000", "--height", "2000", "--samples", "16", "--scheduler", "local:2", "-q"]
    render = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              start_new_session=True)
    try:
        leader = psutil.Process(render.pid)
        deadline = time.monotonic() + PROCESS_LIMIT
        workers = []
        while len(workers) < 2 and render.poll() is None and time.monotonic() < deadline:
            workers = [p for p in leader.children(recursive=True)
                       if "resource_tracker" not in " ".join(p.cmdline())]
            time.sleep(0.2)
        assert len(workers) >= 2, "the cluster's workers never started"
        # Tiles reach the workers only once the cluster is up (a Ctrl-C while it starts is not seen): wait
        # until one worker has spent more CPU than starting takes, i.e. it is tracing.
        while max(sum(p.cpu_times()[:2]) for p in workers) < 4 and render.poll() is None \
                and time.monotonic() < deadline:
            time.sleep(0.2)
        assert render.poll() is None, "the render ended before its workers were tracing: make it larger"
        os.killpg(render.pid, signal.SIGINT)
        _, stderr = render.communicate(timeout=PROCESS_LIMIT)
    finally:
        if render.poll() is None:
            os.killpg(render.pid, signal.SIGKILL)
            render.wait()
    assert render.returncode == 130, stderr
    assert [line for line in stderr.splitlines() if line.strip()] == ["interrupted"], stderr
    assert not out.exists()
    assert not [p for p in workers if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]


#: The numbers of an accuracy summary that are measured, not computed from images and ray counts.
TIMINGS = {"seconds_median", "seconds_iqr", "cpu_median", "cpu_iqr", "compile_median", "trace_median",
           "pareto_seconds", "seconds", "seconds_all", "seconds_with", "iqr_all", "iqr_with", "cpu_all", "cpu_with",
           "cpu_iqr_all", "cpu_iqr_with", "cpu_mean", "cpu_sd"}


def _without_timings(value):
    if isinstance(value, dict):
        return {k: _without_timings(v) for k, v in value.items() if k not in TIMINGS}
    if isinstance(value, list):
        return [_without_timings(v) for v in value]
    return value


def test_an_accuracy_sweep_on_the_cluster_equals_the_local_sweep(client, tmp_path):
    """bench accuracy --scheduler: every render of the sweep is a task that carries its setting (depth, solver
    tolerances, ray savings, seed) to a worker, which reads the scene once from the bundle; errors, rays,
    slopes, fronts, targets and the cost to reach them equal the local sweep's, and the progress lines come in order."""
    from tracer.accuracy import BenchConfig, measure

    path = SCENES / "shapes.sdl"  # a torus (its Newton steps are swept), mirrors, shadows
    config = BenchConfig(width=16, height=12, reference_samples=8, seeds=3, sample_counts=(4, 16),
                         targets=(0.05,), savings_size=(16, 12), savings_runs=1)
    local = measure(tracer.load(path), "local", tmp_path / "local", config, progress=lambda _: None)
    lines = []
    scene = tracer.load(path)
    cluster = measure(scene, "cluster", tmp_path / "cluster", dataclasses.replace(config, threads=1),
                      progress=lines.append, run_tasks=dist.SceneTasks(client, dist.SceneBundle.of(path, scene)))
    assert _without_timings({**cluster, "scene": "local"}) == _without_timings(local)
    assert [line.split(" (")[0] for line in lines[1:5]] == \
        [f"  reference: estimated RMSE {local['reference']['estimated_rmse']:.2e}", "  round 1/3 done",
         "  round 2/3 done", "  round 3/3 done"]
    assert (tmp_path / "cluster" / "cluster.csv").is_file() and (tmp_path / "cluster" / "cluster.png").is_file()


def test_a_settings_solver_tolerances_travel_with_its_task(client):
    """A setting's tolerances are process-wide state only while its scene compiles: tasks of coarse and default
    tolerances, one after the other on the same workers, each give what they give locally (and the coarse
    one differs)."""
    from tracer.accuracy import BenchConfig, Setting, run_setting

    path = SCENES / "shapes.sdl"
    config = BenchConfig(width=16, height=12, threads=1)
    # (1e13 ulps, 1e-3 of every coordinate: offsets follow a hit point's distance from its surface, not its t
    # error, and 1e12 no longer moves a pixel of this image)
    default, coarse = Setting("baseline", "default"), Setting("hit error ulps", "coarse", hit_ulps=1e13)
    calls = [(run_setting, (setting, 0, config)) for setting in (default, coarse, default, coarse)]
    scene = tracer.load(path)
    arrived = []
    results = dist.SceneTasks(client, dist.SceneBundle.of(path, scene))(calls, lambda i, _: arrived.append(i))
    assert sorted(arrived) == [0, 1, 2, 3]
    here = [run_setting(scene, setting, 0, config) for setting in (default, coarse)]
    assert np.abs(here[1]["image"] - here[0]["image"]).max() > 0.01  # coarse bounds change this image
    for k, record in enumerate(results):
        assert np.array_equal(record["image"], here[k % 2]["image"]) and record["rays"] == here[k % 2]["rays"]


def test_bench_accuracy_with_a_scheduler_writes_the_local_numbers(tmp_path):
    """The command line: ``bench accuracy --scheduler local:2`` writes the CSV a local sweep writes, timings
    aside; a bad address is one line."""
    import csv

    common = [SCENES / "lecture.sdl", "--width", 8, "--height", 7, "--reference-samples", 4, "--seeds", 3]
    local = _run("bench", "accuracy", *common, "-o", tmp_path / "local")
    assert local.returncode == 0, local.stderr
    cluster = _run("bench", "accuracy", *common, "-o", tmp_path / "cluster", "--scheduler", "local:2")
    assert cluster.returncode == 0, cluster.stderr
    tables = []
    for folder in ("local", "cluster"):
        with open(tmp_path / folder / "lecture.csv") as handle:
            tables.append([{k: v for k, v in row.items() if k not in TIMINGS} for row in csv.DictReader(handle)])
    assert tables[0] == tables[1] and len(tables[0]) > 10
    assert (tmp_path / "cluster" / "report.md").is_file()
    bad = _run("bench", "accuracy", *common, "-o", tmp_path / "x", "--scheduler", "nonsense")
    assert bad.returncode == 2 and bad.stderr.startswith("error: --scheduler nonsense") and bad.stderr.count("\n") == 1
