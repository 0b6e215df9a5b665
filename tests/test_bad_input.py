"""Every class of bad input we handle, in one table each for scenario files, the Python API and the
sweep options: a clear one-line error naming the field, exit code 2 from the CLI, never garbage.

Running this file as a script prints the table (class -> message) for the docs."""

import math
import sys
import warnings

import numpy as np
import pytest
import yaml

from mpcdrive.cli import main
from mpcdrive.scene.road import Road
from mpcdrive.control import DelayCompensator, FallbackConfig, MpcConfig, PythonLtvMpc
from mpcdrive.models import KinematicBicycle3, KinematicParams
from mpcdrive.ocp import MpcProblem
from mpcdrive.paths import CirclePath, StraightPath, WaypointPath
from mpcdrive.scenarios import ScenarioError, load_scenario
from mpcdrive.sim import Disturbance, Plant, SteeringActuator, simulate
from mpcdrive.solvers.osqp_backend import OsqpSettings
from mpcdrive.sweep import SuccessCriteria, SweepError, plan_sweep, run_sweep
from mpcdrive.types import WarmStart

BASE = {
    "id": "t",
    "duration_s": 0.2,
    "path": {"type": "straight", "start": [0, 0], "end": [5, 0]},
    "controller": {"horizon": 5, "Q": [1, 1, 1], "R": [1]},
}
K4 = {"vehicle": {"model": "kinematic4"}, "controller": {"horizon": 5, "Q": [1, 1, 1, 1], "R": [1, 1]}}


def _set(path, value):
    def f(d):
        node = d
        for k in path[:-1]:
            node = node.setdefault(k, {})
        node[path[-1]] = value

    return f


def _k4(extra_path, value):
    def f(d):
        d.update(yaml.safe_load(yaml.safe_dump(K4)))
        _set(extra_path, value)(d)

    return f


