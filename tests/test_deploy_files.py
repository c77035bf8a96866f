"""The shipped service units call the swarmloc command with options it really has."""

from __future__ import annotations

import configparser
import shlex
from pathlib import Path

import pytest

from swarmloc.deploy.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
UNITS = sorted((ROOT / "deploy" / "systemd").glob("*.service"))


def _env() -> dict[str, str]:
    env = {}
    for line in (ROOT / "deploy" / "systemd" / "swarmloc.env.example").read_text().splitlines():
        if line and not line.startswith("#"):
            key, _, value = line.partition("=")
            env[key] = value
    return env


def test_there_are_units_for_router_world_and_agents():
    names = {u.name for u in UNITS}
    assert names == {"swarmloc-router.service", "swarmloc-world.service", "swarmloc-agent@.service"}


def _service(unit: Path):
    parser = configparser.ConfigParser(interpolation=None, strict=False)
    parser.read_string(unit.read_text())
    return parser["Service"]


@pytest.mark.parametrize("unit", UNITS, ids=lambda u: u.name)
def test_unit_command_parses(unit):
    command = _service(unit)["ExecStart"]
    env = _env()
    for key, value in env.items():
        command = command.replace("${" + key + "}", value)
    command = command.replace("%i", "7")
    assert "${" not in command, f"{unit.name}: unknown variable in {command}"
    argv = shlex.split(command)
    assert argv[0] == env["SWARMLOC"]
    args = build_parser().parse_args(argv[1:])  # argparse exits on an unknown option
    assert args.command in {"router", "world", "agent"}
    if args.command == "agent":
        assert args.robot == 7


@pytest.mark.parametrize("unit", [u for u in UNITS if "router" not in u.name], ids=lambda u: u.name)
def test_world_and_agent_units_warm_the_kernels_before_they_start(unit):
    service = _service(unit)
    pre = shlex.split(service["ExecStartPre"].replace("${SWARMLOC}", _env()["SWARMLOC"]))
    assert build_parser().parse_args(pre[1:]).command == "warm"
    assert float(service["TimeoutStartSec"]) >= 120, "a cold compile takes about a minute"
