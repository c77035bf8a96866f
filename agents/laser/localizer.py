"""The contract every map-based localizer of the laser robots follows (seeds 002 and 003).

One localizer instance is one robot's brain: MR-SSGA, CFS-GA, the simple GA and the AMCL-style
particle filter all implement :class:`Localizer`, so that the same object runs inside an agent
process (fed by the world-server over Zenoh) and inside the in-process runner (fed by the laser
world directly). A localizer is a pure model: no Zenoh, no clock, no global random state; it gets
its own ``numpy.random.Generator`` when it is built.

Each step the robot receives a :class:`LaserObservation`:

- its odometry increments since the last step (eq. 3 of 002: ``delta_s``, ``delta_phi``);
- its laser ranges (eq. 4 of 002), ``L`` beams spread over 360 deg from the heading;
- the teammates it sees (:class:`Sighting`: noisy distance, bearing and relative heading of a
  robot within range and line of sight, 002 §3.2, 003 §IV-B);
- the radio messages teammates broadcast at the previous step (:class:`RadioMessage`), delivered
  by the world's radio medium (range, line of sight, loss). Their payload is opaque bytes built by
  the sender's :meth:`Localizer.outgoing`; each algorithm owns its codec. A payload it cannot
  decode is skipped, never allowed to stop the step, and listed in the localizer's ``rejected``
  attribute as ``(sender_id, ValueError)`` for that step (the shell counts them and goes on).

After :meth:`Localizer.step` the robot reports :meth:`Localizer.estimate` (its best pose) and may
broadcast :meth:`Localizer.outgoing` (at most :data:`MAX_RADIO_PAYLOAD_BYTES`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

# The bound on one radio payload is the protocol's (every world and wire message enforces it).
from swarmloc.protocol.messages import MAX_RADIO_PAYLOAD_BYTES  # noqa: F401 -- re-exported


@dataclass(frozen=True)
class Sighting:
    """Teammate ``robot_id`` as this robot measures it (noisy): distance, the bearing of the
    teammate in this robot's frame, and the teammate's heading minus this robot's heading."""

    robot_id: int
    distance_m: float
    bearing_rad: float
    relative_heading_rad: float


@dataclass(frozen=True)
class RadioMessage:
    """A payload teammate ``sender_id`` broadcast at the previous step."""

    sender_id: int
    payload: bytes


@dataclass(frozen=True)
class LaserObservation:
    """What one laser robot gets at one step. ``ranges_m`` is read-only on every path (the
    in-process world shares one array among its observations; an agent process builds its
    own): a localizer that writes into it fails at once, in ``swarmloc check`` as in an
    experiment (issue 48: it passed ``check`` and ``run``, then failed the experiment)."""

    step: int
    odometry_delta_s_m: float
    odometry_delta_phi_rad: float
    ranges_m: np.ndarray  #: (L,) laser ranges, beam j at heading + j * 2 pi / L
    sightings: tuple[Sighting, ...] = ()
    received: tuple[RadioMessage, ...] = ()

    def __post_init__(self) -> None:
        if isinstance(self.ranges_m, np.ndarray):
            self.ranges_m.flags.writeable = False


@dataclass(frozen=True)
class LocalizerSetup:
    """What every localizer is built from: the robot's id, the map name (see
    ``swarmloc.world.laser.maps``), its laser, and the parameters of its motion and relative
    observations (``swarmloc.world.laser.laser``). Algorithm parameters come separately."""

    robot_id: int
    map_name: str
    n_beams: int
    max_range_m: float
    laser_noise_std_m: float
    speed_std_mps: float
    turn_rate_std_rad_s: float
    relative_distance_std_m: float
    relative_orientation_std_rad: float
    dt_s: float = 1.0
    cooperative: bool = True
    extra: dict = field(default_factory=dict)

    @classmethod
    def from_world_config(cls, config, robot_id: int, cooperative: bool = True,
                          extra: dict | None = None) -> LocalizerSetup:
        """The setup of robot ``robot_id`` of a laser world configured by ``config`` (a
        ``LaserWorldConfig``): what the world and an agent process both derive from the scenario."""
        return cls(
            robot_id=int(robot_id), map_name=config.map, n_beams=config.laser.n_beams,
            max_range_m=config.laser.max_range_m, laser_noise_std_m=config.laser.noise_std_m,
            speed_std_mps=config.motion.speed_std_mps,
            turn_rate_std_rad_s=config.motion.turn_rate_std_rad_s,
            relative_distance_std_m=config.relative.distance_std_m,
            relative_orientation_std_rad=config.relative.orientation_std_rad,
            dt_s=config.dt_s, cooperative=bool(cooperative), extra=dict(extra or {}))


@runtime_checkable
class Localizer(Protocol):
    """One robot's map-based localizer."""

    def step(self, obs: LaserObservation) -> None:
        """Apply the odometry, then the laser and the teammates' data of this step."""

    def estimate(self) -> np.ndarray:
        """The best pose estimate ``(x_m, y_m, theta_rad)``, shape (3,)."""

    def outgoing(self) -> bytes | None:
        """What to broadcast to teammates after this step (None: nothing)."""

    # Optional: ``samples(n) -> (k, 3)``, at most ``n`` poses of the belief's population (particles,
    # GA individuals) for observers to draw (:func:`population_samples`). It must not draw from
    # the localizer's generator or change its state: watching a run must not change it.


def evenly_spaced(poses: np.ndarray, n: int) -> np.ndarray:
    """At most ``n`` rows of ``poses``, evenly spaced through it (every row when it has no more
    than ``n``): a subsample with no random draw."""
    count = poses.shape[0]
    if count <= n:
        return poses
    return poses[np.arange(n) * count // n]


def population_samples(localizer, n: int) -> tuple[tuple[float, float, float], ...]:
    """What an Act logs for observers (``EstimateAct.samples``): at most ``n`` finite poses of the
    localizer's population from its optional ``samples(n)``; none when it has no such method, or
    when ``n`` is 0 (nobody asked)."""
    method = getattr(localizer, "samples", None)
    if n <= 0 or method is None:
        return ()
    poses = np.asarray(method(n), dtype=float).reshape(-1, 3)[:n]
    poses = poses[np.isfinite(poses).all(axis=1)]
    return tuple(map(tuple, poses.tolist()))
