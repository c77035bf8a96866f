"""The robot families, in one registry: what each family plugs into the shells.

A robot family (e-puck foraging, map-based laser, vision, a replay of recorded data) is a
scenario type, a world served to agent processes, and the brain an agent process runs; the
shells (``world/server.py``, ``agents/node.py``, ``deploy/run.py``) know none of them and look
them up here by the scenario's ``family`` key. Entries are ``"module:attribute"`` paths, imported
on first use, so that serving e-pucks never imports OpenCV or the laser maps.

A new family registers a :class:`Family` (``FAMILIES.register("my-family", Family(...))``) from a
plugin (:mod:`swarmloc.registry`); ``docs/extending.md`` says what each piece must do, and
:mod:`swarmloc.checker` checks it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from swarmloc.config import ConfigError
from swarmloc.registry import Registry, resolve


@dataclass(frozen=True)
class Family:
    """One robot family's pieces, as ``"module:attribute"`` paths (or the objects themselves).

    - ``scenario``: the scenario class (``from_dict``/``to_dict``, strict: an unknown key is an
      error naming it);
    - ``world``: ``scenario -> ServedWorld`` (:class:`swarmloc.world.service.ServedWorld`);
    - ``brain``: ``(welcome, scenario) -> AgentBrain`` (:class:`swarmloc.agents.brains.AgentBrain`);
    - ``flags``: what the common command-line flags (``--robots``, ``--seed``, ...) set in the
      family's scenario;
    - ``seeded_world``: the run seed reaches the world's Senses (False for a replay of recorded
      data, where only the brains' generators take it);
    - ``compiled_kernels``: its world or brains run swarmloc's numba kernels (deploy/warm.py), so
      a run compiles them first, once per machine; a family without them starts at once (a
      laser run compiled the e-puck kernels it never calls: 79 of its first 91 s, issue 48);
    - ``frames``: ``service -> FrameSource`` (``swarmloc.deploy.observe.frames``), what the view
      and the recorder draw of a served world (None: the run is neither viewed nor recorded);
    - ``experiment``: the module of the experiment engine's hooks
      (``swarmloc.deploy.lab.experiment.Family``: ``settings``, ``run_job``, ``columns``, ``row``;
      None: no ``swarmloc experiment`` for it);
    - ``report``: its ``swarmloc report`` template (``swarmloc.deploy.lab.report.ReportTemplate``;
      None: the generic comparison page reports its rows).

    The scenario class also gives ``n_ticks`` (how many ticks a run lasts) and ``label`` (what
    tells runs of one scenario apart: the strategy, the algorithm), which the shells print.
    One registry holds every family, under one name; ``FAMILIES.alias`` keeps a former name
    working (the e-puck family is "foraging", and "epuck" as experiment specs and reports called
    it before issue 48).
    """

    scenario: object
    world: object
    brain: object
    flags: dict = field(default_factory=dict)
    seeded_world: bool = True
    compiled_kernels: bool = False
    frames: object = None
    experiment: object = None
    report: object = None


def needs_kernels(family: str | None) -> bool:
    """Whether a run of ``family`` compiles the kernels first (None, unknown: yes, as before)."""
    if family is None or family not in FAMILIES:
        return True
    return FAMILIES.get(family).compiled_kernels


FAMILIES: Registry[Family] = Registry("robot family")

FAMILIES.register("foraging", Family(
    scenario="swarmloc.world.epuck.scenario:Scenario",
    world="swarmloc.world.epuck.service:_foraging",
    brain="swarmloc.agents.epuck.agent:ForagingAgent.from_welcome",
    flags={"robots": "world.robots", "strategy": "agent.strategy", "beta": "agent.beta",
           "seed": "world.seed", "duration_s": "world.duration_s"}, compiled_kernels=True,
    frames="swarmloc.deploy.observe.frames:ForagingSource",
    experiment="swarmloc.deploy.lab.epuck.experiment", report="swarmloc.deploy.lab.epuck.report:TEMPLATE"))
FAMILIES.alias("epuck", "foraging")
FAMILIES.register("laser", Family(
    scenario="swarmloc.world.laser.scenario:LaserScenario",
    world="swarmloc.world.laser.service:LaserService",
    brain="swarmloc.agents.laser.agent:LaserAgent.from_welcome",
    flags={"robots": "world.robots", "seed": "world.seed", "algorithm": "algorithm.name"},
    frames="swarmloc.deploy.observe.frames:LaserSource",
    experiment="swarmloc.deploy.lab.laser.experiment", report="swarmloc.deploy.lab.laser.report:TEMPLATE"))
FAMILIES.register("vision", Family(
    scenario="swarmloc.world.vision.scenario:VisionScenario",
    world="swarmloc.world.vision.service:VisionService",
    brain="swarmloc.agents.vision.agent:VisionAgent.from_welcome",
    flags={"seed": "world.seed", "duration_s": "setup.duration_s"},
    frames="swarmloc.deploy.observe.frames:VisionSource",
    experiment="swarmloc.deploy.lab.vision.experiment", report="swarmloc.deploy.lab.vision.report:TEMPLATE"))
FAMILIES.register("replay", Family(
    scenario="swarmloc.world.replay.service:ReplayScenario",
    world="swarmloc.world.replay.service:ReplayService",
    brain="swarmloc.agents.replay.agent:ReplayAgent.from_welcome",
    flags={"seed": "seed", "duration_s": "duration_s", "algorithm": "algorithm"},
    seeded_world=False, frames="swarmloc.deploy.observe.frames:ReplaySource",
    experiment="swarmloc.deploy.lab.replay.experiment", report="swarmloc.deploy.lab.replay.report:TEMPLATE"))


# -- a scenario of any family ------------------------------------------------------------------


@dataclass(frozen=True)
class AnyScenario:
    """A scenario of any robot family, as the process commands (``run``, ``world``) need it."""

    family: str
    scenario: object

    @property
    def name(self) -> str:
        return self.scenario.name

    @property
    def seed(self) -> int:
        return self.scenario.world.seed

    @property
    def robots(self) -> int:
        robots = self.scenario.world.robots
        return robots if isinstance(robots, int) else len(robots)

    @property
    def n_ticks(self) -> int:
        """Ticks of a run: the family's scenario class says (its ``n_ticks``)."""
        return self.scenario.n_ticks

    @property
    def label(self) -> str:
        """What distinguishes runs of one scenario (the strategy, the algorithm, ...): the
        family's scenario class says (its ``label``)."""
        return self.scenario.label

    def to_dict(self) -> dict:
        return {"family": self.family, **self.scenario.to_dict()}


