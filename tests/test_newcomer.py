"""A new user's first commands, run as they would be: from their own working directory, with the
default (relative) output folders, reading what the tool prints."""

import json
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from mpcdrive import __version__


def cli(*args, cwd, env=None):
    return subprocess.run(
        [sys.executable, "-m", "mpcdrive.cli", *args], capture_output=True, text=True, cwd=cwd, env=env
    )


def _short(tmp_path, name="short.yaml"):
    p = tmp_path / name
    p.write_text(
        "id: short\nduration_s: 0.3\npath: {type: circle, radius_m: 1.5}\n"
        "initial_state: {x_m: 1.5, y_m: 0.0, yaw_deg: 90}\nroad: {lane_width_m: 1.0}\n"
        "controller: {horizon: 10, Q: [1, 1, 1], R: [1]}\n"
    )
    return p


def _only_dir(parent):
    dirs = [d for d in parent.iterdir() if d.is_dir()]
    assert len(dirs) == 1, dirs
    return dirs[0]


def test_run_with_the_default_output_folder_from_another_directory(tmp_path):
    """The default --out is relative, named after the file (runs/<file stem>-<timestamp>, not the
    id inside it, as the README says); the HTML report used to join the report folder to figure
    paths already relative to the working directory and crashed."""
    scenario = _short(tmp_path, "my-first.yaml")  # (its id: short)
    work = tmp_path / "work"
    work.mkdir()
    r = cli("run", str(scenario), "-q", cwd=work)
    assert r.returncode == 0, r.stderr
    out = _only_dir(work / "runs")
    assert out.name.startswith("my-first-")
    assert f"wrote {Path('runs') / out.name}" in r.stdout
    for name in ("trajectory.csv", "metrics.json", "scenario.yaml", "report.html", "trajectory.png"):
        assert (out / name).is_file(), name
    assert "<img" in (out / "report.html").read_text(encoding="utf-8")


