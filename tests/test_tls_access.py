"""TLS with certificates, mutual TLS, and access control on every key (issue 21), with real
sessions.

Each test makes a CA (``swarmloc.protocol.tls``) in its tmp folder and starts its own router from
``deploy/zenoh/router-secure.json5`` on ``tls/127.0.0.1:0`` (every placeholder replaced; the
dictionary is ``credentials.example`` without its comments); clients connect in client mode with
their own certificate and their user of the example file. Readiness and the "not delivered"
checks work as in ``tests/test_security.py`` (a forbidden message is sent before an allowed
marker from the same session; once the marker arrived, a bounded wait confirms the forbidden one
did not), whose helpers this module reuses.
"""

from __future__ import annotations

import datetime as dt
import json
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import zenoh
from test_security import (
    ARRIVE_S,
    HELD,
    QUIET_S,
    TEMPLATE,
    Inbox,
    _credentials_file,
    _keys,
    _probe_until_received,
)

from swarmloc.protocol import tls
from swarmloc.protocol.session import bound_endpoints, open_session, session_config

pytestmark = pytest.mark.integration

PASSWORDS = {
    "world": "change-me-world", "observer": "change-me-observer",
    **{f"robot-{i}": f"change-me-robot-{i}" for i in range(4)},
}
CLIENT_TEMPLATE = TEMPLATE.with_name("client-secure.json5")


@pytest.fixture
def pki(tmp_path) -> Path:
    """A CA with a certificate for the router and each user; a second, foreign CA in other/."""
    folder = tmp_path / "pki"
    tls.make_ca(folder)
    for name in ("router", *PASSWORDS):
        tls.issue(folder, name)
    tls.make_ca(tmp_path / "other", common_name="someone else's CA")
    tls.issue(tmp_path / "other", "robot-3")
    return folder


def _router_file(tmp_path: Path, pki: Path) -> Path:
    text = TEMPLATE.read_text()
    for placeholder, value in {
        "@LISTEN_ENDPOINT@": "tls/127.0.0.1:0",
        "@CREDENTIALS_FILE@": str(_credentials_file(tmp_path)),
        "@TLS_ROOT_CA@": str(pki / "ca.pem"),
        "@TLS_CERTIFICATE@": str(pki / "router.pem"),
        "@TLS_PRIVATE_KEY@": str(pki / "router-key.pem"),
    }.items():
        assert placeholder in text
        text = text.replace(placeholder, value)
    assert "@" not in "".join(line.split("//")[0] for line in text.splitlines())
    path = tmp_path / "router-tls.json5"
    path.write_text(text)
    return path


@pytest.fixture
def router(tmp_path, pki) -> Iterator[tuple[zenoh.Session, str]]:
    session = open_session(session_config(mode=None, config_file=_router_file(tmp_path, pki),
                                          admin_space=True))
    try:
        endpoints = bound_endpoints(session)
        assert len(endpoints) == 1 and endpoints[0].startswith("tls/127.0.0.1:")
        yield session, endpoints[0]
    finally:
        session.close()
        HELD.clear()


def _client_file(tmp_path: Path, user: str, ca: Path, cert: Path | None, key: Path | None,
                 timeout_ms: int = 5000, mode: str = "client") -> Path:
    """The shipped client template filled in; ``cert=None`` drops the client's certificate."""
    text = CLIENT_TEMPLATE.read_text()
    for placeholder, value in {"@USER@": user, "@PASSWORD@": PASSWORDS.get(user, "x"),
                               "@TLS_ROOT_CA@": str(ca), "@TLS_CERTIFICATE@": str(cert),
                               "@TLS_PRIVATE_KEY@": str(key)}.items():
        assert placeholder in text
        text = text.replace(placeholder, value)
    text = text.replace("timeout_ms: 10000", f"timeout_ms: {timeout_ms}")
    text = text.replace('mode: "client"', f'mode: "{mode}"')
    if cert is None:
        text = "\n".join(line for line in text.splitlines()
                         if "connect_certificate" not in line and "connect_private_key" not in line)
    path = tmp_path / f"client-{user}-{abs(hash((str(cert), mode))) % 10**8}.json5"
    path.write_text(text)
    return path


def _config(tmp_path, pki, endpoint, user, mode="client", **kw):
    file = _client_file(tmp_path, user, pki / "ca.pem", pki / f"{user}.pem", pki / f"{user}-key.pem",
                        mode=mode, **kw)
    return session_config(mode=None, connect=[endpoint], config_file=file)


