"""A vision robot's agent (seed 004): the :class:`VisionBrain` fed by the world-server over Zenoh,
sharing its detections with its teammates directly on the team keys ("Telepathy", §III).

Per Sense: decode, step the brain, publish this frame's detections on
``swarmloc/<run>/team/<team>/blobs/<id>`` (the frame's tick rides along as the sample's
attachment), answer with a :class:`VisionAct` (command and estimates). A teammate's payload is
held until the Sense of the next tick and handed to the brain then, in (tick, sender) order: a
teammate quicker than us must not make us see its frame k before our own step k. The teammate
publishes before its Act and the world sends Sense k+1 only after every Act of k, so the payloads
of k are in by then; the run is the in-process runner's, message for message. A frame that does
not decode, or a teammate's impossible detection, is counted; the robot keeps its previous
command and goes on.
"""

from __future__ import annotations

import threading

import numpy as np
import zenoh

from swarmloc.agents.brains import BrainError
from swarmloc.protocol.errors import ErrorCounter
from swarmloc.protocol.keys import Keys
from swarmloc.protocol.messages import VisionAct, VisionSense, Welcome


class VisionAgent:
    sense_type = VisionSense

    def __init__(self, brain, robot_id: int, team: str, camera) -> None:
        self.brain = brain
        self.robot_id = robot_id
        self.team = team
        self.camera = camera
        self._lock = threading.Lock()
        self._command = (0.0, 0.0, 0.0, 0.0)
        self._pub = None
        self._errors: ErrorCounter | None = None
        self._pending: list[tuple[int, int, bytes]] = []  # (tick, sender, payload)

    @classmethod
    def from_welcome(cls, welcome: Welcome, scenario) -> VisionAgent:
        from swarmloc.agents.vision.brain import VisionBrain
        from swarmloc.world.vision.scenario import AGENT_STREAM, world_config

        seed = scenario.world.seed
        try:
            wcfg, lay = world_config(scenario, seed)
        except (ValueError, TypeError) as exc:
            raise BrainError(f"the world's vision scenario is not usable: {exc}") from None
        i, n = welcome.robot_id, len(lay.robots)
        if i >= n:
            raise BrainError(f"robot {i} is not in a world of {n}")
        teams = [r.team for r in lay.robots]
        mates = [j for j in range(n) if j != i and teams[j] == teams[i]]
        brain = VisionBrain(i, mates, scenario.agent, wcfg.camera,
                            np.random.default_rng([seed, AGENT_STREAM, i]))
        return cls(brain, i, teams[i], wcfg.camera)

    # -- the team keys (agent to agent) -------------------------------------------------------

    def declare(self, session: zenoh.Session, keys: Keys, errors: ErrorCounter) -> list:
        self._errors = errors
        self._pub = session.declare_publisher(
            keys.team_blobs(self.team, self.robot_id), congestion_control=zenoh.CongestionControl.BLOCK
        )
        # Run in Zenoh's receiving task, not on a Python thread of its own: a teammate's payload of
        # tick k reaches us before the world's Sense of tick k+1 (the world sends that only after
        # the teammate's Act k, which the teammate puts after its payload), and a direct callback
        # files it before the Sense is even dispatched. With the default indirect callback the
        # two ran on two Python threads, and the Sense's thread could win the race: the payload
        # then reached the brain a tick late (seen as a process run differing from the in-process
        # one under load, about 1 run in 8).
        return [session.declare_subscriber(f"{keys.prefix}/team/{self.team}/blobs/*",
                                           zenoh.handlers.Callback(self._on_blobs, indirect=False))]

    def _on_blobs(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            sender = int(key.rsplit("/", 1)[1])
        except ValueError:
            self._errors.record(key, "blobs", ValueError("the key names no robot"))
            return
        if sender == self.robot_id:
            return
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else b""
        if len(attachment) != 8:
            self._errors.record(key, "blobs", ValueError("no 8-byte tick attachment"))
            return
        tick = int.from_bytes(attachment, "little")
        with self._lock:
            self._pending.append((tick, sender, sample.payload.to_bytes()))

    def _deliver(self, tick: int, errors: ErrorCounter) -> None:
        """Hand the brain its teammates' payloads of the ticks before ``tick``."""
        ready = sorted((p for p in self._pending if p[0] < tick), key=lambda p: (p[0], p[1]))
        self._pending = [p for p in self._pending if p[0] >= tick]
        for _, sender, payload in ready:
            try:
                self.brain.receive(sender, payload)
            except ValueError as exc:
                errors.record(f"robot {sender} blobs", "blobs", exc)

    # -- per frame ------------------------------------------------------------------------------

    def act(self, sense: VisionSense, errors: ErrorCounter) -> VisionAct:
        from swarmloc.world.vision.world import VisionObservation

        obs = VisionObservation(
            robot_id=sense.robot_id, tick=sense.tick, time_s=sense.time_s, image=sense.image,
            odometry_pose=sense.odometry_pose, head_pan_rad=sense.head_pan_rad,
        )
        with self._lock:
            self._deliver(sense.tick, errors)
            try:
                cmd = self.brain.step(obs)
                self._command = (cmd.forward_mps, cmd.left_mps, cmd.turn_rad_s, cmd.head_pan_rad)
            except ValueError as exc:  # a frame that does not decode: keep the previous command
                errors.record(f"robot {self.robot_id} camera", "image", exc)
            est = self.brain.estimates()
            shared = self.brain.share()
        if shared is not None and self._pub is not None:
            self._pub.put(shared, attachment=sense.tick.to_bytes(8, "little"))
        estimates = {
            "teammates": {str(j): [float(v) for v in xy] for j, xy in est.teammates.items()},
            "ball": None if est.ball is None else [float(v) for v in est.ball],
            "ball_source": est.ball_source,
            "goal": est.goal,
            "reached": bool(est.reached),
        }
        return VisionAct(tick=sense.tick, robot_id=self.robot_id,
                         command=tuple(float(c) for c in self._command), estimates=estimates)