# (class, how to break BASE (a function of the dict) or raw YAML text, field named, words in the message)
SCENARIO_CASES = [
    ("unknown key", _set(["colour"], "red"), "colour", "unknown key"),
    ("unknown nested key", _set(["vehicle", "colour_rgb"], 3.0), "vehicle.colour_rgb", "unknown key"),
    ("misspelt key", _set(["controller", "horizn"], 3), "controller.horizn", "unknown key"),
    ("required key missing", lambda d: d.pop("controller"), "controller", "required key missing"),
    ("wrong type: text for a number", _set(["duration_s"], "long"), "duration_s", "valid number"),
    ("wrong type: quoted number", _set(["duration_s"], "10"), "duration_s", "valid number"),
    ("wrong type: boolean for a number", _set(["dt_s"], True), "dt_s", "valid number"),
    (
        "wrong type: fraction for an integer",
        _set(["controller", "horizon"], 10.5),
        "controller.horizon",
        "valid integer",
    ),
    ("wrong type: mapping for a list", _set(["controller", "Q"], {"a": 1}), "controller.Q", "valid list"),
    ("non-finite number (.nan)", _set(["dt_s"], float("nan")), "dt_s", "finite"),
    ("non-finite number (.inf)", _set(["initial_state", "x_m"], float("inf")), "initial_state.x_m", "finite"),
    (
        "non-finite number (1e400)",
        "id: t\nduration_s: 1e400\npath: {type: circle, radius_m: 1}\ncontroller: {Q: [1, 1, 1], R: [1]}\n",
        "duration_s",
        "finite",
    ),
    ("negative horizon", _set(["controller", "horizon"], -3), "controller.horizon", "greater than or equal to 1"),
    ("zero horizon", _set(["controller", "horizon"], 0), "controller.horizon", "greater than or equal to 1"),
    ("negative duration", _set(["duration_s"], -1.0), "duration_s", "greater than 0"),
    ("duration shorter than one step", _set(["duration_s"], 0.001), "duration_s", "shorter than one step"),
    ("negative seed", _set(["seed"], -1), "seed", "greater than or equal to 0"),
    ("bad id", _set(["id"], "a b/c"), "id", "pattern"),
    ("weights of the wrong length", _set(["controller", "Q"], [1, 1]), "controller.Q", "needs 3 entries"),
    ("negative weight", _set(["controller", "R"], [-1]), "controller.R.0", "greater than or equal to 0"),
    (
        "impossible: steering limit >= 90 deg",
        _set(["controller", "max_steer_deg"], 95),
        "controller.max_steer_deg",
        "below 90",
    ),
    (
        "impossible: speed limits reversed",
        _set(["controller", "speed_limits_mps"], [2, 0]),
        "controller.speed_limits_mps",
        "exceeds",
    ),
    (
        "impossible: accel limits reversed",
        _set(["controller", "accel_limits_mps2"], [1, -1]),
        "controller.accel_limits_mps2",
        "exceeds",
    ),
    (
        "impossible: accel limits exclude 0",
        _set(["controller", "accel_limits_mps2"], [0.5, 1]),
        "controller.accel_limits_mps2",
        "must include 0",
    ),
    (
        "impossible: no forward speed allowed",
        _set(["controller", "speed_limits_mps"], [-1, 0]),
        "controller.speed_limits_mps",
        "must be positive",
    ),
    ("impossible: lane narrower than the car", _set(["road"], {"lane_width_m": 0.2}), "road", "not wider than the car"),
    ("impossible: zero vehicle speed", _set(["vehicle", "speed_mps"], 0.0), "vehicle.speed_mps", "greater than 0"),
    ("path: straight with equal ends", _set(["path", "end"], [0, 0]), "path", "differ"),
    (
        "path: fewer than two points",
        _set(["path"], {"type": "waypoints", "points": [[0, 0]]}),
        "path.points",
        "at least 2",
    ),
    (
        "path: two points, one distinct",
        _set(["path"], {"type": "waypoints", "points": [[1, 1], [1, 1]]}),
        "path",
        "at least 2 distinct",
    ),
    (
        "path: closed with two points",
        _set(["path"], {"type": "waypoints", "points": [[0, 0], [1, 0]], "closed": True}),
        "path",
        "at least 3 distinct",
    ),
    ("path: zero radius", _set(["path"], {"type": "circle", "radius_m": 0}), "path.radius_m", "greater than 0"),
    ("path: unknown type", _set(["path", "type"], "spiral"), "path", "spiral"),
    ("path: point with three numbers", _set(["path", "start"], [0, 0, 0]), "path.start", "at most 2"),
    (
        "initial state: coordinates out of range",
        _set(["initial_state", "x_m"], 1e9),
        "initial_state.x_m",
        "less than or equal to 1000000",
    ),
    ("initial state: far from the path", _set(["initial_state", "y_m"], 5000.0), "initial_state", "from the path"),
    (
        "initial state: absurd yaw",
        _set(["initial_state", "yaw_deg"], 1e6),
        "initial_state.yaw_deg",
        "less than or equal to 3600",
    ),
    (
        "initial state: negative speed",
        _k4(["initial_state", "v_mps"], -1.0),
        "initial_state.v_mps",
        "greater than or equal to 0",
    ),
    (
        "initial state: absurd speed",
        _k4(["initial_state", "v_mps"], 1000.0),
        "initial_state.v_mps",
        "less than or equal to 100",
    ),
    (
        "noise: negative std",
        _set(["disturbance"], {"distribution": "normal", "std": [-1, 0, 0]}),
        "disturbance.std.0",
        "greater than or equal to 0",
    ),
    (
        "noise: low above high",
        _set(["disturbance"], {"distribution": "uniform", "low": [1, 0, 0], "high": [0, 0, 0]}),
        "disturbance",
        "low exceeds high",
    ),
    (
        "noise: wrong length",
        _set(["measurement_noise"], {"distribution": "normal", "std": [1, 1]}),
        "measurement_noise.std",
        "needs 3 entries",
    ),
    ("fallback: unknown rung", _set(["controller", "fallback"], ["relax", "pray"]), "controller.fallback.1", "relax"),
    (
        "fallback: ladder without a terminal rung",
        _set(["controller", "fallback"], ["relax"]),
        "controller.fallback",
        "must end with",
    ),
    (
        "fallback: zero braking",
        _set(["controller", "brake_decel_mps2"], 0.0),
        "controller.brake_decel_mps2",
        "greater than 0",
    ),
    (
        "plant: speed error on a speed-state model",
        _k4(["plant", "speed_mps"], 1.2),
        "plant.speed_mps",
        "only for the constant-speed model",
    ),
    ("plant: negative axle distance", _set(["plant", "lr_m"], -0.1), "plant.lr_m", "greater than 0"),
    (
        "obstacle on the start",
        _set(
            ["obstacles"],
            [
                {"shape": "circle", "position": [3, 1], "radius_m": 0.1},
                {"shape": "circle", "position": [0.3, 0.1], "radius_m": 0.1},
            ],
        ),
        "obstacles.1",
        "overlaps the car's footprint at the start",
    ),
    (
        "moving obstacle on the start",
        _set(
            ["obstacles"],
            [
                {
                    "shape": "rectangle",
                    "position": [0.5, 0.0],
                    "length_m": 0.6,
                    "width_m": 0.3,
                    "velocity_mps": [-1.0, 0.0],
                }
            ],
        ),
        "obstacles.0",
        "overlaps the car's footprint at the start",
    ),
    ("YAML: duplicate key", "id: t\nid: u\n", "line 2", "duplicate key 'id'"),
    ("YAML: malformed", "id: [unclosed\n", "line 2", "not valid YAML"),
    ("YAML: two documents", "id: t\n---\nid: u\n", "", "not valid YAML"),
    ("YAML: not a mapping", "- 1\n- 2\n", "", "mapping"),
    ("YAML: empty file", "", "", "mapping"),
]


