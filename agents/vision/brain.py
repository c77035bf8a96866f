"""The vision robot's brain: colour blobs, shared detections, cooperative localization, PFA.

Seed 004 (``seeds/004_e71d8ee95e0baa56.txt``: Peula et al., "Explicit coordinated localization
using common visual objects"), §II-IV, eq. 1-5.
:class:`VisionBrain` is one robot's brain, a pure model (no Zenoh, no clock, no global random
state) that runs inside an agent process or inside the in-process runner
(``swarmloc.deploy.lab.vision.runner``). Each tick (:meth:`VisionBrain.step`):

1. **Image** (§III, colour events): the encoded camera frame is decoded (:func:`decode_image`: a
   payload that does not decode, or decodes to the wrong size, raises ``ValueError`` naming the
   problem before any state changes; the shell counts it and goes on) and its colour blobs are
   found with ``swarmloc.agents.vision.detection.detect_blobs`` (HSV thresholds, morphology, components).
   Each blob becomes a :class:`~swarmloc.agents.vision.cooperative.Detection`: colour, bearing in
   the body frame (head pan + angle off the optical axis), apparent size and size-based distance.
   Cylinders cut by the left or right image edge are dropped (their width, hence distance and
   bearing, are wrong); a ball cut by the image edge keeps the larger of its equal-area radius and
   half its width (a ball cut at the bottom keeps its full width).
2. **Telepathy** (§III): :meth:`VisionBrain.share` packs this frame's detections, with the head
   angle ("the angle of the neck") and the time (and the odometry pose only with the addition
   ``shared_odometry``), into a msgpack payload (``telepathy.encode_share``); :meth:`VisionBrain.receive` decodes a teammate's payload with
   :func:`decode_share`, which rejects impossible values with ``ValueError`` naming the field:
   NaN or infinite numbers, a negative or zero size or distance, a bearing outside the camera's
   field of view, a time in the future, a sender that is not who it claims to be, an unknown
   colour. Detections older than the window (2 s, §III) are dropped (``cooperative.fresh``).
3. **Cooperative localization** (§II, eq. 1 and 2). ``relative_heading = "perception"`` (the
   default, the paper's information only): a teammate's frame is paired with my own frame of the
   same time; one common object puts the teammate on a circle around it, and the direction grid
   of ``swarmloc.agents.vision.heading`` (a Markov filter, §II) narrows it with a second common
   object (Fig. 2), sightings of yellow blobs by either robot and negative information; while
   the direction is unresolved the head looks for the teammate. With the additions ``"odometry"``
   / ``"objects"`` (below), for each colour both see exactly once (ball, obstacle, beacon) the
   teammate's position in my body frame follows by stereo (eq. 1,
   ``cooperative.stereo_relative_position``), or by the law of cosines (eq. 2,
   ``teammate_from_common_object``) where stereo has no disparity; a direct sighting of the
   teammate (a yellow blob, monocular size-based distance) is one more estimate; the estimates
   are checked against each other and fused (``cooperative.fuse``: a minority that
   disagrees by more than ``consistency_tolerance_m`` is rejected, a contradictory set gives
   nothing). Objects I cannot see are placed from what a teammate sees (eq. 2,
   ``object_from_teammate``: Fig. 3, experiment 3).
4. **Goals and navigation** (§III-IV, eq. 3-5): the robot nearest the orange obstacle takes it,
   the others take the ball (``potential_field.assign_goals``, decided once and kept); the robot
   walks along the potential-field force (``potential_field.potential_field``: attraction to the
   goal, eq. 4; repulsion from the obstacle and from teammates at their estimated positions,
   eq. 5), turns its body towards the walking direction, and points its head so that its goal and
   the other object stay in view (common objects are what stereo needs).

With sharing off the robot uses only what it sees: a teammate is known only while it is in view.

Choices where the paper is silent
---------------------------------
- **Relative heading.** Seed 004 §IV-A: "The information that they are sharing is the position
  of the ball respect to each AIBO, and the angle of the neck. With this information, they can
  estimate the position of the other AIBO". One common object fixes a teammate's position only
  up to a circle (``heading``). The default, ``"perception"``, resolves it from perception alone
  (§II: "statistical tools like Markov Fields", negative information; §III: "triangulation is
  used to reduce ambiguity"); how the head looks for an unresolved teammate (0.6 s in every 2 s,
  staggered by robot) is not in the paper. **Additions beyond the paper**, off in the
  reproduction specs: ``"odometry"`` assumes the relative heading at the start,
  ``initial_relative_heading_rad`` (0: the parallel start of §IV's figures), and follows it with
  both robots' odometry, carried in every payload (``shared_odometry``):
  ``psi(t) = psi0 + theta_teammate_odo(t) - theta_mine_odo(t)``; ``"objects"`` takes psi from two
  common objects (``relative_heading_from_two_objects``, Fig. 2), else as ``"odometry"``.
- **Without sharing** (``sharing = false``; the paper only shows Fig. 6a, the robots "cannot
  avoid each other without position estimation"): a robot knows a teammate only while it sees
  it; it applies the goal rule among the teammates it sees, and if it sees none it takes the
  nearest goal it sees (``alone_goal = "nearest-seen"``), so the contrast with sharing is
  measured, not built in.
- **Tracking a moving teammate** (``"odometry"`` / ``"objects"``). Each paired measurement gives the transform between the
  teammate's odometry frame and mine (nearly constant: it drifts only with odometry error). The
  brain takes the median of the last ``link_samples`` transforms (no older than
  ``link_memory_s``) and applies it to the teammate's latest shared odometry pose, so the estimate
  follows the teammate between measurements. Detections themselves are used only within the
  window (2 s); the teammate is forgotten when its payloads stop for longer than the window or
  when no measurement is younger than ``link_memory_s``.
- **Objects out of view** are remembered in my odometry frame for ``landmark_memory_s``.
- **Detour.** Eq. 3-5 have a local minimum where the goal is straight behind an obstacle (the
  blind robot of experiment 3 walks towards a ball hidden by the obstacle). When the repulsion
  (obstacles and teammates) opposes the attraction, a sideways force, ``detour_gain`` times the
  opposing part of the repulsion, perpendicular to the attraction, is added on the side the
  repulsion pushes to (away from the obstacle's and the teammate's side; left on an exact tie);
  the side is kept until the repulsion no longer opposes. ``detour_gain = 0`` is plain PFA.
- **Ambiguity.** Several blobs of one colour (two rivals) are not matched between robots: only
  colours seen exactly once by both robots are common objects. With several teammates a yellow
  blob is attributed to the teammate whose estimate it falls near (``sighting_gate_m``); with a
  single teammate, to it.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from swarmloc.agents.vision.cooperative import (
    FRESH_WINDOW_S,
    Detection,
    fresh,
    fuse,
    object_from_teammate,
    relative_heading_from_two_objects,
    stereo_relative_position,
    teammate_from_common_object,
    wrap_rad,
)
from swarmloc.agents.vision.detection import detect_blobs
from swarmloc.agents.vision.frames import (  # noqa: F401 -- re-exported
    MAX_IMAGE_BYTES,
    decode_image,
    detections_from_blobs,
)
from swarmloc.agents.vision.heading import (
    DirectionGrid,
    heading_of,
    in_view,
    object_likelihood,
    ring,
    sighting_likelihood,
    to_frame,
)
from swarmloc.agents.vision.potential_field import (
    BALL,
    OBSTACLE,
    FieldParams,
    assign_goals,
    potential_field,
)
from swarmloc.agents.vision.telepathy import (  # noqa: F401 -- re-exported
    MAX_ROBOT_ID,
    MAX_SHARE_BYTES,
    MAX_SHARED_DETECTIONS,
    SHARE_VERSION,
    SharedFrame,
    _number,
    decode_share,
    encode_share,
)
from swarmloc.world.vision.camera import OBJECT_KINDS, CameraParams
from swarmloc.world.vision.world import VisionCommand, VisionObservation

#: Colour of each goal kind, and of teammates (seed 004 §III).
GOAL_COLOURS = {BALL: "pink", OBSTACLE: "orange"}
TEAMMATE_COLOUR = "yellow"
_COMMON_COLOURS = ("pink", "orange", "blue")
#: Perception mode: common objects, anchor preference first (the obstacle: then the teammate's
#: distance to it, which the goal rule compares, is its own measurement, not a hypothesis).
_ANCHOR_COLOURS = (("orange", "obstacle"), ("pink", "ball"))
#: Ways of getting a teammate's heading relative to mine (module docstring).
RELATIVE_HEADING_MODES = ("perception", "odometry", "objects")


# -- configuration ------------------------------------------------------------------------------


@dataclass(frozen=True)
class VisionAgentConfig:
    """Parameters of :class:`VisionBrain` (see the module docstring)."""

    sharing: bool = True
    window_s: float = FRESH_WINDOW_S
    #: "perception" (the paper: shared detections and neck angles only), or the additions
    #: "odometry" / "objects", which need ``initial_relative_heading_rad`` and ``shared_odometry``.
    relative_heading: str = "perception"
    #: Addition beyond the paper: the robots' relative heading at the start (parallel start: 0).
    initial_relative_heading_rad: float | None = None
    #: Addition beyond the paper: each payload carries the sender's odometry pose.
    shared_odometry: bool = False
    #: Perception mode: bins of the direction grid, miss likelihood of negative information,
    #: spread of a sighting / object check, and whether the head looks for an unresolved teammate.
    heading_bins: int = 72
    miss_likelihood: float = 0.3
    match_sigma_m: float = 0.08
    look_for_teammate: bool = True
    resolved_mass: float = 0.8
    #: Without sharing: "nearest-seen" (each robot takes the nearest goal it sees, or applies the
    #: rule among the teammates it sees).
    alone_goal: str = "nearest-seen"
    consistency_tolerance_m: float = 0.3
    pair_tolerance_s: float = 0.06
    max_clock_skew_s: float = 0.05
    link_samples: int = 10
    link_memory_s: float = 5.0
    sighting_gate_m: float = 0.5
    landmark_memory_s: float = 5.0
    assign_wait_s: float = 1.0
    stop_margin_m: float = 0.04
    turn_gain_per_s: float = 2.0
    max_turn_rate_rad_s: float = 1.5
    detour_gain: float = 1.0
    head_span_fraction: float = 0.7
    scan_period_s: float = 4.0
    field: FieldParams = field(default_factory=FieldParams)

    def __post_init__(self) -> None:
        if not isinstance(self.sharing, bool):
            raise ValueError(f"sharing: must be true or false, got {self.sharing!r}")  # noqa: TRY004
        if self.relative_heading not in RELATIVE_HEADING_MODES:
            raise ValueError(
                f"relative_heading: must be one of {list(RELATIVE_HEADING_MODES)}, "
                f"got {self.relative_heading!r}"
            )
        for name in ("shared_odometry", "look_for_teammate"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name}: must be true or false")  # noqa: TRY004
        if self.relative_heading != "perception" and (
            self.initial_relative_heading_rad is None or not self.shared_odometry
        ):
            raise ValueError(
                f"relative_heading: {self.relative_heading!r} is an addition beyond seed 004 that "
                "needs initial_relative_heading_rad (a number) and shared_odometry = true"
            )
        if self.alone_goal not in ("nearest-seen",):
            raise ValueError(f"alone_goal: must be 'nearest-seen', got {self.alone_goal!r}")
        if (
            isinstance(self.heading_bins, bool)
            or not isinstance(self.heading_bins, int)
            or not 8 <= self.heading_bins <= 720
        ):
            raise ValueError(f"heading_bins: must be an integer in 8..720, got {self.heading_bins!r}")
        if not 0.0 < self.miss_likelihood <= 1.0:
            raise ValueError(f"miss_likelihood: must be in (0, 1], got {self.miss_likelihood!r}")
        if not self.match_sigma_m > 0.0:
            raise ValueError(f"match_sigma_m: must be > 0, got {self.match_sigma_m!r}")
        if not 0.0 < self.resolved_mass <= 1.0:
            raise ValueError(f"resolved_mass: must be in (0, 1], got {self.resolved_mass!r}")
        for name in (
            "window_s",
            "consistency_tolerance_m",
            "pair_tolerance_s",
            "max_clock_skew_s",
            "sighting_gate_m",
            "landmark_memory_s",
            "link_memory_s",
            "assign_wait_s",
            "stop_margin_m",
            "turn_gain_per_s",
            "max_turn_rate_rad_s",
            "detour_gain",
            "scan_period_s",
        ):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not (math.isfinite(value) and value >= 0.0)
            ):
                raise ValueError(f"{name}: must be a finite number >= 0, got {value!r}")
        for name in ("window_s", "scan_period_s"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)!r}")
        if self.initial_relative_heading_rad is not None and (
            not math.isfinite(self.initial_relative_heading_rad)
            or abs(self.initial_relative_heading_rad) > math.pi
        ):
            raise ValueError("initial_relative_heading_rad: must lie in [-pi, pi]")
        if (
            isinstance(self.link_samples, bool)
            or not isinstance(self.link_samples, int)
            or not (1 <= self.link_samples <= 1000)
        ):
            raise ValueError(
                f"link_samples: must be an integer in 1..1000, got {self.link_samples!r}"
            )
        if not 0.0 < self.head_span_fraction <= 1.0:
            raise ValueError(
                f"head_span_fraction: must be in (0, 1], got {self.head_span_fraction!r}"
            )
        if not isinstance(self.field, FieldParams):
            raise ValueError("field: expected a FieldParams table")  # noqa: TRY004


# -- what the brain reports ---------------------------------------------------------------------


@dataclass(frozen=True)
class VisionEstimates:
    """The brain's estimates after a step, in its body frame (x forward, y left, metres).

    ``teammates``: robot id -> position; ``ball``/``obstacle``: position or ``None``;
    ``ball_source``: ``"own"`` (seen now), ``"teammate"`` (eq. 2 from a teammate's detection),
    ``"memory"`` (remembered) or ``None``; ``goal``: ``"ball"``, ``"obstacle"`` or ``None``
    (not assigned yet); ``reached``: the robot believes it is at its goal.
    """

    time_s: float
    teammates: dict[int, tuple[float, float]]
    ball: tuple[float, float] | None
    obstacle: tuple[float, float] | None
    ball_source: str | None
    goal: str | None
    reached: bool


@dataclass
class _Frame:
    time_s: float
    pose: np.ndarray  # odometry pose (3,)
    head_pan_rad: float
    detections: list[Detection]
    #: Body bearings of every yellow blob, whole or not (negative information needs them).
    yellow_bearings: tuple[float, ...] = ()


def _rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def _near_blob(positions_body: np.ndarray, bearings_rad) -> np.ndarray:
    """Hypotheses at a bearing where some yellow blob was seen, whole or not: no negative
    information there (a box seen from the side fails the shape check but is there)."""
    if not bearings_rad:
        return np.zeros(len(positions_body), dtype=bool)
    hyp = np.arctan2(positions_body[:, 1], positions_body[:, 0])
    gap = np.abs(wrap_rad(hyp[:, None] - np.asarray(bearings_rad)[None, :]))
    half = np.arctan2(0.2, np.maximum(np.hypot(positions_body[:, 0], positions_body[:, 1]), 0.1))
    return (gap <= half[:, None] + 0.05).any(axis=1)


def _unique(detections, colour: str) -> Detection | None:
    found = [d for d in detections if d.colour == colour]
    return found[0] if len(found) == 1 else None


class VisionBrain:
    """One vision robot's brain (seed 004); see the module docstring.

    ``teammate_ids``: the other robots of its team (the ids their payloads carry). ``camera``:
    the intrinsics its images are taken with. ``rng``: its own generator (the brain is
    deterministic today; the generator is part of the brain contract).
    """

    def __init__(
        self,
        robot_id: int,
        teammate_ids,
        config: VisionAgentConfig,
        camera: CameraParams,
        rng: np.random.Generator,
    ):
        if (
            isinstance(robot_id, bool)
            or not isinstance(robot_id, (int, np.integer))
            or not (0 <= robot_id <= MAX_ROBOT_ID)
        ):
            raise ValueError(f"robot_id: expected 0..{MAX_ROBOT_ID}, got {robot_id!r}")
        self.robot_id = int(robot_id)
        self.teammate_ids = tuple(sorted(int(i) for i in teammate_ids))
        if self.robot_id in self.teammate_ids:
            raise ValueError("teammate_ids: must not contain the robot's own id")
        self.config = config
        self.camera = camera
        self.rng = rng
        self.now_s = 0.0
        self.pose = np.zeros(3)
        self.head_pan_rad = 0.0
        self._first_object_s: float | None = None
        self._frames: deque[_Frame] = deque()
        self._last: _Frame | None = None
        self._theirs: dict[int, deque[SharedFrame]] = {i: deque() for i in self.teammate_ids}
        self._unpaired: dict[int, list[SharedFrame]] = {i: [] for i in self.teammate_ids}
        # Frame-transform samples (time, tau (2,), phi) per teammate: its odometry frame -> mine.
        self._links: dict[int, deque[tuple[float, np.ndarray, float]]] = {
            i: deque() for i in self.teammate_ids
        }
        # Direct sightings (time, position in my odometry frame) per teammate.
        self._sightings: dict[int, deque[tuple[float, np.ndarray]]] = {
            i: deque() for i in self.teammate_ids
        }
        self._landmarks: dict[str, tuple[float, np.ndarray, str]] = {}
        self._own_sightings: dict[str, tuple[float, np.ndarray]] = {}
        # Perception mode: the direction grid and the pose estimates (time, xy, heading,
        # resolved) of each teammate, in my odometry frame.
        self._grids = {i: DirectionGrid(config.heading_bins) for i in self.teammate_ids}
        self._poses: dict[int, deque[tuple[float, np.ndarray, float, bool]]] = {
            i: deque() for i in self.teammate_ids
        }
        self._look: tuple[float, float] | None = None  # (until time_s, body bearing_rad)
        self._teammates_now: dict[int, np.ndarray] = {}
        self.goal: str | None = None
        self.reached = False
        self._detour_side = 0
        self.steps = 0

    # -- Telepathy ------------------------------------------------------------------------------

    def share(self) -> bytes | None:
        """This step's payload for the team (``None`` before the first step or with sharing off)."""
        if not self.config.sharing or self._last is None:
            return None
        f = self._last
        return encode_share(
            SharedFrame(
                self.robot_id,
                f.time_s,
                f.head_pan_rad,
                tuple(float(v) for v in f.pose) if self.config.shared_odometry else None,
                tuple(f.detections),
                f.yellow_bearings,
            )
        )

    def receive(self, sender_id: int, payload) -> None:
        """Take a teammate's payload; ``ValueError`` (naming the field) if it is invalid."""
        if not self.config.sharing:
            return
        if sender_id not in self._theirs:
            raise ValueError(
                f"sender: robot {sender_id!r} is not a teammate of robot {self.robot_id}"
            )
        frame = decode_share(
            payload, self.camera, sender_id, self.now_s, self.config.max_clock_skew_s
        )
        if self.now_s - frame.time_s > self.config.window_s:
            return  # too old to use: dropped, not an error
        frames = self._theirs[sender_id]
        if frames and frame.time_s <= frames[-1].time_s:
            return  # a duplicate or out of order: the newer frame wins
        frames.append(frame)
        self._unpaired[sender_id].append(frame)

    # -- the step -------------------------------------------------------------------------------

    def step(self, obs: VisionObservation) -> VisionCommand:
        """Process one observation; return the velocity and head command."""
        cfg = self.config
        image = decode_image(obs.image, self.camera)  # raises before any state changes
        pose = np.array(
            [_number(f"odometry_pose[{i}]", v) for i, v in enumerate(obs.odometry_pose)]
        )
        pan = _number("head_pan_rad", obs.head_pan_rad, -math.pi, math.pi)
        now = _number("time_s", obs.time_s, lo=0.0)
        if self.steps and now < self.now_s:
            raise ValueError(f"time_s: {now} is earlier than the previous step's {self.now_s}")
        self.now_s, self.pose, self.head_pan_rad = now, pose, pan
        self.steps += 1

        blobs = detect_blobs(image, self.camera)
        frame = _Frame(
            now, pose, pan, detections_from_blobs(blobs, self.robot_id, now, pan, self.camera),
            tuple(float(wrap_rad(pan + b.bearing_rad)) for b in blobs
                  if b.colour == TEAMMATE_COLOUR)[:MAX_SHARED_DETECTIONS],
        )
        self._frames.append(frame)
        self._last = frame
        self._prune()
        self._record_sightings(frame)
        if cfg.sharing:
            for tid in self.teammate_ids:
                if cfg.relative_heading == "perception":
                    self._pair_perception(tid)
                else:
                    self._pair(tid)
        self._update_teammates()
        self._update_landmarks(frame)
        self._assign()
        return self._command()

    def estimates(self) -> VisionEstimates:
        """What the brain believes after its last step (body frame)."""
        ball = self._body("ball")
        obstacle = self._body("obstacle")
        return VisionEstimates(
            time_s=self.now_s,
            teammates={i: (float(p[0]), float(p[1])) for i, p in self._teammates_now.items()},
            ball=None if ball is None else (float(ball[0]), float(ball[1])),
            obstacle=None if obstacle is None else (float(obstacle[0]), float(obstacle[1])),
            ball_source=self._landmarks["ball"][2] if "ball" in self._landmarks else None,
            goal=self.goal,
            reached=self.reached,
        )

    # -- frames ---------------------------------------------------------------------------------

    def _prune(self) -> None:
        horizon = self.now_s - self.config.window_s
        while self._frames and self._frames[0].time_s < horizon:
            self._frames.popleft()
        link_horizon = self.now_s - self.config.link_memory_s
        for tid in self.teammate_ids:
            theirs, links, sightings = self._theirs[tid], self._links[tid], self._sightings[tid]
            while theirs and theirs[0].time_s < horizon:
                theirs.popleft()
            while sightings and sightings[0][0] < horizon:
                sightings.popleft()
            while links and links[0][0] < link_horizon:
                links.popleft()
            poses = self._poses[tid]
            while poses and poses[0][0] < link_horizon:
                poses.popleft()
            self._unpaired[tid] = [f for f in self._unpaired[tid] if f.time_s >= horizon]
        memory = self.now_s - self.config.landmark_memory_s
        for name in [k for k, v in self._landmarks.items() if v[0] < memory]:
            del self._landmarks[name]
        for name in [k for k, v in self._own_sightings.items() if v[0] < memory]:
            del self._own_sightings[name]

    def _my_frame_at(self, time_s: float) -> _Frame | None:
        best = None
        for f in self._frames:
            if abs(f.time_s - time_s) <= self.config.pair_tolerance_s and (
                best is None or abs(f.time_s - time_s) < abs(best.time_s - time_s)
            ):
                best = f
        return best

    @staticmethod
    def _to_odom(frame_pose: np.ndarray, body_xy) -> np.ndarray:
        return frame_pose[:2] + _rot(frame_pose[2]) @ np.asarray(body_xy, float)

    def _to_body_now(self, odom_xy: np.ndarray) -> np.ndarray:
        return _rot(-self.pose[2]) @ (odom_xy - self.pose[:2])

    # -- teammates ------------------------------------------------------------------------------

    def _pose_at(self, tid: int, time_s: float) -> tuple[np.ndarray, float] | None:
        """Teammate ``tid``'s estimated (position, heading) in my odometry frame at ``time_s``."""
        if self.config.relative_heading == "perception":
            poses = self._poses[tid]
            if not poses:
                return None
            best = min(poses, key=lambda p: abs(p[0] - time_s))
            return best[1], best[2]
        link = self._link(tid)
        theirs = [f for f in self._theirs[tid] if f.odometry_pose is not None]
        if link is None or not theirs:
            return None
        tau, phi = link
        th = min(theirs, key=lambda f: abs(f.time_s - time_s))
        xy = tau + _rot(phi) @ np.asarray(th.odometry_pose[:2])
        return xy, float(wrap_rad(phi + th.odometry_pose[2]))

    def _predicted_in_frame(self, tid: int, frame: _Frame) -> np.ndarray | None:
        """Teammate ``tid``'s estimated position in ``frame``'s body frame."""
        if self.config.relative_heading == "perception":
            pose = self._pose_at(tid, frame.time_s)
            return None if pose is None else _rot(-frame.pose[2]) @ (pose[0] - frame.pose[:2])
        link = self._link(tid)
        theirs = self._theirs[tid]
        if link is None or not theirs:
            return None
        tau, phi = link
        # The teammate's odometry pose closest in time to the frame.
        th = min(theirs, key=lambda f: abs(f.time_s - frame.time_s))
        odom_xy = tau + _rot(phi) @ np.asarray(th.odometry_pose[:2])
        return _rot(-frame.pose[2]) @ (odom_xy - frame.pose[:2])

    def _attribute_sighting(self, frame: _Frame, position_body: np.ndarray) -> int | None:
        if len(self.teammate_ids) == 1:
            return self.teammate_ids[0]
        best, best_gap = None, self.config.sighting_gate_m
        for tid in self.teammate_ids:
            predicted = self._predicted_in_frame(tid, frame)
            if predicted is not None:
                gap = float(np.hypot(*(predicted - position_body)))
                if gap <= best_gap:
                    best, best_gap = tid, gap
        return best

    def _record_sightings(self, frame: _Frame) -> None:
        for d in frame.detections:
            if d.colour != TEAMMATE_COLOUR:
                continue
            tid = self._attribute_sighting(frame, d.position_m())
            if tid is not None:
                self._sightings[tid].append(
                    (frame.time_s, self._to_odom(frame.pose, d.position_m()))
                )

    def _relative_heading(self, mine: _Frame, theirs: SharedFrame) -> float:
        cfg = self.config
        if cfg.relative_heading == "objects":
            pairs = [
                (_unique(mine.detections, c), _unique(theirs.detections, c))
                for c in ("pink", "orange")
            ]
            if all(m is not None and t is not None for m, t in pairs):
                psi = relative_heading_from_two_objects(
                    (pairs[0][0], pairs[1][0]), (pairs[0][1], pairs[1][1])
                )
                if psi is not None:
                    return psi
        return float(
            wrap_rad(cfg.initial_relative_heading_rad + theirs.odometry_pose[2] - mine.pose[2])
        )

    def _pair(self, tid: int) -> None:
        """Turn the teammate's unpaired frames into frame-transform samples (eq. 1, eq. 2)."""
        pending, keep = self._unpaired[tid], []
        for theirs in pending:
            mine = self._my_frame_at(theirs.time_s)
            if mine is None:
                if theirs.time_s > self.now_s - self.config.pair_tolerance_s:
                    keep.append(theirs)  # my frame of that time may still come
                continue
            if theirs.odometry_pose is None:
                continue  # these modes need the teammate's odometry
            psi = self._relative_heading(mine, theirs)
            estimates = []
            for colour in _COMMON_COLOURS:
                m, t = _unique(mine.detections, colour), _unique(theirs.detections, colour)
                if m is None or t is None:
                    continue
                est = stereo_relative_position(m, t, psi, self.camera.focal_px)  # eq. 1
                if est is None:
                    est = teammate_from_common_object(m, t, psi)  # eq. 2
                if est is not None:
                    estimates.append(est)
            sighted = [d for d in mine.detections if d.colour == TEAMMATE_COLOUR]
            for d in sighted:
                if self._attribute_sighting(mine, d.position_m()) == tid:
                    estimates.append(d.position_m())
            if len(self.teammate_ids) == 1:
                me_seen = [d for d in theirs.detections if d.colour == TEAMMATE_COLOUR]
                if len(me_seen) == 1:  # the teammate sees me: it is at -R(psi) (me in its frame)
                    estimates.append(-(_rot(psi) @ me_seen[0].position_m()))
            if not estimates:
                continue
            r = fuse(estimates, self.config.consistency_tolerance_m)
            if r is None:
                continue
            phi = float(wrap_rad(mine.pose[2] + psi - theirs.odometry_pose[2]))
            tau = self._to_odom(mine.pose, r) - _rot(phi) @ np.asarray(theirs.odometry_pose[:2])
            self._links[tid].append((theirs.time_s, tau, phi))
        self._unpaired[tid] = keep

    def _common_objects(self, mine: _Frame, theirs: SharedFrame) -> list:
        """``(colour, O in my odometry frame, teammate's detection)`` of each object the
        teammate sees once and I see in ``mine`` or remember from my own sightings."""
        out = []
        for colour, name in _ANCHOR_COLOURS:
            t = _unique(theirs.detections, colour)
            if t is None:
                continue
            m = _unique(mine.detections, colour)
            if m is not None:
                out.append((colour, self._to_odom(mine.pose, m.position_m()), t))
            elif name in self._own_sightings:  # remembered from my own frames, never relayed
                out.append((colour, self._own_sightings[name][1], t))
        return out

    def _pair_perception(self, tid: int) -> None:
        """The teammate's pose from shared detections alone (``heading``: the direction grid)."""
        cfg, cam = self.config, self.camera
        pending, keep = self._unpaired[tid], []
        exclusive = len(self.teammate_ids) == 1
        body_r = OBJECT_KINDS["teammate"].radius_m
        for theirs in pending:
            mine = self._my_frame_at(theirs.time_s)
            if mine is None:
                if theirs.time_s > self.now_s - cfg.pair_tolerance_s:
                    keep.append(theirs)
                continue
            common = self._common_objects(mine, theirs)
            if not common:
                continue
            grid = self._grids[tid]
            colours = [c[0] for c in common]
            if grid.anchor not in colours:
                if grid.anchor is not None:  # gamma' = gamma + beta_new - beta_old
                    grid.shift(float(wrap_rad(common[0][2].bearing_rad - grid.anchor_bearing_rad)))
                grid.anchor = colours[0]
            _, anchor_xy, anchor_t = common[colours.index(grid.anchor)]
            if grid.time_s is not None:
                dt = max(0.0, theirs.time_s - grid.time_s)
                grid.diffuse(cfg.field.max_speed_mps * dt / max(anchor_t.distance_m, 0.3))
            gammas = grid.gamma_rad
            positions = ring(anchor_xy, anchor_t.distance_m, gammas)
            headings = heading_of(gammas, anchor_t.bearing_rad)
            likelihood = np.ones(len(gammas))
            occluders = []
            for colour, obj_xy, det in common:
                occluders.append((_rot(-mine.pose[2]) @ (obj_xy - mine.pose[:2]), 0.1))
                if colour != grid.anchor:  # Fig. 2: a second common object
                    seen = to_frame(np.broadcast_to(obj_xy, positions.shape), positions, headings)
                    likelihood *= object_likelihood(seen, det.position_m(), cfg.match_sigma_m)
            # My view of the teammate, and the teammate's view of me (negative information).
            mine_body = to_frame(positions, mine.pose[:2], mine.pose[2])
            mine_yellow = [d.position_m() for d in mine.detections if d.colour == TEAMMATE_COLOUR]
            visible = in_view(mine_body, mine.head_pan_rad, cam.half_fov_rad, body_r, occluders)
            visible &= ~_near_blob(mine_body, mine.yellow_bearings)
            likelihood *= sighting_likelihood(
                mine_body, mine_yellow, visible, cfg.match_sigma_m, cfg.miss_likelihood, exclusive
            )
            me_body = to_frame(np.broadcast_to(mine.pose[:2], positions.shape), positions, headings)
            their_yellow = [d.position_m() for d in theirs.detections if d.colour == TEAMMATE_COLOUR]
            their_occluders = [(d.position_m(), 0.1) for d in theirs.detections
                               if d.colour != TEAMMATE_COLOUR]
            their_visible = in_view(
                me_body, theirs.head_pan_rad, cam.half_fov_rad, body_r, their_occluders
            )
            their_visible &= ~_near_blob(me_body, theirs.yellow_bearings)
            likelihood *= sighting_likelihood(
                me_body, their_yellow, their_visible, cfg.match_sigma_m, cfg.miss_likelihood,
                exclusive,
            )
            grid.update(likelihood)
            grid.time_s = theirs.time_s
            grid.anchor_bearing_rad = anchor_t.bearing_rad
            gamma, mass = grid.mode()
            phi = float(heading_of(gamma, anchor_t.bearing_rad))
            estimates = [ring(anchor_xy, anchor_t.distance_m, np.array([gamma]))[0]]
            for colour, obj_xy, det in common:
                if colour != grid.anchor:
                    estimates.append(obj_xy - _rot(phi) @ det.position_m())
            for d in mine.detections:  # a direct sighting near the estimate
                if d.colour == TEAMMATE_COLOUR:
                    seen = self._to_odom(mine.pose, d.position_m())
                    if np.hypot(*(seen - estimates[0])) <= cfg.sighting_gate_m:
                        estimates.append(seen)
            fused = fuse(estimates, cfg.consistency_tolerance_m)
            xy = estimates[0] if fused is None else fused
            self._poses[tid].append((theirs.time_s, xy, phi, mass >= cfg.resolved_mass))
        self._unpaired[tid] = keep

    def teammate_resolved(self, tid: int) -> bool | None:
        """Perception mode: whether the teammate's direction is resolved (``None``: no estimate
        yet, or another mode)."""
        if self.config.relative_heading != "perception" or not self._poses.get(tid):
            return None
        return self._poses[tid][-1][3]

    def _link(self, tid: int) -> tuple[np.ndarray, float] | None:
        samples = list(self._links[tid])[-self.config.link_samples :]
        if not samples:
            return None
        # Component-wise median: a wrong measurement among the samples has no effect.
        tau = np.median([s[1] for s in samples], axis=0)
        phis = np.array([s[2] for s in samples])
        ref = phis[-1]
        phi = float(wrap_rad(ref + np.median(wrap_rad(phis - ref))))
        return tau, phi

    def _update_teammates(self) -> None:
        self._teammates_now = {}
        for tid in self.teammate_ids:
            if self.config.sharing and self.config.relative_heading == "perception":
                # The newer of the shared-perception estimate and my own last sighting.
                # (forgotten when its payloads stop for longer than the window, as below)
                latest = [(p[0], p[1]) for p in list(self._poses[tid])[-1:] if self._theirs[tid]]
                latest += list(self._sightings[tid])[-1:]
                if latest:
                    self._teammates_now[tid] = self._to_body_now(max(latest, key=lambda e: e[0])[1])
                continue
            link = self._link(tid) if self.config.sharing else None
            if link is not None and self._theirs[tid] and self._theirs[tid][-1].odometry_pose:
                tau, phi = link
                odom_xy = tau + _rot(phi) @ np.asarray(self._theirs[tid][-1].odometry_pose[:2])
                self._teammates_now[tid] = self._to_body_now(odom_xy)
            elif self._sightings[tid]:
                self._teammates_now[tid] = self._to_body_now(self._sightings[tid][-1][1])

    # -- objects --------------------------------------------------------------------------------

    def _update_landmarks(self, frame: _Frame) -> None:
        for name, colour in (("ball", "pink"), ("obstacle", "orange")):
            own = [d for d in frame.detections if d.colour == colour]
            if own:
                nearest = min(own, key=lambda d: d.distance_m)
                self._own_sightings[name] = (
                    frame.time_s, self._to_odom(frame.pose, nearest.position_m())
                )
                self._landmarks[name] = (
                    frame.time_s,
                    self._to_odom(frame.pose, nearest.position_m()),
                    "own",
                )
                continue
            if not self.config.sharing:
                continue
            relayed = []
            latest_t = -math.inf
            for tid in self.teammate_ids:
                theirs = fresh(  # the teammate's latest frame within the window
                    [
                        d
                        for f in list(self._theirs[tid])[-1:]
                        for d in f.detections
                        if d.colour == colour
                    ],
                    self.now_s,
                    self.config.window_s,
                )
                if not theirs:
                    continue
                t_s = theirs[0].time_s
                mine = self._my_frame_at(t_s)
                pose = self._pose_at(tid, t_s)
                if mine is None or pose is None:
                    continue
                teammate_body = _rot(-mine.pose[2]) @ (pose[0] - mine.pose[:2])
                psi = float(wrap_rad(pose[1] - mine.pose[2]))
                det = min(theirs, key=lambda d: d.distance_m)
                obj = object_from_teammate(teammate_body, psi, det)  # eq. 2 (Fig. 3)
                if obj is not None:
                    relayed.append(self._to_odom(mine.pose, obj))
                    latest_t = max(latest_t, t_s)
            if relayed:
                fused = fuse(relayed, self.config.consistency_tolerance_m)
                if fused is not None:
                    self._landmarks[name] = (latest_t, fused, "teammate")
                    continue
            if name in self._landmarks and self._landmarks[name][2] != "memory":
                t_s, xy, _ = self._landmarks[name]
                self._landmarks[name] = (t_s, xy, "memory")

    def _body(self, name: str) -> np.ndarray | None:
        if name not in self._landmarks:
            return None
        return self._to_body_now(self._landmarks[name][1])

    # -- goals, head and body -------------------------------------------------------------------

    def _assign(self) -> None:
        if self.goal is not None:
            return
        ball, obstacle = self._body("ball"), self._body("obstacle")
        if ball is None and obstacle is None:
            return
        if self._first_object_s is None:
            self._first_object_s = self.now_s
        # Wait (at most assign_wait_s from the first object seen) until every teammate is placed.
        waited = self.now_s - self._first_object_s >= self.config.assign_wait_s
        known = sorted(self._teammates_now)
        if not self.config.sharing:
            # Alone (no shared detections): the rule among the teammates I see, else the
            # nearest goal I see (alone_goal = "nearest-seen").
            if not known:
                seen = {k: float(np.hypot(*p)) for k, p in (("ball", ball), ("obstacle", obstacle))
                        if p is not None}
                self.goal = min(seen, key=lambda k: (seen[k], k != BALL))
                return
        elif len(known) < len(self.teammate_ids) and not waited:
            return
        ids = sorted([self.robot_id, *known])
        positions = [np.zeros(2) if i == self.robot_id else self._teammates_now[i] for i in ids]
        goals = assign_goals(positions, obstacle, ball)
        self.goal = goals[ids.index(self.robot_id)] or BALL

    def _head_target(self, goal_xy: np.ndarray | None) -> float:
        cfg, cam = self.config, self.camera
        points = []
        if goal_xy is not None:
            points.append(goal_xy)
        for name in ("ball", "obstacle"):
            p = self._body(name)
            if p is not None and (self.goal is None or name != self.goal):
                points.append(p)
        look = self._look_for_teammate()
        if look is not None:
            return look
        if not points:  # nothing known: sweep the head (a triangle wave over the pan range)
            phase = (self.now_s / cfg.scan_period_s) % 1.0
            return cam.pan_limit_rad * 0.9 * (4.0 * abs(phase - 0.5) - 1.0)
        bearings = np.array([math.atan2(p[1], p[0]) for p in points])
        lo, hi = float(bearings.min()), float(bearings.max())
        if hi - lo <= 2.0 * cam.half_fov_rad * cfg.head_span_fraction:
            target = 0.5 * (lo + hi)
        else:
            target = float(bearings[0])
        return float(np.clip(target, -cam.pan_limit_rad, cam.pan_limit_rad))

    def _look_for_teammate(self) -> float | None:
        """Perception mode, ``look_for_teammate``: while a teammate's direction is unresolved,
        look for it (0.6 s in every 2 s, staggered by robot) at its most probable hypothesis
        that is out of view now; the sighting, or its absence (negative information), narrows
        the grid."""
        cfg, cam = self.config, self.camera
        if not (cfg.sharing and cfg.relative_heading == "perception" and cfg.look_for_teammate):
            return None
        if self._look is not None and self.now_s < self._look[0]:
            return self._look[1]
        self._look = None
        # Staggered by robot (teammates looking away at the same time share no object).
        team = sorted([self.robot_id, *self.teammate_ids])
        offset_s = 2.0 * team.index(self.robot_id) / len(team)
        if ((self.now_s + offset_s) % 2.0) >= 0.6:
            return None
        best = None
        for tid in self.teammate_ids:
            grid, poses = self._grids[tid], self._poses[tid]
            if not poses or poses[-1][3] or grid.anchor is None:
                continue
            name = dict(_ANCHOR_COLOURS)[grid.anchor]
            if name not in self._own_sightings:
                continue
            latest = self._theirs[tid][-1] if self._theirs[tid] else None
            theirs = None if latest is None else _unique(latest.detections, grid.anchor)
            if theirs is None:
                continue
            positions = ring(self._own_sightings[name][1], theirs.distance_m, grid.gamma_rad)
            body = to_frame(positions, self.pose[:2], self.pose[2])
            bearing = np.arctan2(body[:, 1], body[:, 0])
            off_now = np.abs(wrap_rad(bearing - self.head_pan_rad))
            usable = (np.abs(bearing) <= cam.pan_limit_rad) & (off_now > 0.7 * cam.half_fov_rad)
            usable &= grid.weights >= 0.3 * grid.weights.max()
            if usable.any():
                k = int(np.argmax(np.where(usable, grid.weights, -1.0)))
                if best is None or grid.weights[k] > best[0]:
                    best = (float(grid.weights[k]), float(bearing[k]))
        if best is None:
            return None
        self._look = (self.now_s + 0.6, best[1])
        return best[1]

    def _detour(self, attraction: np.ndarray, repulsion_force: np.ndarray) -> np.ndarray:
        """The detour force (module docstring): sideways, on the side the repulsion leans to."""
        gain = self.config.detour_gain
        norm = float(np.hypot(*attraction))
        opposing = -float(repulsion_force @ attraction) / norm if norm > 0.0 else 0.0
        if gain <= 0.0 or opposing <= 0.0:
            self._detour_side = 0
            return np.zeros(2)
        ahead = attraction / norm
        left = np.array([-ahead[1], ahead[0]])
        if self._detour_side == 0:  # chosen once per detour: no dithering on noise
            self._detour_side = -1 if float(repulsion_force @ left) < 0.0 else 1
        return gain * opposing * self._detour_side * left

    def _command(self) -> VisionCommand:
        cfg, fp = self.config, self.config.field
        goal_xy = self._body(self.goal) if self.goal is not None else None
        head = self._head_target(goal_xy)
        if self.goal is None:
            return VisionCommand(0.0, 0.0, 0.0, head)
        if goal_xy is None:  # assigned but lost: turn on the spot while the head sweeps
            return VisionCommand(0.0, 0.0, 0.5 * cfg.max_turn_rate_rad_s, head)
        goal_radius = OBJECT_KINDS[self.goal].radius_m
        stop_m = OBJECT_KINDS["teammate"].radius_m + goal_radius + cfg.stop_margin_m
        distance = float(np.hypot(*goal_xy))
        if distance <= stop_m or (self.reached and distance <= stop_m + 0.1):
            self.reached = True
            return VisionCommand(0.0, 0.0, 0.0, head)
        self.reached = False
        obstacles = []
        if self.goal != OBSTACLE and self._body("obstacle") is not None:
            obstacles.append(self._body("obstacle"))
        teammates = list(self._teammates_now.values())
        origin = np.zeros(2)
        result = potential_field(origin, goal_xy, obstacles or None, teammates or None, fp)
        force = result.attraction + result.repulsion
        force = force + self._detour(result.attraction, result.repulsion)
        speed = float(np.hypot(*force))
        velocity = force * (fp.max_speed_mps / speed) if speed > fp.max_speed_mps else force
        turn = 0.0
        if speed > 1e-6:
            turn = float(
                np.clip(
                    cfg.turn_gain_per_s * math.atan2(velocity[1], velocity[0]),
                    -cfg.max_turn_rate_rad_s,
                    cfg.max_turn_rate_rad_s,
                )
            )
        return VisionCommand(float(velocity[0]), float(velocity[1]), turn, head)
