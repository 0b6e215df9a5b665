"""Monte Carlo sweeps: plan the runs, run them on a local process pool or a Ray cluster, collect rows.

The plan is made in the calling process and does not depend on the backend or the number of
workers: run ``i`` draws its varied values and its scenario seed from child ``i`` of
``numpy.random.SeedSequence(seed)``, its scenario is validated there (a run whose values make an
invalid scenario is reported, not dispatched), and workers only simulate. The simulation is
deterministic, so every column but the timings is identical between backends for the same seed.
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..scenarios import ScenarioError, ScenarioSpec, validate_scenario_data
from .vary import Setting, SweepError, Variation, apply, parse_set, parse_vary

if TYPE_CHECKING:
    from ..sim import Metrics

__all__ = [
    "METRIC_COLUMNS",
    "RunTask",
    "SuccessCriteria",
    "SweepPlan",
    "plan_sweep",
    "run_sweep",
    "run_task",
]

#: metric columns of the results table, in order (after run_id, seed and the varied values)
METRIC_COLUMNS: tuple[str, ...] = (
    "success",
    "failure_reason",
    "termination",
    "steps",
    "duration_s",
    "rms_lateral_error_m",
    "max_abs_lateral_error_m",
    "final_lateral_error_m",
    "rms_heading_error_rad",
    "max_abs_steer_rad",
    "max_abs_steer_rate_rad_s",
    "min_obstacle_clearance_m",
    "collisions",
    "max_lane_excess_m",
    "max_lane_excess_t_s",
    "lane_excess_at_start_m",
    "goal_reached",
    "solver_failures",
    "fallbacks",
    "fallbacks_relax",
    "fallbacks_shifted_plan",
    "fallbacks_brake",
    "fallbacks_hold_last",
    "solve_time_p50_us",
    "solve_time_p99_us",
    "solve_time_max_us",
    "wall_s",
)
#: columns that depend on the machine (left out when comparing backends)
TIMING_COLUMNS: tuple[str, ...] = ("solve_time_p50_us", "solve_time_p99_us", "solve_time_max_us", "wall_s")


@dataclass(frozen=True)
class SuccessCriteria:
    """A run succeeds when its verdict passes (``Metrics.verdict``, :func:`~mpcdrive.sim.run_verdict`:
    no divergence, no collision, inside the road, its goal reached safely and ending close to the
    path); these override the verdict's tolerances of every run (None: the scenario's own, its
    ``verdict`` block): ``max_final_lateral_error_m`` [m] (``verdict.max_final_lateral_error_m``)
    and ``max_lane_excess_m`` [m] (``verdict.max_lane_excess_m``)."""

    max_final_lateral_error_m: float | None = None
    max_lane_excess_m: float | None = None

    def __post_init__(self):
        for name in ("max_final_lateral_error_m", "max_lane_excess_m"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise SweepError(f"{name} must be a finite number >= 0, got {v!r}")

    def apply(self, data: dict) -> dict:
        """Scenario ``data`` (a dict, changed in place and returned) with these overrides in its
        ``verdict`` block."""
        verdict = data.setdefault("verdict", {})
        for name in ("max_final_lateral_error_m", "max_lane_excess_m"):
            v = getattr(self, name)
            if v is not None:
                verdict[name] = v
        return data

    @staticmethod
    def judge(
        m: Metrics, *, max_lane_excess_t_s: float | None = None, lane_excess_at_start_m: float | None = None
    ) -> list[str]:
        """Reasons the run with metrics ``m`` failed (empty: success): its verdict's reasons,
        verbatim; ``max_lane_excess_t_s`` (when the lane excess was largest [s]) and
        ``lane_excess_at_start_m`` (the excess at the first step [m]) add to the road's."""
        why = []
        for name, part in m.verdict.parts:
            if part.ok is not False or not part.reason:
                continue
            msg = part.reason
            if name == "road" and msg.startswith("left the"):
                if max_lane_excess_t_s is not None:
                    msg += f" at t = {max_lane_excess_t_s:.2f} s"
                if lane_excess_at_start_m:
                    msg += f" (already {lane_excess_at_start_m:.3g} m outside at the start)"
            why.append(msg)
        return why


@dataclass(frozen=True)
class RunTask:
    """One run: its id, seed, varied values and the validated scenario as plain data (picklable)."""

    run_id: int
    seed: int
    values: dict
    scenario: dict | None
    invalid: str = ""
    criteria: SuccessCriteria = SuccessCriteria()


@dataclass(frozen=True)
class SweepPlan:
    """Every run of a sweep, made before any runs (see the module docstring)."""

    base: ScenarioSpec
    source: str
    seed: int
    variations: tuple[Variation, ...]
    settings: tuple[Setting, ...]
    criteria: SuccessCriteria
    tasks: tuple[RunTask, ...] = field(repr=False)

    @property
    def varied_names(self) -> list[str]:
        return [v.name for v in self.variations]


