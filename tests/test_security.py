"""Security deployment: user/password authentication and access control on a Zenoh router.

Every test starts its own router from ``deploy/zenoh/router-secure.json5`` (placeholders
replaced: listen on ``tcp/127.0.0.1:0``, the port read back with ``bound_endpoints``; the
dictionary is ``deploy/zenoh/credentials.example`` without its comment lines), with multicast
scouting and gossip off, and a fresh run name. Clients connect in client mode with the
credentials of the example file.

Readiness is awaited on data (a probe on an allowed key is re-sent until it arrives, each try
waiting on a ``threading.Event``), never by sleeping. To show that a forbidden message is NOT
delivered, it is sent BEFORE an allowed marker from the same session; once the marker has
arrived, a further bounded wait confirms the forbidden message did not.
"""

from __future__ import annotations

import json
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import zenoh

from swarmloc.protocol.keys import Keys
from swarmloc.protocol.session import bound_endpoints, open_session, session_config

pytestmark = pytest.mark.integration

DEPLOY = Path(__file__).resolve().parent.parent / "deploy" / "zenoh"
TEMPLATE = DEPLOY / "router-secure.json5"
EXAMPLE_CREDENTIALS = DEPLOY / "credentials.example"
PASSWORDS = {"world": "change-me-world", "robot-2": "change-me-robot-2", "robot-3": "change-me-robot-3"}

#: How long a negative check waits after its positive marker arrived.
QUIET_S = 0.3
#: Upper bound for anything that must arrive.
ARRIVE_S = 5.0
#: Declared entities are kept referenced until their session closes (a dropped token object
#: is undeclared); the router fixture empties the list.
HELD: list[object] = []


def _credentials_file(tmp_path: Path) -> Path:
    lines = EXAMPLE_CREDENTIALS.read_text().splitlines()
    path = tmp_path / "credentials"
    path.write_text("".join(line + "\n" for line in lines if not line.startswith("#")))
    path.chmod(0o600)
    return path


def _router_config_file(tmp_path: Path, dictionary: Path) -> Path:
    text = TEMPLATE.read_text()
    assert "@LISTEN_ENDPOINT@" in text and "@CREDENTIALS_FILE@" in text
    text = text.replace("@LISTEN_ENDPOINT@", "tcp/127.0.0.1:0")
    text = text.replace("@CREDENTIALS_FILE@", str(dictionary))
    path = tmp_path / "router.json5"
    path.write_text(text)
    return path


@pytest.fixture
def router(tmp_path) -> Iterator[tuple[zenoh.Session, str]]:
    """A secure router on a free loopback port: (its session, its endpoint)."""
    config_file = _router_config_file(tmp_path, _credentials_file(tmp_path))
    config = session_config(mode=None, listen=["tcp/127.0.0.1:0"], config_file=config_file)
    assert json.loads(config.get_json("mode")) == "router"
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    session = open_session(config)
    try:
        endpoints = bound_endpoints(session)
        assert len(endpoints) == 1 and endpoints[0].startswith("tcp/127.0.0.1:")
        yield session, endpoints[0]
    finally:
        session.close()
        HELD.clear()


def _client_config(endpoint: str, user: str | None, password: str | None, timeout_ms: int):
    config = session_config(mode="client", connect=[endpoint])
    # A finite connect timeout: a refused client must fail, not wait for ever.
    config.insert_json5("connect/timeout_ms", str(timeout_ms))
    if user is not None:
        config.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
    if password is not None:
        config.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return config


@contextmanager
def _client(endpoint: str, user: str, password: str | None = None) -> Iterator[zenoh.Session]:
    if password is None:
        password = PASSWORDS[user]
    session = open_session(_client_config(endpoint, user, password, timeout_ms=5000))
    try:
        yield session
    finally:
        session.close()