def _write_case(tmp_path, mutate):
    p = tmp_path / "s.yaml"
    if isinstance(mutate, str):
        p.write_text(mutate)
    else:
        data = yaml.safe_load(yaml.safe_dump(BASE))
        mutate(data)
        p.write_text(yaml.safe_dump(data))
    return p


@pytest.mark.parametrize("cls, mutate, field, words", SCENARIO_CASES, ids=[c[0] for c in SCENARIO_CASES])
def test_bad_scenario_files(tmp_path, capsys, monkeypatch, cls, mutate, field, words):
    p = _write_case(tmp_path, mutate)
    with pytest.raises(ScenarioError) as e:
        load_scenario(p)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"{p}: {field}: " if field else f"{p}: "), msg  # where exactly
    assert words.lower() in msg.lower() and "(top level)" not in msg, msg
    # the CLI: exit code 2, one line on stderr naming the file, nothing written
    monkeypatch.setattr(sys, "argv", ["mpcdrive", "run", str(p), "--out", str(tmp_path / "out"), "-q"])
    with pytest.raises(SystemExit) as ex:
        main()
    assert ex.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(p) in err and words.lower() in err.lower()
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "cls, make, words",
    [
        ("file not found", lambda t: t / "nope.yaml", "file not found"),
        ("no such built-in", lambda t: "paper-exp99", "no built-in scenario"),
        ("unsupported file type", lambda t: (t / "s.txt").write_text("x") and t / "s.txt", "unsupported file type"),
        ("a directory", lambda t: (t / "d.yaml").mkdir() or t / "d.yaml", "cannot read file"),
        ("not UTF-8", lambda t: (t / "b.yaml").write_bytes(b"id: \xff\xfe\n") and t / "b.yaml", "cannot read file"),
    ],
    ids=lambda v: v if isinstance(v, str) else "",
)
def test_bad_scenario_sources(tmp_path, cls, make, words):
    with pytest.raises(ScenarioError, match=words):
        load_scenario(make(tmp_path))


