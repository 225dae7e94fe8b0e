"""The fuzz run: mutated (mutate.py) and generated (generators.py) inputs through the command line, each in its
own process, judged by harness.judge (and, for a run sent a signal or the SDL readers' comparison, here).

    python tests/fuzz/fuzz.py --count 10000 --seed 1 --jobs 2     # what `make fuzz` runs
    python tests/fuzz/fuzz.py --only 4711                         # one case again, from its seed

Starting Python and importing NumPy, Pillow and USD for each of 10^4 inputs would take hours, so this
process imports the tracer once and forks a child per input: the child sets its limits (memory, no core
files), runs ``tracer.cli.main`` with stdout and stderr going to files, and exits with its status; an
exception that escapes is printed as Python prints it (a traceback) and exits 1, as the real command would.
The parent kills a child that runs past the hang limit.  Every failure is copied to ``--findings`` (its
files, options and stderr) to be turned into a regression file.  Valid scenes that rendered are, for a
slice of them (``--compare``), rendered again with the other backend and compared: C = NumPy within 1/255.

Prints a JSON summary on stdout; exits 1 if any input failed.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import random
import signal
import sys
import tempfile
import time
import traceback
from collections import Counter
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parents[1]))

from harness import (FAILURES, HANG_SECONDS, MEMORY_BYTES, WALL_FACTOR, Outcome, judge,  # noqa: E402
                     SANITIZED, set_memory_limit)
from generators import OLD_OUTPUT, differential_sdl, generated_case  # noqa: E402
from mutate import SCENES, Case, make_case  # noqa: E402

#: Image difference allowed between the backends (tracer's C = NumPy promise).
SAME_IMAGE = 1
#: A comparison whose second render (the slow NumPy path, mostly) ran out of time: counted apart, not judged.
SLOW = "too slow to compare"
#: The share of inputs made by tests/fuzz/generators.py (the rest are mutations of the bundled files).
GENERATED_SHARE = 0.5
#: How soon after SIGINT or SIGTERM a run must have ended (tests/test_signals.py holds a real process to 0.5 s;
#: here many runs share a loaded machine).
SIGNAL_LATENCY = 2.0
#: What a run's folder may hold besides its inputs and output.
HOUSEKEEPING = {"stdout", "stderr", "images", "meshes", "other.png"}


def case_for(seed: int, usd: bool = True):
    """The input of one seed: a generated one (generators.py) or a mutation (mutate.py), as a draw of its own
    decides (so a mutation's seed makes the same case as before generators were added)."""
    if random.Random(seed * 7919 + 1).random() < GENERATED_SHARE:
        return generated_case(seed, usd)
    return make_case(seed, usd)


def _child(argv: list[str], folder: Path, memory_bytes: int, cpu_seconds: float) -> None:
    """In the forked child: limits, redirections, the command; never returns."""
    code = 1
    try:
        os.setsid()
        set_memory_limit(memory_bytes)
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        # CPU seconds, not wall-clock ones, decide a hang: on a loaded machine a run may wait long for a core
        # (the parent still kills anything past WALL_FACTOR times the limit: a read blocked on a FIFO).
        cpu = max(1, int(cpu_seconds))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 5))
        from tracer import signals

        signal.signal(signal.SIGINT, signal.SIG_DFL)  # (a fuzz run started with `&` ignores SIGINT; its runs not)
        signals.install_at_start()  # (as the program does first: a signal before the command ends it at once)
        os.chdir(folder)
        for fd, name in ((1, "stdout"), (2, "stderr")):
            out = os.open(folder / name, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(out, fd)
            os.close(out)
        sys.stdout = open(1, "w", closefd=False)
        sys.stderr = open(2, "w", closefd=False)
        # The parent forked with both signals blocked (see Runner.start): one sent meanwhile is heard now.
        signal.pthread_sigmask(signal.SIG_UNBLOCK, signals.SIGNALS)
        if argv[0] == "differential-sdl":  # (generators.readers)
            code, detail = differential_sdl(argv[1], "--lenient" in argv)
            if detail:
                print(detail, file=sys.stderr)
        else:
            from tracer.cli import main

            code = main(argv)
    except SystemExit as exit_:
        code = exit_.code if isinstance(exit_.code, int) else 2
    except BaseException:  # what Python would print for an exception nobody caught
        traceback.print_exc()
        code = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


class Runner:
    """Up to ``jobs`` children at a time; finished ones collect in ``done`` as (token, Outcome, hung)."""

    def __init__(self, jobs: int, timeout: float, memory_bytes: int):
        self.jobs, self.timeout, self.memory_bytes = jobs, timeout, memory_bytes
        self.running: dict[int, tuple] = {}
        self.done: list = []

    def start(self, argv: list[str], folder: Path, token, cpu_seconds: float | None = None,
              signal_at: tuple[int, float] | None = None) -> None:
        """``signal_at``: (signal, seconds after the start) to send the child."""
        while len(self.running) >= self.jobs:
            self.done.append(self.wait_one())
        sys.stdout.flush()
        sys.stderr.flush()
        cpu_seconds = cpu_seconds or self.timeout
        # Forked with SIGINT and SIGTERM blocked, so that one sent before the child has installed the program's
        # handlers (on a loaded machine a child may wait 0.1 s for its first turn) waits for them instead of
        # meeting the fuzz run's own (a KeyboardInterrupt and its traceback, in no real run of the program).
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, (signal.SIGINT, signal.SIGTERM))
        pid = os.fork()
        if pid == 0:
            _child(argv, folder, self.memory_bytes, cpu_seconds)
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        self.running[pid] = (time.monotonic(), argv, folder, token, [False], cpu_seconds, [signal_at, None])

    def wait_one(self):
        """Reap one finished child (killing any past the limit meanwhile): (token, Outcome) or None."""
        while True:
            now = time.monotonic()
            for pid, (started, _, _, _, killed, cpu_seconds, sending) in self.running.items():
                if sending[0] is not None and sending[1] is None and now - started >= sending[0][1]:
                    sending[1] = now
                    try:
                        os.kill(pid, sending[0][0])
                    except ProcessLookupError:
                        pass
                if not killed[0] and now - started > WALL_FACTOR * cpu_seconds:
                    killed[0] = True
                    try:
                        os.killpg(pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
            for pid in self.running:  # only our own children (another Runner may have some running)
                pid, status, usage = os.wait4(pid, os.WNOHANG)
                if pid:
                    break
            else:
                time.sleep(0.01)
                continue
            started, argv, folder, token, killed, _, sending = self.running.pop(pid)
            ended = time.monotonic()
            stderr = (folder / "stderr").read_text("utf-8", "replace") if (folder / "stderr").exists() else ""
            code = os.waitstatus_to_exitcode(status)
            outcome = Outcome("", code, stderr, ended - started, usage.ru_maxrss * 1024, args=argv)
            outcome.signal_latency = None if sending[1] is None else ended - sending[1]
            return token, outcome, killed[0] or code in (-signal.SIGXCPU, -signal.SIGKILL)

    def drain(self):
        while self.running:
            self.done.append(self.wait_one())


def _compare_argv(case: Case) -> list[str]:
    """The command rendering a case again with the other backend, into other.png."""
    backend = "c" if "numpy" in case.options else "numpy"
    options = [o for i, o in enumerate(case.options) if o != "--backend" and case.options[i - 1:i] != ["--backend"]]
    return ["render", case.main, "-o", "other.png", *options, "--backend", backend]


def _output(case) -> str:
    return getattr(case, "output", "out.png")


def _compared(folder: Path, outcome: Outcome, hung: bool, output: str = "out.png"):
    """None if the output and other.png agree within SAME_IMAGE, else why not."""
    import numpy as np
    from PIL import Image

    other = folder / "other.png"
    if hung:
        return SLOW
    if outcome.returncode != 0 or not other.exists():
        return f"the other backend did not render it (exit {outcome.returncode}): {outcome.stderr[-300:]}"
    a = np.asarray(Image.open(folder / output).convert("RGB"), dtype=np.int16)
    b = np.asarray(Image.open(other).convert("RGB"), dtype=np.int16)
    worst = int(np.abs(a - b).max()) if a.shape == b.shape else 255
    return None if worst <= SAME_IMAGE else f"C and NumPy images differ by up to {worst}/255"


def _litter(folder: Path, case) -> list[str]:
    """What a run left in its folder besides its inputs, its output (convert's with the meshes an SDL file
    names: out_mesh1.3vn, ...) and the harness's files."""
    expected = set(case.files) | HOUSEKEEPING | {_output(case), "out.sdl", "out.usda"}
    return sorted(p.name for p in folder.iterdir()
                  if p.name not in expected and not (case.command == "convert" and p.name.startswith("out_")))


def _judge_signal(case, outcome: Outcome, folder: Path) -> None:
    """A run sent a signal (generators.interrupt, kill): it ended by the signal's status (or finished first),
    soon, saying "interrupted" (when it ended by its own hand: 128 + the signal), with the old output intact
    or the whole new one, and nothing else left behind."""
    signum = case.signal[0]
    output = folder / _output(case)
    data = output.read_bytes() if output.exists() else b""
    interrupted = outcome.returncode in (128 + signum, -signum)
    latency = getattr(outcome, "signal_latency", None)
    lines = [line for line in outcome.stderr.splitlines() if line.strip()]
    stray = [line for line in lines if line not in ("interrupted",) and not line.startswith("warning: ")]
    if "Traceback" in outcome.stderr or stray:
        outcome.verdict, outcome.detail = "stray-output", (stray or ["a traceback"])[0][:200]
    elif outcome.returncode != 0 and not interrupted:
        outcome.verdict, outcome.detail = "bad-exit", f"exit {outcome.returncode} after {signal.Signals(signum).name}"
    elif outcome.returncode == 128 + signum and lines[-1:] != ["interrupted"]:
        outcome.verdict, outcome.detail = "bad-exit", f"{signal.Signals(signum).name} ended it without a word"
    elif interrupted and signum != signal.SIGKILL and latency is not None and latency > SIGNAL_LATENCY:
        outcome.verdict, outcome.detail = "hang", f"{signal.Signals(signum).name} heard after {latency:.2f} s"
    elif data != OLD_OUTPUT and (outcome.returncode != 0 or not data) and not _whole_output(output):
        outcome.verdict, outcome.detail = "bad-exit", "the output is neither the old one nor a whole new one"
    elif _litter(folder, case):
        outcome.verdict, outcome.detail = "bad-exit", f"left {_litter(folder, case)}"
    else:
        outcome.verdict, outcome.detail = ("error" if interrupted else "image"), ""


def _whole_output(path: Path) -> bool:
    """Whether ``path`` is a whole output: an image Pillow reads, a USD stage usd-core opens, an SDL file the
    tracer reads (a kill just after the output was put in place leaves the whole new file and a -9 status)."""
    try:
        if path.suffix in (".usda", ".usdc", ".usd"):
            from pxr import Usd

            return bool(Usd.Stage.Open(str(path)))
        if path.suffix == ".sdl":
            from tracer.sdl.parser import load

            load(path, strict=True)
            return True
        from PIL import Image

        with Image.open(path) as picture:
            picture.load()
        return True
    except Exception:  # noqa: BLE001
        return False


def run(count: int, seed: int, jobs: int, timeout: float, memory_bytes: int, compare_every: int,
        findings: Path | None, only: int | None = None, log=None) -> dict:
    work = Path(tempfile.mkdtemp(prefix="sdl-fuzz-"))
    for folder in ("images", "meshes"):  # the bundled scenes name these relative to themselves
        shutil.copytree(SCENES / folder, work / folder)
    runner = Runner(jobs, timeout, memory_bytes)
    verdicts: Counter = Counter()
    failures, mismatches, skipped, compared = [], [], [], 0
    seeds = [only] if only is not None else [seed * 1_000_003 + i for i in range(count)]
    started = time.monotonic()

    def finish(item):
        nonlocal compared
        (case_seed, case, folder, comparing), outcome, killed = item
        if comparing:
            why = _compared(folder, outcome, killed, _output(case))
            if why is SLOW:
                skipped.append(case_seed)
            elif why:
                mismatches.append({"seed": case_seed, "kind": case.kind, "detail": why})
                if log:
                    log(f"MISMATCH seed {case_seed} {case.kind}: {why}")
            shutil.rmtree(folder, ignore_errors=True)
            return
        output = folder / _output(case)
        if getattr(case, "signal", None) is not None:
            _judge_signal(case, outcome, folder)
        elif case.command == "differential-sdl":
            outcome.verdict = "image" if outcome.returncode == 0 else "mismatch" if outcome.returncode == 3 else \
                judge(outcome, killed).verdict
            outcome.detail = outcome.stderr.strip()[-300:]
        else:
            judge(outcome, killed, output if case.command == "render" else None,
                  names=[*case.files, "--", "out.", *getattr(case, "names", ())],
                  memory_bytes=memory_bytes)  # an input, an option or the output
            if outcome.ok and _litter(folder, case):
                outcome.verdict, outcome.detail = "bad-exit", f"left {_litter(folder, case)}"
            old = getattr(case, "old_output", None)
            if outcome.verdict == "error" and old is not None and output.read_bytes() != old:
                outcome.verdict, outcome.detail = "bad-exit", "a failed run changed the old output"
        verdicts[outcome.verdict] += 1
        if not outcome.ok:
            failures.append({"seed": case_seed, "kind": case.kind, "verdict": outcome.verdict,
                             "detail": outcome.detail[:300], "args": outcome.args})
            if findings is not None:
                keep = findings / f"{outcome.verdict}-{case.kind}-{case_seed}"
                shutil.copytree(folder, keep, dirs_exist_ok=True)
                (keep / "command").write_text(" ".join(["python -m tracer", *outcome.args]) + "\n")
            if log:
                log(f"FAIL seed {case_seed} {case.kind}: {outcome.verdict} {outcome.detail[:200]}")
        elif (case.command == "render" and outcome.verdict == "image" and "--lenient" not in case.options
              and getattr(case, "signal", None) is None
              and (getattr(case, "compare", False) or compare_every and case.kind in ("sdl", "3vn", "png")
                   and (case_seed % compare_every == 0 or only is not None))):
            compared += 1
            # (the NumPy path is the slower one: it gets three times the limit)
            runner.start(_compare_argv(case), folder, (case_seed, case, folder, True), cpu_seconds=3 * timeout)
            return
        shutil.rmtree(folder, ignore_errors=True)

    try:
        for index, case_seed in enumerate(seeds):
            # (under make sanitize, usd-core's C++ exceptions abort with ASan's runtime preloaded: no USD)
            case = case_for(case_seed, usd=not SANITIZED)
            folder = work / f"case{case_seed}"
            folder.mkdir()
            for folder_name in ("images", "meshes"):
                os.symlink(work / folder_name, folder / folder_name)
            for name, data in case.files.items():
                (folder / name).write_bytes(data)
            if getattr(case, "old_output", None) is not None:
                try:
                    (folder / _output(case)).write_bytes(case.old_output)
                except OSError:  # (a name past the file system's limit: there is no old output)
                    case.old_output = None
            argv = [case.command, case.main]
            if case.command == "render":
                argv += ["-o", _output(case)]
            elif case.command == "convert":
                argv += ["out.sdl" if case.main.endswith(".usda") else "out.usda"]
            runner.start(argv + case.options, folder, (case_seed, case, folder, False),
                         signal_at=getattr(case, "signal", None))
            while runner.done:
                finish(runner.done.pop())
            if log and (index + 1) % 500 == 0:
                log(f"{index + 1} inputs, {time.monotonic() - started:.0f} s: {dict(verdicts)}")
        while runner.running or runner.done:
            runner.drain()
            while runner.done:
                finish(runner.done.pop())
    finally:
        shutil.rmtree(work, ignore_errors=True)
    failed = {kind: verdicts[kind] for kind in FAILURES + ("mismatch",) if verdicts[kind]}
    return {"inputs": len(seeds), "seconds": round(time.monotonic() - started, 1), "verdicts": dict(verdicts),
            "failures": failed, "failed_inputs": failures[:50], "compared": compared - len(skipped),
            "compare_too_slow": skipped, "mismatches": mismatches}


def _import_before_forking() -> None:
    """What every child needs, imported (and the C core built) once in the parent."""
    import tracer.cli  # noqa: F401
    import tracer.native  # noqa: F401
    import tracer.render  # noqa: F401
    from PIL import Image

    Image.init()  # every format plugin
    if SANITIZED:
        return
    try:
        from tracer.usd.common import pxr

        pxr()
    except Exception:  # noqa: BLE001 — without usd-core the USD cases report that themselves
        pass


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--only", type=int, default=None, help="run the one case with this seed")
    parser.add_argument("--jobs", type=int, default=max(1, min(4, os.cpu_count() or 1)))
    parser.add_argument("--timeout", type=float, default=HANG_SECONDS)
    parser.add_argument("--memory", type=float, default=MEMORY_BYTES / 2**30, help="GiB")
    parser.add_argument("--compare-every", type=int, default=20,
                        help="render every Nth valid scene with both backends (0: never)")
    parser.add_argument("--findings", type=Path, default=None, help="folder to copy failing inputs to")
    args = parser.parse_args(argv)
    os.environ.setdefault("SDL_TRACER_THREADS", "1")
    _import_before_forking()

    summary = run(args.count, args.seed, args.jobs, args.timeout, int(args.memory * 2**30), args.compare_every,
                  args.findings, args.only, log=lambda line: print(line, file=sys.stderr, flush=True))
    print(json.dumps(summary, indent=2))
    return 1 if summary["failures"] or summary["mismatches"] else 0


if __name__ == "__main__":
    sys.exit(main())