class Inbox:
    """Collects (key, payload) of samples; signals when a given payload has arrived."""

    def __init__(self) -> None:
        self.samples: list[tuple[str, bytes]] = []
        self._lock = threading.Lock()
        self._events: dict[bytes, threading.Event] = {}

    def _event(self, payload: bytes) -> threading.Event:
        with self._lock:
            return self._events.setdefault(payload, threading.Event())

    def __call__(self, sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        with self._lock:
            self.samples.append((str(sample.key_expr), payload))
        self._event(payload).set()

    def wait_for(self, payload: bytes, timeout: float = ARRIVE_S) -> bool:
        return self._event(payload).wait(timeout)

    def payloads(self) -> list[bytes]:
        with self._lock:
            return [payload for _, payload in self.samples]

    def keys(self) -> list[str]:
        with self._lock:
            return [key for key, _ in self.samples]


def _probe_until_received(put, inbox: Inbox, deadline_s: float = ARRIVE_S) -> None:
    """Re-send a probe (``put(payload)``) until ``inbox`` gets it: the route is then up."""
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        put(b"probe")
        if inbox.wait_for(b"probe", timeout=0.05):
            return
    raise AssertionError("probe never arrived: the route was not established")


def _keys() -> Keys:
    return Keys(f"sec-{uuid.uuid4().hex[:12]}")


# --------------------------------------------------------------------------------------------
# Configuration files


def test_template_loads_and_enables_auth_and_access_control(tmp_path):
    config = zenoh.Config.from_file(str(_router_config_file(tmp_path, _credentials_file(tmp_path))))
    acl = json.loads(config.get_json("access_control"))
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    subjects = {s["id"]: s for s in acl["subjects"]}
    assert subjects["world"]["usernames"] == ["world"]
    for robot in range(4):
        assert subjects[f"robot-{robot}"]["usernames"] == [f"robot-{robot}"]
    usrpwd = json.loads(config.get_json("transport/auth/usrpwd"))
    assert usrpwd["dictionary_file"] == str(tmp_path / "credentials")
    assert usrpwd["user"] is None and usrpwd["password"] is None


def test_dictionary_with_comment_lines_is_rejected_by_zenoh(tmp_path):
    """Observed: Zenoh 1.10 refuses '#' lines, so the example's comments must be removed."""
    config_file = _router_config_file(tmp_path, EXAMPLE_CREDENTIALS)
    config = session_config(mode=None, listen=["tcp/127.0.0.1:0"], config_file=config_file)
    with pytest.raises(zenoh.ZError, match="invalid format"):
        session = open_session(config)
        session.close()


# --------------------------------------------------------------------------------------------
# Authentication


@pytest.mark.parametrize(
    ("user", "password"),
    [
        (None, None),  # no credentials: the router closes the link at InitSyn
        ("world", "wrong-password"),  # wrong password: closed at OpenSyn
        ("robot-9", "change-me-robot-3"),  # unknown user: closed at OpenSyn
    ],
    ids=["no-credentials", "wrong-password", "unknown-user"],
)
def test_router_refuses_client_without_valid_credentials(router, user, password):
    """Observed: the session does not open at all; zenoh.open raises once the timeout expires."""
    _, endpoint = router
    config = _client_config(endpoint, user, password, timeout_ms=500)
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        session = open_session(config)
        session.close()  # only reached if the router wrongly accepted the client


def test_correct_credentials_exchange_data(router):
    _, endpoint = router
    keys = _keys()
    with _client(endpoint, "world") as world, _client(endpoint, "robot-3") as robot:
        inbox = Inbox()
        HELD.append(world.declare_subscriber(keys.act_all, inbox))
        _probe_until_received(lambda p: robot.put(keys.act(3), p), inbox)
        robot.put(keys.act(3), b"act-3")
        assert inbox.wait_for(b"act-3")
        assert set(inbox.keys()) == {keys.act(3)}


# --------------------------------------------------------------------------------------------
# Access control: robot-3


def test_robot_put_on_another_robots_act_never_arrives(router):
    router_session, endpoint = router
    keys = _keys()
    # A second observer inside the router: it sees whatever passed the router's ingress check.
    inside = Inbox()
    HELD.append(router_session.declare_subscriber(f"{keys.prefix}/**", inside))
    with _client(endpoint, "world") as world, _client(endpoint, "robot-3") as robot:
        inbox = Inbox()
        HELD.append(world.declare_subscriber(keys.act_all, inbox))
        _probe_until_received(lambda p: robot.put(keys.act(3), p), inbox)

        robot.put(keys.act(4), b"forged-act-4")  # forbidden, sent first
        robot.put(keys.act(3), b"marker")  # allowed, same session, after it
        assert inbox.wait_for(b"marker")
        assert inside.wait_for(b"marker")
        assert not inbox.wait_for(b"forged-act-4", timeout=QUIET_S)
        assert b"forged-act-4" not in inside.payloads()
        assert keys.act(4) not in inbox.keys() + inside.keys()


def test_robot_shares_blobs_only_under_its_own_id_and_teammates_hear_them(router):
    router_session, endpoint = router
    keys = _keys()
    inside = Inbox()
    HELD.append(router_session.declare_subscriber(f"{keys.prefix}/**", inside))
    with _client(endpoint, "robot-2") as mate, _client(endpoint, "robot-3") as robot:
        inbox = Inbox()
        HELD.append(mate.declare_subscriber(f"{keys.prefix}/team/A/blobs/*", inbox))
        _probe_until_received(lambda p: robot.put(keys.team_blobs("A", 3), p), inbox)

        robot.put(keys.team_blobs("A", 2), b"forged-blobs-2")  # as its teammate: forbidden
        robot.put(keys.team_blobs("A", 3), b"marker")
        assert inbox.wait_for(b"marker")
        assert inside.wait_for(b"marker")
        assert not inbox.wait_for(b"forged-blobs-2", timeout=QUIET_S)
        assert b"forged-blobs-2" not in inside.payloads()


def test_robot_cannot_publish_sense_or_world_keys(router):
    router_session, endpoint = router
    keys = _keys()
    inside = Inbox()  # one subscriber for every key of the run, inside the router
    HELD.append(router_session.declare_subscriber(f"{keys.prefix}/**", inside))
    with _client(endpoint, "robot-3") as robot:
        _probe_until_received(lambda p: robot.put(keys.act(3), p), inside)
        robot.put(keys.sense(3), b"fake-own-sense")
        robot.put(keys.sense(4), b"fake-other-sense")
        robot.put(keys.world_state, b"fake-state")
        robot.put(keys.run_end, b"fake-end")
        robot.put(f"{keys.prefix}/anything/else", b"fake-other")
        robot.put(keys.act(3), b"marker")
        assert inside.wait_for(b"marker")
        assert not inside.wait_for(b"fake-state", timeout=QUIET_S)
        assert set(inside.keys()) == {keys.act(3)}, inside.samples


def test_robot_receives_its_own_sense_and_world_keys_only(router):
    _, endpoint = router
    keys = _keys()
    with _client(endpoint, "world") as world, _client(endpoint, "robot-3") as robot:
        own, other, world_keys = Inbox(), Inbox(), Inbox()
        HELD.append(robot.declare_subscriber(keys.sense(3), own))
        # robot-3 may not subscribe to robot 4's sense: the router refuses the declaration.
        HELD.append(robot.declare_subscriber(keys.sense(4), other))
        HELD.append(robot.declare_subscriber(f"{keys.prefix}/world/**", world_keys))
        _probe_until_received(lambda p: world.put(keys.world_state, p), world_keys)
        _probe_until_received(lambda p: world.put(keys.sense(3), p), own)

        world.put(keys.sense(4), b"sense-4")
        world.put(keys.sense(3), b"sense-3")
        world.put(keys.run_end, b"end")
        assert own.wait_for(b"sense-3")
        assert world_keys.wait_for(b"end")
        # Different subscribers run on different threads: a bounded wait after the markers.
        assert not other.wait_for(b"sense-4", timeout=QUIET_S)
        assert other.samples == []


def test_robot_liveliness_token_only_on_its_own_alive_key(router):
    _, endpoint = router
    keys = _keys()
    with _client(endpoint, "world") as world, _client(endpoint, "robot-3") as robot:
        seen: list[str] = []
        own_seen, other_seen = threading.Event(), threading.Event()

        def on_alive(sample: zenoh.Sample) -> None:
            seen.append(str(sample.key_expr))
            if str(sample.key_expr) == keys.alive(3):
                own_seen.set()
            if str(sample.key_expr) == keys.alive(4):
                other_seen.set()

        watcher = world.liveliness().declare_subscriber(keys.alive_all, on_alive, history=True)
        # Keep the tokens referenced: a dropped token object is undeclared.
        forged = robot.liveliness().declare_token(keys.alive(4))  # forbidden, declared first
        token = robot.liveliness().declare_token(keys.alive(3))  # allowed
        assert own_seen.wait(ARRIVE_S)
        assert not other_seen.wait(QUIET_S)
        # history=True may deliver the allowed token twice (history answer + live declaration).
        assert set(seen) == {keys.alive(3)}
        # The world's own query of the liveliness space does not see it either.
        replies = world.liveliness().get(keys.alive_all, timeout=2.0)
        alive = {str(r.ok.key_expr) for r in replies if r.ok is not None}
        assert alive == {keys.alive(3)}
        for entity in (forged, token, watcher):
            entity.undeclare()


def test_robot_can_join_through_the_worlds_queryable(router):
    _, endpoint = router
    keys = _keys()
    with _client(endpoint, "world") as world, _client(endpoint, "robot-3") as robot:
        HELD.append(
            world.declare_queryable(
                keys.join, lambda query: query.reply(query.key_expr, b"welcome")
            )
        )
        end = time.monotonic() + ARRIVE_S
        answers: list[bytes] = []
        while not answers and time.monotonic() < end:  # until the queryable is routed
            answers = [r.ok.payload.to_bytes() for r in robot.get(keys.join, timeout=0.5) if r.ok]
        assert answers == [b"welcome"]


# --------------------------------------------------------------------------------------------
# Access control: world


def test_world_publishes_sense_and_world_keys_but_not_act_or_other_keys(router):
    router_session, endpoint = router
    keys = _keys()
    inside = Inbox()
    HELD.append(router_session.declare_subscriber(f"{keys.prefix}/**", inside))
    with _client(endpoint, "world") as world, _client(endpoint, "world") as world_reader:
        acts = Inbox()  # another world process, which may receive act
        HELD.append(world_reader.declare_subscriber(keys.act_all, acts))
        _probe_until_received(lambda p: world.put(keys.world_state, p), inside)

        world.put(keys.act(3), b"forged-act")  # forbidden
        world.put(keys.alive(3), b"forged-alive")  # forbidden (a put, not a token)
        world.put(f"{keys.prefix}/team/a/blobs/3", b"forged-blobs")  # forbidden
        world.put(keys.sense(3), b"sense-3")  # allowed
        world.put(keys.sense(0), b"sense-0")  # allowed
        world.put(keys.run_end, b"marker")  # allowed
        assert inside.wait_for(b"marker")
        assert not inside.wait_for(b"forged-act", timeout=QUIET_S)
        assert set(inside.keys()) == {keys.world_state, keys.sense(3), keys.sense(0), keys.run_end}
        assert acts.samples == []


def test_unlisted_user_gets_nothing_through(tmp_path):
    """A user in the dictionary but in no ACL subject authenticates, then every put is denied."""
    dictionary = _credentials_file(tmp_path)
    dictionary.write_text(dictionary.read_text() + "intruder:intruder-pass\n")
    config_file = _router_config_file(tmp_path, dictionary)
    router_session = open_session(
        session_config(mode=None, listen=["tcp/127.0.0.1:0"], config_file=config_file)
    )
    try:
        endpoint = bound_endpoints(router_session)[0]
        keys = _keys()
        inside = Inbox()
        HELD.append(router_session.declare_subscriber(f"{keys.prefix}/**", inside))
        with (
            _client(endpoint, "robot-3") as robot,
            _client(endpoint, "intruder", "intruder-pass") as intruder,
        ):
            _probe_until_received(lambda p: robot.put(keys.act(3), p), inside)
            for key in (keys.act(3), keys.sense(3), keys.world_state):
                intruder.put(key, b"intruder")
            # The intruder's puts and robot-3's marker travel on different links: the bounded
            # wait after the marker is what covers the intruder's.
            intruder.put(keys.act(3), b"intruder-last")
            robot.put(keys.act(3), b"marker")
            assert inside.wait_for(b"marker")
            assert not inside.wait_for(b"intruder-last", timeout=1.0)
            assert b"intruder" not in inside.payloads()
    finally:
        router_session.close()
