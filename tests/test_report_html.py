"""The interactive HTML report: replay data, a self-contained page, and the page in a real
browser (headless Chromium driven through the WebDriver protocol).

The browser tests are skipped only when Chromium or its driver is not installed (CI installs
both: Debian packages ``chromium`` and ``chromium-driver``)."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mpcdrive.control import MpcConfig, PythonLtvMpc
from mpcdrive.scene.road import Road
from mpcdrive.models import KinematicBicycle3
from mpcdrive.ocp import MpcProblem
from mpcdrive.paths import CirclePath
from mpcdrive.report.html import (
    HtmlRun,
    replay_data,
    write_reproduce_html,
    write_run_html,
)
from mpcdrive.sim import Footprint, Plant, compute_metrics, simulate

FOOTPRINT = Footprint(0.5, 0.27)


def circle_run(steps: int = 150, radius_m: float = 1.5, lane: float | None = 0.4, N: int = 10):
    """A real closed loop: a car starting 0.2 m outside a circle of ``radius_m`` at 1 m/s."""
    model = KinematicBicycle3(v_mps=1.0)
    path = CirclePath(radius_m=radius_m)
    problem = MpcProblem(
        nx=3,
        nu=1,
        N=N,
        dt_s=0.02,
        Q=[1, 1, 1],
        R=1.0,
        u_min=-np.radians(60),
        u_max=np.radians(60),
        road=None if lane is None else Road.constant(2 * lane, 0.0),
    )
    mpc = PythonLtvMpc(model, path, problem, MpcConfig(), "osqp")
    return simulate(
        mpc,
        Plant(model),
        path,
        x0=[radius_m + 0.2, 0.0, np.pi / 2],
        dt_s=0.02,
        steps=steps,
        road=problem.road,
        meta={"id": "circle", "max_steer_rad": np.radians(60)},
    )


def tiny_pngs(directory: Path, n: int = 2) -> list[Path]:
    """Small PNG files standing in for figures (embedding is about bytes, not plots)."""
    from PIL import Image

    paths = []
    for i in range(n):
        p = directory / f"figure_{i}.png"
        Image.new("RGB", (24, 12), (40 * i, 120, 200)).save(p)
        paths.append(p)
    return paths


def with_obstacles(result, shapes):
    return replace(result, meta={**result.meta, "obstacles": shapes})


def decode_horizon(data: dict) -> list[np.ndarray]:
    """The page's decoding of the horizons, in Python (integers from the vehicle position)."""
    u = 10.0 ** -data["decimals"]
    fr = data["frames"]
    out = []
    for i, d in enumerate(data["horizon"]):
        if not d:
            out.append(np.zeros((0, 2)))
            continue
        base = np.round(np.array([fr["x"][i], fr["y"][i]]) / u)
        q = base + np.cumsum(np.asarray(d, float).reshape(-1, 2), axis=0)
        out.append(q * u)
    return out


# --------------------------------------------------------------------------- replay data
@pytest.fixture(scope="module")
def run150():
    return circle_run(150)


def test_replay_frames_are_subsampled_keeping_first_and_last_step(run150):
    data = replay_data(run150, FOOTPRINT, max_frames=40)
    k = np.array(data["frames"]["k"])
    assert 2 <= len(k) <= 40 and k[0] == 0 and k[-1] == run150.steps - 1
    assert np.all(np.diff(k) > 0)
    res = 10.0 ** -data["decimals"]
    np.testing.assert_allclose(data["frames"]["t"], run150.t_s[k], atol=1e-6)
    np.testing.assert_allclose(data["frames"]["x"], run150.x[k, 0], atol=res)
    np.testing.assert_allclose(data["frames"]["yaw"], run150.yaw_rad[k], atol=1e-5)
    np.testing.assert_allclose(data["frames"]["ey"], run150.e_y_m[k], atol=res)
    assert [data["statuses"][c] for c in data["frames"]["st"]] == [run150.status[j] for j in k]
    full = replay_data(run150, FOOTPRINT)
    assert full["frames"]["k"] == list(range(run150.steps))
    with pytest.raises(ValueError, match="max_frames"):
        replay_data(run150, FOOTPRINT, max_frames=1)


