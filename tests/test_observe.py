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
    ESTIMATES_TOPIC,
    FOXGLOVE_TOPIC,
    FRAME_TOPIC,
    SAMPLES_TOPIC,
    SCENE_TOPIC,
    TF_TOPIC,
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
SAMPLE_RGB = np.array([23, 190, 207])  # view.js: SAMPLE
#: sha256 of each Foxglove schema as ``@foxglove/schemas`` 2.1.0 (npm) exports it in
#: ``dist/jsonschema`` (json.dumps with sort_keys and no spaces), taken from that package: a
#: recording must declare Foxglove's own schema text, not a shape swarmloc wrote.
FOXGLOVE_SCHEMA_SHA256 = {
    "foxglove.SceneUpdate": "441ff6e3d0e6413eb0bb5cc1bedab904a3289c4f30c0263d1f2120cb45fa2adb",
    "foxglove.FrameTransforms": "abfec5a42f4a9eb2f7c7e5da9bb15f76d09781dd1e6e0d4be936521059714400",
    "foxglove.PosesInFrame": "2284dddb0d276c039e378ed21d77e71af68b32c3317aeee791c9265cc3e0e492",
}
FOXGLOVE_TOPICS = {FOXGLOVE_TOPIC: "foxglove.SceneUpdate", TF_TOPIC: "foxglove.FrameTransforms",
                   ESTIMATES_TOPIC: "foxglove.PosesInFrame", SAMPLES_TOPIC: "foxglove.PosesInFrame"}


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
    assert rec.encodings == {SCENE_TOPIC: "json", FRAME_TOPIC: "msgpack", **dict.fromkeys(FOXGLOVE_TOPICS, "json"),
                             "/swarmloc/sense": "swarmloc-msgpack", "/swarmloc/act": "swarmloc-msgpack"}
    assert rec.schemas == {SCENE_TOPIC: "swarmloc.Scene", FRAME_TOPIC: "swarmloc.Frame", **FOXGLOVE_TOPICS,
                           "/swarmloc/sense": "", "/swarmloc/act": ""}
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
                     **{name: ("jsonschema", name) for name in FOXGLOVE_SCHEMA_SHA256}}
    # Foxglove's channels: Foxglove's schema text, every message valid against it, every 0.5 s
    for path, frames in ((mcap, rec.frames), (tmp_path / "batch.mcap", brec.frames)):
        by_tick = {f["tick"]: f for f in frames}
        messages = _foxglove_messages(path, scenario.world.tick_s)
        assert {t: len(m) for t, m in messages.items()} == {FOXGLOVE_TOPIC: 1 + 81, TF_TOPIC: 81,
                                                            ESTIMATES_TOPIC: 81}
        for tick, tf in messages[TF_TOPIC]:  # world -> robot_i at the true pose of that tick
            truth = by_tick[tick]["truth"]
            assert [t["child_frame_id"] for t in tf["transforms"]] == [f"robot_{i}" for i in range(4)]
            for t, pose in zip(tf["transforms"], truth):
                assert t["parent_frame_id"] == "world"
                _assert_pose_near(t["translation"], t["rotation"], pose)
        for tick, poses in messages[ESTIMATES_TOPIC]:  # each robot's own pose belief
            known = [e for e in by_tick[tick]["estimates"] if e is not None]  # none before the first Act
            assert len(known) == (4 if tick else 0) and poses["frame_id"] == "world"
            assert len(poses["poses"]) == len(known)
            for p, e in zip(poses["poses"], known):
                _assert_pose_near(p["position"], p["orientation"], e)


