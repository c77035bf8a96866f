"""The contract checker: does a world and its brains keep the contracts the shells rely on?

In the spirit of Gymnasium's ``utils/env_checker.py``: one function, :func:`check`, that any new
world, brain, localizer or strategy goes through before it is run as processes or in an
experiment, and that the test suite runs over every registered family, strategy and localizer
(``tests/test_checker.py``). It runs the scenario in this process, without Zenoh, exactly as the
shells would: the world's Senses as bytes, each robot's brain built from the world's Welcome,
each Act encoded and decoded by the protocol codec. Checks, each named in the error it raises:

1. ``types``: every Sense decodes as the brain's ``sense_type``, every Act is an instance of the
   world's ``act_type``, and both survive an encode/decode round trip unchanged (what crosses a
   process boundary is what the codec lets through: types, lengths, finite numbers, sizes);
   ``state()`` is a :class:`WorldState` with one pose per robot; ``summary()`` is JSON.
2. ``determinism``: a second run with the same seed gives the same Sense and Act bytes, tick for
   tick; a run with another seed gives other Senses (the seed reaches the world; not for a
   replay of recorded data, whose Senses are the data).
3. ``batch``: for brains that step a batch of robots (the e-puck brain), one brain holding the
   whole swarm gives the same Acts as one brain per robot (what the batch engine runs against
   what the agent processes run).
4. ``pure``: the modules of the world model and of the brains import without importing zenoh
   (checked in a fresh interpreter): pure models never touch the transport.
5. ``bad input``: a teammate's payload replaced by garbage bytes is recorded in the brain's error
   counter and skipped; the brain still answers with an Act (families whose Senses carry
   teammates' payloads).

A world that drives its robots itself (laser, replay) has no commands to check; a brain whose
Senses carry no payloads skips check 5 (the report says which were skipped and why).
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from dataclasses import dataclass, field
from typing import Any

#: Garbage in place of a teammate's payload (check 5): not msgpack of anything a brain expects.
GARBAGE_PAYLOAD = b"\xc1\xff\x00not a payload"


class CheckError(AssertionError):
    """A contract the shells rely on is broken; the message names the check and the robot."""


@dataclass
class CheckReport:
    """What :func:`check` did: the checks passed and those skipped, with the reason."""

    scenario: str
    family: str
    ticks: int
    passed: list[str] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)

    def __str__(self) -> str:
        lines = [f"{self.family} scenario {self.scenario}: {self.ticks} ticks",
                 *(f"  ok    {name}" for name in self.passed),
                 *(f"  skip  {name}: {why}" for name, why in self.skipped.items())]
        return "\n".join(lines)


def _fail(check_name: str, message: str) -> CheckError:
    return CheckError(f"{check_name}: {message}")


def _where(exc: BaseException) -> str:
    """`` at FILE:LINE in FUNCTION``: where ``exc`` was raised (its innermost frame), so that a
    failed check points at the line of the brain or localizer that broke, not at the checker."""
    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    if tb is None:
        return ""
    code = tb.tb_frame.f_code
    return f" at {code.co_filename}:{tb.tb_lineno} in {code.co_name}"


#: What a determinism failure most often is, said with it.
DETERMINISM_HINT = ("a brain or world that draws from the global random state (np.random.*, "
                    "random.*) or reads the clock is not reproducible: draw from the generator "
                    "its setup is given (rng), seeded from the run seed and the robot id")


def _welcome(scenario, robot_id: int):
    from swarmloc.protocol.messages import Welcome

    return Welcome(robot_id=robot_id, run="check", seed=scenario.seed, scenario=scenario.to_dict())


def _brains(scenario) -> list:
    from swarmloc.agents.brains import brain_from_welcome

    return [brain_from_welcome(_welcome(scenario, rid)) for rid in range(scenario.robots)]


def _run(scenario, ticks: int, corrupt: bool = False) -> dict:
    """Serve ``scenario`` for ``ticks`` ticks, answered by a brain per robot; every byte kept."""
    from swarmloc.protocol.errors import ErrorCounter
    from swarmloc.protocol.messages import WorldState, decode, encode
    from swarmloc.world.service import served_world

    world = served_world(scenario)
    brains = _brains(scenario)
    errors = ErrorCounter()
    senses, acts, corrupted = [], [], 0
    for tick in range(ticks):
        if world.done:
            break
        step: list[Any] = [None] * world.n_robots
        for rid, data in world.senses():
            if not isinstance(rid, int) or not isinstance(data, bytes):
                raise _fail("types", f"senses() must give (robot id, bytes), got {type(rid).__name__}, "
                                     f"{type(data).__name__}")
            brain = brains[rid]
            try:
                sense = decode(data, brain.sense_type)
            except Exception as exc:
                raise _fail("types", f"tick {tick}, robot {rid}: the Sense does not decode as "
                                     f"{brain.sense_type.__name__}: {exc}") from exc
            if corrupt and getattr(sense, "received", ()):
                bad = dataclasses.replace(sense.received[0], payload=GARBAGE_PAYLOAD)
                sense = dataclasses.replace(sense, received=(bad, *sense.received[1:]))
                corrupted += 1
            try:
                act = brain.act(sense, errors)
            except Exception as exc:
                what = "bad input" if corrupt else "types"
                raise _fail(what, f"tick {tick}, robot {rid}: act() raised {type(exc).__name__}: {exc}"
                            f"{_where(exc)}"
                            + (" on a Sense with a garbage teammate payload" if corrupt else "")) from exc
            if not isinstance(act, world.act_type):
                raise _fail("types", f"tick {tick}, robot {rid}: act() returned {type(act).__name__}, "
                                     f"the world takes {world.act_type.__name__}")
            try:
                wire = encode(act)
            except Exception as exc:
                raise _fail("types", f"tick {tick}, robot {rid}: the Act does not encode: {exc}") from exc
            if decode(wire, world.act_type) != act:
                raise _fail("types", f"tick {tick}, robot {rid}: the Act changes through the codec")
            senses.append(data)
            acts.append(wire)
            step[rid] = act
        world.step(step)
    state = world.state()
    if not isinstance(state, WorldState) or len(state.poses) != world.n_robots:
        raise _fail("types", f"state() must be a WorldState with {world.n_robots} poses")
    decode(encode(state), WorldState)
    json.dumps(world.summary())
    return {"senses": senses, "acts": acts, "errors": dict(errors.counts), "corrupted": corrupted,
            "poses": state.poses}


def _with(scenario, key: str, value):
    """``scenario`` with one value replaced: in its ``world`` table where that has the key (the
    families with a world table), else at the top (MRCLAM's flat scenarios)."""
    from swarmloc.families import scenario_from_dict

    data = scenario.to_dict()
    section = data["world"] if key in data.get("world", {}) else data
    section[key] = value
    return scenario_from_dict(data)


def _model_modules(adapter) -> set[str]:
    """The modules of the pure models an adapter wraps (its attributes that are objects of
    swarmloc's or a plugin's classes), not the adapter's own: an adapter is part of a shell."""
    out = set()
    for value in vars(adapter).values():
        module = getattr(type(value), "__module__", "")
        if module.startswith(("swarmloc.", "swarmloc_plugin_")) and not isinstance(value, type):
            out.add(module)
    return out


def _check_pure(scenario) -> None:
    from swarmloc.world.service import served_world

    modules = _model_modules(served_world(scenario))
    for brain in _brains(scenario):
        modules |= _model_modules(brain)
    modules -= {"swarmloc.protocol.errors"}
    modules = sorted(modules)
    paths = {m: getattr(sys.modules.get(m), "__file__", None) for m in modules}
    code = (
        "import importlib.util, sys\n"
        f"paths = {paths!r}\n"
        "for name, path in paths.items():\n"
        "    if name.startswith('swarmloc_plugin_') and path:\n"
        "        spec = importlib.util.spec_from_file_location(name, path)\n"
        "        module = importlib.util.module_from_spec(spec); sys.modules[name] = module\n"
        "        spec.loader.exec_module(module)\n"
        "    else:\n"
        "        importlib.import_module(name)\n"
        "    if 'zenoh' in sys.modules:\n"
        "        print(name); break\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          check=False)
    if done.returncode != 0:
        raise _fail("pure", f"importing {modules} failed: {done.stderr.strip()[-500:]}")
    if done.stdout.strip():
        raise _fail("pure", f"importing {done.stdout.strip()} imports zenoh: a pure model must "
                            f"not touch the transport (only the shells do)")


def _check_batch(scenario, ticks: int) -> bool:
    """E-puck brains (check 3): the batch engine, one brain holding the whole swarm, against the
    run of :func:`_run`, one brain per robot as the agent processes run: the same true poses
    after ``ticks`` ticks, bit for bit."""
    if scenario.family != "foraging":
        return False
    import numpy as np

    from swarmloc.deploy.lab.epuck.batch import run_ticks, swarm_brain
    from swarmloc.world.epuck.foraging import ForagingWorld

    short = _with(scenario, "duration_s", ticks * scenario.scenario.world.tick_s)
    world = ForagingWorld(short.scenario.world)
    run_ticks(world, swarm_brain(short.scenario))
    served = _run(short, ticks + 1)["poses"]
    if not np.array_equal(world.pose, np.array(served)):
        raise _fail("batch", f"after {ticks} ticks one brain of {scenario.robots} robots and "
                             f"{scenario.robots} brains of one put the robots in different places")
    return True


def check_determinism(scenario, ticks: int = 30, first: dict | None = None) -> None:
    """Check 2 alone (CheckError if it fails): two runs of the seed give the same Sense and Act
    bytes, another seed other Senses. ``first``: a run of ``scenario`` already made. The
    experiment engine runs this on a job of each setting before a grid with a plugin's code."""
    if first is None:
        first = _run(scenario, ticks)
    again = _run(scenario, ticks)
    for name in ("senses", "acts"):
        for k, (a, b) in enumerate(zip(first[name], again[name], strict=True)):
            if a != b:
                raise _fail("determinism", f"message {k} of the {name} differs between two runs "
                                           f"of seed {scenario.seed}: {DETERMINISM_HINT}")
    from swarmloc.families import FAMILIES

    other = _run(_with(scenario, "seed", scenario.seed + 1), ticks)
    if FAMILIES.get(scenario.family).seeded_world and other["senses"] == first["senses"]:
        raise _fail("determinism", f"seeds {scenario.seed} and {scenario.seed + 1} gave the same "
                                   f"Senses: the seed does not reach the world")


def check(scenario, *, ticks: int = 30, batch: bool = True, pure: bool = True) -> CheckReport:
    """Run every check on ``scenario`` (a :class:`swarmloc.deploy.scenario.AnyScenario`);
    CheckError names the first that fails. ``ticks``: how long each run lasts."""
    report = CheckReport(scenario.name, scenario.family, ticks)
    first = _run(scenario, ticks)
    if not first["senses"]:
        raise _fail("types", "the world served no Sense")
    report.passed.append("types")
    check_determinism(scenario, ticks, first)
    report.passed.append("determinism")
    if batch and _check_batch(scenario, ticks):
        report.passed.append("batch")
    else:
        report.skipped["batch"] = "no batched brain in this family" if batch else "not asked"
    if pure:
        _check_pure(scenario)
        report.passed.append("pure")
    else:
        report.skipped["pure"] = "not asked"
    spoilt = _run(scenario, ticks, corrupt=True)
    if spoilt["corrupted"] == 0:
        report.skipped["bad input"] = "no teammate payload reached a robot in these ticks"
    else:
        rejected = sum(spoilt["errors"].values()) - sum(first["errors"].values())
        if rejected < spoilt["corrupted"]:
            raise _fail("bad input", f"{spoilt['corrupted']} garbage payloads, only {rejected} "
                                     f"recorded as rejected")
        report.passed.append("bad input")
    return report


def add_parser(sub) -> None:
    p = sub.add_parser("check", help="run the contract checker on a scenario (a new brain, "
                                     "localizer or world: see docs/extending.md)")
    p.add_argument("scenario", help="shipped scenario name or a .toml file")
    p.add_argument("--ticks", type=int, default=30)
    p.add_argument("--robots", type=int)
    p.add_argument("--strategy")
    p.add_argument("--algorithm")
    p.add_argument("--seed", type=int)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    p.set_defaults(func=main)


def main(args) -> int:
    from swarmloc.deploy.scenario import load_any

    flags = {k: getattr(args, k) for k in ("robots", "strategy", "algorithm", "seed")}
    scenario = load_any(args.scenario, flags, args.set)
    try:
        report = check(scenario, ticks=args.ticks)
    except CheckError as exc:
        print(f"check failed: {exc}", file=sys.stderr)
        return 1
    print(report)
    return 0
