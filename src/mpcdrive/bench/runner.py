"""Time closed loops step by step, the way a user calls a controller from Python."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..control.mpc import LtvMpc
from ..sim.closed_loop import Plant
from ..sim.contact import clearances
from .problems import PROBLEMS, BenchProblem

WARMUP_STEPS = 10
#: SQP to convergence (P3): at most this many QPs per step, stop when the inputs move less than
#: SQP_TOL [rad]; an iteration cap, not a wall-time cap, so the loop (and its safety figures) is
#: the same on every machine and only its timing differs
SQP_MAX_ITERATIONS, SQP_TOL = 20, 1e-4


def time_closed_loop(controller, prob: BenchProblem, steps: int) -> dict:
    """Run ``steps`` steps of the closed loop, timing each ``controller.step`` call.

    Returns p50/p99/max [us] over the steps after the warm-up, the step count, the RMS lateral
    error [m] (evidence that every implementation solved the same problem), and what safety
    says: ``solver_failures`` (steps whose solve did not succeed), ``min_obstacle_clearance_m``
    (least signed distance between the footprint and any obstacle over the drive, negative when
    they overlapped; None without obstacles), ``collision_steps`` (steps with the footprint
    touching or overlapping an obstacle, at the step or before the next) and
    ``max_lane_excess_m`` (how far the body got outside the lane or road, 0 inside; None without
    a lane), measured as a run's metrics measure them (:func:`~mpcdrive.sim.contact.clearances`,
    :meth:`~mpcdrive.scene.road.Road.measure_excess_m`)."""
    plant = Plant(prob.model)
    x = prob.x0.copy()
    warm = controller.initial_warm(x)
    times = np.empty(steps)
    ey = np.empty(steps)
    s_m = np.empty(steps)
    X = np.empty((steps, 3))
    failures = 0
    qps = 0
    for k in range(steps):
        t0 = time.perf_counter()
        out = controller.step(x, warm)
        times[k] = time.perf_counter() - t0
        warm = out.warm
        ey[k], s_m[k], X[k] = out.e_y_m, out.s_m, x[:3]
        failures += out.status not in ("ok", "inaccurate")
        qps += out.sqp_iterations
        x = plant.step(x, out.u, prob.dt_s)
    t = times[min(WARMUP_STEPS, steps - 1) :] * 1e6
    collisions, min_clear = 0, None
    if prob.obstacles:  # as a run's metrics judge them: at the steps and between them
        clear = clearances(X, prob.dt_s * np.arange(steps), prob.obstacles, prob.footprint)[1].min(axis=0)
        collisions, min_clear = int(np.count_nonzero(clear <= 0.0)), float(clear.min())
    road = prob.problem.road
    excess = None
    if road is not None:  # the road's own measure, as a run's metrics measure it
        excess = float(np.max(road.whole().measure_excess_m(prob.path, X, s_m, prob.footprint)))
    return {
        "p50_us": float(np.percentile(t, 50)),
        "p99_us": float(np.percentile(t, 99)),
        "max_us": float(t.max()),
        "steps": int(steps),
        "rms_lateral_error_m": float(np.sqrt(np.mean(ey**2))),
        "solver_failures": int(failures),
        "min_obstacle_clearance_m": min_clear,
        "collision_steps": int(collisions),
        "max_lane_excess_m": excess,
        "qps_per_step": qps / steps,
    }


#: the controller rows of the bench: ``fast``, the default controller (the condensed solver),
#: and ``osqp``, OSQP on the same stage QP (the reference solver)
BACKENDS: tuple[str, ...] = ("osqp", "fast")
DEFAULT_BACKEND = "fast"
_SOLVER_OF = {"fast": "condensed", "osqp": "osqp"}


def make_controller(prob: BenchProblem, backend: str = DEFAULT_BACKEND):
    """mpcdrive's controller of a bench problem with ``backend`` (``osqp`` or ``fast``)."""
    if backend not in _SOLVER_OF:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    return LtvMpc(
        prob.model,
        prob.path,
        prob.problem,
        prob.config,
        _SOLVER_OF[backend],  # type: ignore[arg-type]
        obstacles=prob.obstacles,
        avoidance=prob.avoidance,
        footprint=prob.footprint,
    )