def _materialize_plant(data: dict) -> None:
    """Write the true vehicle's parameters (``plant``) explicitly from ``vehicle`` where unset, so
    that varying ``vehicle.*`` alone makes a model error (the controller's model is wrong) and
    ``plant.*`` alone a different true vehicle."""
    plant, veh = data["plant"], data["vehicle"]
    for k in ("lf_m", "lr_m"):
        if plant.get(k) is None:
            plant[k] = veh[k]
    if veh["model"] == "kinematic3" and plant.get("speed_mps") is None:
        plant["speed_mps"] = veh["speed_mps"]


def plan_sweep(
    spec: ScenarioSpec,
    runs: int,
    seed: int,
    vary: Sequence[str] = (),
    set_: Sequence[str] = (),
    criteria: SuccessCriteria = SuccessCriteria(),
    source: str | None = None,
) -> SweepPlan:
    """The runs of a sweep of ``spec``; :class:`SweepError` (one line) for bad options.

    ``set_`` (``NAME=VALUE``) are applied first, then ``vary`` (``NAME=DISTRIBUTION``) on top, so a
    relative distribution may scale or offset a value that ``--set`` gave."""
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise SweepError(f"--runs must be an integer >= 1, got {runs!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SweepError(f"--seed must be an integer >= 0, got {seed!r}")
    source = source or spec.id
    data = spec.model_dump(mode="json")
    _materialize_plant(data)
    settings = tuple(parse_set(s, data) for s in set_)
    base_data = criteria.apply(apply(data, settings, {}))
    try:
        base = validate_scenario_data(base_data, f"{source} with --set")
    except ScenarioError as e:
        raise SweepError(f"--set: the scenario is not valid with these settings: {e}") from None
    variations = tuple(parse_vary(v, base_data) for v in vary)
    names = [v.name for v in variations]
    dup = [n for i, n in enumerate(names) if n in names[:i]]
    if dup:
        raise SweepError(f"--vary {dup[0]}: given twice")
    # each option on its own at its centre value must give a valid scenario
    for var in variations:
        nominal = var.dist.nominal(_base_value(base_data, var))
        trial = apply(base_data, (), {var: int(round(nominal)) if var.integer else nominal})
        try:
            validate_scenario_data(trial, "")
        except ScenarioError as e:
            raise SweepError(
                f"--vary {var}: gives an invalid scenario at its centre value {nominal:g}: {e.field}: {e.problem}"
            ) from None
    tasks = []
    for i, child in enumerate(np.random.SeedSequence(seed).spawn(runs)):
        rng = np.random.default_rng(child)
        run_seed = int(child.generate_state(1, dtype=np.uint32)[0])
        values = {var: var.value(rng, base_data) for var in variations}
        data_i = apply(base_data, (), values)
        data_i["seed"] = run_seed
        data_i["id"] = f"{base.id}-run{i:04d}"
        plain = {v.name: x for v, x in values.items()}
        try:
            ok = validate_scenario_data(data_i, f"run {i}")
            tasks.append(RunTask(i, run_seed, plain, ok.model_dump(mode="json"), "", criteria))
        except ScenarioError as e:
            tasks.append(RunTask(i, run_seed, plain, None, f"invalid scenario: {e.field}: {e.problem}", criteria))
    return SweepPlan(base, source, seed, variations, settings, criteria, tuple(tasks))


def _base_value(data: dict, var: Variation):
    from .vary import get_value

    return get_value(data, var.keys, "--vary", var.name)


# -- the worker ------------------------------------------------------------------------------------
def _row(task: RunTask) -> dict:
    row = {"run_id": task.run_id, "seed": task.seed, **task.values}
    row.update({c: None for c in METRIC_COLUMNS})
    return row


def run_task(task: RunTask) -> dict:
    """Simulate one run and return its row of the results table; never raises.

    A top-level function, so process pools using ``spawn`` or ``forkserver`` and Ray can ship it
    by reference."""
    t0 = time.perf_counter()
    row = _row(task)
    if task.scenario is None:
        row.update(success=False, failure_reason=task.invalid, termination="invalid", wall_s=0.0)
        return row
    try:
        from ..scenarios import build_experiment, run_experiment
        from ..sim import compute_metrics, lane_excess_per_step

        spec = ScenarioSpec.model_validate(task.scenario)
        exp = build_experiment(spec)
        result = run_experiment(exp)
        m = compute_metrics(result)
        excess = lane_excess_per_step(result)
        lane: dict[str, float] = {}  # when the excess was largest, and the excess at the start
        if excess is not None and excess.size:
            lane["max_lane_excess_t_s"] = float(result.t_s[int(np.argmax(excess))])
            lane["lane_excess_at_start_m"] = float(excess[0])
    except Exception as e:  # a run's error is its result; the sweep goes on
        msg = " ".join(str(e).split())
        row.update(
            success=False,
            failure_reason=f"error: {type(e).__name__}: {msg}",
            termination="error",
            wall_s=time.perf_counter() - t0,
        )
        return row
    fc = m.fallback_counts
    st = m.solve_time_us
    row.update({k: v for k, v in m.items() if k in METRIC_COLUMNS})
    row.update(lane)
    row.update(
        fallbacks_relax=fc.get("relax", 0),
        fallbacks_shifted_plan=fc.get("shifted_plan", 0),
        fallbacks_brake=fc.get("brake", 0),
        fallbacks_hold_last=fc.get("hold_last", 0),
        solve_time_p50_us=st.p50,
        solve_time_p99_us=st.p99,
        solve_time_max_us=st.max,
    )
    why = task.criteria.judge(m, **lane)
    row.update(success=m.verdict.passed, failure_reason="; ".join(why), wall_s=time.perf_counter() - t0)
    return row


def _ignore_sigint() -> None:
    """Pool workers leave Ctrl-C to the parent, which cancels the sweep and stops them."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# -- backends -----------------------------------------------------------------------------------------
Progress = Callable[[int, int, dict], None]


def _run_inline(tasks, progress: Progress | None, fn=run_task) -> list[dict]:
    rows = []
    for t in tasks:
        rows.append(fn(t))
        if progress is not None:
            progress(len(rows), len(tasks), rows[-1])
    return rows


def _mp_context():
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")


def _raise_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


@contextlib.contextmanager
def _signals_raise():
    """In the block, Ctrl-C (SIGINT) and SIGTERM raise KeyboardInterrupt (a signal ignored stays
    ignored), whatever the process's handlers are: the block's cleanup stops the workers or
    cancels the tasks before the interrupt goes on (a handler that ends the process at once,
    as the command line's does, would leave them running). Only in the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    sigs = [signal.SIGINT] + ([signal.SIGTERM] if hasattr(signal, "SIGTERM") else [])
    old = {s: signal.getsignal(s) for s in sigs}
    try:
        for s in sigs:
            if old[s] is not signal.SIG_IGN:
                signal.signal(s, _raise_interrupt)
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


@contextlib.contextmanager
def _signals_deferred():
    """Hold Ctrl-C (SIGINT) and SIGTERM back until the block ends, then raise KeyboardInterrupt
    if one came. Only the Python-level handlers change (the signal mask is left alone, so child
    processes started in the block receive signals as usual)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got = []
    sigs = [signal.SIGINT] + ([signal.SIGTERM] if hasattr(signal, "SIGTERM") else [])
    old = {s: signal.signal(s, lambda signum, frame: got.append(signum)) for s in sigs}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    if got:
        raise KeyboardInterrupt


def _run_local(tasks, workers: int, progress: Progress | None, fn=run_task, crashed=None) -> list[dict]:
    """``fn(task)`` for every task on a pool of ``workers`` processes (inline for one worker or
    one task unless ``crashed`` is given). At most ``workers`` tasks are in flight, so a worker
    that dies (a crash in compiled code: a segmentation fault) breaks the pool with only those
    tasks in it: each is tried again alone, in a pool of its own, and one that dies alone gets
    the row ``crashed(task, reason)`` (without ``crashed`` the pool's error is raised); the other
    tasks go on in a new pool."""
    if (workers == 1 or len(tasks) == 1) and crashed is None:
        return _run_inline(tasks, progress, fn)
    rows: list[dict] = []
    queue, alone = list(tasks), []
    while queue or alone:
        if alone:  # a task that was in flight when a worker died: alone, in a pool of its own
            task = alone.pop(0)
            broken, _ = _pool_rows([task], 1, fn, rows, progress, len(tasks))
            if broken:
                if crashed is None:
                    raise SweepError("a worker process died (a crash in compiled code?) running a task")
                rows.append(crashed(task, "its process died (a crash in compiled code, e.g. a segmentation fault)"))
                if progress is not None:
                    progress(len(rows), len(tasks), rows[-1])
            continue
        broken, started = _pool_rows(queue, workers, fn, rows, progress, len(tasks))
        # those in flight when a worker died are tried alone; those never started, in a new pool
        queue = queue[started:]
        alone += broken
    return rows


def _pool_rows(tasks, workers: int, fn, rows: list, progress: Progress | None, total: int) -> tuple[list, int]:
    """Run ``tasks`` in order on a new pool of ``workers`` processes, at most ``workers`` in
    flight, appending each result to ``rows``; returns (the tasks in flight when a worker died,
    else []; how many tasks were started). A pool a worker died in is given up: the tasks after
    those in flight are not started."""
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    before = set(multiprocessing.active_children())
    todo = list(tasks)
    broken: list = []
    started = 0
    with _signals_raise():
        ex = ProcessPoolExecutor(max_workers=workers, mp_context=_mp_context(), initializer=_ignore_sigint)
        try:
            running: dict = {}
            while todo or running:
                while todo and len(running) < workers and not broken:
                    task = todo.pop(0)
                    with _signals_deferred():  # workers start inside submit(): never leave one half-started
                        running[ex.submit(fn, task)] = task
                    started += 1
                if not running:
                    break
                done, _ = wait(set(running), timeout=0.5, return_when=FIRST_COMPLETED)
                for f in done:
                    task = running.pop(f)
                    try:
                        rows.append(f.result())
                    except BrokenProcessPool:
                        broken.append(task)
                        continue
                    if progress is not None:
                        progress(len(rows), total, rows[-1])
        except BaseException:  # Ctrl-C or an error: stop the workers now, not after their runs
            _stop_pool(ex, before)
            raise
        if broken:
            _stop_pool(ex, before)
        else:
            ex.shutdown(wait=True)
    return broken, started


def _stop_pool(ex, before: set) -> None:
    """Stop the workers of pool ``ex`` now (those not among ``before``, the processes alive before
    it), not after their runs."""
    terminate = getattr(ex, "terminate_workers", None)  # Python >= 3.14
    if terminate is not None:
        terminate()
        return
    # the pool's workers, including one whose start Ctrl-C interrupted before the pool registered it
    procs = set((getattr(ex, "_processes", None) or {}).values())
    procs |= set(multiprocessing.active_children()) - before
    ex.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        p.terminate()
    for p in procs:
        p.join(timeout=5)


def _run_ray(tasks, address: str | None, progress: Progress | None, fn=run_task) -> list[dict]:
    try:
        import ray
    except ImportError:
        raise SweepError("--backend ray: Ray is not installed (pip install 'mpcdrive[ray]')") from None
    with _signals_raise():
        return _ray_rows(ray, tasks, address, progress, fn)


def _ray_rows(ray, tasks, address: str | None, progress: Progress | None, fn) -> list[dict]:
    started = False
    if not ray.is_initialized():
        kwargs = {"address": address} if address else {"include_dashboard": False}
        ray.init(**kwargs, logging_level="ERROR", log_to_driver=False)
        started = True
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(fn)
        cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
        queue = list(tasks)
        pending, rows = [], []
        try:
            while queue or pending:
                while queue and len(pending) < 4 * cpus:  # bounded number of tasks in flight
                    pending.append(remote.remote(queue.pop(0)))
                done, pending = ray.wait(pending, num_returns=1, timeout=0.5)
                for ref in done:
                    rows.append(ray.get(ref))
                    if progress is not None:
                        progress(len(rows), len(tasks), rows[-1])
        except BaseException:
            for ref in pending:
                ray.cancel(ref, force=True)
            raise
        return rows
    finally:
        if started:
            ray.shutdown()


def run_sweep(
    plan: SweepPlan,
    backend: str = "local",
    workers: int | None = None,
    address: str | None = None,
    progress: Progress | None = None,
) -> list[dict]:
    """Run every task of ``plan``; rows sorted by run id.

    backend : ``local`` (a process pool of ``workers`` processes, all cores by default; 1 runs in
    this process) or ``ray`` (tasks on the Ray cluster at ``address``, a new local one when None;
    the cluster's nodes need mpcdrive installed). ``progress(done, total, row)`` after each run."""
    return sorted(
        run_parallel(run_task, list(plan.tasks), backend, workers, address, progress), key=lambda r: r["run_id"]
    )


def run_parallel(
    fn,
    tasks: list,
    backend: str = "local",
    workers: int | None = None,
    address: str | None = None,
    progress: Progress | None = None,
    crashed: Callable | None = None,
) -> list:
    """``fn(task)`` for every task, in completion order, on ``backend`` (as :func:`run_sweep`);
    ``fn`` must be a top-level function that never raises (its result reports an error). With
    ``crashed`` every task runs in a worker process (one worker too), and a task whose process
    dies gets the row ``crashed(task, reason)``: the others go on (:func:`_run_local`)."""
    if backend not in ("local", "ray"):
        raise SweepError(f"--backend must be 'local' or 'ray', got {backend!r}")
    if address is not None and backend != "ray":
        raise SweepError("--address is only for --backend ray")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise SweepError(f"--workers must be an integer >= 1, got {workers!r}")
    if backend == "ray" and workers is not None:
        raise SweepError("--workers is only for --backend local (Ray uses the cluster's CPUs)")
    if backend == "ray":
        return _run_ray(tasks, address, progress, fn)
    return _run_local(tasks, workers or os.cpu_count() or 1, progress, fn, crashed)
