"""Observers (issue 17): MCAP recordings, the live page in headless Chromium, the replay page,
`swarmloc replay` on Zenoh, bad input.

Real processes over real Zenoh sessions, as `swarmloc run` starts them: own router on a free
port, own run name, readiness awaited (announced endpoints and URLs, the page's tick counter,
Zenoh's matching status), every process stopped by id. The browser is Debian's chromium driven by
Playwright (never a downloaded browser); the tests that need it skip, saying why, without it.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import threading
import uuid
from pathlib import Path

import numpy as np
import pytest

from swarmloc.deploy.launch import supervised
from swarmloc.deploy.observe.cli import start_view
from swarmloc.deploy.observe.record import (
    FOXGLOVE_TOPIC,
    FRAME_TOPIC,
    SCENE_TOPIC,
    RecordingError,
    read_recording,
)
from swarmloc.deploy.run import start_swarm
from swarmloc.deploy.scenario import load_any, load_scenario

pytestmark = pytest.mark.integration

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
HAVE_CHROMIUM = Path(CHROMIUM).is_file()
try:
    import playwright.sync_api  # noqa: F401

    HAVE_PLAYWRIGHT = True
except ImportError:
    HAVE_PLAYWRIGHT = False
needs_browser = pytest.mark.skipif(
    not (HAVE_CHROMIUM and HAVE_PLAYWRIGHT),
    reason="needs Debian's chromium (apt-get install chromium) and the playwright package")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
ROBOT_RGB = np.array([214, 39, 40])  # view.js: TRUE


def _write(tmp_path, scenario) -> Path:
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps(scenario.to_dict()))
    return path


def _batch_poses(scenario) -> dict[int, list]:
    """The batch engine's true poses after every tick (what the world's state holds)."""
    from swarmloc.deploy.lab.epuck.batch import run_ticks, swarm_brain
    from swarmloc.world.epuck.foraging import ForagingWorld

    world, brain = ForagingWorld(scenario.world), swarm_brain(scenario)
    poses: dict[int, list] = {}
    run_ticks(world, brain, lambda: poses.__setitem__(world.tick, world.pose.tolist()))
    poses[world.tick] = world.pose.tolist()
    return poses


# -- recording a lockstep run ----------------------------------------------------------------


def test_lockstep_recording_has_every_tick_bit_for_bit(tmp_path):
    scenario = load_scenario("ES1", ["world.robots=4", "world.duration_s=40.0", "world.seed=7"])
    path = _write(tmp_path, scenario)
    mcap = tmp_path / "run.mcap"
    with supervised() as sup:
        swarm = start_swarm(sup, path, run="rec" + uuid.uuid4().hex[:8], robots=4, out=tmp_path / "out",
                            log_dir=tmp_path, join_timeout_s=60,
                            world_args=("--record", str(mcap), "--record-messages"))
        assert swarm.world.wait(timeout=120) == 0, (tmp_path / "world.log").read_text()[-2000:]
        [a.wait(timeout=30) for a in swarm.agents]
    rec = read_recording(mcap, keep_messages=True)
    assert rec.truncated is None
    assert rec.encodings == {SCENE_TOPIC: "json", FRAME_TOPIC: "msgpack", FOXGLOVE_TOPIC: "json",
                             "/swarmloc/sense": "swarmloc-msgpack", "/swarmloc/act": "swarmloc-msgpack"}
    assert rec.schemas == {SCENE_TOPIC: "swarmloc.Scene", FRAME_TOPIC: "swarmloc.Frame",
                           FOXGLOVE_TOPIC: "foxglove.SceneUpdate", "/swarmloc/sense": "",
                           "/swarmloc/act": ""}
    ticks = [f["tick"] for f in rec.frames]
    assert ticks == list(range(401)), "every tick, in order, from 0 to the last"
    batch = _batch_poses(scenario)
    assert [f["state"]["poses"] for f in rec.frames] == [batch[t] for t in ticks], "poses bit for bit"
    assert all(f["truth"] == f["state"]["poses"] for f in rec.frames)
    assert rec.topics["/swarmloc/sense"] == rec.topics["/swarmloc/act"] == 400 * 4
    # the batch engine's own recording of the same seed: the same poses, tick by tick
    from swarmloc.deploy.observe.batch_record import run_batch_recorded

    run_batch_recorded(scenario, tmp_path / "batch.mcap")
    brec = read_recording(tmp_path / "batch.mcap")
    assert [f["tick"] for f in brec.frames] == ticks
    assert [f["state"]["poses"] for f in brec.frames] == [f["state"]["poses"] for f in rec.frames]
    # the documented schemas, as the file carries them
    from mcap.reader import make_reader

    with open(mcap, "rb") as f:
        summary = make_reader(f).get_summary()
    names = {s.name: (s.encoding, json.loads(s.data)["title"]) for s in summary.schemas.values()}
    assert names == {"swarmloc.Scene": ("jsonschema", "swarmloc.Scene"),
                     "swarmloc.Frame": ("jsonschema", "swarmloc.Frame"),
                     "foxglove.SceneUpdate": ("jsonschema", "foxglove.SceneUpdate")}


# -- bad recordings --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_recording(tmp_path_factory) -> Path:
    from swarmloc.deploy.observe.batch_record import run_batch_recorded

    path = tmp_path_factory.mktemp("rec") / "small.mcap"
    run_batch_recorded(load_scenario("ES1", ["world.robots=3", "world.duration_s=10.0"]), path)
    return path


def test_truncated_recording_keeps_its_whole_messages(small_recording, tmp_path):
    data = small_recording.read_bytes()
    whole = read_recording(small_recording)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    rec = read_recording(cut)
    assert rec.truncated and "truncated" in rec.truncated
    assert 10 < len(rec.frames) < len(whole.frames)
    assert rec.frames == whole.frames[: len(rec.frames)], "every whole message up to the cut"


@pytest.mark.parametrize("mangle, expect", [
    (lambda d: b"PNG\x89" + d[4:], "not an MCAP file"),
    (lambda d: b"", "not an MCAP file"),
    (lambda d: d[:20], "no /swarmloc/frame channel"),
    (lambda d: d.replace(b'"bounds_m":[', b'"bounds_m"![', 1), "not valid json"),
])
def test_corrupt_recording_is_named(small_recording, tmp_path, mangle, expect):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(mangle(small_recording.read_bytes()))
    with pytest.raises(RecordingError, match=expect):
        read_recording(bad)
    proc = subprocess.run(["swarmloc", "view", str(bad), "--http", "127.0.0.1:0"],
                          capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 2 and expect in proc.stderr


# -- the page --------------------------------------------------------------------------------


class Page:
    """Headless chromium on one page of the view."""

    def __init__(self, url: str):
        from playwright.sync_api import sync_playwright

        self._pw = sync_playwright().start()
        self.browser = self._pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        self.page = self.browser.new_page(viewport={"width": 1300, "height": 760})
        self.page.goto(url)

    def tick(self) -> int:
        text = self.page.inner_text("#tick")
        return int(text) if text.isdigit() else -1

    def wait_tick(self, predicate: str, timeout_s: float = 60) -> None:
        self.page.wait_for_function(
            f"(() => {{ const t = Number(document.getElementById('tick').textContent); return {predicate}; }})()",
            timeout=timeout_s * 1000)

    def shown(self) -> dict:
        return self.page.evaluate("window.swarmloc.frame")

    def pixels_at(self, poses) -> list[np.ndarray]:
        from PIL import Image

        points = [self.page.evaluate(f"window.swarmloc.toPixel({p[0]}, {p[1]})") for p in poses]
        image = np.asarray(Image.open(io.BytesIO(self.page.locator("#arena").screenshot())).convert("RGB"))
        return [image[round(y), round(x)].astype(int) for x, y in points]

    def close(self) -> None:
        self.browser.close()
        self._pw.stop()


def _robots_drawn_at(page: Page, poses, alive) -> None:
    shown = page.pixels_at([p for p, a in zip(poses, alive) if a and p is not None])
    assert shown, "no robot to look at"
    for rgb in shown:
        assert np.abs(rgb - ROBOT_RGB).max() <= 40, f"no robot drawn there: pixel {rgb.tolist()}"
    # and nowhere a robot is not: the arena's far corner from every robot
    scene = page.page.evaluate("window.swarmloc.scene")
    x0, y0, x1, y1 = scene["bounds_m"]
    corners = [(x0 + 0.01, y0 + 0.01), (x1 - 0.01, y0 + 0.01), (x0 + 0.01, y1 - 0.01), (x1 - 0.01, y1 - 0.01)]
    far = max(corners, key=lambda c: min(np.hypot(c[0] - p[0], c[1] - p[1]) for p in poses if p))
    assert np.abs(page.pixels_at([far])[0] - ROBOT_RGB).max() > 60


def _synthetic_replay(tmp_path):
    from swarmloc.world.replay.mrclam import SyntheticConfig, synthesize, write_dataset

    folder = write_dataset(synthesize(SyntheticConfig(n_robots=3, n_landmarks=8, duration_s=30.0),
                                      np.random.default_rng(11)), tmp_path / "Synthetic")
    return load_any("mrclam6-ekf-coop", {"seed": 1},
                    [f"dataset={json.dumps(str(folder))}", "duration_s=12.0", "calibration_s=0.0"])


FAMILIES = {
    # name: (scenario builder, lockstep?) -- in lockstep these short runs end before a page has
    # loaded, so they run in real time (the recording test covers lockstep).
    "foraging": (lambda tmp: load_any("ES1", {"robots": 4, "duration_s": 25.0, "seed": 3}, []), False),
    "laser": (lambda tmp: load_any("laser-collab-three-rooms", {"seed": 1}, ["world.steps=40"]), False),
    "vision": (lambda tmp: load_any("vision-exp2", {"seed": 2}, []), False),
    "replay": (_synthetic_replay, False),
}


@needs_browser
@pytest.mark.parametrize("family", list(FAMILIES))
def test_live_page_and_replay_page_show_the_robots(tmp_path, family):
    build, lockstep = FAMILIES[family]
    scenario = build(tmp_path)
    path = _write(tmp_path, scenario)
    mcap = tmp_path / "run.mcap"
    run = "view" + uuid.uuid4().hex[:8]
    page = None
    with supervised() as sup:
        swarm = start_swarm(sup, path, run=run, robots=scenario.robots, out=tmp_path / "out",
                            log_dir=tmp_path, join_timeout_s=90, realtime=not lockstep,
                            world_args=("--record", str(mcap)))
        _view, url = start_view(sup, swarm.router_endpoint, run, "127.0.0.1:0", tmp_path / "view.log")
        assert url.startswith("http://127.0.0.1:")
        try:
            page = Page(url)
            page.wait_tick("t > 0", 120)
            first = page.tick()
            page.wait_tick(f"t > {first}", 60)  # the counter advances
            page.page.click("#pause")  # the page keeps what it shows; the run goes on
            shown = page.shown()
            _robots_drawn_at(page, shown["truth"], shown["state"]["alive"])
            page.page.evaluate("window.swarmloc.socket.send('garbage {')")  # counted, ignored
            page.page.evaluate("window.swarmloc.socket.send(JSON.stringify({cmd: 'seek', tick: 'x'}))")
            page.close()
            page = None  # a browser that vanished mid-run
            assert swarm.world.wait(timeout=240) == 0, (tmp_path / "world.log").read_text()[-2000:]
            stats = json.loads(_get(url + "stats"))
            assert stats["bad_messages"] == 2 and stats["disconnects"] == 1
        finally:
            if page is not None:
                page.close()
    result = json.loads((tmp_path / "out" / "results.json").read_text())
    assert result["reason"] == "completed" and result["rejected"] == {}
    rec = read_recording(mcap)
    by_tick = {f["tick"]: f for f in rec.frames}
    assert sorted(by_tick) == list(range(len(rec.frames)))
    assert by_tick[shown["tick"]]["state"]["poses"] == shown["state"]["poses"], \
        "the page showed the world's state of its tick"
    # the replay page: seek to a tick and show its poses
    target = len(rec.frames) * 2 // 3
    with supervised() as sup:
        proc = sup.start(["view", str(mcap), "--http", "127.0.0.1:0", "--announce"], stdout=subprocess.PIPE)
        url = json.loads(proc.stdout.readline())["url"]
        page = Page(url)
        try:
            page.page.click("#pause")
            page.page.evaluate(f"window.swarmloc.seek({target})")
            page.wait_tick(f"t === {target}", 30)
            frame = by_tick[target]
            assert page.shown()["state"]["poses"] == frame["state"]["poses"]
            _robots_drawn_at(page, frame["truth"], frame["state"]["alive"])
            if family == "foraging":
                os.makedirs(tmp_path / "shots", exist_ok=True)
            shot = os.environ.get("SWARMLOC_SCREENSHOTS")
            if shot:  # docs/images: `SWARMLOC_SCREENSHOTS=docs/images pytest -k live_page`
                page.page.screenshot(path=str(Path(shot) / f"view-{family}.png"))
        finally:
            page.close()


def _get(url: str) -> str:
    from urllib.request import urlopen

    with urlopen(url, timeout=10) as r:
        return r.read().decode()


# -- replay on Zenoh ---------------------------------------------------------------------------


def test_replay_republishes_a_recording_as_if_live(small_recording, tmp_path):
    from swarmloc.deploy.launch import start_router
    from swarmloc.protocol.keys import Keys
    from swarmloc.protocol.messages import RunEnd, WorldState, decode
    from swarmloc.protocol.session import open_session, session_config

    rec = read_recording(small_recording)
    run = "rp" + uuid.uuid4().hex[:8]
    keys = Keys(run)
    states, done = [], threading.Event()
    with supervised() as sup:
        _, endpoint = start_router(sup)
        with open_session(session_config(mode="client", connect=[endpoint])) as session:
            session.declare_subscriber(keys.world_state,
                                       lambda s: states.append(decode(s.payload.to_bytes(), WorldState)))
            session.declare_subscriber(keys.run_end,
                                       lambda s: (decode(s.payload.to_bytes(), RunEnd), done.set()))
            proc = sup.start(["replay", str(small_recording), "--lockstep", "--run", run, "-e", endpoint,
                              "--wait-subscriber-s", "30"], stdout=subprocess.PIPE)
            assert done.wait(60), "no run end"
            assert proc.wait(30) == 0
            status = subprocess.run(["swarmloc", "status", "-e", endpoint, "--run", run, "--timeout-s", "0"],
                                    capture_output=True, text=True, timeout=30, check=False)
    assert [s.tick for s in states] == [f["tick"] for f in rec.frames]
    assert [[list(p) for p in s.poses] for s in states] == [f["state"]["poses"] for f in rec.frames]
    assert status.returncode == 1  # the replay's world token left with it
