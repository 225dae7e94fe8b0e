"""Run the command line on one hostile input in a child process, under limits, and judge what came out.

The promise being checked (README, "Errors in the input"): the program either writes an image and exits 0,
or prints exactly one ``error:`` line that names a file (or the option) at fault and exits 2.  Any
traceback, signal, hang, run over the memory budget, raw library warning or other stray line on stderr is a
failure, reported with the kind below.
"""
from __future__ import annotations

import os
import re
import resource
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence

REPO = Path(__file__).resolve().parents[2]

#: Under AddressSanitizer (make sanitize preloads it) the C core's memory is shadowed and its code slower:
#: address-space limits would stop ASan itself from starting, so only the peak resident size is judged, and
#: the time and memory budgets are doubled.
SANITIZED = "libasan" in os.environ.get("LD_PRELOAD", "")
#: A run that takes more CPU seconds than this is a hang (the inputs are tiny and the images 32 x 24).
HANG_SECONDS = 20.0 * (2 if SANITIZED else 1)
#: ... and one still running after this many times as long in wall-clock time (blocked, say) is killed.
WALL_FACTOR = 5
#: An error line longer than this echoes the input instead of describing it (tracer.reporting cuts at 600).
MAX_ERROR_LINE = 700
#: Peak resident memory above which a run counts as over budget.
MEMORY_BYTES = (2 << 30) * (2 if SANITIZED else 1)

# Verdicts that keep the promise; every other verdict is a failure of that name.
GOOD = ("image", "error")
FAILURES = ("traceback", "signal", "hang", "memory", "bad-exit", "bad-error", "stray-output")

_ERROR_LINE = re.compile(r"^error: \S.*")
_WARNING_LINE = re.compile(r"^warning: \S.*")


@dataclass
class Outcome:
    verdict: str
    returncode: Optional[int]
    stderr: str
    seconds: float
    peak_bytes: int
    detail: str = ""
    args: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.verdict in GOOD

    def describe(self) -> str:
        tail = self.stderr.strip().splitlines()[-3:]
        return (f"{self.verdict} (exit {self.returncode}, {self.seconds:.1f} s, "
                f"{self.peak_bytes / 2**20:.0f} MiB){': ' + self.detail if self.detail else ''}\n"
                f"  args: {' '.join(map(str, self.args))}\n  stderr tail: {tail}")


def set_memory_limit(memory_bytes: int) -> None:
    """In a child: a backstop a little above the budget, which ru_maxrss then judges exactly.  RLIMIT_DATA
    counts the heap and private anonymous mappings (NumPy arrays, thread stacks), not shared libraries."""
    if not SANITIZED:
        limit = memory_bytes + (1 << 30)
        resource.setrlimit(resource.RLIMIT_DATA, (limit, limit))


def _limit_child(memory_bytes: int, cpu_seconds: float):
    def apply():
        os.setsid()  # its own process group, so a hang can be killed with every thread and child
        set_memory_limit(memory_bytes)
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        # CPU seconds decide a hang (a loaded machine may keep a run waiting for a core); the parent kills
        # what is still there after WALL_FACTOR times as long in wall-clock time (a read blocked on a FIFO).
        cpu = max(1, int(cpu_seconds))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 5))
    return apply


def run_cli(args: Sequence, *, output: Optional[Path] = None, names: Sequence[str] = (),
            timeout: float = HANG_SECONDS, memory_bytes: int = MEMORY_BYTES, cwd: Optional[Path] = None,
            env: Optional[dict] = None) -> Outcome:
    """Run ``python -m tracer ARGS`` and judge it.

    ``output`` is the image a successful run must leave; ``names`` are the strings of which an ``error:``
    line must contain one (the input's file names, or an option).
    """
    args = [str(a) for a in args]
    child_env = dict(os.environ if env is None else env)
    child_env.setdefault("SDL_TRACER_THREADS", "2")
    child_env["PYTHONPATH"] = str(REPO) + os.pathsep + child_env.get("PYTHONPATH", "")
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        start = time.monotonic()
        proc = subprocess.Popen([sys.executable, "-m", "tracer", *args], stdout=out, stderr=err,
                                stdin=subprocess.DEVNULL, cwd=cwd, env=child_env,
                                preexec_fn=_limit_child(memory_bytes, timeout))
        hung = threading.Event()

        def kill():
            hung.set()
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

        timer = threading.Timer(WALL_FACTOR * timeout, kill)
        timer.start()
        try:
            _, status, usage = os.wait4(proc.pid, 0)
        finally:
            timer.cancel()
        proc.returncode = os.waitstatus_to_exitcode(status)
        seconds = time.monotonic() - start
        err.seek(0)
        stderr = err.read().decode("utf-8", "replace")
    return judge(Outcome("", proc.returncode, stderr, seconds, usage.ru_maxrss * 1024, args=args),
                 hung.is_set(), output, names, memory_bytes)


def judge(outcome: Outcome, hung: bool, output: Optional[Path] = None, names: Sequence[str] = (),
          memory_bytes: int = MEMORY_BYTES) -> Outcome:
    """Fill in ``outcome.verdict`` and ``outcome.detail`` from how the run ended."""
    outcome.verdict, outcome.detail = _verdict(outcome, hung, output, names, memory_bytes)
    return outcome


def _verdict(o: Outcome, hung: bool, output: Optional[Path], names: Sequence[str], memory_bytes: int):
    if hung or o.returncode in (-signal.SIGXCPU, -signal.SIGKILL):
        return "hang", f"stopped after {o.seconds:.0f} s"
    if "Traceback (most recent call last)" in o.stderr:
        return "traceback", o.stderr.strip().splitlines()[-1]
    if o.returncode < 0:
        return "signal", signal.Signals(-o.returncode).name
    if o.peak_bytes > memory_bytes or "MemoryError" in o.stderr:
        return "memory", f"peak {o.peak_bytes / 2**20:.0f} MiB"
    lines = [line for line in o.stderr.splitlines() if line.strip()]
    stray = [line for line in lines if not (_ERROR_LINE.match(line) or _WARNING_LINE.match(line))]
    if stray:
        return "stray-output", stray[0][:200]
    errors = [line for line in lines if line.startswith("error:")]
    if o.returncode == 0:
        if errors:
            return "bad-error", "exit 0 with an error line"
        if output is not None and not (output.is_file() and output.stat().st_size > 0):
            return "bad-exit", "exit 0 without an image"
        return "image", ""
    if o.returncode == 2:
        if len(errors) != 1:
            return "bad-error", f"{len(errors)} error lines"
        if len(errors[0]) > MAX_ERROR_LINE:
            return "bad-error", f"error line of {len(errors[0])} characters"
        if names and not any(name in errors[0] for name in names):
            return "bad-error", f"error line names none of {list(names)}: {errors[0][:200]}"
        return "error", errors[0]
    return "bad-exit", f"exit status {o.returncode}"
