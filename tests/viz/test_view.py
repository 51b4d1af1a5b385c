"""The run view: reading run directories, the figure, the CLI, and the page in a real browser.

The browser check drives Debian's Chromium headless over the DevTools protocol on a pipe
(``--remote-debugging-pipe``: JSON messages ending in NUL on fds 3 and 4), with the standard
library only. It is skipped when ``/usr/bin/chromium`` is missing (CI: ``apt-get install -y
chromium``).
"""

from __future__ import annotations

import base64
import io
import json
import os
import re
import select
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from aftir_rl.core.errors import AftirError, CheckpointError
from aftir_rl.core.robot import Posture
from aftir_rl.planning.jointspace import densify
from aftir_rl.viz.page import build_figure, read_run, write_view

CHROMIUM = Path("/usr/bin/chromium")
L = 50.0


def _motion() -> list[Posture]:
    """Three sections pushed in straight, then the top two bending toward +x (dense)."""
    keys = [
        Posture(-150.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        Posture(-100.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        Posture(-100.0, [0.0, 0.4, 0.9], [0.3, 0.3, 0.3]),
    ]
    return densify(keys, max_angle=0.02, max_dis=1.0)


def _q_table_run(root: Path, tank, name: str = "q_table__AFTIR-Tank-v0__t__0__now") -> Path:
    run = root / name
    run.mkdir(parents=True)
    motion = _motion()
    tips = np.array([p.tip(L) for p in motion])
    cells: list[list[int]] = []
    for tip in tips[tips[:, 2] > 0]:
        cell = list(tank.raster.point_to_cell(tip))
        if not cells or cells[-1] != cell:
            cells.append(cell)
    path = {
        "target": tips[-1].tolist(),
        "target_cell": cells[-1],
        "cells": cells,
        "points_cm": [tank.raster.cell_center(c).tolist() for c in cells],
    }
    trajectory = {
        "complete": True,
        "margin_cm": 1.0,
        "section_length": L,
        "method": "test",
        "motion": [p.to_dict() for p in motion],
        "waypoint_index": [0, 50, len(motion) - 1],
    }
    (run / "path.json").write_text(json.dumps(path))
    (run / "trajectory.json").write_text(json.dumps(trajectory))
    return run


def _sb3_run(root: Path) -> Path:
    run = root / "ppo__AFTIR-Arm-v0__random__0__now"
    run.mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"algo": "ppo", "tank": "b737_center"}))
    (run / "summary.json").write_text(json.dumps({"algo": "ppo", "timesteps": 64}))
    return run


# ------------------------------------------------------------------------------ without a browser
def test_read_run_and_figure(tmp_path, tank):
    run = read_run(_q_table_run(tmp_path, tank))
    motion = _motion()
    assert run.n_motion == len(motion) and run.section_length == L
    assert np.allclose(run.tips()[-1], motion[-1].tip(L))
    assert run.waypoint_index == [0, 50, len(motion) - 1]
    fig = build_figure([run, read_run(_sb3_run(tmp_path))], tank, max_frames=20)
    assert len(fig.frames) == 20
    names = {t.name for t in fig.data}
    assert {"baffle", "pipes", "boxes (stringers)", "access panel", "cell path", "arm"} <= names
    arm = next(i for i, t in enumerate(fig.data) if t.name == "arm")
    assert fig.frames[-1].traces == (arm,)
    assert np.allclose(np.array(fig.frames[-1].data[0].z)[-1], motion[-1].tip(L)[2], atol=0.01)
    assert fig.data[arm].legendgroup == "run0"


def test_a_simulated_body_is_drawn_beside_the_arm(tmp_path, tank):
    """physics.json (aftir simulate) adds the rod's body: the last instant at or before each
    frame's entry, animated with the arm; a malformed one is a one-line error naming it."""
    folder = _q_table_run(tmp_path, tank)
    motion = _motion()
    entries = [0, 40, len(motion) - 1]
    bodies = [np.array(motion[e].points(L, 5)) - [0.0, 0.0, 1.0 + e] for e in entries]
    physics = {
        "summary": {"margin_held": True, "least_clearance_cm": 3.5},
        "snapshots": [{"entry": e, "body": b.tolist()} for e, b in zip(entries, bodies)],
    }
    (folder / "physics.json").write_text(json.dumps(physics))
    run = read_run(folder)
    assert "margin held on the simulated body (3.50 cm)" in run.facts["physics"]
    assert np.allclose(run.simulated_body(39), bodies[0])
    assert np.allclose(run.simulated_body(len(motion) - 1), bodies[2])
    fig = build_figure([run], tank, max_frames=20)
    names = [t.name for t in fig.data]
    arm, body = names.index("arm"), names.index("simulated body")
    assert body == arm + 1 and fig.frames[-1].traces == (arm, body)
    assert np.allclose(np.array(fig.data[body].z), bodies[2][:, 2], atol=0.01)
    assert np.allclose(np.array(fig.frames[0].data[1].z), bodies[0][:, 2], atol=0.01)
    physics["snapshots"][1]["body"] = [[0.0, 0.0, float("nan")]] * 3
    (folder / "physics.json").write_text(json.dumps(physics).replace("NaN", '"x"'))
    with pytest.raises(CheckpointError, match="physics.json: snapshots"):
        read_run(folder)