# -- the Python API ------------------------------------------------------------------------------
def _p1(**kw):
    model = KinematicBicycle3(1.0)
    pb = MpcProblem(3, 1, 5, 0.01, Q=np.ones(3), R=1.0, u_min=-1.0, u_max=1.0)
    return model, PythonLtvMpc(model, StraightPath([0, 0], [5, 0]), pb, MpcConfig(**kw), "osqp")


def _sim(**kw):
    model, c = _p1()
    args = dict(controller=c, plant=Plant(model), path=c.path, x0=[0.0, 0.1, 0.0], dt_s=0.01, steps=3)
    args.update(kw)
    return simulate(**args)


def _step_state(x):
    _, c = _p1()
    return c.step(np.array(x, float), c.initial_warm([0.0, 0.0, 0.0]))


def _step_warm(u_prev):
    _, c = _p1()
    return c.step(np.zeros(3), WarmStart(s_m=0.0, u_prev=np.array(u_prev, float)))


def _step_delay_foreign_warm():
    model, c = _p1()
    d = DelayCompensator(c, model, SteeringActuator(dead_time_s=0.02), 0.01, c.path)
    return d.step(np.zeros(3), c.initial_warm([0.0, 0.0, 0.0]))  # the inner controller's warm start


NAN, INF = float("nan"), float("inf")
API_CASES = [
    ("controller: NaN state", lambda: _step_state([0, NAN, 0]), "state field(s) y not finite"),
    ("controller: state of the wrong size", lambda: _step_state([0, 0]), "state must have shape (3,)"),
    ("controller: NaN previous input", lambda: _step_warm([NAN]), "warm.u_prev must be 1 finite"),
    (
        "controller: model/problem size mismatch",
        lambda: PythonLtvMpc(
            KinematicBicycle3(),
            StraightPath([0, 0], [1, 0]),
            MpcProblem(4, 2, 5, 0.01, Q=1.0, R=1.0),
            MpcConfig(),
            "osqp",
        ),
        "problem is sized",
    ),
    (
        "DelayCompensator: warm start of the inner controller",
        _step_delay_foreign_warm,
        "warm must come from this DelayCompensator",
    ),
    ("MpcConfig: zero horizon step", lambda: MpcConfig(horizon_step_m=0.0), "horizon_step_m"),
    ("MpcConfig: NaN projection window", lambda: MpcConfig(projection_window_m=NAN), "projection_window_m"),
    ("MpcConfig: infinite reference speed", lambda: MpcConfig(v_ref_mps=INF), "v_ref_mps"),
    ("MpcConfig: unknown linearization", lambda: MpcConfig(linearization="exact"), "linearization"),
    ("FallbackConfig: bad ladder", lambda: FallbackConfig(("relax",)), "must end with"),
    ("MpcProblem: zero horizon", lambda: MpcProblem(3, 1, 0, 0.01, Q=1.0, R=1.0), "horizon N"),
    ("MpcProblem: fractional horizon", lambda: MpcProblem(3, 1, 2.5, 0.01, Q=1.0, R=1.0), "horizon N"),
    ("MpcProblem: NaN dt", lambda: MpcProblem(3, 1, 5, NAN, Q=1.0, R=1.0), "dt_s"),
    ("MpcProblem: zero states", lambda: MpcProblem(0, 1, 5, 0.01, Q=1.0, R=1.0), "nx must be a positive integer"),
    ("MpcProblem: NaN weight", lambda: MpcProblem(3, 1, 5, 0.01, Q=[1, NAN, 1], R=1.0), "Q contains non-finite"),
    ("MpcProblem: weight of the wrong size", lambda: MpcProblem(3, 1, 5, 0.01, Q=[1, 1], R=1.0), "Q must have 3"),
    ("MpcProblem: negative definite weight", lambda: MpcProblem(3, 1, 5, 0.01, Q=-1.0, R=1.0), "positive semidefinite"),
    (
        "MpcProblem: bounds reversed",
        lambda: MpcProblem(3, 1, 5, 0.01, Q=1.0, R=1.0, u_min=1, u_max=-1),
        "lower bound exceeds",
    ),
    ("MpcProblem: infinite lower bound", lambda: MpcProblem(3, 1, 5, 0.01, Q=1.0, R=1.0, u_min=INF), "impossible"),
    ("MpcProblem: NaN bound", lambda: MpcProblem(3, 1, 5, 0.01, Q=1.0, R=1.0, x_max=NAN), "NaN"),
    ("MpcProblem: zero rate limit", lambda: MpcProblem(3, 1, 5, 0.01, Q=1.0, R=1.0, du_max_per_s=0.0), "du_max_per_s"),
    ("MpcProblem: a lane width for a road", lambda: MpcProblem(3, 1, 5, 0.01, Q=1.0, R=1.0, road=-1), "road must be"),
    ("Road: edges swapped", lambda: Road(0.0, -1.0, 1.0), "is not left of its right edge"),
    ("Road: NaN width", lambda: Road.constant(NAN), "non-finite"),
    ("Road: knots not increasing", lambda: Road([0.0, 0.0], 1.0, -1.0), "strictly increasing"),
    (
        "MpcProblem: NaN slack weight",
        lambda: MpcProblem(3, 1, 5, 0.01, Q=1.0, R=1.0, lane_slack_weight=NAN),
        "lane_slack_weight",
    ),
    (
        "MpcProblem: singular input weight, unbounded inputs",
        lambda: MpcProblem(4, 2, 5, 0.01, Q=1.0, R=np.array([[1.0, 0.5], [0.5, 0.25]])),
        "positive definite",
    ),
    ("OsqpSettings: zero iterations", lambda: OsqpSettings(max_iter=0), "max_iter"),
    ("OsqpSettings: negative tolerance", lambda: OsqpSettings(eps_abs=-1.0), "eps_abs"),
    ("StraightPath: equal ends", lambda: StraightPath([1, 1], [1, 1]), "two finite points at least"),
    ("StraightPath: 3-D point", lambda: StraightPath([0, 0, 0], [1, 0, 0]), "must be points"),
    ("StraightPath: NaN point", lambda: StraightPath([0, NAN], [1, 0]), "two finite points at least"),
    ("CirclePath: NaN centre", lambda: CirclePath([NAN, 0], 1.0), "center must be 2 finite"),
    ("CirclePath: zero radius", lambda: CirclePath([0, 0], 0.0), "radius_m"),
    ("CirclePath: NaN start angle", lambda: CirclePath([0, 0], 1.0, start_angle_rad=NAN), "start_angle_rad"),
    ("WaypointPath: one point", lambda: WaypointPath([[0, 0]]), "at least 2 distinct"),
    ("WaypointPath: repeated point", lambda: WaypointPath([[0, 0], [0, 0]]), "at least 2 distinct"),
    (
        "WaypointPath: closed with two points",
        lambda: WaypointPath([[0, 0], [1, 0]], closed=True),
        "at least 3 distinct",
    ),
    ("WaypointPath: infinite point", lambda: WaypointPath([[0, 0], [INF, 0]]), "non-finite"),
    ("WaypointPath: wrong shape", lambda: WaypointPath([[0, 0, 0], [1, 0, 0]]), "shape (M, 2)"),
    ("WaypointPath: zero table step", lambda: WaypointPath([[0, 0], [1, 0]], ds_m=0.0), "ds_m"),
    ("Path.project: NaN position", lambda: StraightPath([0, 0], [1, 0]).project([NAN, 0]), "2 finite numbers"),
    ("Path.project: NaN guess", lambda: StraightPath([0, 0], [1, 0]).project([0, 0], NAN), "s_guess"),
    ("Path.project: zero window", lambda: StraightPath([0, 0], [1, 0]).project([0, 0], 0.0, 0.0), "window_m"),
    ("KinematicParams: negative length", lambda: KinematicParams(lr_m=-0.1), "lf_m and lr_m"),
    ("KinematicParams: NaN length", lambda: KinematicParams(lf_m=NAN), "lf_m and lr_m"),
    ("KinematicBicycle3: infinite speed", lambda: KinematicBicycle3(INF), "v_mps must be finite"),
    ("Plant: zero substeps", lambda: Plant(KinematicBicycle3(), substeps=0), "substeps"),
    ("Plant: fractional substeps", lambda: Plant(KinematicBicycle3(), substeps=1.5), "substeps"),
    ("Plant: unknown integrator", lambda: Plant(KinematicBicycle3(), method="rk45"), "method"),
    ("Plant: not a model", lambda: Plant("bicycle"), "vehicle model"),
    ("Disturbance: NaN std", lambda: Disturbance("normal", std=[NAN, 0, 0]), "std must be finite"),
    ("Disturbance: negative std", lambda: Disturbance("normal", std=[-1.0, 0, 0]), "std must be >= 0"),
    ("Disturbance: NaN bound", lambda: Disturbance("uniform", low=[NAN] * 3, high=[1] * 3), "low must be finite"),
    ("Disturbance: low above high", lambda: Disturbance("uniform", low=[1] * 3, high=[0] * 3), "low exceeds high"),
    ("Disturbance: unknown distribution", lambda: Disturbance("cauchy"), "distribution"),
    ("simulate: NaN initial state", lambda: _sim(x0=[0.0, NAN, 0.0]), "x0 field(s) y not finite"),
    ("simulate: initial state of the wrong size", lambda: _sim(x0=[0.0, 0.0]), "x0 must have shape (3,)"),
    ("simulate: text initial state", lambda: _sim(x0="origin"), "x0 must be 3 numbers"),
    ("simulate: zero dt", lambda: _sim(dt_s=0.0), "dt_s must be a positive"),
    ("simulate: NaN dt", lambda: _sim(dt_s=NAN), "dt_s must be a positive"),
    ("simulate: zero steps", lambda: _sim(steps=0), "steps must be an integer >= 1"),
    ("simulate: fractional steps", lambda: _sim(steps=2.5), "steps must be an integer >= 1"),
    ("simulate: negative seed", lambda: _sim(seed=-1), "seed must be an integer >= 0"),
    ("simulate: a lane width for a road", lambda: _sim(road=-1.0), "road must be"),
    (
        "simulate: disturbance of the wrong size",
        lambda: _sim(disturbance=Disturbance("normal", std=[0.1, 0.1])),
        "disturbance.std needs 3 entries",
    ),
    ("simulate: measurement noise not a Disturbance", lambda: _sim(measurement_noise=0.1), "measurement_noise must be"),
]


