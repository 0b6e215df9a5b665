"""Ctrl-C and SIGTERM at any moment of a command: exit code 130, the one-line message, no
traceback, nothing written.

Each try starts a command in an empty working directory (its default output folder would be
made there) and sends the signal a given time after the command's handlers are in place: the
first statement of mpcdrive's entry point installs them, before anything heavy is imported; the
test sees the moment in ``/proc/<pid>/status`` (the caught-signal mask gains SIGTERM). Before it
the interpreter is still starting up, where a signal ends the process as it ends any Python
program. Delays run from 0 ms (the imports: typer, numpy, numba, scipy, matplotlib) through
building the controller to the closed loop, and a first numba compile with an empty cache. When a
signal lands does not change what is asserted, so the outcome does not depend on the machine's
speed (only which phase each delay covers does).
"""

import importlib.util
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MESSAGE = "mpcdrive: interrupted; no partial output was kept"

pytestmark = pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc (Linux)")

LONG = (  # runs for minutes: every delay lands while the command is still running
    "id: long\ndescription: a long circle\nduration_s: 3600.0\n"
    "path: {type: circle, radius_m: 1.5}\n"
    "initial_state: {x_m: 1.5, y_m: 0.0, yaw_deg: 90}\n"
    "controller: {horizon: 10, Q: [1, 1, 1], R: [1]}\n"
)


def _caught(pid: int) -> int:
    """The caught-signal mask of process ``pid`` (0 when it is gone)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0
    for line in status.splitlines():
        if line.startswith("SigCgt:"):
            return int(line.split()[1], 16)
    return 0


def _own_lines(err: str) -> list[str]:
    """The command's stderr lines without the warnings of Python's multiprocessing resource
    tracker: a separate process that outlives the command (the pool's fork server holds it open)
    and, when a worker was stopped mid-run, may warn of a semaphore after the command's own last
    line (seen once in a full run under load, after "interrupted; no partial output was kept")."""
    lines = err.splitlines()
    out = []
    skip = False
    for line in lines:
        if "multiprocessing/resource_tracker.py" in line:
            skip = True  # its warning, and the source line indented below it
            continue
        if skip and line.startswith(" "):
            continue
        skip = False
        out.append(line)
    return out or [""]


class _Try:
    """One command started in its own process group (as a terminal's foreground job is: Ctrl-C
    reaches every process of the group), in an empty working directory, stderr read as it comes."""

    def __init__(self, tmp_path: Path, args: list[str], env: dict | None = None):
        self.cwd = tmp_path / f"cwd-{time.monotonic_ns()}"
        self.cwd.mkdir()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "mpcdrive", *args],
            cwd=self.cwd,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})},
            start_new_session=True,
            # a shell's background job ignores SIGINT and children inherit that: restore the
            # default, as in a terminal
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
        self.err: list[str] = []
        self._reader = threading.Thread(target=lambda: self.err.extend(self.proc.stderr), daemon=True)
        self._reader.start()

    def wait_for_handlers(self, timeout_s: float = 60.0) -> None:
        t0 = time.monotonic()
        while not _caught(self.proc.pid) & (1 << (signal.SIGTERM - 1)):
            if self.proc.poll() is not None or time.monotonic() - t0 > timeout_s:
                self.proc.kill()
                pytest.fail(f"the command never installed its handlers: {''.join(self.err)}")
            time.sleep(0.0002)

    def wait_for_line(self, text: str, timeout_s: float = 300.0) -> None:
        t0 = time.monotonic()
        while not any(text in line for line in self.err):
            if self.proc.poll() is not None or time.monotonic() - t0 > timeout_s:
                self.proc.kill()
                pytest.fail(f"no {text!r} on stderr: {''.join(self.err)}")
            time.sleep(0.01)

    def interrupt(self, sig: int, after_s: float) -> None:
        """Send ``sig`` ``after_s`` from now, as a terminal does: Ctrl-C to the process group,
        SIGTERM to the process (as ``kill`` sends it); then wait for the end and check it."""
        time.sleep(after_s)
        assert self.proc.poll() is None, f"the command ended before the signal: {''.join(self.err)}"
        if sig == signal.SIGINT:
            os.killpg(self.proc.pid, sig)
        else:
            self.proc.send_signal(sig)
        try:
            rc = self.proc.wait(timeout=120)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            pytest.fail(f"the command did not end after {signal.Signals(sig).name}: {''.join(self.err)}")
        self._reader.join(timeout=10)
        err = "".join(self.err)
        what = f"{signal.Signals(sig).name} {after_s * 1000:.0f} ms after the handlers"
        assert rc == 130, f"{what}: exit {rc}: {err}"
        assert _own_lines(err)[-1] == MESSAGE, f"{what}: {err}"
        assert "Traceback" not in err and "Fatal Python error" not in err, f"{what}: {err}"
        assert not any(self.cwd.iterdir()), f"{what}: left {sorted(p.name for p in self.cwd.rglob('*'))}"


@pytest.fixture
def long_scenario(tmp_path) -> str:
    path = tmp_path / "long.yaml"
    path.write_text(LONG)
    return str(path)


#: the delays after the handlers are in place [s]: the imports, loading the scenario, building
#: the controller, the closed loop
DELAYS_S = (0.0, 0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 0.6, 1.0, 1.5, 2.5)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["sigint", "sigterm"])
def test_a_signal_at_any_moment_of_a_run_ends_it_with_130_and_nothing_written(tmp_path, long_scenario, sig):
    for after_s in DELAYS_S:
        t = _Try(tmp_path, ["run", long_scenario, "-q"])
        t.wait_for_handlers()
        t.interrupt(sig, after_s)


def test_a_signal_with_the_progress_bar_on(tmp_path, long_scenario):
    t = _Try(tmp_path, ["run", long_scenario])
    t.wait_for_handlers()
    t.interrupt(signal.SIGTERM, 2.5)


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["sigint", "sigterm"])
def test_a_signal_during_the_first_compile_ends_it_with_130(tmp_path, long_scenario, sig):
    """An empty numba cache: the controller compiles for many seconds, in numba's compiler and
    LLVM; a signal there must not abort the interpreter or be lost."""
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    for after_s in (0.0, 0.5, 2.0):
        t = _Try(tmp_path, ["run", long_scenario, "-q"], env={"NUMBA_CACHE_DIR": str(cache)})
        t.wait_for_line("compiling the fast controller")
        t.interrupt(sig, after_s)


CR_FILE = str(ROOT / "tests" / "data" / "commonroad" / "USA_Peach-4_8_T-1.xml")
OTHER_COMMANDS = {
    "sweep": ["sweep", "LONG", "--runs", "4", "--workers", "2", "-q"],
    "reproduce": ["reproduce", "-q"],
    "compare-avoidance": ["compare-avoidance", "-q"],
    "compare-models": ["compare-models"],
    "bench": ["bench", "--problem", "P1", "--steps", "100000", "--json", "bench.json"],
    "commonroad": ["commonroad", CR_FILE, "--workers", "1"],
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(OTHER_COMMANDS))
def test_every_long_command_ends_with_130_at_any_moment(tmp_path, long_scenario, name):
    if name == "commonroad" and importlib.util.find_spec("commonroad") is None:
        pytest.skip("needs the commonroad extra")
    args = [long_scenario if a == "LONG" else a for a in OTHER_COMMANDS[name]]
    for sig, after_s in ((signal.SIGINT, 0.0), (signal.SIGTERM, 0.3), (signal.SIGINT, 2.5)):
        t = _Try(tmp_path, args)
        t.wait_for_handlers()
        t.interrupt(sig, after_s)