def run_bench(
    names,
    baselines: bool = False,
    steps: int = 1000,
    baseline_steps: int = 200,
    log: Callable[[str], None] = lambda m: None,
) -> dict:
    """``{problem: {implementation: figures}}`` for the named problems (docs/benchmarks.md).

    A problem with its own closed-loop length (P4: 300 steps) runs at most that many steps
    (``steps`` and ``baseline_steps`` cap it). Implementations: ``mpcdrive_<backend>`` for each controller backend, ``mpcdrive`` (the
    figures of the default backend, named in its ``backend`` field) and, with ``baselines``,
    the installed baselines plus ``mpcdrive_same_steps`` (the default backend over the
    baselines' step count). Every entry is timed on the same closed loop in this process."""
    out: dict[str, dict] = {}
    for name in names:
        prob = PROBLEMS[name]()
        steps_p = steps if prob.steps is None else min(steps, prob.steps)
        baseline_steps_p = baseline_steps if prob.steps is None else min(baseline_steps, prob.steps)
        res: dict[str, dict] = {}
        for backend in BACKENDS:
            log(f"{name}: mpcdrive ({backend} backend), {steps_p} steps")
            ctrl = make_controller(prob, backend)
            res[f"mpcdrive_{backend}"] = {**time_closed_loop(ctrl, prob, steps_p), "backend": ctrl.backend_name}
        res = {"mpcdrive": dict(res[f"mpcdrive_{DEFAULT_BACKEND}"]), **res}
        if prob.avoidance is not None and prob.avoidance.uses_cost:
            converged = replace(
                prob,
                config=replace(
                    prob.config, sqp_max_iterations=SQP_MAX_ITERATIONS, sqp_tol=SQP_TOL, sqp_max_time_s=None
                ),
            )
            for backend in BACKENDS:
                log(
                    f"{name}: mpcdrive ({backend} backend), SQP to convergence (<= {SQP_MAX_ITERATIONS} QPs, "
                    f"inputs within {SQP_TOL:g}), {steps_p} steps"
                )
                ctrl = make_controller(converged, backend)
                res[f"mpcdrive_sqp_converged_{backend}"] = {
                    **time_closed_loop(ctrl, converged, steps_p),
                    "backend": ctrl.backend_name,
                }
            res["mpcdrive_sqp_converged"] = dict(res[f"mpcdrive_sqp_converged_{DEFAULT_BACKEND}"])
        if baselines:
            from .baselines import available_baselines

            for bname, factory in available_baselines(prob).items():
                log(f"{name}: {bname}, {baseline_steps_p} steps")
                res[bname] = time_closed_loop(factory(prob), prob, baseline_steps_p)
            # our controller over the baselines' step count, for a like-for-like tracking error
            res["mpcdrive_same_steps"] = time_closed_loop(make_controller(prob), prob, baseline_steps_p)
        out[name] = res
    return out


def format_table(results: dict) -> str:
    """A plain-text table of the bench results; with obstacles, the least clearance [m] and the
    steps in collision of each implementation (``—`` without obstacles)."""
    lines = [
        f"{'problem':<8}{'implementation':<30}{'p50 [us]':>12}{'p99 [us]':>12}{'max [us]':>12}{'steps':>8}"
        f"{'rms e_y [m]':>14}{'min clear [m]':>15}{'collisions':>12}"
    ]
    for prob, impls in results.items():
        for impl, r in impls.items():
            clear = r.get("min_obstacle_clearance_m")
            hits = r.get("collision_steps") if clear is not None else None
            lines.append(
                f"{prob:<8}{impl:<30}{r['p50_us']:>12.1f}{r['p99_us']:>12.1f}{r['max_us']:>12.1f}"
                f"{r['steps']:>8d}{r['rms_lateral_error_m']:>14.5f}"
                f"{'—' if clear is None else f'{clear:.3f}':>15}{'—' if hits is None else hits:>12}"
            )
    return "\n".join(lines)