@pytest.mark.parametrize("cls, call, words", API_CASES, ids=[c[0] for c in API_CASES])
def test_bad_python_api_input_is_a_value_error_naming_the_field(cls, call, words):
    with pytest.raises(ValueError) as e:
        call()
    msg = str(e.value)
    assert words in msg, msg
    assert "\n" not in msg


# -- sweep options --------------------------------------------------------------------------------
def _plan(vary=(), set_=(), runs=2, seed=0, scenario="paper-exp3"):
    return plan_sweep(load_scenario(scenario), runs, seed, list(vary), list(set_))


SWEEP_CASES = [
    (
        "--vary without =",
        lambda: _plan(["initial_state.y_m"]),
        "--vary 'initial_state.y_m': expected NAME=DISTRIBUTION (e.g. initial_state.y_m=uniform(-0.5, 0.5))",
    ),
    (  # its own example, not one of --vary's
        "--set without =",
        lambda: _plan(set_=["road.lane_width_m"]),
        "--set 'road.lane_width_m': expected NAME=VALUE (e.g. road.lane_width_m=0.8)",
    ),
    ("--vary bad name", lambda: _plan(["initial state=uniform(0,1)"]), "dotted path"),
    ("--vary unknown field", lambda: _plan(["initial_state.z_m=uniform(0,1)"]), "initial_state has no key 'z_m'"),
    (
        "--vary unknown section",
        lambda: _plan(["obstacles.0.center.0=uniform(0,1)"]),
        "obstacles has no item 0 (it is a list of 0 items)",
    ),
    ("--vary list index out of range", lambda: _plan(["path.center.5=uniform(0,1)"]), "path.center has no item 5"),
    ("--vary not a number", lambda: _plan(["path.center=uniform(0,1)"]), "not a number; vary one of its numbers"),
    ("--vary text field", lambda: _plan(["vehicle.model=uniform(0,1)"]), "not a number"),
    ("--vary unknown distribution", lambda: _plan(["initial_state.y_m=cauchy(0,1)"]), "unknown distribution 'cauchy'"),
    ("--vary not a distribution", lambda: _plan(["initial_state.y_m=0.5"]), "expected a distribution"),
    ("--vary wrong parameter count", lambda: _plan(["initial_state.y_m=uniform(0)"]), "takes 2 parameters"),
    ("--vary non-numeric parameter", lambda: _plan(["initial_state.y_m=uniform(a,1)"]), "'a' is not a number"),
    ("--vary non-finite parameter", lambda: _plan(["initial_state.y_m=normal(0,inf)"]), "not finite"),
    (
        "--vary reversed bounds",
        lambda: _plan(["initial_state.y_m=uniform(1,0)"]),
        "lower bound 1 exceeds upper bound 0",
    ),
    ("--vary negative sigma", lambda: _plan(["initial_state.y_m=normal(0,-1)"]), "standard deviation -1 is negative"),
    (
        "--vary scale of an unset value",
        lambda: _plan(["initial_state.v_mps=scale_uniform(0.8,1.2)"]),
        "is not set in this scenario",
    ),
    ("--vary the seed", lambda: _plan(["seed=uniform(0,9)"]), "gives every run its own seed"),
    ("--vary twice", lambda: _plan(["initial_state.y_m=uniform(0,1)", "initial_state.y_m=normal(0,1)"]), "given twice"),
    ("--vary invalid at its centre", lambda: _plan(["vehicle.lr_m=uniform(-2,-1)"]), "invalid scenario at its centre"),
    ("--set unknown field", lambda: _plan(set_=["road.width=1"]), "road"),
    ("--set invalid value", lambda: _plan(set_=["road.lane_width_m=-1"]), "not valid with these settings"),
    ("--set bad YAML", lambda: _plan(set_=["duration_s=[1,"]), "not valid YAML"),
    ("--runs zero", lambda: _plan(runs=0), "--runs must be an integer >= 1"),
    ("--seed negative", lambda: _plan(seed=-1), "--seed must be an integer >= 0"),
    ("--backend unknown", lambda: run_sweep(_plan(), backend="dask"), "--backend must be 'local' or 'ray'"),
    (
        "--address without ray",
        lambda: run_sweep(_plan(), address="127.0.0.1:6379"),
        "--address is only for --backend ray",
    ),
    ("--workers zero", lambda: run_sweep(_plan(), workers=0), "--workers must be an integer >= 1"),
    (
        "criteria: negative tolerance",
        lambda: SuccessCriteria(max_final_lateral_error_m=-1.0),
        "max_final_lateral_error_m",
    ),
]