def test_replay_horizon_decodes_to_the_predictions(run150):
    data = replay_data(run150, FOOTPRINT, max_frames=60)
    hz = decode_horizon(data)
    res = 10.0 ** -data["decimals"]
    for i, k in enumerate(data["frames"]["k"]):
        pred = run150.X_pred[k, :, :2]
        assert hz[i].shape == pred.shape
        np.testing.assert_allclose(hz[i], pred, atol=0.51 * res + 1e-12)
    # the predictions move: not a copy of the vehicle position
    assert np.ptp(hz[5][:, 1]) > 0.05


def test_replay_lane_boundaries_lie_half_a_lane_from_the_path(run150):
    data = replay_data(run150, FOOTPRINT)
    path, left, right = (np.array(data[k]) for k in ("path", "left", "right"))
    r_path = np.hypot(*path.T)
    np.testing.assert_allclose(r_path, 1.5, atol=1e-4)
    # counter-clockwise circle: left is inside
    np.testing.assert_allclose(np.hypot(*left.T), 1.5 - 0.4, atol=2e-3)
    np.testing.assert_allclose(np.hypot(*right.T), 1.5 + 0.4, atol=2e-3)
    assert data["closed"] is True
    assert data["footprint"] == {"length": 0.5, "width": 0.27, "offset": 0.0}
    no_lane = replay_data(circle_run(20, lane=None), FOOTPRINT)
    assert no_lane["left"] is None and no_lane["right"] is None


def test_replay_obstacles_static_moving_and_unknown(run150):
    K = run150.steps
    t = run150.t_s
    shapes = [
        {"type": "circle", "center": [0.0, 0.0], "radius_m": 0.3, "label": "pole"},
        {"type": "circle", "center": [[-1.0, 0.0], [1.0, 0.0]], "t_s": [0.0, t[-1]], "radius_m": 0.1},
        {"type": "polygon", "points": [[0, 0.5], [0.5, 0.5], [0.3, 0.9]]},
        {"type": "polygon", "points": np.stack([np.array([[0, 0], [1, 0], [0, 1]]) + [k * 0.01, 0] for k in range(K)])},
        {"type": "rectangle", "center": [2.0, 0.0], "length_m": 1.0, "width_m": 0.5, "yaw_rad": np.pi / 2},
        {"type": "ellipse", "center": [0, 0]},
    ]
    data = replay_data(with_obstacles(run150, shapes), FOOTPRINT, max_frames=30)
    obs = data["obstacles"]
    assert data["skipped_obstacles"] == ["ellipse"]
    assert len(obs) == 5
    assert obs[0] == {"type": "circle", "r": 0.3, "c": [0.0, 0.0], "label": "pole"}
    tf = np.array(data["frames"]["t"])
    moving = np.array(obs[1]["c"])
    assert moving.shape == (len(tf), 2)
    np.testing.assert_allclose(moving[:, 0], -1.0 + 2.0 * tf / t[-1], atol=1e-4)
    assert obs[2]["p"] == [[0, 0.5], [0.5, 0.5], [0.3, 0.9]]
    poly = np.array(obs[3]["p"])
    assert poly.shape == (len(tf), 3, 2)
    np.testing.assert_allclose(poly[:, 0, 0], np.array(data["frames"]["k"]) * 0.01, atol=1e-4)
    rect = np.array(obs[4]["p"])  # turned by 90 deg: 0.5 wide along x, 1.0 long along y
    np.testing.assert_allclose(np.ptp(rect[:, 0]), 0.5, atol=1e-4)
    np.testing.assert_allclose(np.ptp(rect[:, 1]), 1.0, atol=1e-4)
    np.testing.assert_allclose(rect.mean(axis=0), [2.0, 0.0], atol=1e-4)
    # no obstacles: nothing to draw
    assert replay_data(run150, FOOTPRINT)["obstacles"] == []