@contextmanager
def _client(tmp_path, pki, endpoint, user, mode="client") -> Iterator[zenoh.Session]:
    session = open_session(_config(tmp_path, pki, endpoint, user, mode=mode))
    try:
        yield session
    finally:
        session.close()


# --------------------------------------------------------------------------------------------
# Certificates


def test_check_tls_names_each_problem(tmp_path, pki):
    """The check :func:`session_config` runs before a tls/ session: it names file and problem."""
    ok = tls.tls_settings(pki / "ca.pem", pki / "robot-3.pem", pki / "robot-3-key.pem")

    def check(**changes):
        config = zenoh.Config()
        for k, v in {**ok, **changes}.items():
            config.insert_json5(f"transport/link/tls/{k}", json.dumps(v))
        tls.check_tls(config)

    check()
    old = tls.issue(pki, "old", valid_from=dt.datetime.now(dt.UTC) - dt.timedelta(days=3),
                    days=1)
    with pytest.raises(ValueError, match=r"old\.pem: expired on"):
        check(connect_certificate=str(old[0]), connect_private_key=str(old[1]))
    early = tls.issue(pki, "early", valid_from=dt.datetime.now(dt.UTC) + dt.timedelta(days=2))
    with pytest.raises(ValueError, match=r"early\.pem: not valid before"):
        check(connect_certificate=str(early[0]), connect_private_key=str(early[1]))
    other = tmp_path / "other"
    with pytest.raises(ValueError, match=r"robot-3\.pem: not signed by the CA .*someone else's CA"):
        check(connect_certificate=str(other / "robot-3.pem"),
              connect_private_key=str(other / "robot-3-key.pem"))
    with pytest.raises(ValueError, match=r"robot-2-key\.pem: does not belong to .*robot-3\.pem"):
        check(connect_private_key=str(pki / "robot-2-key.pem"))
    with pytest.raises(ValueError, match=r"nope\.pem: no such file"):
        check(root_ca_certificate=str(tmp_path / "nope.pem"))
    (tmp_path / "junk.pem").write_text("not a certificate")
    with pytest.raises(ValueError, match=r"junk\.pem: not a PEM certificate"):
        check(connect_certificate=str(tmp_path / "junk.pem"))
    with pytest.raises(ValueError, match="a CA is already there"):
        tls.make_ca(pki)


def test_certificate_holder_connects_and_exchanges_data(router, tmp_path, pki):
    _, endpoint = router
    keys = _keys()
    with (_client(tmp_path, pki, endpoint, "world") as world,
          _client(tmp_path, pki, endpoint, "robot-3") as robot):
        inbox = Inbox()
        HELD.append(world.declare_subscriber(keys.act_all, inbox))
        _probe_until_received(lambda p: robot.put(keys.act(3), p), inbox)


def test_client_without_certificate_cannot_connect(router, tmp_path, pki):
    _, endpoint = router
    file = _client_file(tmp_path, "robot-3", pki / "ca.pem", None, None, timeout_ms=800)
    config = session_config(mode=None, connect=[endpoint], config_file=file)
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        open_session(config).close()


def test_client_with_another_cas_certificate_cannot_connect(router, tmp_path, pki):
    """Both ways round: its certificate from another CA (with our CA to check the router), and
    another CA altogether (then it does not trust the router either)."""
    _, endpoint = router
    other = tmp_path / "other"
    for ca in (pki / "ca.pem", other / "ca.pem"):
        file = _client_file(tmp_path, "robot-3", ca, other / "robot-3.pem", other / "robot-3-key.pem",
                            timeout_ms=800)
        # The check names the problem first; past it, the router refuses the handshake.
        if ca == pki / "ca.pem":
            with pytest.raises(ValueError, match="not signed by the CA"):
                session_config(mode=None, connect=[endpoint], config_file=file)
        config = zenoh.Config.from_file(str(file))
        config.insert_json5("connect/endpoints", json.dumps([endpoint]))
        with pytest.raises(zenoh.ZError, match="Unable to connect"):
            open_session(config).close()