@pytest.mark.parametrize("cls, call, words", SWEEP_CASES, ids=[c[0] for c in SWEEP_CASES])
def test_bad_sweep_options_are_one_line_sweep_errors(cls, call, words):
    with pytest.raises(SweepError) as e:
        call()
    msg = str(e.value)
    assert words in msg, msg
    assert "\n" not in msg


def test_bad_sweep_option_from_the_cli_exits_2_with_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(
        sys,
        "argv",
        [
            "mpcdrive",
            "sweep",
            "paper-exp3",
            "--runs",
            "2",
            "--vary",
            "initial_state.q=uniform(0,1)",
            "--out",
            str(tmp_path / "o"),
        ],
    )
    with pytest.raises(SystemExit) as ex:
        main()
    assert ex.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--vary initial_state.q" in err
    assert not (tmp_path / "o").exists()


def test_obstacle_near_the_start_is_judged_on_the_real_shapes(tmp_path):
    """A circle 0.12 m from the body's front-left corner (inside the body's bounding circle) is
    clear of the footprint (0.5 m x 0.27 m at the origin): accepted."""
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["obstacles"] = [{"shape": "circle", "position": [0.35, 0.2], "radius_m": 0.1}]
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump(data))
    assert len(load_scenario(p).obstacles) == 1


