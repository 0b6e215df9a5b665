"""Bench figures beyond the per-step latency of P1 / P2 / P3 (``mpcdrive bench --report DIR``):
per-step time as the horizon grows (P1) and as obstacles are added (P3 with 0..20 obstacles),
cold start, peak memory and allocations per step.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
import tracemalloc
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

from ..control.mpc import FastPathUnavailable
from .problems import p1, p3_obstacles
from .runner import BACKENDS, make_controller, time_closed_loop

HORIZONS = (10, 20, 30, 50, 100)
OBSTACLE_COUNTS = (0, 1, 2, 5, 10, 20)


def horizon_sweep(
    horizons: Sequence[int] = HORIZONS,
    steps: int = 300,
    backends: Sequence[str] = BACKENDS,
    log: Callable[[str], None] = lambda m: None,
) -> dict:
    """``{N: {backend: figures}}``: P1 with horizon N, each backend timed on the same closed loop."""
    out: dict[int, dict] = {}
    for N in horizons:
        prob = p1(int(N))
        out[int(N)] = {}
        for backend in backends:
            log(f"P1 with N = {N}: {backend}, {steps} steps")
            ctrl = make_controller(prob, backend)
            out[int(N)][backend] = {**time_closed_loop(ctrl, prob, steps), "backend": ctrl.backend_name}
    return out


def obstacle_sweep(
    counts: Sequence[int] = OBSTACLE_COUNTS,
    steps: int = 1000,
    backends: Sequence[str] = BACKENDS,
    log: Callable[[str], None] = lambda m: None,
) -> dict:
    """``{n: {backend: figures}}``: P3 with n obstacles (:func:`~mpcdrive.bench.problems.p3_obstacles`),
    each backend timed on the same closed loop.

    figures : those of :func:`~mpcdrive.bench.runner.time_closed_loop` (p50 / p99 / max per step
    [us], ``solver_failures``, ``min_obstacle_clearance_m`` over the whole drive -- None without
    obstacles -- and the RMS lateral error [m]), plus ``backend``, the backend that actually ran,
    and ``fallback``, why the requested one did not (a :class:`FastPathUnavailable` message;
    None when it ran). The fallback warning is recorded there and logged once per reason instead
    of being raised for every count. The default 1000 steps (10 s at 1 m/s) take the car past
    every obstacle, so the clearance covers them all."""
    out: dict[int, dict] = {}
    told: set[str] = set()
    for n in counts:
        prob = p3_obstacles(int(n))
        out[int(n)] = {}
        for backend in backends:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", FastPathUnavailable)
                ctrl = make_controller(prob, backend)
            fallback = None
            for w in caught:
                if issubclass(w.category, FastPathUnavailable):
                    fallback = str(w.message)
                else:  # anything else is not ours to swallow
                    warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
            if fallback is not None and fallback not in told:
                told.add(fallback)
                log(f"{backend}: {fallback} (recorded in the sweep's 'fallback' field)")
            log(f"P3 with {n} obstacle(s): {backend} (runs {ctrl.backend_name}), {steps} steps")
            out[int(n)][backend] = {
                **time_closed_loop(ctrl, prob, steps),
                "backend": ctrl.backend_name,
                "fallback": fallback,
            }
    return out


_COLD_SCRIPT = """
import time
t0 = time.perf_counter()
import json, resource
from mpcdrive.bench.problems import p1
from mpcdrive.bench.runner import make_controller
from mpcdrive.sim.closed_loop import Plant
prob = p1()
ctrl = make_controller(prob, {backend!r})
x = prob.x0.copy()
warm = ctrl.initial_warm(x)
out = ctrl.step(x, warm)
t1 = time.perf_counter()
plant = Plant(prob.model)
for _ in range({steps}):
    out = ctrl.step(x, warm)
    warm = out.warm
    x = plant.step(x, out.u, prob.dt_s)
t2 = time.perf_counter()
try:  # this process's own peak (ru_maxrss also counts the parent's peak carried over an exec)
    with open("/proc/self/status") as f:
        peak = [float(line.split()[1]) for line in f if line.startswith("VmHWM:")][0] / 1024.0
except (OSError, IndexError):
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print(json.dumps({{"first_step_s": t1 - t0, "loop_s": t2 - t1, "backend": ctrl.backend_name,
                  "maxrss_mib": peak}}))
"""


def _subprocess_env() -> dict:
    """The environment of a child process that imports this same mpcdrive."""
    import mpcdrive

    src = str(Path(mpcdrive.__file__).resolve().parents[1])
    env = dict(os.environ)
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def cold_start(backend: str, steps: int = 1000, repeats: int = 3) -> dict:
    """Fresh processes running P1 with ``backend`` (compile cache warm: one unmeasured run first).

    Returns medians over ``repeats``: ``import_build_first_step_s`` (in the process: imports,
    controller build, first step), ``process_1000_steps_s`` (the whole process as the shell sees
    it: interpreter start, imports, build and a ``steps``-step closed loop incl. the plant),
    ``peak_rss_mib`` (peak resident memory of that process)."""
    env = _subprocess_env()
    code = _COLD_SCRIPT.format(backend=backend, steps=int(steps))
    runs = []
    for k in range(repeats + 1):
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=False)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            raise RuntimeError(f"cold-start child failed: {proc.stderr.strip().splitlines()[-1:]}")
        if k == 0:
            continue  # fills the compile cache if it was empty
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        runs.append((r["first_step_s"], wall, r["maxrss_mib"], r["backend"]))
    return {
        "import_build_first_step_s": statistics.median(r[0] for r in runs),
        "process_1000_steps_s": statistics.median(r[1] for r in runs),
        "peak_rss_mib": statistics.median(r[2] for r in runs),
        "backend": runs[-1][3],
        "repeats": repeats,
    }


def step_allocations(backend: str, steps: int = 200) -> dict:
    """Python-heap memory a P1 step allocates (tracemalloc, after a warm-up): the peak extra
    bytes held during ``steps`` steps and the bytes allocated per step that are still alive at
    the end (0 means nothing accumulates)."""
    prob = p1()
    ctrl = make_controller(prob, backend)
    x = prob.x0.copy()
    warm = ctrl.initial_warm(x)
    for _ in range(20):
        out = ctrl.step(x, warm)
        warm = out.warm
    tracemalloc.start()
    try:
        base, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for _ in range(steps):
            out = ctrl.step(x, warm)
            warm = out.warm
        cur, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return {
        "peak_extra_bytes": int(peak - base),
        "retained_bytes_per_step": max(0.0, (cur - base) / steps),
        "backend": ctrl.backend_name,
    }
