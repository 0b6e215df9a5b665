"""The documents under docs/ state what the code does: checked against the code, so they cannot
drift (the README has its own test, test_readme.py)."""

import re
from pathlib import Path

import pytest

from mpcdrive.experiments import PAPER_EXPERIMENTS
from mpcdrive.scenarios import load_scenario

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _paper_settings_table() -> dict[str, tuple[str, str]]:
    """docs/paper.md's table of settings: controller key -> (the paper's value, the scenarios')."""
    text = (DOCS / "paper.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| `controller\.([a-z_]+)` \| `([a-z_0-9]+)`[^|]*\| `([a-z_0-9]+)`[^|]*\|$", text, re.M)
    assert rows, "docs/paper.md has no table of the paper scenarios' settings"
    return {key: (paper, ours) for key, paper, ours in rows}


@pytest.mark.parametrize("sid", PAPER_EXPERIMENTS)
def test_docs_paper_states_the_settings_each_paper_scenario_runs_with(sid):
    controller = load_scenario(sid).controller
    for key, (paper, ours) in _paper_settings_table().items():
        assert getattr(controller, key) == ours, (
            f"{sid}: controller.{key} is {getattr(controller, key)!r}, docs say {ours!r}"
        )
        assert paper in type(controller).model_fields[key].annotation.__args__, f"controller.{key}: no value {paper!r}"


BENCH_DOC = DOCS / "benchmarks.md"


def _bench_section(title: str) -> str:
    text = BENCH_DOC.read_text(encoding="utf-8")
    assert f"\n## {title}\n" in text, f"docs/benchmarks.md has no section {title!r}"
    return text.split(f"\n## {title}\n", 1)[1].split("\n## ", 1)[0]


def test_docs_benchmarks_names_every_implementation_and_the_default():
    from mpcdrive.bench.runner import BACKENDS, DEFAULT_BACKEND

    rows = dict(re.findall(r"^\| `([a-z_\[\]/]+)`[^|]*\| (.*) \|$", _bench_section("How latency is measured"), re.M))
    names = {f"mpcdrive_{b}" for b in BACKENDS} | {"mpcdrive", "cvxpy_rebuild", "casadi_ipopt", "mpcdrive_same_steps"}
    assert names <= set(rows), f"implementations not described: {sorted(names - set(rows))}"
    for b in BACKENDS:
        says_default = "the default controller" in rows[f"mpcdrive_{b}"]
        assert says_default == (b == DEFAULT_BACKEND), f"mpcdrive_{b}: {rows[f'mpcdrive_{b}']}"
    if DEFAULT_BACKEND != "osqp":  # nowhere called the default
        text = BENCH_DOC.read_text(encoding="utf-8")
        wrong = re.findall(r"(?i)osqp[^.|\n]{0,30}\bthe default\b[^.|\n]{0,20}|\bdefault \(osqp\)", text)
        assert not wrong, f"docs/benchmarks.md calls OSQP the default: {wrong}"


def _doc_loops() -> dict[str, list[str]]:
    """'The figures now': the table of what each loop did, row label -> cells."""
    out = {}
    for line in _bench_section("The figures now").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 7 and cells[0].startswith("P") and cells[6][:1].isdigit():
            out[cells[0]] = cells
    assert out, "no table of what each loop did"
    return out


def test_docs_benchmarks_states_what_the_loops_do_now():
    """The safety and tracking figures of the benchmark loops do not depend on the machine: the
    doc's must be those the default controller drives today (a change that moves them must
    update the doc)."""
    from dataclasses import replace

    from mpcdrive.bench.problems import PROBLEMS
    from mpcdrive.bench.runner import SQP_MAX_ITERATIONS, SQP_TOL, make_controller, time_closed_loop

    rows = _doc_loops()
    loops = {name: PROBLEMS[name]() for name in PROBLEMS}
    p3 = loops["P3"]
    loops["P3, SQP to convergence"] = replace(
        p3, config=replace(p3.config, sqp_max_iterations=SQP_MAX_ITERATIONS, sqp_tol=SQP_TOL, sqp_max_time_s=None)
    )
    assert set(rows) == set(loops), sorted(rows)
    for label, prob in loops.items():
        got = time_closed_loop(make_controller(prob), prob, prob.steps or 1000)
        rms, failures, clearance, collisions, _, qps = rows[label][1:]
        assert float(rms.split()[0]) == pytest.approx(got["rms_lateral_error_m"], abs=6e-6), label
        assert int(failures) == got["solver_failures"], label
        if got["min_obstacle_clearance_m"] is None:
            assert clearance == "—" and collisions == "—", label
        else:
            assert float(clearance) == pytest.approx(got["min_obstacle_clearance_m"], abs=6e-4), label
            assert int(collisions) == got["collision_steps"], label
        assert float(qps) == pytest.approx(got["qps_per_step"], abs=6e-3), label