def test_expired_certificate_cannot_connect(router, tmp_path, pki):
    _, endpoint = router
    cert, key = tls.issue(pki, "robot-3-old", days=1,
                          valid_from=dt.datetime.now(dt.UTC) - dt.timedelta(days=5))
    file = _client_file(tmp_path, "robot-3", pki / "ca.pem", cert, key, timeout_ms=800)
    with pytest.raises(ValueError, match="expired on"):
        session_config(mode=None, connect=[endpoint], config_file=file)
    config = zenoh.Config.from_file(str(file))  # without the check: the router refuses it
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        open_session(config).close()


def test_certificate_without_password_is_not_enough(router, tmp_path, pki):
    """mTLS and user/password both apply: a good certificate with a wrong password is refused."""
    _, endpoint = router
    file = _client_file(tmp_path, "robot-3", pki / "ca.pem", pki / "robot-3.pem",
                        pki / "robot-3-key.pem", timeout_ms=800)
    file.write_text(file.read_text().replace("change-me-robot-3", "wrong"))
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        open_session(session_config(mode=None, connect=[endpoint], config_file=file)).close()


@pytest.mark.parametrize("problem", ["expired", "other-ca"])
def test_command_with_bad_certificate_stops_naming_the_problem(router, tmp_path, pki, problem):
    """``swarmloc status`` with an expired or foreign certificate: exit 2, the file and the
    problem named, before it tries to connect."""
    _, endpoint = router
    if problem == "expired":
        cert, key = tls.issue(pki, "observer-old", days=1,
                              valid_from=dt.datetime.now(dt.UTC) - dt.timedelta(days=5))
        want = "observer-old.pem: expired on"
    else:
        other = tmp_path / "other"
        cert, key = tls.issue(other, "observer")
        want = "not signed by the CA"
    file = _client_file(tmp_path, "observer", pki / "ca.pem", cert, key, timeout_ms=800)
    done = subprocess.run([sys.executable, "-m", "swarmloc.deploy.cli", "status", "-c", str(file),
                           "-e", endpoint, "--timeout-s", "1"],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 2, done
    assert want in done.stderr and "-c/--config" in done.stderr, done.stderr


def test_tls_cli_makes_a_ca_and_certificates(tmp_path):
    folder = tmp_path / "ca"
    for argv in (["tls", "make-ca", str(folder)],
                 ["tls", "issue", str(folder), "router", "--host", "router.lab", "--host", "10.0.0.5"]):
        done = subprocess.run([sys.executable, "-m", "swarmloc.deploy.cli", *argv],
                              capture_output=True, text=True, timeout=60, check=False)
        assert done.returncode == 0, done
    from cryptography import x509

    cert = x509.load_pem_x509_certificate((folder / "router.pem").read_bytes())
    sans = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert sans.get_values_for_type(x509.DNSName) == ["router.lab"]
    assert [str(a) for a in sans.get_values_for_type(x509.IPAddress)] == ["10.0.0.5"]
    assert (folder / "router-key.pem").stat().st_mode & 0o077 == 0
    assert (folder / "ca-key.pem").stat().st_mode & 0o077 == 0
    done = subprocess.run([sys.executable, "-m", "swarmloc.deploy.cli", "tls", "make-ca", str(folder)],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 2 and "a CA is already there" in done.stderr


# --------------------------------------------------------------------------------------------
# Access control over TLS: teams, observers, peers


def test_team_a_robot_cannot_publish_or_receive_team_b_blobs(router, tmp_path, pki):
    """robot-3 (team A) against robot-0 and robot-1 (team B): robot-1 hears its teammate robot-0
    (the marker), never robot-3's put on team B's key; robot-3's subscriber on team B's key hears
    nothing, while its subscriber on its own team's key hears robot-2."""
    router_session, endpoint = router
    keys = _keys()
    inside = Inbox()  # what passed the router's ingress check
    HELD.append(router_session.declare_subscriber(f"{keys.prefix}/**", inside))
    with (_client(tmp_path, pki, endpoint, "robot-0") as b0,
          _client(tmp_path, pki, endpoint, "robot-1") as b1,
          _client(tmp_path, pki, endpoint, "robot-2") as a2,
          _client(tmp_path, pki, endpoint, "robot-3") as a3,
          _client(tmp_path, pki, endpoint, "robot-3") as a3_ears):
        # robot-3 listens in a session of its own (a session hears its own puts locally).
        b1_hears, a3_hears_b, a3_hears_a = Inbox(), Inbox(), Inbox()
        HELD.append(b1.declare_subscriber(f"{keys.prefix}/team/B/blobs/*", b1_hears))
        HELD.append(a3_ears.declare_subscriber(f"{keys.prefix}/team/B/blobs/*", a3_hears_b))
        HELD.append(a3_ears.declare_subscriber(f"{keys.prefix}/team/A/blobs/*", a3_hears_a))
        _probe_until_received(lambda p: b0.put(keys.team_blobs("B", 0), p), b1_hears)
        _probe_until_received(lambda p: a2.put(keys.team_blobs("A", 2), p), a3_hears_a)

        # Publish: robot-3 on team B's keys (its own id and a team B member's), then its marker.
        a3.put(keys.team_blobs("B", 3), b"a3-on-B3")
        a3.put(keys.team_blobs("B", 0), b"a3-on-B0")
        a3.put(keys.team_blobs("A", 3), b"a3-marker")
        assert inside.wait_for(b"a3-marker")
        # Receive: team B's traffic, then team A's marker to robot-3.
        b0.put(keys.team_blobs("B", 0), b"b0-blobs")
        a2.put(keys.team_blobs("A", 2), b"a2-marker")
        assert b1_hears.wait_for(b"b0-blobs")
        assert a3_hears_a.wait_for(b"a2-marker")
        assert not b1_hears.wait_for(b"a3-on-B3", timeout=QUIET_S)
        assert b"a3-on-B0" not in b1_hears.payloads()
        assert not {b"a3-on-B3", b"a3-on-B0"} & set(inside.payloads())
        assert a3_hears_b.samples == []


def test_observer_cannot_publish_anything_but_can_watch(router, tmp_path, pki):
    router_session, endpoint = router
    keys = _keys()
    inside = Inbox()
    HELD.append(router_session.declare_subscriber(f"{keys.prefix}/**", inside))
    with (_client(tmp_path, pki, endpoint, "world") as world,
          _client(tmp_path, pki, endpoint, "observer") as observer):
        # It watches: the world's state reaches it, and it sees the world's liveliness token.
        state = Inbox()
        HELD.append(observer.declare_subscriber(keys.world_state, state))
        _probe_until_received(lambda p: world.put(keys.world_state, p), state)
        HELD.append(world.liveliness().declare_token(keys.world_alive))
        end_seen = False
        for _ in range(50):
            replies = observer.liveliness().get(keys.alive_all, timeout=0.2)
            if {str(r.ok.key_expr) for r in replies if r.ok is not None} == {keys.world_alive}:
                end_seen = True
                break
        assert end_seen, "the observer's liveliness query never saw the world"

        # It publishes nothing: no put on any key, no liveliness token.
        watcher = Inbox()
        HELD.append(world.liveliness().declare_subscriber(f"{keys.prefix}/alive/*", watcher,
                                                          history=True))
        forbidden = [keys.world_state, keys.run_end, keys.act(0), keys.sense(0),
                     keys.team_blobs("A", 2), f"{keys.prefix}/anything"]
        for key in forbidden:
            observer.put(key, b"observer-put")
        HELD.append(observer.liveliness().declare_token(keys.alive(0)))
        observer.put(keys.world_state, b"observer-last")
        world.put(keys.run_end, b"marker")
        assert inside.wait_for(b"marker")
        assert state.wait_for(b"probe")
        assert not inside.wait_for(b"observer-last", timeout=1.0)
        # (Its own subscriber hears its puts inside its own session: they never left it.)
        assert b"observer-put" not in inside.payloads()
        assert keys.alive(0) not in watcher.keys()  # noqa: SIM118 -- Inbox.keys(), not a dict


def test_a_peer_linked_to_the_router_is_held_to_the_same_rules(router, tmp_path, pki):
    """A piece opened as a peer (not the documented client mode) that links to the router: the
    router checks that link like a client's, so robot-3's forged act never arrives."""
    router_session, endpoint = router
    keys = _keys()
    inside = Inbox()
    HELD.append(router_session.declare_subscriber(f"{keys.prefix}/**", inside))
    with _client(tmp_path, pki, endpoint, "robot-3", mode="peer") as robot:
        _probe_until_received(lambda p: robot.put(keys.act(3), p), inside)
        robot.put(keys.act(4), b"forged-act-4")
        robot.put(keys.team_blobs("B", 3), b"forged-blobs")
        robot.put(keys.act(3), b"marker")
        assert inside.wait_for(b"marker", ARRIVE_S)
        assert not inside.wait_for(b"forged-act-4", timeout=QUIET_S)
        assert set(inside.keys()) == {keys.act(3)}


# --------------------------------------------------------------------------------------------
# What the router cannot check: a piece that listens


@pytest.mark.parametrize("mode", ["client", "peer"])
def test_a_piece_opened_from_the_client_template_listens_on_nothing(router, tmp_path, pki, mode):
    """``client-secure.json5`` (``listen: []``, no scouting, no gossip), in client mode or even
    in peer mode: the session listens on no endpoint, so no other piece can link to it; its one
    link is to the router, which checks every message on it."""
    _, endpoint = router
    file = _client_file(tmp_path, "robot-2", pki / "ca.pem", pki / "robot-2.pem",
                        pki / "robot-2-key.pem", mode=mode)
    session = open_session(session_config(mode=None, connect=[endpoint], config_file=file,
                                          admin_space=True))
    try:
        assert bound_endpoints(session) == []
    finally:
        session.close()


@pytest.mark.parametrize("attacker_has_credentials", [True, False], ids=["own-password", "none"])
def test_a_piece_from_the_client_template_refuses_direct_links_even_if_it_listens(
        router, tmp_path, pki, attacker_has_credentials):
    """Robot 2 opened from ``client-secure.json5`` but as a peer that also listens (what the
    guide forbids), linked to the router. Robot 3 (a valid certificate; its own password, or
    none) tries to link to robot 2 directly, around the router: robot 2 refuses the session (it
    holds credentials to show but no dictionary to check anyone's: Zenoh closes the handshake at
    InitSyn without credentials, at OpenSyn with them), so robot 3's ``zenoh.open`` fails."""
    _, endpoint = router
    victim = open_session(_listening_robot_2(tmp_path, pki, endpoint))
    try:
        (victim_endpoint,) = bound_endpoints(victim)
        attacker = _config(tmp_path, pki, victim_endpoint, "robot-3", mode="peer", timeout_ms=3000)
        attacker.insert_json5("connect/exit_on_failure", "true")
        if not attacker_has_credentials:
            attacker.insert_json5("transport/auth/usrpwd", "{}")
        with pytest.raises(zenoh.ZError, match="Unable to connect"):
            open_session(attacker).close()
    finally:
        victim.close()


def test_a_piece_that_listens_without_credentials_is_a_way_around_the_router(router, tmp_path, pki):
    """The same listening robot 2 with its user/password block removed: robot 3 links to it
    directly, and on that link no rule applies, so its fake sense data for robot 2, which the
    router drops (``test_security.py``), reaches robot 2. Hence the guide's rule: no piece
    listens, and none runs without its ``transport.auth.usrpwd`` block."""
    _, endpoint = router
    keys = _keys()
    config = _listening_robot_2(tmp_path, pki, endpoint)
    config.insert_json5("transport/auth/usrpwd", "{}")
    victim = open_session(config)
    try:
        (victim_endpoint,) = bound_endpoints(victim)
        inbox = Inbox()
        HELD.append(victim.declare_subscriber(keys.sense(2), inbox))
        attacker = _config(tmp_path, pki, victim_endpoint, "robot-3", mode="peer")
        attacker.insert_json5("transport/auth/usrpwd", "{}")
        with open_session(attacker) as robot_3:
            _probe_until_received(lambda p: robot_3.put(keys.sense(2), p), inbox)
            robot_3.put(keys.sense(2), b"fake-sense-for-2")
            assert inbox.wait_for(b"fake-sense-for-2")
    finally:
        HELD.clear()
        victim.close()


def _listening_robot_2(tmp_path, pki, router_endpoint) -> zenoh.Config:
    """Robot 2's ``client-secure.json5`` in peer mode, linked to the router, also listening on
    ``tls/127.0.0.1:0`` with its own certificate."""
    config = _config(tmp_path, pki, router_endpoint, "robot-2", mode="peer")
    config.insert_json5("listen/endpoints", '["tls/127.0.0.1:0"]')
    config.insert_json5("adminspace/enabled", "true")
    return tls.apply_tls(config, pki / "ca.pem", pki / "robot-2.pem", pki / "robot-2-key.pem",
                         listen=True)