def test_commonroad_obstacle_on_the_start_is_rejected():
    pytest.importorskip("commonroad_dc")
    from pathlib import Path

    from mpcdrive.adapters.commonroad import load_commonroad
    from mpcdrive.scenarios import reject_initial_overlap

    f = Path(__file__).resolve().parent / "data" / "commonroad" / "ZAM_Tutorial-1_2_T-1.xml"
    spec = load_commonroad(f).spec
    init = spec.initial_state
    parked = spec.obstacles[0].model_copy(
        update={"position": (init.x_m + 1.0, init.y_m), "velocity_mps": None, "trajectory": None}
    )
    bad = spec.model_copy(update={"obstacles": [*spec.obstacles, parked]})
    with pytest.raises(ScenarioError) as e:
        reject_initial_overlap(bad, str(f))
    assert str(e.value).startswith(f"{f}: obstacles.{len(spec.obstacles)}: ") and "overlaps" in str(e.value)
    assert reject_initial_overlap(spec, str(f)) is spec


# (value that looks wrong, field named, words of the warning)
WARNING_CASES = [
    ("speed far beyond the model", _set(["vehicle", "speed_mps"], 100.0), "vehicle.speed_mps", "far beyond"),
    ("initial speed far beyond the model", _k4(["initial_state", "v_mps"], 60.0), "initial_state.v_mps", "far beyond"),
    (
        "steering limit in radians",
        _set(["controller", "max_steer_deg"], 0.7),
        "controller.max_steer_deg",
        "looks like radians",
    ),
    (
        "steering rate in radians",
        _set(["controller", "max_steer_rate_deg_s"], 1.5),
        "controller.max_steer_rate_deg_s",
        "looks like radians",
    ),
    ("dt in milliseconds", lambda d: d.update(dt_s=10, duration_s=20.0), "dt_s", "looks like milliseconds"),
    (
        "start outside the lane",
        lambda d: d.update(road={"lane_width_m": 1.0}, initial_state={"y_m": -0.8}),
        "initial_state",
        "outside the lane",
    ),
]


