"""The README is a contract: every command, flag, snippet and scenario key it shows works.

The two set-up commands of its first block are run verbatim by CI (``.ci/run``); here: the
commands table against each command's ``--help``, every other shell example and Python snippet
run (with the step counts of ``SMALLER`` where the README's own would take minutes), the
scenario-file YAML validated, and every key a built-in scenario uses shown in the README."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from mpcdrive.scenarios import builtin_ids

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")

#: README text -> what the test runs instead (fewer runs / steps); each must occur in the README
SMALLER = {
    "--runs 200": "--runs 2",
    "steps=300": "steps=20",
    "mpcdrive commonroad tests/data/commonroad --workers 2": "mpcdrive commonroad tests/data/commonroad/"
    "ZAM_Tutorial-1_1_T-1.xml tests/data/commonroad/C-DEU_B471-2_1.xml --workers 2",
}


def blocks(lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```", README, re.S | re.M)


def _commands_table() -> list[str]:
    return re.findall(r"^\| `(mpcdrive [^`]+)` \|", README, re.M)


def _help(cmd: str | None) -> str:
    """``mpcdrive CMD --help`` (the root's with None)."""
    args = ["--help"] if cmd is None else [cmd, "--help"]
    r = subprocess.run([sys.executable, "-m", "mpcdrive", *args], capture_output=True, text=True)
    assert r.returncode == 0, f"mpcdrive {cmd or ''} --help: {r.stderr}"
    return r.stdout


FLAG = r"(?<![\w-])--?[a-z][a-z-]*"


def _help_flags(text: str) -> set[str]:
    """Every flag an ``--help`` text lists in its Options section (long and short, both halves
    of an on/off pair), but ``--help``."""
    options = text.split("\nOptions:\n", 1)[1].split("\nCommands:\n", 1)[0]
    flags = set()
    for line in options.splitlines():
        m = re.match(r"^  (-\S.*?)(?:\s{2,}|$)", line)  # the option's names, before its help text
        if m:
            flags |= set(re.findall(FLAG, m.group(1)))
    return flags - {"--help"}


def _table_rows() -> dict[str | None, set[str]]:
    """The README's commands table: command (None for the root's row) -> the flags its usage shows."""
    rows: dict[str | None, set[str]] = {}
    for usage in _commands_table():
        words = usage.split()
        cmd = None if words[1].startswith("-") else words[1]
        assert cmd not in rows, f"two rows for mpcdrive {cmd or '(root)'}"
        rows[cmd] = set(re.findall(FLAG, usage.replace("\\|", " ")))
    return rows


def _commands() -> list[str]:
    return re.findall(r"^  ([a-z][a-z-]+)\s{2,}", _help(None).split("\nCommands:\n")[1], re.M)


def test_first_block_is_the_two_set_up_commands():
    first = blocks("bash")[0].strip().splitlines()
    assert len(first) == 2
    assert "pip install -e ." in first[0] and first[0].endswith("mpcdrive reproduce")
    assert "pytest" in first[1]
    assert README.startswith("```bash\n"), "the set-up commands come first"


def test_every_substitution_still_matches_the_readme():
    for text in SMALLER:
        assert text in README, f"{text!r} no longer in the README: update SMALLER"


def test_commands_table_has_one_row_per_command_and_the_root():
    rows, commands = _table_rows(), _commands()
    assert commands, "mpcdrive --help lists no commands"
    assert set(rows) == {None, *commands}, (
        f"commands without a row: {sorted(set(commands) - set(rows))}; rows without a command: "
        f"{sorted(str(c) for c in set(rows) - {None, *commands})}"
    )


@pytest.mark.parametrize("cmd", [None, *_commands()], ids=lambda c: c or "root")
def test_commands_table_shows_exactly_the_flags_of_the_help(cmd):
    shown, helped = _table_rows().get(cmd, set()), _help_flags(_help(cmd))
    where = f"mpcdrive {cmd or '(root)'}"
    assert not helped - shown, f"{where} --help has {sorted(helped - shown)}, the README's table does not"
    assert not shown - helped, f"the README's table shows {sorted(shown - helped)} for {where}, its --help does not"


def test_commands_table_takes_one_value_per_flag():
    for usage in _commands_table():
        for token in re.findall(r"(--[a-z-]+) [A-Z_=]+ \.\.\.", usage):
            pytest.fail(
                f"README shows '{token} X ...' (several values after one flag); the flag takes one: write '[{token} X]...'"
            )


def _shell_examples() -> list[str]:
    out = []
    for block in blocks("bash")[1:]:
        text = block.replace("\\\n", " ")
        out += [line.strip() for line in text.splitlines() if line.strip().startswith("mpcdrive ")]
    return out


@pytest.mark.parametrize("line", _shell_examples())
def test_shell_examples_run(line, tmp_path):
    for a, b in SMALLER.items():
        line = line.replace(a, b)
    line = line.split("  #")[0]  # a trailing comment
    args = [a.strip("'") for a in re.findall(r"'[^']*'|\S+", line)][1:]
    if "--out" in args:  # into the test's folder (the examples' paths are the repository's)
        args[args.index("--out") + 1] = str(tmp_path / "out")
    else:
        args += ["--out", str(tmp_path / "out")]
    r = subprocess.run([sys.executable, "-m", "mpcdrive.cli", *args], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, f"{line}\n{r.stderr}"


@pytest.mark.parametrize("index", range(len(blocks("python"))))
def test_python_snippets_run(index, tmp_path):
    code = blocks("python")[index]
    for a, b in SMALLER.items():
        code = code.replace(a, b)
    if "highway_env" in code:
        pytest.importorskip("highway_env")
    r = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**__import__("os").environ, "SDL_VIDEODRIVER": "dummy"},
    )
    assert r.returncode == 0, r.stderr
    assert "DeprecationWarning" not in r.stderr and "is out of date" not in r.stderr, r.stderr


