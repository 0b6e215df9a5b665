"""No lost or half-written output: a run, a reproduce or a sweep that is interrupted (Ctrl-C,
SIGTERM) or fails part-way leaves either its complete output directory or nothing, and says so."""

import os
import signal
import subprocess
import sys
import time

import pytest

import mpcdrive.scenarios
from mpcdrive.cli import main

LONG = (  # long enough (minutes) that a signal the command lost shows as a resend, not an end
    "id: long\nduration_s: 3600.0\n"
    "path: {type: circle, radius_m: 1.5}\n"
    "initial_state: {x_m: 1.5, y_m: 0.0, yaw_deg: 90}\n"
    "controller: {horizon: 10, Q: [1, 1, 1], R: [1]}\n"
)


def _start(tmp_path, *args):
    scen = tmp_path / "long.yaml"
    scen.write_text(LONG)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    # a shell's background job ignores SIGINT and children inherit that: restore the default, as
    # in a terminal, so that Python turns SIGINT into KeyboardInterrupt
    return subprocess.Popen(
        [sys.executable, "-m", "mpcdrive.cli", *[str(scen) if a == "SCEN" else a for a in args]],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


def _wait_for_temp_dir(tmp_path, proc, timeout_s=60.0):
    """Wait until the command has created its temporary output directory (it is running)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if [p for p in tmp_path.iterdir() if p.name.startswith(".out.")]:
            time.sleep(1.0)  # well inside the simulation
            return
        if proc.poll() is not None:
            pytest.fail(f"the command ended early: {proc.communicate()}")
        time.sleep(0.1)
    proc.kill()
    pytest.fail("the command never started its output")


@pytest.mark.parametrize(
    "args, sig",
    [
        (["run", "SCEN", "-q"], signal.SIGINT),
        (["run", "SCEN"], signal.SIGTERM),  # with the progress bar on
        (["sweep", "SCEN", "--runs", "4", "--workers", "2", "-q"], signal.SIGINT),
    ],
    ids=["run-sigint", "run-sigterm", "sweep-sigint"],
)
def test_interrupted_command_leaves_no_output_and_says_so(tmp_path, args, sig):
    out = tmp_path / "out"
    proc = _start(tmp_path, *args, "--out", str(out))
    _wait_for_temp_dir(tmp_path, proc)
    # OSQP listens for Ctrl-C during a solve and reports it as its status; a SIGINT that lands as
    # a solve is ending is taken by its listener and not reported (seen once in a few hundred
    # runs): as a user would, press it again if the command goes on -- after long enough for a
    # loaded machine to clean up (a second Ctrl-C during the cleanup of the first ends Python with
    # the signal itself: seen with 10 s on 2 busy cores)
    err = None
    for _ in range(3):
        proc.send_signal(sig)
        try:
            _, err = proc.communicate(timeout=40)
            break
        except subprocess.TimeoutExpired:
            continue
    if err is None:
        proc.kill()
        pytest.fail("the command did not stop after the signal, sent three times")
    assert proc.returncode == 130, err
    assert "interrupted; no partial output was kept" in err
    assert "Traceback" not in err
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.yaml"]  # no temporary directory left


def _fail_after(n_steps):
    """run_experiment whose simulation raises after ``n_steps`` steps."""
    real = mpcdrive.scenarios.run_experiment

    def run(exp, progress=None):
        def boom(k, total):
            if k >= n_steps:
                raise RuntimeError("simulated crash mid-run")

        return real(exp, progress=boom)

    return run


@pytest.mark.parametrize(
    "args",
    [["run", "paper-exp3"], ["reproduce", "--only", "paper-exp3", "--only", "paper-exp4"]],
    ids=["run", "reproduce"],
)
def test_exception_mid_run_leaves_no_output_and_says_so(tmp_path, capsys, monkeypatch, args):
    calls = []
    failing = _fail_after(50)

    def second_fails(exp, progress=None):  # reproduce: the first experiment completes, the second fails
        calls.append(exp.spec.id)
        if args[0] == "reproduce" and len(calls) == 1:
            return mpcdrive.scenarios.build.run_experiment(exp, progress)
        return failing(exp, progress)

    monkeypatch.setattr(mpcdrive.scenarios, "run_experiment", second_fails)
    out = tmp_path / "out"
    monkeypatch.setattr(sys, "argv", ["mpcdrive", *args, "--out", str(out), "-q"])
    with pytest.raises(SystemExit) as ex:
        main()
    assert ex.value.code == 1
    err = capsys.readouterr().err
    last = err.splitlines()[-1]  # (reproduce logs its progress above)
    assert last.startswith("mpcdrive: error: RuntimeError: simulated crash mid-run; no partial output was kept")
    assert sum(1 for line in err.splitlines() if line.startswith("mpcdrive:")) == 1
    assert not out.exists() and list(tmp_path.iterdir()) == []
    assert len(calls) == (2 if args[0] == "reproduce" else 1)


def test_the_signal_handler_leaves_nothing_uncommitted_and_ends_with_130(tmp_path, monkeypatch, capfd):
    """The command line's handler ends the process at once (no exception unwinds the code it
    interrupted): it removes every output not committed yet -- an output directory, a file being
    written, the parent directories made for them -- and keeps what is committed."""
    from mpcdrive.cli import interrupt
    from mpcdrive.io.atomic import atomic_output_dir, atomic_write_text

    seen = {}

    def fake_exit(code):  # what is on disk when the process would end
        seen["code"] = code
        seen["left"] = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
        raise SystemExit(code)

    monkeypatch.setattr(os, "_exit", fake_exit)
    monkeypatch.setattr(signal, "signal", lambda *a: None)  # (the test process keeps its handlers)
    atomic_write_text(tmp_path / "done" / "kept.txt", "committed")
    with pytest.raises(SystemExit):
        with atomic_output_dir(tmp_path / "runs" / "deep" / "out") as tmp:
            (tmp / "metrics.json").write_text("{}")
            atomic_write_text(tmp / "sub" / "trajectory.csv", "t\n0\n")
            interrupt.exit_interrupted(signal.SIGTERM, None)
    assert seen == {"code": 130, "left": ["done", "done/kept.txt"]}
    assert capfd.readouterr().err.splitlines()[-1] == interrupt.MESSAGE


def test_a_failed_output_takes_the_parent_directories_made_for_it(tmp_path):
    from mpcdrive.io.atomic import atomic_output_dir

    with pytest.raises(RuntimeError):
        with atomic_output_dir(tmp_path / "runs" / "out") as tmp:
            (tmp / "metrics.json").write_text("{}")
            raise RuntimeError("failed part-way")
    assert list(tmp_path.iterdir()) == []
    with atomic_output_dir(tmp_path / "runs" / "out") as tmp:
        (tmp / "metrics.json").write_text("{}")
    assert [p.name for p in (tmp_path / "runs" / "out").iterdir()] == ["metrics.json"]