def test_relative_out_for_run_and_reproduce(tmp_path):
    r = cli("run", str(_short(tmp_path)), "--out", "rel/run1", "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "rel" / "run1" / "report.html").is_file()
    r = cli("reproduce", "--only", "paper-exp3", "--out", "rel/rep", "-q", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "rel" / "rep" / "report.html").is_file()
    assert set(json.loads((tmp_path / "rel" / "rep" / "metrics.json").read_text())) == {"paper-exp3"}


@pytest.mark.slow
def test_compare_avoidance_with_a_relative_out_counts_its_runs(tmp_path):
    r = cli(
        "compare-avoidance",
        "--scenario",
        "paper-exp5-hard",
        "--formulation",
        "hard",
        "--formulation",
        "gaussian",
        "--out",
        "cmp",
        "-q",
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "cmp" / "avoidance.md").is_file()
    assert "[1/2] paper-exp5-hard / hard" in r.stderr and "[2/2] paper-exp5-hard / gaussian" in r.stderr


def test_outputs_are_created_as_the_umask_says(tmp_path):
    """Results are readable like any file the user writes (temporary names made them 0600/0700)."""
    env = dict(os.environ)
    script = (
        "import os, sys; os.umask(0o022); sys.argv = ['mpcdrive', 'run', sys.argv[1], '--out', 'o', '-q'];"
        "from mpcdrive.cli import main; main()"
    )
    r = subprocess.run(
        [sys.executable, "-c", script, str(_short(tmp_path))], capture_output=True, text=True, cwd=tmp_path, env=env
    )
    assert r.returncode == 0, r.stderr
    out = tmp_path / "o"
    assert stat.S_IMODE(out.stat().st_mode) == 0o755
    for f in out.iterdir():
        assert stat.S_IMODE(f.stat().st_mode) == 0o644, f.name


def test_version_and_python_dash_m(tmp_path):
    r = cli("--version", cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.strip() == f"mpcdrive {__version__}"
    r = subprocess.run([sys.executable, "-m", "mpcdrive", "--version"], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.strip() == f"mpcdrive {__version__}"


def test_bare_command_shows_the_help(tmp_path):
    r = cli(cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "Usage:" in r.stdout and "reproduce" in r.stdout and len(r.stdout.splitlines()) > 5


def test_flags_have_no_bool_metavar(tmp_path):
    for cmd in ("run", "reproduce", "sweep", "bench", "compare-avoidance", "compare-models", "commonroad"):
        r = cli(cmd, "--help", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        options = [ln for ln in r.stdout.splitlines() if ln.lstrip().startswith("-")]
        assert "<bool>" not in r.stdout and not any("<list[" in ln for ln in options), cmd


def test_sweep_reports_progress_when_stderr_is_not_a_terminal(tmp_path):
    r = cli(
        "sweep",
        str(_short(tmp_path)),
        "--runs",
        "4",
        "--seed",
        "1",
        "--workers",
        "1",
        "--out",
        "sw",
        "--vary",
        "initial_state.y_m=offset_uniform(-0.05, 0.05)",
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("sweep: ")]
    assert lines and lines[-1].startswith("sweep: 4/4 runs"), r.stderr


def test_first_compile_is_announced_once(tmp_path):
    """Before numba builds the fast controller's step for a spec (no cache for its sources yet),
    one line says so, once per spec."""
    import logging

    from mpcdrive.control import compiled_mpc

    records = []
    handler = logging.Handler()
    handler.emit = records.append
    log = logging.getLogger("mpcdrive")
    log.addHandler(handler)
    old_level = log.level
    log.setLevel(logging.INFO)
    try:
        announced = set(compiled_mpc._announced)
        compiled_mpc._announced.clear()
        real = compiled_mpc._jitcache.has_cache
        compiled_mpc._jitcache.has_cache = lambda dispatcher: False
        try:
            compiled_mpc._announce_compile(compiled_mpc.control_step(compiled_mpc.StepSpec(3)))
            compiled_mpc._announce_compile(compiled_mpc.control_step(compiled_mpc.StepSpec(3)))
            # another spec: its own step, its own line
            compiled_mpc._announce_compile(compiled_mpc.control_step(compiled_mpc.StepSpec(3, extras=True)))
        finally:
            compiled_mpc._jitcache.has_cache = real
            compiled_mpc._announced.clear()
            compiled_mpc._announced.update(announced)
    finally:
        log.removeHandler(handler)
        log.setLevel(old_level)
    assert len(records) == 2 and all("compiling the fast controller" in r.getMessage() for r in records)


def test_has_cache_finds_numba_index_files(tmp_path):
    mod = tmp_path / "tinyjit.py"
    mod.write_text("from numba import njit\n\n@njit(cache=True)\ndef twice(x):\n    return 2 * x\n")
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); import tinyjit; from mpcdrive import _jitcache;"
        "before = _jitcache.has_cache(tinyjit.twice); tinyjit.twice(1.0);"
        "print(before, _jitcache.has_cache(tinyjit.twice))"
    )
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "True"]


def test_has_cache_tells_the_steps_of_two_specs_apart(run_with_empty_numba_cache):
    """The compiled steps of all specs are made by one function in one file; numba names each
    one's cache index after the step's own name, so an index of one spec does not make another
    look cached (an empty cache directory: nothing is compiled here)."""
    code = (
        "from mpcdrive import _jitcache\n"
        "from mpcdrive.control.compiled_step import StepSpec, control_step\n"
        "a, b = control_step(StepSpec(3)), control_step(StepSpec(3, extras=True))\n"
        "before = [_jitcache.has_cache(a), _jitcache.has_cache(b)]\n"
        "where, stem = _jitcache._cache_location(a)\n"
        "where.mkdir(parents=True, exist_ok=True)\n"
        "(where / f'{stem}.{a.py_func.__name__}-{a.py_func.__code__.co_firstlineno}.py311.nbi').write_bytes(b'')\n"
        "print(*before, _jitcache.has_cache(a), _jitcache.has_cache(b))\n"
    )
    assert run_with_empty_numba_cache(code).split() == ["False", "False", "True", "False"]
