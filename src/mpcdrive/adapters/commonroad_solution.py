"""CommonRoad's own solution checker on a written solution, isolated from the run's process.

``commonroad_dc.feasibility.solution_checker.valid_solution`` builds the road's boundary in
compiled code, which crashed the process on a generated road (a segmentation fault in its
triangulation). Where the platform forks it runs in a child process: its answer comes back as it
gave it, and a crash is a rejection that names the signal.
"""

from __future__ import annotations

import signal
from pathlib import Path


def solution_accepted(imp, solution_file: Path) -> tuple[bool, str]:
    """(accepted, reason): CommonRoad's own solution checker
    (``commonroad_dc.feasibility.solution_checker.valid_solution``) on the written solution file.

    The checker builds the road's boundary in compiled code that can crash the process on some
    maps (a segmentation fault triangulating a generated road with a bend): where the platform
    forks, it runs in a child process, and a crash is a rejection that says so, the run and a
    batch going on."""
    import multiprocessing as mp

    if "fork" not in mp.get_all_start_methods():
        return _check_solution(imp.scenario, imp.problems, str(solution_file))
    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_check_solution_child, args=(imp.scenario, imp.problems, str(solution_file), send))
    try:
        child.start()
    except (AssertionError, OSError):  # a daemonic process cannot have children; no fork left
        recv.close()
        send.close()
        return _check_solution(imp.scenario, imp.problems, str(solution_file))
    send.close()
    try:
        got = recv.recv()
    except EOFError:  # the child died without answering
        got = None
    finally:
        recv.close()
        child.join()
    if got is None:
        code = child.exitcode
        how = signal.Signals(-code).name if code is not None and code < 0 else f"exit code {code}"
        return False, f"CommonRoad's solution checker crashed ({how}) on this scenario: not accepted"
    return got


def _check_solution(scenario, problems, solution_file: str) -> tuple[bool, str]:
    from commonroad.common.solution import CommonRoadSolutionReader
    from commonroad_dc.feasibility.solution_checker import valid_solution

    try:
        sol = CommonRoadSolutionReader.open(solution_file)
        ok, _ = valid_solution(scenario, problems, sol)
    except Exception as e:  # the checker raises SolutionCheckerException (and others) with its reason
        return False, " ".join(f"{type(e).__name__}: {e}".split())[:300]
    return bool(ok), "accepted" if ok else "rejected"


def _check_solution_child(scenario, problems, solution_file: str, send) -> None:
    """:func:`_check_solution` in a forked child, its answer sent back."""
    send.send(_check_solution(scenario, problems, solution_file))
    send.close()