def _foxglove_messages(path, tick_s: float) -> dict[str, list[tuple[int, dict]]]:
    """Every message of a recording's Foxglove channels as (tick, JSON), each validated against
    the schema text the file declares, which must be Foxglove's own (FOXGLOVE_SCHEMA_SHA256)."""
    import hashlib

    import jsonschema
    from mcap.reader import make_reader

    out: dict[str, list] = {}
    validators: dict[int, jsonschema.Draft202012Validator] = {}
    with open(path, "rb") as f:
        tick_ns = round(tick_s * 1e9)
        for schema, channel, message in make_reader(f).iter_messages():
            if not channel.topic.startswith("/foxglove/"):
                continue
            if schema.id not in validators:
                text = json.loads(schema.data)
                digest = hashlib.sha256(json.dumps(text, sort_keys=True, separators=(",", ":")).encode())
                assert digest.hexdigest() == FOXGLOVE_SCHEMA_SHA256[schema.name], \
                    f"{schema.name}: not Foxglove's schema text"
                assert FOXGLOVE_TOPICS[channel.topic] == schema.name
                validators[schema.id] = jsonschema.Draft202012Validator(text)
            assert channel.message_encoding == "json"
            value = json.loads(message.data)
            validators[schema.id].validate(value)
            out.setdefault(channel.topic, []).append((message.log_time // tick_ns, value))
    return out


def _assert_pose_near(position: dict, orientation: dict, pose) -> None:
    """A Foxglove position and quaternion against (x, y, theta): four decimals are written."""
    assert abs(position["x"] - pose[0]) <= 6e-5 and abs(position["y"] - pose[1]) <= 6e-5
    yaw = 2 * np.arctan2(orientation["z"], orientation["w"])
    assert abs((yaw - pose[2] + np.pi) % (2 * np.pi) - np.pi) <= 1e-4
    assert orientation["x"] == orientation["y"] == 0


def test_foxglove_schemas_reject_what_foxglove_would_not_read():
    """The schema check can fail: Foxglove's FrameTransforms and PosesInFrame refuse a transform
    without its rotation, a pose without its orientation, a timestamp with negative seconds."""
    import jsonschema

    from swarmloc.deploy.observe.record import FOXGLOVE_SCHEMAS, foxglove_poses, foxglove_transforms

    frame = {"truth": [[1.0, 2.0, 0.5], None], "estimates": [[1.1, 2.1, 0.4], None]}
    tf = json.loads(foxglove_transforms(frame, 1_500_000_000))
    poses = json.loads(foxglove_poses(frame["estimates"], 1_500_000_000))
    jsonschema.validate(tf, FOXGLOVE_SCHEMAS["foxglove.FrameTransforms"])
    jsonschema.validate(poses, FOXGLOVE_SCHEMAS["foxglove.PosesInFrame"])
    assert tf["transforms"][0]["timestamp"] == {"sec": 1, "nsec": 500_000_000}
    assert len(tf["transforms"]) == 1 and len(poses["poses"]) == 1, "unknown poses left out"
    del tf["transforms"][0]["rotation"]
    del poses["poses"][0]["orientation"]
    for bad, name in ((tf, "foxglove.FrameTransforms"), (poses, "foxglove.PosesInFrame"),
                      ({**poses, "timestamp": {"sec": -1, "nsec": 0}}, "foxglove.PosesInFrame")):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, FOXGLOVE_SCHEMAS[name])


# -- populations on request ------------------------------------------------------------------


@pytest.mark.parametrize("algorithm", ["cfsga", "ssga", "simple_ga", "amcl"])
def test_laser_agents_log_their_population_only_when_asked_and_unchanged_by_it(algorithm):
    """Welcome.samples = N: each Act carries at most N finite poses of the robot's population,
    inside the map; 0: none. Asking changes nothing else: the Acts are equal but for samples."""
    import dataclasses

    from swarmloc.agents.brains import brain_from_welcome
    from swarmloc.protocol.errors import ErrorCounter
    from swarmloc.protocol.messages import MAX_SAMPLES, EstimateAct, Welcome, decode, encode
    from swarmloc.world.service import served_world

    scenario = load_any("laser-collab-three-rooms", {"seed": 4, "algorithm": algorithm}, ["world.steps=4"])
    asked = 40
    world = served_world(scenario)
    x0, y0, x1, y1 = world.world.map.bounds_m
    brains = {n: [brain_from_welcome(Welcome(robot_id=r, run="unit", seed=scenario.seed,
                                             scenario=scenario.to_dict(), samples=n))
                  for r in range(scenario.robots)] for n in (0, asked)}
    while not world.done:
        acts = []
        for r, data in world.senses():
            plain, watched = (b[r].act(decode(data, b[r].sense_type), ErrorCounter()) for b in brains.values())
            assert plain.samples == ()
            assert 0 < len(watched.samples) <= asked
            assert all(x0 - 1 <= p[0] <= x1 + 1 and y0 - 1 <= p[1] <= y1 + 1 for p in watched.samples)
            assert dataclasses.replace(watched, samples=()) == plain, "watching changes nothing"
            assert decode(encode(watched), EstimateAct) == watched
            acts.append(plain)
        world.step(acts)
    # the bound is the protocol's: more than MAX_SAMPLES poses do not encode, --particles says so
    with pytest.raises(ValueError, match="samples"):
        encode(dataclasses.replace(watched, samples=((0.0, 0.0, 0.0),) * (MAX_SAMPLES + 1)))
    proc = subprocess.run(["swarmloc", "run", "laser-collab-three-rooms", "--particles", "999"],
                          capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 2 and f"within 0..{MAX_SAMPLES}" in proc.stderr


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


@pytest.fixture(scope="module")
def unchunked_recording(small_recording, tmp_path_factory) -> Path:
    """The small recording in the layout before issue 44 (one record per message, no
    compression): a file of an earlier version, and one whose JSON can be spoilt byte-wise."""
    from swarmloc.deploy.observe.record import rewrite

    path = tmp_path_factory.mktemp("rec") / "unchunked.mcap"
    rewrite(small_recording, path, chunked=False)
    return path


@pytest.mark.parametrize("mangle, expect, layout", [
    (lambda d: b"PNG\x89" + d[4:], "not an MCAP file", "chunked"),
    (lambda d: b"", "not an MCAP file", "chunked"),
    (lambda d: d[:20], "no /swarmloc/frame channel", "chunked"),
    (lambda d: d.replace(b'"bounds_m":[', b'"bounds_m"![', 1), "not valid json", "unchunked"),
])
def test_corrupt_recording_is_named(small_recording, unchunked_recording, tmp_path, mangle, expect, layout):
    source = small_recording if layout == "chunked" else unchunked_recording
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(mangle(source.read_bytes()))
    with pytest.raises(RecordingError, match=expect):
        read_recording(bad)
    proc = subprocess.run(["swarmloc", "view", str(bad), "--http", "127.0.0.1:0"],
                          capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 2 and expect in proc.stderr


# -- the page --------------------------------------------------------------------------------


class Page:
    """Headless chromium on one page of the view."""

    def __init__(self, url: str | None = None):
        from playwright.sync_api import sync_playwright

        self._pw = sync_playwright().start()
        self.browser = self._pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        self.page = self.browser.new_page(viewport={"width": 1300, "height": 760})
        if url is not None:
            self.open(url)

    def open(self, url: str) -> None:
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

    def to_pixels(self, points) -> list[list[float]]:
        """The page's own world-to-pixel transform of (x, y, ...) points."""
        return self.page.evaluate("(ps) => ps.map((p) => window.swarmloc.toPixel(p[0], p[1]))",
                                  [list(p[:2]) for p in points])

    def image(self) -> np.ndarray:
        from PIL import Image

        return np.asarray(Image.open(io.BytesIO(self.page.locator("#arena").screenshot())).convert("RGB"))

    def pixels_at(self, poses) -> list[np.ndarray]:
        points = self.to_pixels(poses)
        image = self.image()
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


def _samples_drawn_at(page: Page, frame: dict, per_robot: int) -> None:
    """Every robot's population is drawn where its poses are (a cyan square each), and goes when
    the page's particles box is unticked. The robots, their estimates and the lines joining them
    are drawn over the particles: only particles away from them are looked at."""
    assert len(frame["samples"]) == len(frame["truth"])
    assert all(0 < len(own) <= per_robot for own in frame["samples"]), "at most what was asked"
    samples = [p for own in frame["samples"] for p in own]
    radius_px = page.page.evaluate(
        "Math.max(window.swarmloc.scene.robot_radius_m * window.swarmloc.transform.s, 5)")
    drawn_over = np.array(page.to_pixels([p for p in frame["truth"] + frame["estimates"] if p]))
    free = [xy for xy in page.to_pixels(samples)
            if np.hypot(*(drawn_over - xy).T).min() > 1.5 * radius_px + 3]
    assert len(free) >= 5, "particles to look at, away from the robots"

    def cyan(image) -> np.ndarray:
        return np.array([np.abs(image[round(y), round(x)].astype(int) - SAMPLE_RGB).max() <= 40
                         for x, y in free])

    shown = cyan(page.image())
    assert shown.mean() >= 0.9, f"particles drawn at {shown.sum()} of {len(free)} of their poses"
    page.page.uncheck("#samples")
    assert cyan(page.image()).mean() <= 0.05, "unticked: no particles drawn"
    page.page.check("#samples")


def _synthetic_replay(tmp_path):
    from swarmloc.world.replay.mrclam import SyntheticConfig, synthesize, write_dataset

    folder = write_dataset(synthesize(SyntheticConfig(n_robots=3, n_landmarks=8, duration_s=30.0),
                                      np.random.default_rng(11)), tmp_path / "Synthetic")
    return load_any("mrclam6-ekf-coop", {"seed": 1},
                    [f"dataset={json.dumps(str(folder))}", "duration_s=12.0", "calibration_s=0.0"])


PARTICLES = 48
FAMILIES = {
    # name: (scenario builder, lockstep?, the world's extra flags) -- in lockstep these short runs
    # end before a page has loaded, so they run in real time (the recording test covers lockstep).
    # The laser robots are asked for their populations (--particles): the page draws them.
    "foraging": (lambda tmp: load_any("ES1", {"robots": 4, "duration_s": 25.0, "seed": 3}, []), False, ()),
    "laser": (lambda tmp: load_any("laser-collab-three-rooms", {"seed": 1}, ["world.steps=60"]), False,
              ("--particles", str(PARTICLES))),
    "vision": (lambda tmp: load_any("vision-exp2", {"seed": 2}, []), False, ()),
    "replay": (_synthetic_replay, False, ()),
}


@needs_browser
@pytest.mark.parametrize("family", list(FAMILIES))
def test_live_page_and_replay_page_show_the_robots(tmp_path, family):
    build, lockstep, world_flags = FAMILIES[family]
    scenario = build(tmp_path)
    path = _write(tmp_path, scenario)
    mcap = tmp_path / "run.mcap"
    run = "view" + uuid.uuid4().hex[:8]
    # The browser starts first: on a crowded machine its start took longer than a short run.
    page = Page()
    with supervised() as sup:
        try:
            swarm = start_swarm(sup, path, run=run, robots=scenario.robots, out=tmp_path / "out",
                                log_dir=tmp_path, join_timeout_s=90, realtime=not lockstep,
                                world_args=("--record", str(mcap), *world_flags))
            _view, url = start_view(sup, swarm.router_endpoint, run, "127.0.0.1:0", tmp_path / "view.log")
            assert url.startswith("http://127.0.0.1:")
            page.open(url)
            page.wait_tick("t > 0", 120)
            first = page.tick()
            page.wait_tick(f"t > {first}", 60)  # the counter advances
            page.page.click("#pause")  # the page keeps what it shows; the run goes on
            shown = page.shown()
            _robots_drawn_at(page, shown["truth"], shown["state"]["alive"])
            if world_flags:
                _samples_drawn_at(page, shown, PARTICLES)
            else:
                assert "samples" not in shown, "populations only on request"
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
    if world_flags:  # the populations are recorded, and Foxglove gets them (its own schema)
        assert by_tick[shown["tick"]]["samples"] == shown["samples"]
        clouds = _foxglove_messages(mcap, rec.scene["tick_s"])[SAMPLES_TOPIC]
        assert clouds and all(len(c["poses"]) == sum(map(len, by_tick[t]["samples"])) for t, c in clouds)
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
            if world_flags:
                _samples_drawn_at(page, frame, PARTICLES)
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


def test_standalone_recorder_keeps_the_frames_it_receives(tmp_path):
    """`swarmloc record --run RUN`: the world's bounded frame stream (msgpack) to a recording
    whose frames are the world's own for their ticks, in order, ending at the run's end."""
    scenario = load_any("ES1", {"robots": 3, "duration_s": 12.0, "seed": 5}, [])
    path = _write(tmp_path, scenario)
    run = "sr" + uuid.uuid4().hex[:8]
    mcap, received = tmp_path / "world.mcap", tmp_path / "received.mcap"
    with supervised() as sup:
        swarm = start_swarm(sup, path, run=run, robots=3, out=tmp_path / "out", log_dir=tmp_path,
                            join_timeout_s=90, realtime=True, world_args=("--record", str(mcap)))
        recorder = sup.start(["record", str(received), "--run", run, "-e", swarm.router_endpoint],
                             stdout=subprocess.PIPE)
        assert json.loads(recorder.stdout.readline())["run"] == run  # subscribed: readiness
        assert swarm.world.wait(timeout=120) == 0, (tmp_path / "world.log").read_text()[-2000:]
        assert recorder.wait(timeout=60) == 0, "the recorder stops at the run's end"
    world = {f["tick"]: f for f in read_recording(mcap).frames}
    rec = read_recording(received)
    ticks = [f["tick"] for f in rec.frames]
    assert rec.truncated is None and len(ticks) > 20 and ticks == sorted(set(ticks))
    assert ticks[-1] == max(world), "the last tick, sent when the run ends"
    assert all(f["state"]["poses"] == world[f["tick"]]["state"]["poses"] for f in rec.frames)