def test_rollout_and_tour_pages_show_their_targets(tmp_path, tank):
    """A run with only trajectory.json (a rollout, a tour) still draws its target(s)."""
    motion = [p.to_dict() for p in _motion()]
    rollout, tour = tmp_path / "rollout", tmp_path / "tour"
    extras = [{"target": [180.0, 110.0, 50.0]}, {"targets": [[100, 50, 50], [180, 110, 50]]}]
    for folder, extra in zip((rollout, tour), extras):
        folder.mkdir()
        data = {"complete": False, "section_length": L, "motion": motion, **extra}
        (folder / "trajectory.json").write_text(json.dumps(data))
    fig = build_figure([read_run(rollout), read_run(tour)], tank, max_frames=5)
    drawn = {t.name: t for t in fig.data}
    assert list(drawn["target"].x) == [180.0] and list(drawn["targets"].y) == [50, 110]


def test_frames_are_bounded_and_keep_the_ends(tmp_path, tank):
    run = read_run(_q_table_run(tmp_path, tank))
    from aftir_rl.viz.figure import _frame_indices

    idx = _frame_indices(run, 30)
    assert len(idx) <= 30 and idx[0] == 0 and idx[-1] == run.n_motion - 1
    assert 50 in idx and np.all(np.diff(idx) > 0)


def test_old_trajectory_form_pads_sections(tmp_path):
    run = tmp_path / "old"
    run.mkdir()
    short = {"dis": -40.0, "theta": [0.2], "phi": [0.0], "section_length": 25}
    long = {"dis": -50.0, "theta": [0.0, 0.3], "phi": [0.0, 0.0], "section_length": 25}
    via = {"dis": -45.0, "theta": [0.0, 0.25], "phi": [0.0, 0.0]}
    data = {"postures": [short, None, long], "moves": [{"from": 0, "via": [via]}]}
    (run / "trajectory.json").write_text(json.dumps(data))
    got = read_run(run)
    assert got.n_motion == 3 and got.theta.shape == (3, 2) and got.waypoint_index == [0, 2]
    # the one-section posture is the same arm as a straight section below it and dis - l
    assert np.allclose(got.tips()[0], Posture(-40.0, [0.2], [0.0]).tip(25))


@pytest.mark.parametrize(
    "setup, message",
    [
        (None, "no such directory"),
        ({}, "not a run directory"),
        ({"path.json": "{not json"}, "not a valid path.json"),
        ({"trajectory.json": '{"motion": [{"dis": 1}]}'}, "motion[0]"),
        ({"trajectory.json": '{"motion": 3}'}, "motion: expected a list"),
        ({"path.json": '{"points_cm": [[1, 2]]}'}, "points_cm"),
    ],
)
def test_unreadable_runs_raise_one_line(tmp_path, setup, message):
    run = tmp_path / "run"
    if setup is not None:
        run.mkdir()
        for name, text in setup.items():
            (run / name).write_text(text)
    with pytest.raises(CheckpointError, match=message.replace("[", r"\[")) as err:
        write_view([run], tmp_path / "v.html")
    assert isinstance(err.value, AftirError) and "\n" not in str(err.value)
    assert not (tmp_path / "v.html").exists()