def family_of(data: dict) -> str:
    family = data.get("family", "foraging")
    try:
        return FAMILIES.canonical(family)
    except ValueError as exc:
        raise ConfigError(f"family: {exc}") from None


def scenario_from_dict(data: dict) -> AnyScenario:
    """A scenario of any family from its plain dict, as a run folder's ``scenario.json``, a
    world's Welcome or :meth:`AnyScenario.to_dict` carries it; ConfigError names what is wrong."""
    family = family_of(data)
    cls = resolve(FAMILIES.get(family).scenario)
    fields = {k: v for k, v in data.items() if k != "family"}
    if "family" in getattr(cls, "__dataclass_fields__", {}):
        fields["family"] = family
    return AnyScenario(family, cls.from_dict(fields))


def run_in_process(scenario: AnyScenario, ticks: int | None = None) -> dict:
    """Serve ``scenario`` in this process, each robot answered by the brain an agent process
    builds from the world's Welcome, every Sense and Act through the protocol codec: what a
    lockstep run of processes computes, without the transport. Returns the world's ``summary()``.

    For a family without an in-process engine of its own (a plugin family's experiment hooks
    call it); the shipped families have faster engines (the batch engine, the laser and replay
    runners), which their tests hold equal to their processes.
    """
    from swarmloc.agents.brains import brain_from_welcome
    from swarmloc.protocol.errors import ErrorCounter
    from swarmloc.protocol.messages import Welcome, decode, encode
    from swarmloc.world.service import served_world

    world = served_world(scenario)
    plain = scenario.to_dict()
    brains = [brain_from_welcome(Welcome(robot_id=r, run="in-process", seed=scenario.seed, scenario=plain))
              for r in range(world.n_robots)]
    errors = ErrorCounter()
    limit = scenario.n_ticks if ticks is None else ticks
    for _ in range(limit):
        if world.done:
            break
        acts: list = [None] * world.n_robots
        for r, data in world.senses():
            brain = brains[r]
            sense = decode(data, brain.sense_type)
            if getattr(sense, "final", False):
                continue  # as an agent node: a final Sense ends the agent, unanswered
            acts[r] = decode(encode(brain.act(sense, errors)), world.act_type)
        world.step(acts)
    return world.summary()