@pytest.mark.parametrize(
    "shape, field",
    [
        ({"type": "circle", "center": [0, 0]}, r"obstacles\[0\]\.radius_m"),
        ({"type": "circle", "center": [0, 0], "radius_m": -1}, r"obstacles\[0\]\.radius_m"),
        ({"type": "circle", "center": [0, 0, 1], "radius_m": 1}, r"obstacles\[0\]\.center"),
        ({"type": "circle", "center": [[0, 0], [1, 1]], "radius_m": 1}, r"obstacles\[0\]: 2 positions"),
        ({"type": "circle", "center": [[0, 0], [1, 1]], "t_s": [1.0, 0.0], "radius_m": 1}, r"obstacles\[0\]\.t_s"),
        ({"type": "polygon", "points": [[0, 0], [1, 1]]}, r"obstacles\[0\]\.points"),
        ({"type": "polygon", "points": [[0, 0], [1, np.nan], [2, 0]]}, r"obstacles\[0\]\.points"),
        ({"type": "rectangle", "center": [0, 0], "length_m": 1.0}, r"obstacles\[0\]\.width_m"),
        ("a circle", r"obstacles\[0\]: expected a mapping"),
    ],
)
def test_replay_rejects_malformed_obstacles(run150, shape, field):
    with pytest.raises(ValueError, match=field):
        replay_data(with_obstacles(run150, [shape]), FOOTPRINT)


def _page_data(text: str) -> list:
    m = re.search(r'<script type="application/json" id="replay-data">(.*?)</script>', text, re.S)
    assert m, "replay data script missing"
    return json.loads(m.group(1))


def test_run_page_is_self_contained(tmp_path, run150):
    figs = tiny_pngs(tmp_path, 3)
    metrics = compute_metrics(run150)
    page = write_run_html(
        tmp_path, run150, metrics, figs, FOOTPRINT, run_id="circle", description="a <b>circle</b> & </script> test"
    )
    assert page == tmp_path / "report.html"
    text = page.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>")
    # nothing fetched from elsewhere: no external scripts, styles, images or fonts
    assert not re.search(r"https?://|<script[^>]+src=|<link[^>]+stylesheet|@import|url\(", text)
    imgs = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    assert len(imgs) == len(figs)
    assert base64.b64decode(imgs[0]) == Path(figs[0]).read_bytes()
    # user text is escaped, the closing tag inside it cannot end a script
    assert "a &lt;b&gt;circle&lt;/b&gt; &amp; &lt;/script&gt; test" in text
    assert text.count("</script>") == 2  # the data and the viewer
    data = _page_data(text)
    assert len(data) == 1 and data[0]["id"] == "circle"
    assert data[0] == json.loads(json.dumps(replay_data(run150, FOOTPRINT, run_id="circle")))
    # the metrics table shows SI values and degrees
    assert "<code>rms_lateral_error_m</code>" in text and "<code>solve_time_us.p50</code>" in text
    assert re.search(r"max_abs_steer_rad</code></th><td>[0-9.]+ rad \([0-9.]+°\)", text)


def test_page_embeds_the_packaged_viewer_and_style_sheet(tmp_path, run150):
    """The viewer and the style sheet are package data (found through importlib.resources, as
    in an installed wheel) and every page carries them whole, inline."""
    from importlib import resources

    assets = resources.files("mpcdrive.report") / "assets"
    js = (assets / "replay.js").read_text(encoding="utf-8")
    css = (assets / "report.css").read_text(encoding="utf-8")
    assert "RUNS" in js and "#replay" in css
    # nothing in them could end the element they are embedded in
    assert "</script" not in js.lower() and "</style" not in css.lower()
    text = write_run_html(tmp_path, run150, compute_metrics(run150), [], FOOTPRINT).read_text(encoding="utf-8")
    assert f"<style>\n{css}</style>" in text
    assert f"<script>\n{js}</script>\n</body></html>\n" in text