@pytest.mark.parametrize("cls, mutate, field, words", WARNING_CASES, ids=[c[0] for c in WARNING_CASES])
def test_suspicious_values_warn_once_naming_the_field(tmp_path, cls, mutate, field, words):
    from mpcdrive.types import ScenarioWarning

    p = _write_case(tmp_path, mutate)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_scenario(p)
    ours = [str(w.message) for w in caught if issubclass(w.category, ScenarioWarning)]
    assert len(ours) == 1, ours
    assert ours[0].startswith(f"{p}: {field}: ") and words in ours[0] and "\n" not in ours[0]


def test_valid_edge_inputs_still_run():
    """The limits are not too tight: a car facing backwards, 20 m off the path, 3 laps of yaw."""
    r = _sim(x0=[0.0, 20.0, math.radians(3 * 360 + 180)], steps=5)
    assert r.steps == 5 and np.all(np.isfinite(r.u))


if __name__ == "__main__":  # print the table: class -> message
    import pathlib
    import tempfile

    print("| class | message |\n|---|---|")
    with tempfile.TemporaryDirectory() as d:
        for cls, mutate, _, _ in SCENARIO_CASES:
            p = _write_case(pathlib.Path(d), mutate)
            try:
                load_scenario(p)
            except ScenarioError as e:
                print(f"| scenario: {cls} | `{str(e).replace(str(p), 's.yaml')}` |")
    for group, cases in (("API", API_CASES), ("sweep", SWEEP_CASES)):
        for cls, call, _ in cases:
            try:
                call()
            except ValueError as e:
                print(f"| {group}: {cls} | `{e}` |")
