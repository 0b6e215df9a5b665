"""The command line as docs/interfaces.md describes it, run as a user would (subprocess)."""

import csv
import json
import subprocess
import sys

import pytest
import yaml

REQUIRED_COLUMNS = ["t", "x", "y", "yaw", "v", "steer", "accel", "s", "e_y", "e_psi", "solve_time_us", "status"]
REQUIRED_METRICS = [
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
    "solver_failures",
    "fallbacks",
    "solve_time_us",
    "goal_reached",
]


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "mpcdrive.cli", *args], capture_output=True, text=True, cwd=cwd)


def short_scenario(tmp_path, **extra):
    text = (
        "id: short\nduration_s: 0.3\n"
        "path: {type: circle, radius_m: 1.5}\n"
        "initial_state: {x_m: 1.5, y_m: 0.0, yaw_deg: 90}\n"
        "road: {lane_width_m: 1.0}\n"
        "controller: {horizon: 10, Q: [1, 1, 1], R: [1]}\n"
    )
    p = tmp_path / "short.yaml"
    p.write_text(text)
    return p


def test_list_names_every_paper_experiment():
    r = cli("list")
    assert r.returncode == 0
    ids = [line.split("\t")[0] for line in r.stdout.splitlines()]
    for sid in (
        "paper-exp1",
        "paper-exp2",
        "paper-exp3",
        "paper-exp4",
        "paper-disturbance-v1",
        "paper-disturbance-v4",
        "paper-smoothing",
    ):
        assert sid in ids


def test_run_writes_the_contract_files(tmp_path):
    out = tmp_path / "out"
    r = cli("run", str(short_scenario(tmp_path)), "--out", str(out), "-q")
    assert r.returncode == 0, r.stderr
    with open(out / "trajectory.csv") as f:
        rows = list(csv.reader(f))
    assert rows[0][: len(REQUIRED_COLUMNS)] == REQUIRED_COLUMNS
    assert len(rows) == 1 + 30
    assert {row[REQUIRED_COLUMNS.index("status")] for row in rows[1:]} == {"ok"}
    metrics = json.loads((out / "metrics.json").read_text())
    for key in REQUIRED_METRICS:
        assert key in metrics
    assert set(metrics["solve_time_us"]) == {"p50", "p99", "max"}
    assert metrics["steps"] == 30 and metrics["max_lane_excess_m"] == 0.0
    assert (out / "scenario.yaml").read_text().startswith("id: short")
    assert (out / "trajectory.png").stat().st_size > 1000
    page = (out / "report.html").read_text(encoding="utf-8")  # the interactive report
    assert page.startswith("<!DOCTYPE html>") and '"steps":30' in page and '"left":[[' in page
    assert page.count("data:image/png;base64,") == len(list(out.glob("*.png")))
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert metrics["controller_backend"] == "fast"  # compiled by default


def test_run_fast_uses_the_compiled_controller_with_the_same_commands(tmp_path):
    """``--fast`` runs the scenario on the fast path (recorded in metrics.json and the resolved
    scenario) and steers as the OSQP reference does."""
    runs = {}
    for name, extra in (("ref", ("--osqp",)), ("fast", ("--fast",))):
        out = tmp_path / name
        r = cli("run", str(short_scenario(tmp_path)), "--out", str(out), "-q", *extra)
        assert r.returncode == 0, r.stderr
        runs[name] = (
            json.loads((out / "metrics.json").read_text()),
            list(csv.DictReader((out / "trajectory.csv").read_text().splitlines())),
        )
    assert runs["fast"][0]["controller_backend"] == "fast" and runs["ref"][0]["controller_backend"] == "osqp"
    resolved = {k: yaml.safe_load((tmp_path / k / "scenario.yaml").read_text())["controller"] for k in runs}
    assert resolved["fast"]["backend"] == "fast" and "solver" not in resolved["fast"]  # says what ran
    assert resolved["ref"]["backend"] == "osqp" and resolved["ref"]["solver"] == "osqp"
    steer = {k: [float(row["steer"]) for row in v[1]] for k, v in runs.items()}
    assert max(abs(a - b) for a, b in zip(steer["fast"], steer["ref"])) < 1e-4