def test_scenario_file_examples_validate(tmp_path):
    """Every YAML block is a complete scenario file a user can copy: it validates."""
    from mpcdrive.scenarios import load_scenario

    docs = blocks("yaml")
    assert docs, "the README shows no scenario file"
    for i, text in enumerate(docs):
        p = tmp_path / f"readme-{i}.yaml"
        p.write_text(text)
        load_scenario(p)  # raises with the file, field and problem on drift


def _keys(d, prefix=""):
    for k, v in d.items():
        yield prefix + k
        if isinstance(v, dict):
            yield from _keys(v, prefix + k + ".")


def test_every_key_of_the_built_in_scenarios_is_shown():
    from mpcdrive.scenarios.loader import _builtin_dir

    shown = set(re.findall(r"\b([A-Za-z_][A-Za-z0-9_]*)\b", "\n".join(blocks("yaml"))))
    shown |= set(re.findall(r"`([a-z_][a-z0-9_.]*)`", README))
    missing = set()
    for sid in builtin_ids():
        data = yaml.safe_load((_builtin_dir() / f"{sid}.yaml").read_text())
        for key in _keys(data):
            leaf = key.rsplit(".", 1)[-1]
            if leaf not in shown and key not in shown:
                missing.add(key)
    assert not missing, f"built-in scenarios use keys the README never shows: {sorted(missing)}"


def _run_example(path: Path, out: Path) -> tuple[subprocess.CompletedProcess, dict, np.ndarray]:
    r = subprocess.run(
        [sys.executable, "-m", "mpcdrive", "run", str(path), "--out", str(out), "-q", "--check"],
        capture_output=True,
        text=True,
    )
    metrics = json.loads((out / "metrics.json").read_text()) if (out / "metrics.json").exists() else {}
    rows = np.genfromtxt(out / "trajectory.csv", delimiter=",", names=True) if metrics else np.empty(0)
    return r, metrics, rows


def _body_radii(rows, footprint, center) -> tuple[np.ndarray, np.ndarray]:
    """Nearest and farthest distance [m] of the body (the footprint's rectangle at each logged
    pose) from the point ``center``: exactly, the farthest at a corner, the nearest on an edge."""
    corners = footprint.corners()
    c, s = np.cos(rows["yaw"])[:, None], np.sin(rows["yaw"])[:, None]
    px = rows["x"][:, None] + c * corners[:, 0] - s * corners[:, 1] - center[0]
    py = rows["y"][:, None] + s * corners[:, 0] + c * corners[:, 1] - center[1]
    far = np.hypot(px, py).max(axis=1)
    ax, ay = px, py
    bx, by = np.roll(px, -1, axis=1), np.roll(py, -1, axis=1)
    ex, ey = bx - ax, by - ay
    u = np.clip(-(ax * ex + ay * ey) / (ex * ex + ey * ey), 0.0, 1.0)  # nearest point of each edge
    near = np.hypot(ax + u * ex, ay + u * ey).min(axis=1)
    return near, far


def _obstacle_centres(ob: dict, t: np.ndarray) -> np.ndarray:
    v = np.asarray(ob.get("velocity_mps") or [0.0, 0.0])
    return np.asarray(ob["position"])[None, :] + t[:, None] * v[None, :]


