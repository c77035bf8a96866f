"""The message types of each robot family: what a world sends an agent, and the agent answers.

The codec, the validation table and the messages every family shares (join, welcome, world
state, run end, error report) are in :mod:`swarmloc.protocol.messages`, which imports these, so
``from swarmloc.protocol.messages import EpuckSense`` keeps working. Here: the e-puck family's
(seeds 000/001: :class:`EpuckSense`, :class:`EpuckAct`, the range-and-bearing
:class:`RabMessage`), the laser family's (seeds 002/003: :class:`LaserSense` with
:class:`SightingMsg` and :class:`RadioMsg`), the replay family's (:class:`ReplaySense` with
:class:`LandmarkMsg`), the vision family's (seed 004: :class:`VisionSense`, :class:`VisionAct`),
and :class:`EstimateAct`, the answer of the localization-only families. Bounds in the comments
are the ones the codec enforces (``messages._FIELD_SPECS``).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class RabMessage:
    """A range-and-bearing message as the receiver's board measured it."""

    sender_id: int  #: 0..65535
    range_m: float  #: measured range, [0, 100] m
    bearing_rad: float  #: measured bearing in the receiver's frame, [-pi, pi] (1e-9 slack)
    payload: bytes  #: at most MAX_RAB_PAYLOAD_BYTES


@dataclass(frozen=True, slots=True)
class EpuckSense:
    """World to agent, each tick: an e-puck's sensor readings and the messages it received."""

    tick: int  #: 0..2**53-1
    robot_id: int  #: 0..65535
    encoder_steps: tuple[float, float]  #: (left, right) encoder steps this tick, finite
    ir: tuple[float, ...]  #: exactly 8 IR proximity readings, each in [0, 1]
    ground: tuple[float, ...]  #: exactly 3 ground sensor readings, each in [0, 2]
    received: tuple[RabMessage, ...]  #: at most 16 range-and-bearing messages
    final: bool = False  #: the run is over: the agent should stop after this


@dataclass(frozen=True, slots=True)
class EpuckAct:
    """Agent to world, each tick: the wheel command, the outgoing message, and logged estimates."""

    tick: int  #: the tick of the Sense this answers, 0..2**53-1
    robot_id: int  #: 0..65535
    wheel_speed_steps_s: tuple[float, float]  #: (left, right), each |v| <= 1000 steps/s
    payload: bytes | None  #: outgoing RAB message (<= MAX_RAB_PAYLOAD_BYTES), None for silence
    state: int  #: controller state code 0..255 (logged)
    pose_estimate: tuple[float, float, float]  #: dead-reckoned (x_m, y_m, theta_rad), logged


@dataclass(frozen=True, slots=True)
class SightingMsg:
    """A teammate as the receiving robot measures it (laser and replay families)."""

    robot_id: int  #: 0..65535
    distance_m: float  #: [0, 100] m
    bearing_rad: float  #: direction of the teammate in the observer's frame, [-pi, pi]
    relative_heading_rad: float  #: teammate heading minus observer heading, [-pi, pi]


@dataclass(frozen=True, slots=True)
class RadioMsg:
    """A teammate's broadcast, as the world's radio medium delivered it."""

    sender_id: int  #: 0..65535
    payload: bytes  #: at most MAX_RADIO_PAYLOAD_BYTES, opaque to the world


@dataclass(frozen=True, slots=True)
class LaserSense:
    """World to a laser robot's agent, each tick (seeds 002/003)."""

    tick: int  #: 0..2**53-1
    robot_id: int  #: 0..65535
    odometry_delta_s_m: float  #: displacement the odometry reports this step, finite
    odometry_delta_phi_rad: float  #: rotation the odometry reports this step, finite
    ranges_m: tuple[float, ...]  #: 1..1024 laser ranges, each in [0, 100] m
    sightings: tuple[SightingMsg, ...]  #: at most 64 teammates in view
    received: tuple[RadioMsg, ...]  #: at most 64 radio messages from the previous tick
    final: bool = False  #: the run is over


@dataclass(frozen=True, slots=True)
class LandmarkMsg:
    """A landmark measurement of the replay family: landmark id, range and bearing."""

    landmark_id: int  #: 0..65535
    range_m: float  #: [0, 100] m
    bearing_rad: float  #: [-pi, pi]


@dataclass(frozen=True, slots=True)
class ReplaySense:
    """World to an agent of a replayed data set (MRCLAM), each tick."""

    tick: int  #: 0..2**53-1
    robot_id: int  #: 0..65535
    time_s: float  #: time since the start of the replay, >= 0
    speed_mps: float  #: recorded forward speed over this tick, finite
    turn_rate_rad_s: float  #: recorded turn rate over this tick, finite
    dt_s: float  #: tick length, (0, 10] s
    landmarks: tuple[LandmarkMsg, ...]  #: at most 64 landmark measurements this tick
    robots: tuple[LandmarkMsg, ...]  #: at most 64 measurements of teammates (id = robot id)
    received: tuple[RadioMsg, ...]  #: at most 64 teammates' broadcasts of the previous tick
    final: bool = False  #: the run is over
    #: the robot's true heading at the tick's end, when the replay gives it (CoLo-AT's setting,
    #: ``heading = "truth"``): one angle in [-pi, pi], else empty
    true_heading_rad: tuple[float, ...] = ()
    #: the sum of the squared gaps of this tick's recorded odometry messages [s^2] (what
    #: CoLo-AT's per-message noise grows with), when known: one value >= 0, else empty
    odometry_gap2_s2: tuple[float, ...] = ()


@dataclass(frozen=True, slots=True)
class EstimateAct:
    """Agent to world, each tick, for localization-only families (laser, replay, vision): the
    robot's pose estimate (logged and scored), an optional broadcast, and optional commands."""

    tick: int  #: the tick of the Sense this answers
    robot_id: int  #: 0..65535
    pose_estimate: tuple[float, float, float]  #: (x_m, y_m, theta_rad), finite
    payload: bytes | None  #: broadcast to teammates (<= MAX_RADIO_PAYLOAD_BYTES), None for silence
    command: tuple[float, ...]  #: family-specific motion command, at most 8 finite values
    #: poses (x_m, y_m, theta_rad) of the belief's population (particles, GA individuals),
    #: subsampled, at most Welcome.samples <= MAX_SAMPLES; logged for observers only (the world
    #: draws and records them, never uses them), empty unless the world asked
    samples: tuple[tuple[float, float, float], ...] = ()


@dataclass(frozen=True, slots=True)
class VisionSense:
    """World to a vision robot's agent, each frame (seed 004)."""

    tick: int  #: 0..2**53-1
    robot_id: int  #: 0..65535
    time_s: float  #: simulated time of the frame, >= 0
    image: bytes  #: the encoded camera frame (JPEG or PNG), at most MAX_IMAGE_BYTES
    odometry_pose: tuple[float, float, float]  #: dead-reckoned (x_m, y_m, heading_rad), finite
    head_pan_rad: float  #: head pan the frame was taken at, [-pi, pi]
    final: bool = False  #: the run is over


@dataclass(frozen=True, slots=True)
class VisionAct:
    """Vision agent to world, each frame: the walking command and the agent's estimates
    (teammates, ball, goal; logged and scored against ground truth, never used for physics)."""

    tick: int  #: the tick of the Sense this answers
    robot_id: int  #: 0..65535
    command: tuple[float, float, float, float]  #: forward_mps, left_mps, turn_rad_s, head_pan_rad
    estimates: dict  #: plain dict, as :attr:`Welcome.scenario`