def test_cli(tmp_path, tank):
    run = _q_table_run(tmp_path, tank)
    cmd = [sys.executable, "-m", "aftir_rl.view"]
    out = tmp_path / "page" / "v.html"
    proc = subprocess.run(
        [*cmd, str(run), "-o", str(out), "--max-frames", "10"], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr
    assert out.stat().st_size < 6e6 and "aftir-view" in out.read_text()
    bad = subprocess.run(
        [*cmd, str(tmp_path / "missing"), "-o", str(out)], capture_output=True, text=True
    )
    assert (
        bad.returncode == 2 and bad.stderr.startswith("error: ") and "Traceback" not in bad.stderr
    )
    assert len(bad.stderr.strip().splitlines()) == 1
    assert "RUN_DIR" in subprocess.run([*cmd, "--help"], capture_output=True, text=True).stdout


# ------------------------------------------------------------------------------ in a real browser
class _DevTools:
    """Chromium headless driven over ``--remote-debugging-pipe`` (stdlib only)."""

    def __init__(self, user_dir: str) -> None:
        to_chrome, from_chrome = os.pipe(), os.pipe()
        # Chromium reads commands on fd 3 and writes replies on fd 4; a tiny shim puts the pipe
        # ends there whatever fds this process already holds.
        shim = (
            "import fcntl, os, sys\n"
            "a, b = (fcntl.fcntl(int(x), fcntl.F_DUPFD, 10) for x in sys.argv[1:3])\n"
            "os.dup2(a, 3)\nos.dup2(b, 4)\nos.execv(sys.argv[3], sys.argv[3:])\n"
        )
        args = [
            str(CHROMIUM),
            "--headless",
            "--no-sandbox",
            "--remote-debugging-pipe",
            "--disable-gpu",
            "--enable-unsafe-swiftshader",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--no-default-browser-check",
            "--window-size=1280,1000",
            f"--user-data-dir={user_dir}",
            "about:blank",
        ]
        self.proc = subprocess.Popen(
            [sys.executable, "-c", shim, str(to_chrome[0]), str(from_chrome[1]), *args],
            pass_fds=(to_chrome[0], from_chrome[1]),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        os.close(to_chrome[0])
        os.close(from_chrome[1])
        self.write, self.read = to_chrome[1], from_chrome[0]
        self.buffer, self.next_id, self.events = b"", 0, []

    def send(self, method: str, params=None, session=None, timeout: float = 60.0):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self.write, json.dumps(msg).encode() + b"\0")
        end = time.monotonic() + timeout
        while True:
            while b"\0" not in self.buffer:
                ready, _, _ = select.select([self.read], [], [], max(0.0, end - time.monotonic()))
                if not ready:
                    raise TimeoutError(f"no reply to {method} in {timeout} s")
                chunk = os.read(self.read, 1 << 20)
                if not chunk:
                    raise EOFError(f"chromium closed the pipe (exit {self.proc.poll()})")
                self.buffer += chunk
            raw, self.buffer = self.buffer.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self.next_id:
                assert "error" not in reply, f"{method}: {reply['error']}"
                return reply["result"]
            self.events.append(reply)

    def evaluate(self, session: str, expression: str):
        result = self.send(
            "Runtime.evaluate",
            {"expression": expression, "awaitPromise": True, "returnByValue": True},
            session,
        )
        assert "exceptionDetails" not in result, result["exceptionDetails"]
        return result["result"].get("value")

    def errors(self) -> list[str]:
        """Uncaught exceptions, console.error/assert calls and error-level log entries."""
        out = []
        for event in self.events:
            method, params = event.get("method"), event.get("params", {})
            if method == "Runtime.exceptionThrown":
                details = params["exceptionDetails"]
                out.append(details.get("exception", {}).get("description") or details["text"])
            elif method == "Runtime.consoleAPICalled" and params["type"] in ("error", "assert"):
                out.append(
                    " ".join(str(a.get("value", a.get("description"))) for a in params["args"])
                )
            elif method == "Log.entryAdded" and params["entry"]["level"] == "error":
                out.append(params["entry"]["text"])
        return out

    def close(self) -> None:
        try:
            self.send("Browser.close", timeout=5)
        except (OSError, TimeoutError, EOFError):
            pass
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self.write)
        os.close(self.read)


def _started(user_dir: str, attempts: int = 3) -> _DevTools:
    """A browser that has answered once. On a loaded machine Chromium's start can take longer
    than 20 s (seen in CI), so the first reply gets 60 s and a browser that stays silent is
    killed and started again."""
    for attempt in range(attempts):
        browser = _DevTools(user_dir)
        try:
            browser.send("Browser.getVersion", timeout=60.0)
            return browser
        except (TimeoutError, EOFError):
            browser.close()
            if attempt == attempts - 1:
                raise
    raise AssertionError("unreachable")


_DRAWN = """new Promise(done => { const start = Date.now(); (function poll() {
  const gd = document.getElementById('aftir-view');
  if (gd && gd._fullLayout && gd._fullLayout.scene && gd._fullLayout.scene._scene &&
      document.querySelector('.gl-container canvas')) return done(true);
  if (Date.now() - start > 30000) return done(false);
  setTimeout(poll, 50); })(); })"""

_STATE = """(() => { const gd = document.getElementById('aftir-view');
  const canvas = document.querySelector('.gl-container canvas');
  return {svg: document.querySelectorAll('.main-svg').length, traces: gd.data.length,
    canvas: canvas ? [canvas.width, canvas.height] : null,
    frames: gd._transitionData._frames.length,
    share: gd.getBoundingClientRect().height / window.innerHeight,
    sliders: document.querySelectorAll('.slider-container').length,
    legend: Array.from(document.querySelectorAll('.legendtext')).map(e => e.textContent),
    noWebGL: document.body.innerText.includes('WebGL is not supported')}; })()"""

