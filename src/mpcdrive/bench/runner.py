"""Time closed loops step by step, the way a user calls a controller from Python."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..control.factory import BACKENDS, DEFAULT_BACKEND, make_mpc
from ..sim.closed_loop import Plant
from ..scene.geometry import shape_distance
from .problems import PROBLEMS, BenchProblem

WARMUP_STEPS = 10
#: SQP to convergence (P3): at most this many QPs per step, stop when the inputs move less than
#: SQP_TOL [rad], and start no new QP after SQP_MAX_TIME_S [s]
SQP_MAX_ITERATIONS, SQP_TOL, SQP_MAX_TIME_S = 20, 1e-4, 0.002
#: the backend whose figures the plain ``mpcdrive`` entry repeats: the compiled fast path
BENCH_HEADLINE = "fast"


def time_closed_loop(controller, prob: BenchProblem, steps: int) -> dict:
    """Run ``steps`` steps of the closed loop, timing each ``controller.step`` call.

    Returns p50/p99/max [us] over the steps after the warm-up, the step count, and the RMS
    lateral error [m] (evidence that every implementation solved the same problem)."""
    plant = Plant(prob.model)
    x = prob.x0.copy()
    warm = controller.initial_warm(x)
    times = np.empty(steps)
    ey = np.empty(steps)
    failures = 0
    qps = 0
    min_clear = None
    for k in range(steps):
        t0 = time.perf_counter()
        out = controller.step(x, warm)
        times[k] = time.perf_counter() - t0
        warm = out.warm
        ey[k] = out.e_y_m
        failures += out.status not in ("ok", "inaccurate")
        qps += out.sqp_iterations
        for ob in prob.obstacles:
            d = shape_distance(prob.footprint.polygon(*x[:3]), ob.at(k * prob.dt_s))
            min_clear = d if min_clear is None else min(min_clear, d)
        x = plant.step(x, out.u, prob.dt_s)
    t = times[min(WARMUP_STEPS, steps - 1):] * 1e6
    return {
        "p50_us": float(np.percentile(t, 50)),
        "p99_us": float(np.percentile(t, 99)),
        "max_us": float(t.max()),
        "steps": int(steps),
        "rms_lateral_error_m": float(np.sqrt(np.mean(ey ** 2))),
        "solver_failures": int(failures),
        "min_obstacle_clearance_m": min_clear,
        "qps_per_step": qps / steps,
    }


def make_controller(prob: BenchProblem, backend: str = DEFAULT_BACKEND):
    """mpcdrive's controller of a bench problem with ``backend`` (``osqp`` or ``fast``)."""
    return make_mpc(prob.model, prob.path, prob.problem, prob.config, backend, obstacles=prob.obstacles,
                    avoidance=prob.avoidance, footprint=prob.footprint)


def run_bench(names, baselines: bool = False, steps: int = 1000, baseline_steps: int = 200,
              log: Callable[[str], None] = lambda m: None) -> dict:
    """``{problem: {implementation: figures}}`` for the named problems (see CONTRACT.md).

    Implementations: ``mpcdrive_<backend>`` for each controller backend, ``mpcdrive`` (the
    figures of the default backend, named in its ``backend`` field) and, with ``baselines``,
    the installed baselines plus ``mpcdrive_same_steps`` (the default backend over the
    baselines' step count). Every entry is timed on the same closed loop in this process."""
    out: dict[str, dict] = {}
    for name in names:
        prob = PROBLEMS[name]()
        res: dict[str, dict] = {}
        for backend in BACKENDS:
            log(f"{name}: mpcdrive ({backend} backend), {steps} steps")
            ctrl = make_controller(prob, backend)
            res[f"mpcdrive_{backend}"] = {**time_closed_loop(ctrl, prob, steps), "backend": ctrl.backend_name}
        res = {"mpcdrive": dict(res[f"mpcdrive_{BENCH_HEADLINE}"]), **res}
        if prob.avoidance is not None and prob.avoidance.uses_cost:
            converged = replace(prob, config=replace(prob.config, sqp_max_iterations=SQP_MAX_ITERATIONS,
                                                     sqp_tol=SQP_TOL, sqp_max_time_s=SQP_MAX_TIME_S))
            for backend in BACKENDS:
                log(f"{name}: mpcdrive ({backend} backend), SQP to convergence (<= {SQP_MAX_ITERATIONS} QPs, "
                    f"{SQP_MAX_TIME_S * 1e3:g} ms cap), {steps} steps")
                ctrl = make_controller(converged, backend)
                res[f"mpcdrive_sqp_converged_{backend}"] = {**time_closed_loop(ctrl, converged, steps),
                                                            "backend": ctrl.backend_name}
            res["mpcdrive_sqp_converged"] = dict(res[f"mpcdrive_sqp_converged_{BENCH_HEADLINE}"])
        if baselines:
            from .baselines import available_baselines

            for bname, factory in available_baselines(prob).items():
                log(f"{name}: {bname}, {baseline_steps} steps")
                res[bname] = time_closed_loop(factory(prob), prob, baseline_steps)
            # our controller over the baselines' step count, for a like-for-like tracking error
            res["mpcdrive_same_steps"] = time_closed_loop(make_controller(prob), prob, baseline_steps)
        out[name] = res
    return out


def format_table(results: dict) -> str:
    """A plain-text table of the bench results."""
    lines = [f"{'problem':<8}{'implementation':<22}{'p50 [us]':>12}{'p99 [us]':>12}{'max [us]':>12}{'steps':>8}{'rms e_y [m]':>14}"]
    for prob, impls in results.items():
        for impl, r in impls.items():
            lines.append(f"{prob:<8}{impl:<22}{r['p50_us']:>12.1f}{r['p99_us']:>12.1f}{r['max_us']:>12.1f}"
                         f"{r['steps']:>8d}{r['rms_lateral_error_m']:>14.5f}")
    return "\n".join(lines)