def test_reproduce_page_has_every_experiment(tmp_path, run150):
    short = circle_run(40, radius_m=2.0)
    (tmp_path / "a").mkdir()
    figs = [f"a/{p.name}" for p in tiny_pngs(tmp_path / "a")]
    runs = [
        HtmlRun("exp-a", "first", compute_metrics(run150), figs, run150, FOOTPRINT),
        HtmlRun("exp-b", "second", compute_metrics(short), [], short, Footprint(0.4, 0.2)),
        {"id": "comparison", "description": "figure only", "metrics": {}, "figures": [figs[0]]},
    ]
    paper = {"exp-a": [("max |e_y| [m]", "about 0.2", "max_abs_lateral_error_m")]}
    text = write_reproduce_html(tmp_path, runs, paper).read_text(encoding="utf-8")
    data = _page_data(text)
    assert [d["id"] for d in data] == ["exp-a", "exp-b"]
    assert len(data[1]["frames"]["k"]) == 40 and data[1]["footprint"]["length"] == 0.4
    assert '<select id="experiment">' in text and text.count('<option value="exp-') == 2
    for rid in ("exp-a", "exp-b", "comparison"):
        assert f'data-run="{rid}"' in text
    assert "<h2>Summary</h2>" in text and "<h2>Ours vs paper</h2>" in text
    assert "about 0.2" in text
    assert len(re.findall(r'src="data:image/png;base64,', text)) == len(figs) + 1
    with pytest.raises(ValueError, match="duplicate"):
        write_reproduce_html(tmp_path, [runs[0], runs[0]])
    with pytest.raises(ValueError, match="no such file"):
        write_reproduce_html(tmp_path, [HtmlRun("x", "", {}, ["missing.png"])])


# --------------------------------------------------------------------------- in a browser
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
    "--window-size=1280,1000",
]


def _find(*names: str) -> str | None:
    for n in names:
        p = shutil.which(n)
        if p:
            return p
    return None


@pytest.fixture(scope="module")
def browser():
    chromium = _find("chromium", "chromium-browser")
    driver_bin = _find("chromedriver") or ("/usr/bin/chromedriver" if Path("/usr/bin/chromedriver").exists() else None)
    if chromium is None or driver_bin is None:
        pytest.skip(
            "headless browser test needs Chromium and its driver; not installed here "
            "(Debian: apt-get install chromium chromium-driver)"
        )
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="mpcdrive-chromium-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for flag in CHROMIUM_FLAGS + [f"--user-data-dir={profile}"]:
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    drv = webdriver.Chrome(service=Service(driver_bin), options=opts)
    drv.set_page_load_timeout(60)
    try:
        yield drv
    finally:
        drv.quit()
        shutil.rmtree(profile, ignore_errors=True)


def _severe(logs) -> list[str]:
    return [e["message"] for e in logs if e.get("level") == "SEVERE"]


def _wait(predicate, timeout_s: float = 10.0, every_s: float = 0.05):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(every_s)
    return predicate()


def _canvas_image(browser, element_id: str):
    from PIL import Image

    png = browser.find_element("id", element_id).screenshot_as_png
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)


def _count_near(img: np.ndarray, rgb, tol: float = 40.0) -> int:
    return int(np.sum(np.linalg.norm(img - np.array(rgb), axis=-1) < tol))