@pytest.mark.parametrize(
    "args, words",
    [
        (["run", "no-such-scenario"], "no built-in scenario"),
        (["run", "{bad}.yaml"], "file not found"),
        (["run"], "Missing argument"),
        (["bench", "--problem", "P9"], "unknown problem"),
        (["reproduce", "--only", "paper-exp99"], "unknown experiment"),
        (["run", "paper-exp1", "--bogus"], "No such option"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, args, words):
    r = cli(*args, cwd=tmp_path)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert words in r.stderr
    assert not (tmp_path / "runs").exists()


def test_bad_scenario_field_exits_2_naming_file_and_field(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("id: bad\nduration_s: 1\npath: {type: circle, radius_m: -1}\ncontroller: {Q: [1,1,1], R: [1]}\n")
    r = cli("run", str(p), "--out", str(tmp_path / "o"))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1
    assert str(p) in lines[0] and "path.radius_m" in lines[0] and "greater than 0" in lines[0]
    assert not (tmp_path / "o").exists()


def test_existing_output_directory_is_not_overwritten(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    r = cli("run", str(short_scenario(tmp_path)), "--out", str(out), "-q")
    assert r.returncode == 2
    assert (out / "keep.txt").read_text() == "mine"


@pytest.mark.slow
def test_reproduce_subset_writes_report(tmp_path):
    out = tmp_path / "rep"
    r = cli("reproduce", "--out", str(out), "--only", "paper-exp3", "--only", "paper-disturbance-v4", "-q")
    assert r.returncode == 0, r.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics) == {"paper-exp3", "paper-disturbance-v4"}
    report = (out / "report.md").read_text()
    assert "paper-exp3/trajectory.png" in report and "paper" in report
    for sid in metrics:
        assert (out / sid / "trajectory.csv").exists()
        assert (out / sid / "report.html").exists()
    page = (out / "report.html").read_text(encoding="utf-8")  # one page, every experiment
    assert '<select id="experiment">' in page
    assert all(f'<option value="{sid}">' in page for sid in metrics)


def test_bench_json(tmp_path):
    out = tmp_path / "b.json"
    r = cli("bench", "--problem", "P1", "--steps", "40", "--json", str(out))
    assert r.returncode == 0, r.stderr
    data = json.loads(out.read_text())
    rec = data["P1"]["mpcdrive"]
    assert set(rec) >= {"p50_us", "p99_us", "max_us", "steps", "rms_lateral_error_m"}
    assert rec["steps"] == 40 and rec["p50_us"] > 0


def test_usage_errors_are_one_line(tmp_path):
    r = cli("run", "paper-exp1", "--bogus", cwd=tmp_path)
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_compare_avoidance_table(tmp_path):
    out = tmp_path / "cmp"
    r = cli(
        "compare-avoidance",
        "--out",
        str(out),
        "--scenario",
        "paper-exp5-hard",
        "--formulation",
        "hard",
        "--formulation",
        "gaussian",
        "-q",
    )
    assert r.returncode == 0, r.stderr
    text = (out / "avoidance.md").read_text()
    assert "| `paper-exp5-hard` | hard |" in text and "| `paper-exp5-hard` | gaussian |" in text
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["paper-exp5-hard"]["hard"]["collisions"] == 0
    assert (out / "cost_map_gaussian.png").exists() and (out / "paper-exp5-hard.png").exists()
    bad = cli("compare-avoidance", "--formulation", "magnets")
    assert bad.returncode == 2 and "unknown magnets" in bad.stderr


def test_reproduce_fast_runs_every_selected_experiment_compiled(tmp_path):
    """``reproduce --fast``, including the Gaussian cost map that reads the controller's obstacles."""
    out = tmp_path / "rep"
    r = cli(
        "reproduce", "--out", str(out), "--only", "paper-exp5-gaussian", "--only", "paper-exp5-hard", "--fast", "-q"
    )
    assert r.returncode == 0, r.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert {m["controller_backend"] for m in metrics.values()} == {"fast"}
    assert (out / "gaussian_cost_map.png").stat().st_size > 1000


def test_scenario_warning_is_one_line_on_stderr_and_the_run_goes_on(tmp_path):
    p = tmp_path / "rad.yaml"
    p.write_text(short_scenario(tmp_path).read_text().replace("R: [1]}", "R: [1], max_steer_deg: 0.7}"))
    r = cli("run", str(p), "--out", str(tmp_path / "out"), "-q")
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if "warning" in ln]
    # 0.7 deg of steering cannot turn the 1.5 m circle either: that is the second warning
    assert lines[0] == (
        f"mpcdrive: warning: {p}: controller.max_steer_deg: 0.7 looks like radians "
        "(0.7 rad = 40.11 deg); this field is in degrees"
    ), r.stderr
    assert len(lines) == 2 and lines[1].startswith(f"mpcdrive: warning: {p}: path: ") and "cannot follow" in lines[1], (
        r.stderr
    )
    assert (tmp_path / "out" / "metrics.json").is_file()


def test_run_summary_states_the_safety_outcome(tmp_path):
    r = cli("run", str(short_scenario(tmp_path)), "--out", str(tmp_path / "out"), "-q")
    assert r.returncode == 0, r.stderr
    line = r.stdout.splitlines()[0]
    assert line.startswith("short: inside the lane; steering at its angle limit "), line
    assert "% of the time; no failed solves | 30 steps" in line, line


@pytest.mark.parametrize(
    "args",
    [["run", "SHORT"], ["reproduce", "--only", "paper-exp3"], ["sweep", "SHORT", "--runs", "2"], ["compare-models"]],
    ids=["run", "reproduce", "sweep", "compare-models"],
)
def test_an_out_that_cannot_be_made_is_bad_input_naming_out(tmp_path, args):
    """A file where the output folder's parent must be: exit 2 and one line naming --out and the
    path as given (not the hidden temporary name), before anything runs; nothing is written."""
    scenario = short_scenario(tmp_path)
    (tmp_path / "afile").write_text("in the way")
    before = sorted(p.name for p in tmp_path.iterdir())
    args = [str(scenario) if a == "SHORT" else a for a in args]
    r = cli(*args, "--out", "afile/out", "-q" if args[0] != "compare-models" else "--no-robustness", cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip() == "mpcdrive: --out: cannot write afile/out: afile is a file, not a folder", r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == before
