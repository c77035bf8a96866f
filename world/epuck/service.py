"""The e-puck foraging world of seeds 000/001 as a served world (:class:`ForagingService`).

The adapter the world-server shell (:mod:`swarmloc.world.server`) runs for scenarios of the
``foraging`` family, around the pure model :class:`~swarmloc.world.epuck.foraging.ForagingWorld`;
:data:`swarmloc.families.FAMILIES` names :func:`_foraging`.

**The Senses' fast path** (issue 47). :meth:`ForagingService.senses` encodes every live robot's
Sense of a tick in one compiled call (:func:`swarmloc.agents.epuck.wire.encode_senses`), byte for
byte what the reference, :meth:`ForagingService.encode_senses_reference` (an :class:`EpuckSense`
per robot through the protocol codec), produces; where the compiled encoder refuses (a reading out of
its bounds, too many messages for one robot), the reference runs and raises the codec's precise
error. Measured with ``python benchmarks/bench_world_models.py --wire``: the reference's cost per
tick at 800 robots against the compiled one's is printed side by side; tests/test_world_wire.py
holds them byte-equal.
"""

from __future__ import annotations

import numpy as np

from swarmloc.protocol.epuck import on_path
from swarmloc.protocol.messages import (
    MAX_RAB_PAYLOAD_BYTES,
    EpuckAct,
    EpuckSense,
    RabMessage,
    WorldState,
    encode,
)


class ForagingService:
    """The e-puck foraging world of seeds 000/001 (:class:`ForagingWorld`) as a served world.

    Messages an agent emits at tick ``k`` (its Act's payload) reach the robots the medium chose
    at ``k`` (measured in :meth:`ForagingWorld.step`) in their Sense of ``k + 1``.
    """

    family = "foraging"
    act_type = EpuckAct

    def __init__(self, world) -> None:
        self.world = world
        n = world.n_robots
        self.n_robots = n
        self.seed = world.config.seed
        self.tick_s = world.config.tick_s
        self._cmd = np.zeros((n, 2))  # a missing Act keeps the previous wheel command
        self._state = np.zeros(n, np.int64)
        self._outgoing: list[bytes | None] = [None] * n
        # the same messages for the compiled encoder: bytes per sender, -1 for none
        self._payloads = np.zeros((n, MAX_RAB_PAYLOAD_BYTES), np.uint8)
        self._payload_len = np.full(n, -1, np.int64)
        self._out = np.zeros(0, np.uint8)

    @property
    def tick(self) -> int:
        return self.world.tick

    @property
    def done(self) -> bool:
        return self.world.done

    @property
    def alive(self) -> np.ndarray:
        return self.world.alive

    def kill(self, robot: int) -> None:
        self.world.kill(robot)

    def revive(self, robot: int) -> None:
        self.world.revive(robot)

    def senses(self) -> list[tuple[int, bytes]]:
        """Every live robot's encoded Sense (the compiled fast path; see the module docstring)."""
        return self.encode_senses(self.world.observe())

    def encode_senses(self, obs) -> list[tuple[int, bytes]]:
        """The Senses of observation ``obs`` through the compiled encoder, falling back to
        :meth:`encode_senses_reference` (which raises the codec's error) where it refuses."""
        from swarmloc.agents.epuck.wire import RAB_MAX_BYTES, SENSE_BASE_MAX_BYTES, encode_senses

        d = obs.deliveries
        robots = np.flatnonzero(self.world.alive).astype(np.int64)
        need = robots.shape[0] * SENSE_BASE_MAX_BYTES + len(d) * RAB_MAX_BYTES
        if self._out.shape[0] < need:
            self._out = np.zeros(2 * need, np.uint8)
        offsets = np.empty(robots.shape[0] + 1, np.int64)
        total = encode_senses(obs.tick, robots, obs.encoder_steps, obs.ir, obs.ground,
                              d.sender, d.receiver, d.range_m, d.bearing_rad, self._payloads,
                              self._payload_len, self._out, offsets)
        if total < 0:  # refused: the reference raises the codec's precise error
            return self.encode_senses_reference(obs)
        data = self._out[:total].tobytes()
        bounds = offsets.tolist()
        return [(r, data[bounds[i]:bounds[i + 1]]) for i, r in enumerate(robots.tolist())]

    def encode_senses_reference(self, obs) -> list[tuple[int, bytes]]:
        """The same Senses through the protocol codec, an :class:`EpuckSense` per robot: the
        reference the compiled path is held to."""
        world = self.world
        d = obs.deliveries
        received: list[list[RabMessage]] = [[] for _ in range(self.n_robots)]
        if len(d.sender):
            outgoing = self._outgoing
            for s, r, rng_m, b in zip(
                d.sender.tolist(), d.receiver.tolist(), d.range_m.tolist(), d.bearing_rad.tolist()
            ):
                payload = outgoing[s]
                if payload is not None:
                    received[r].append(RabMessage(s, rng_m, b, payload))
        enc, ir, ground = obs.encoder_steps.tolist(), obs.ir.tolist(), obs.ground.tolist()
        out = []
        for i in np.flatnonzero(world.alive).tolist():
            sense = EpuckSense(
                tick=obs.tick, robot_id=i, encoder_steps=tuple(enc[i]), ir=tuple(ir[i]),
                ground=tuple(ground[i]), received=tuple(received[i]),
            )
            out.append((i, encode(sense)))
        return out

    def step(self, acts: list[EpuckAct | None]) -> None:
        n = self.n_robots
        sending = np.zeros(n, bool)
        payloads: list[bytes | None] = [None] * n
        self._payload_len[:] = -1
        for i, act in enumerate(acts):
            if act is None:
                continue
            self._cmd[i] = act.wheel_speed_steps_s
            self._state[i] = act.state
            sending[i] = act.payload is not None
            payloads[i] = act.payload
            if act.payload is not None:
                size = len(act.payload)
                kept = min(size, MAX_RAB_PAYLOAD_BYTES)  # longer: the encoder refuses, the codec says why
                self._payloads[i, :kept] = np.frombuffer(act.payload, np.uint8, kept)
                self._payload_len[i] = size
        self.world.step(self._cmd.copy(), sending, on_path(self._state))
        self._outgoing = payloads

    def state(self) -> WorldState:
        w = self.world
        return WorldState(
            tick=w.tick, time_s=w.tick * self.tick_s,
            poses=tuple(tuple(p) for p in w.pose.tolist()), alive=tuple(w.alive.tolist()),
            round_trips=int(w.metrics.round_trips.sum()),
        )

    def summary(self) -> dict:
        return self.world.metrics.summary()


def _foraging(scenario) -> ForagingService:
    from swarmloc.agents.epuck.social_odometry import STRATEGIES
    from swarmloc.world.epuck.foraging import ForagingWorld

    if STRATEGIES[scenario.agent.strategy].central:
        raise ValueError(f"agent.strategy: {scenario.agent.strategy} needs the batch engine's central "
                         f"system; a world-server cannot serve it")
    return ForagingService(ForagingWorld(scenario.world))