def test_run_page_plays_in_a_browser(browser, tmp_path, run150):
    shapes = [
        {"type": "circle", "center": [0.0, 0.0], "radius_m": 0.4},
        {
            "type": "polygon",
            "points": [
                [[-2.2 + 0.01 * k, -2.2], [-1.8 + 0.01 * k, -2.2], [-2.0 + 0.01 * k, -1.8]] for k in range(run150.steps)
            ],
        },
    ]
    result = with_obstacles(run150, shapes)
    write_run_html(tmp_path, result, compute_metrics(result), tiny_pngs(tmp_path), FOOTPRINT, run_id="circle")
    browser.get((tmp_path / "report.html").as_uri())
    slider = browser.find_element("id", "time-slider")
    label = browser.find_element("id", "frame-label")
    assert _wait(lambda: label.text.startswith("frame 1/150")), label.text
    assert slider.get_attribute("max") == "149" and slider.get_attribute("value") == "0"
    assert _severe(browser.get_log("browser")) == []

    before = _canvas_image(browser, "view")
    from selenium.webdriver.support.ui import Select

    Select(browser.find_element("id", "speed")).select_by_value("0.5")  # 3 s of driving in 6 s
    play = browser.find_element("id", "play")
    play.click()
    assert _wait(lambda: int(slider.get_attribute("value")) >= 5), "pressing play did not advance the replay"
    assert play.text == "Pause"
    play.click()
    assert play.text == "Play"
    frozen = int(slider.get_attribute("value"))
    time.sleep(0.3)
    assert int(slider.get_attribute("value")) == frozen and not label.text.startswith("frame 1/")

    img = _canvas_image(browser, "view")
    h, w, _ = img.shape
    assert h > 300 and w > 600
    non_white = np.mean(np.any(img < 245, axis=-1))
    assert 0.02 < non_white < 0.9, non_white
    assert len(np.unique((img[..., 0] << 16) | (img[..., 1] << 8) | img[..., 2])) > 50  # colours
    assert _count_near(img, (31, 119, 180)) > 100  # reference path
    assert _count_near(img, (148, 103, 189), 60) > 50  # obstacles (fill and outline)
    assert _count_near(img, (236, 236, 236), 6) > 1000  # the lane band
    assert np.any(np.abs(img - before).sum(axis=-1) > 60), "the picture did not change while playing"

    # the lower plot seeks; arrow keys step
    series = browser.find_element("id", "series")
    from selenium.webdriver.common.action_chains import ActionChains

    ActionChains(browser).move_to_element_with_offset(series, 0, 0).click().perform()
    assert _wait(lambda: abs(int(slider.get_attribute("value")) - frozen) > 5)
    assert _severe(browser.get_log("browser")) == []
    # the log check is live: an error in the page is seen
    browser.execute_script("setTimeout(function () { throw new Error('probe-error'); }, 0);")
    assert _wait(lambda: any("probe-error" in m for m in _severe(browser.get_log("browser"))), 5.0)


def test_reproduce_page_switches_experiments_in_a_browser(browser, tmp_path, run150):
    short = circle_run(40, radius_m=2.0)
    runs = [
        HtmlRun("exp-a", "first", compute_metrics(run150), [], run150, FOOTPRINT),
        HtmlRun("exp-b", "second", compute_metrics(short), [], short, FOOTPRINT),
    ]
    write_reproduce_html(tmp_path, runs)
    browser.get((tmp_path / "report.html").as_uri())
    label = browser.find_element("id", "frame-label")
    assert _wait(lambda: label.text.startswith("frame 1/150")), label.text
    from selenium.webdriver.support.ui import Select

    Select(browser.find_element("id", "experiment")).select_by_value("exp-b")
    assert _wait(lambda: label.text.startswith("frame 1/40")), label.text
    sections = {
        s.get_attribute("data-run"): s.is_displayed() for s in browser.find_elements("css selector", "section.run")
    }
    assert sections == {"exp-a": False, "exp-b": True}
    # the summary table's links pick an experiment too
    browser.find_element("css selector", 'a.pick[data-run="exp-a"]').click()
    assert _wait(lambda: label.text.startswith("frame 1/150")), label.text
    browser.find_element("id", "play").click()
    slider = browser.find_element("id", "time-slider")
    assert _wait(lambda: int(slider.get_attribute("value")) > 0)
    assert _severe(browser.get_log("browser")) == []