_ANIMATE = """(async () => { const gd = document.getElementById('aftir-view');
  const arm = gd._fullData.findIndex(t => t.name === 'arm');
  const tipZ = () => { const z = gd._fullData[arm].z; return z[z.length - 1]; };
  const before = tipZ();
  await Plotly.animate(gd, ['0'],
    {frame: {duration: 0, redraw: true}, transition: {duration: 0}, mode: 'immediate'});
  return [before, tipZ()]; })()"""


@pytest.mark.slow  # a browser start: 5-20 s on this VM
@pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Chromium: apt-get install -y chromium")
def test_page_draws_in_headless_chromium(tmp_path, tank):
    from PIL import Image

    runs = [_q_table_run(tmp_path, tank), _sb3_run(tmp_path)]
    motion = _motion()  # aftir simulate's bodies: the arm sagged 3 cm, at three instants
    snapshots = [
        {"entry": e, "body": (np.array(motion[e].points(L, 5)) - [0, 0, 3.0]).tolist()}
        for e in (0, len(motion) // 2, len(motion) - 1)
    ]
    (runs[0] / "physics.json").write_text(json.dumps({"snapshots": snapshots}))
    page = write_view(runs, tmp_path / "view.html", max_frames=40)
    fig = build_figure([read_run(r) for r in runs], tank, max_frames=40)
    assert 30 < len(fig.frames) <= 40
    html = page.read_text()
    assert not re.search(r"<(script|link)[^>]+(src|href)=", html)  # plotly.js is inline
    with tempfile.TemporaryDirectory() as user_dir:
        browser = _started(user_dir)
        try:
            target = browser.send("Target.createTarget", {"url": "about:blank"})["targetId"]
            attach = {"targetId": target, "flatten": True}
            session = browser.send("Target.attachToTarget", attach)["sessionId"]
            for domain in ("Runtime", "Log", "Page"):
                browser.send(f"{domain}.enable", session=session)
            browser.send("Page.navigate", {"url": page.as_uri()}, session)
            assert browser.evaluate(session, _DRAWN), "plotly did not draw the 3D scene in 30 s"
            state = browser.evaluate(session, _STATE)
            assert state["svg"] >= 1 and state["canvas"] and min(state["canvas"]) > 100, state
            assert (
                not state["noWebGL"]
                and state["frames"] == len(fig.frames)
                and state["sliders"] == 1
                and state["share"] > 0.75  # the scene fills most of the window
            )
            assert "#1 q_table" in state["legend"] and "arm" in state["legend"]  # short titles
            assert "simulated body" in state["legend"]
            assert "no path to draw" in browser.evaluate(session, "document.body.innerText")
            opened, first = browser.evaluate(session, _ANIMATE)
            assert opened == pytest.approx(_motion()[-1].tip(L)[2], abs=0.01)  # deployed
            assert first == pytest.approx(-150 + 3 * L, abs=0.01)  # straight, tip at z = 0
            shot = browser.send("Page.captureScreenshot", {"format": "png"}, session)["data"]
            pixels = np.asarray(Image.open(io.BytesIO(base64.b64decode(shot))).convert("RGB"))
            browser.send("Runtime.evaluate", {"expression": "0"}, session)  # flush late events
            errors = browser.errors()
        finally:
            browser.close()
    assert not errors, errors
    # the first run's colour (#1f77b4: the arm, tip route and cell path) is on the screen
    blue = np.all(np.abs(pixels.astype(int) - [31, 119, 180]) < 40, axis=-1)
    assert blue.sum() > 200, f"only {blue.sum()} pixels of the run's colour"
    amber = np.all(np.abs(pixels.astype(int) - [240, 162, 2]) < 40, axis=-1)  # the rod's body
    assert amber.sum() > 100, f"only {amber.sum()} pixels of the simulated body's colour"


@pytest.mark.parametrize(
    "name, text, message",
    [
        ("path.json", '{"tank": "/etc/passwd", "points_cm": [[1, 2, 3]]}', "neither a shipped"),
        ("config.json", '{"tank": "../../../etc/passwd"}', "neither a shipped"),
        ("summary.json", None, "leads out of the run directory"),
        ("path.json", "fifo", "not a run directory"),
    ],
)
def test_a_run_opens_no_file_outside_it(tmp_path, name, text, message):
    run = tmp_path / "run"
    run.mkdir()
    if text is None:
        (run / name).symlink_to("/etc/passwd")
    elif text == "fifo":
        os.mkfifo(run / name)  # would block a plain open() forever
    else:
        (run / name).write_text(text)
    with pytest.raises(AftirError, match=message) as err:
        write_view([run], tmp_path / "v.html")
    assert "root:" not in str(err.value) and "\n" not in str(err.value)
    assert not (tmp_path / "v.html").exists()