def _inner_radius(ob: dict) -> float:
    """The radius [m] of the largest disc about an obstacle's centre inside it."""
    if ob["shape"] == "circle":
        return ob["radius_m"]
    assert ob["shape"] == "rectangle", "add the shape here"
    return 0.5 * min(ob["length_m"], ob["width_m"])


def test_the_scenario_example_is_safe_with_margin_and_its_obstacles_matter(tmp_path):
    """The README's scenario file, as written: ``run --check`` passes (no collision, inside the
    lane, no failed solve) with room to spare -- the body at least the road's margin inside its
    lane at every step (measured exactly on the circular lane), the obstacles' margin kept --
    and every obstacle is in the way: without the obstacles the car would drive into each of
    them, with them it steers around, inside its lane."""
    from mpcdrive.scenarios import build_experiment, load_scenario

    text = blocks("yaml")[0]
    spec = yaml.safe_load(text)
    path = tmp_path / "example.yaml"
    path.write_text(text)
    r, m, rows = _run_example(path, tmp_path / "out")
    assert r.returncode == 0, r.stdout + r.stderr
    assert not r.stdout.startswith("UNSAFE"), r.stdout
    assert m["collisions"] == 0 and m["max_lane_excess_m"] == 0 and m["solver_failures"] == 0, m
    assert m["min_obstacle_clearance_m"] >= 0.5 * spec["avoidance"]["margin_m"], m

    assert spec["path"]["type"] == "circle", "the margin check below measures a circular lane"
    radius, half = spec["path"]["radius_m"], 0.5 * spec["road"]["lane_width_m"]
    footprint = build_experiment(load_scenario(path)).footprint
    near, far = _body_radii(rows, footprint, spec["path"]["center"])
    margin = spec["road"]["margin_m"]
    assert near.min() >= radius - half + margin and far.max() <= radius + half - margin, (
        f"the body came within {min(near.min() - radius + half, radius + half - far.max()):.3f} m of the "
        f"lane's edge (the road's margin is {margin} m)"
    )

    free = {k: v for k, v in spec.items() if k not in ("obstacles", "avoidance")}
    free_path = tmp_path / "free.yaml"
    free_path.write_text(yaml.safe_dump(free))
    r_free, _, free_rows = _run_example(free_path, tmp_path / "free")
    assert r_free.returncode == 0, r_free.stderr
    car_half_width = 0.5 * footprint.width_m  # a disc this wide around the reference point is inside the body
    assert footprint.length_m >= footprint.width_m
    for ob in spec["obstacles"]:
        c = _obstacle_centres(ob, free_rows["t"])
        gap = np.hypot(free_rows["x"] - c[:, 0], free_rows["y"] - c[:, 1]) - _inner_radius(ob) - car_half_width
        assert gap.min() < 0, f"{ob['name']}: the car without obstacles passes {gap.min():.3f} m clear of it"
        t_hit = free_rows["t"][int(np.argmin(gap))]  # with the obstacle the car is well off the path there
        assert np.abs(rows["e_y"][np.abs(rows["t"] - t_hit) <= 0.5]).max() > 0.15, f"{ob['name']}: no deviation"


def test_the_obstacle_keys_shown_are_the_schemas():
    """The scenario example's obstacle comment names every key an obstacle takes (and a recorded
    trajectory's), and each shape's keys in parentheses are keys of the schema."""
    from mpcdrive.scenarios.schema import ObstacleSpec, TrajectorySpec

    text = blocks("yaml")[0]
    block = re.search(r"^# obstacles:.*?(?=^[^#])", text, re.S | re.M)  # a comment block before the key
    inline = re.search(r"^obstacles:.*?#(.*)$", text, re.M)  # or a comment on the key's line
    comment = (block.group(0) if block else "") + (inline.group(1) if inline else "")
    assert comment, "the scenario example does not say what an obstacle takes"
    words = set(re.findall(r"[a-z_]+", comment))
    fields = set(ObstacleSpec.model_fields) | set(TrajectorySpec.model_fields)
    assert fields <= words, f"obstacle keys the README never shows: {sorted(fields - words)}"
    for shape, keys in re.findall(r"\b(circle|rectangle|polygon) \(([a-z_]+(?:, [a-z_]+)*)[:)]", comment):
        for key in keys.split(", "):
            assert key in ObstacleSpec.model_fields, f"{shape}: {key!r} is not an obstacle key"
