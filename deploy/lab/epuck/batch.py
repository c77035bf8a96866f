"""The batch engine: the world and every robot's brain stepped in one process, no Zenoh.

It runs the very same models as the world-server and the agent nodes: :class:`ForagingWorld` for
the world and one :class:`ForagingBrain` holding the whole swarm as a batch. Messages that the
medium delivers are routed as arrays instead of bytes (their floats are already rounded to the
float32 they cross the wire with), so a seeded run gives the same trajectories and metrics here
and over processes.

A tick is ``world.observe()``, ``brain.step(...)``, then ``world.step(...)``, each one call of a
compiled kernel (``world/epuck/kernels.py: observe_tick, step_tick``, ``agents/epuck/kernels.py:
brain_tick``). :func:`run_ticks` makes the same three calls from one compiled function
(:func:`batch_tick`: a world's step, the next observation and the brains' step), without the
Python objects in between (Observation, Inbox, BrainOutput): at 100 robots that glue cost as much
as a third of the tick. The objects keep their state as the methods leave it, so that whatever runs
between the brains' step and the world's (seed 001's central system) sees the same brains and
world either way; the tests hold the two ways to the same trajectories, bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

from swarmloc.agents.epuck import kernels as agent_kernels
from swarmloc.agents.epuck.foraging import BrainOutput, ForagingBrain, Inbox, agent_rng
from swarmloc.agents.epuck.global_imitation import central_rng, imitate_brain
from swarmloc.deploy.scenario import Scenario
from swarmloc.world.epuck import kernels as world_kernels
from swarmloc.world.epuck.foraging import ForagingWorld, Observation


def inbox_from(observation: Observation, sent: BrainOutput | None, robot_ids: np.ndarray) -> Inbox:
    """Route the medium's deliveries to the receivers' inbox, with the senders' content."""
    d = observation.deliveries
    capacity = sent.messages.heard_ids.shape[1] if sent is not None else 0
    if sent is None or d.receiver.shape[0] == 0:
        return Inbox.empty(capacity)
    return Inbox(
        receiver=d.receiver,
        sender_id=robot_ids[d.sender],
        range_m=d.range_m,
        bearing_rad=d.bearing_rad,
        content=sent.messages,  # every robot's message; each delivery reads its sender's row
        content_row=d.sender,
    )


def swarm_brain(scenario: Scenario, robot_ids=None) -> ForagingBrain:
    """One brain holding the robots ``robot_ids`` (default: all) of a scenario, each with its own
    generator, exactly as each agent process builds its batch of one."""
    w = scenario.world
    ids = np.arange(w.robots) if robot_ids is None else np.asarray(robot_ids)
    return ForagingBrain(scenario.agent, w.body, ids, [agent_rng(w.seed, int(i)) for i in ids], w.tick_s)


@dataclass
class BatchResult:
    metrics: dict
    final_pose: np.ndarray
    pose_estimate: np.ndarray
    lost_count: np.ndarray
    #: Error (m) of the target estimate at each departure (:class:`DepartureErrors`), in order.
    departure_error_m: np.ndarray | None = None


class DepartureErrors:
    """A diagnostic of retrieval (issue 42): how far from the true area a robot is headed when it
    sets out for it.

    At every tick where a robot's target changes to an area (it left the other area, or was
    recruited, or turned round), the vector from its dead-reckoned pose to its estimate of the
    target, in its believed body frame, is laid at its true pose: the point it will drive to. The
    error is that point's distance to the true centre of the area (the estimate is where the
    ground sensor saw the area, inside its 0.1 m radius). Only for an arena of one tile (the
    tiled ES3 has many nests). Called between the brains' step and the world's, it reads the
    brains' targets and poses and the world's true poses of that tick."""

    def __init__(self, world: ForagingWorld, brain: ForagingBrain):
        self.world, self.brain = world, brain
        arena = world.config.arena
        self.goals_m = (None if arena.tile_robots else
                        np.array([arena.nest_centre_m, arena.prey_centre_m], float))
        self.previous = brain.target.copy()
        self.errors_m: list[float] = []

    def __call__(self) -> None:
        target = self.brain.target
        if self.goals_m is None or np.array_equal(target, self.previous):
            return
        for i in np.flatnonzero((target != self.previous) & (target >= 0)):
            g = int(target[i])
            est = self.brain.pose[i]
            rel = self.brain.goal_xy[i, g] - est[:2]
            true = self.world.pose[i]
            turn = true[2] - est[2]
            c, s = np.cos(turn), np.sin(turn)
            aim = true[:2] + np.array([c * rel[0] - s * rel[1], s * rel[0] + c * rel[1]])
            self.errors_m.append(float(np.hypot(*(aim - self.goals_m[g]))))
        self.previous[:] = target


def run_batch(scenario: Scenario) -> BatchResult:
    """Run one seeded replication to the end."""
    world = ForagingWorld(scenario.world)
    brain = swarm_brain(scenario)
    # seed 001's global imitation: a central system that knows the true poses, with its own noise
    central = central_rng(scenario.world.seed) if brain.strategy.central else None
    departures = DepartureErrors(world, brain)

    def between() -> None:  # after the brains' step, before the world's
        if central is not None:
            imitate_brain(brain, world.pose, central, scenario.world.medium)
        departures()

    run_ticks(world, brain, between)
    return BatchResult(world.metrics.summary(), world.pose.copy(), brain.pose.copy(), brain.lost_count,
                       np.array(departures.errors_m))


def run_ticks(world: ForagingWorld, brain: ForagingBrain, between: Callable[[], None] = lambda: None,
              compiled: bool = True) -> None:
    """Step ``world`` and ``brain`` (the whole swarm, robot ``i`` at index ``i``) to the world's
    end; ``between()`` runs at every tick after the brains' step and before the world's. With
    ``compiled``, in one compiled call per tick where the brain allows it (:class:`CompiledTicks`);
    else through the objects' methods, as the world-server and the agents do."""
    if compiled and CompiledTicks.usable(world, brain):
        ticks = CompiledTicks(world, brain)
        ticks.think()  # tick 0: observe, brains
        while True:
            between()
            if world.tick + 1 >= world.config.n_ticks:
                ticks.last_step()
                return
            ticks.step_and_think()  # this tick's world step, the next tick's observe and brains
    ids = brain.robot_ids
    sent: BrainOutput | None = None
    while not world.done:
        obs = world.observe()
        out = brain.step(obs.encoder_steps, obs.ir, obs.ground, inbox_from(obs, sent, ids))
        between()
        world.step(out.wheel_speed_steps_s, out.sending, out.on_path)
        sent = out


#: What :func:`batch_tick` did: all of it, the world's step only (a crowd: the caller resolves
#: the collisions), or the step but no observation (more neighbour pairs than room for them).
TICK_DONE, TICK_CROWD, TICK_NO_ROOM = 0, 1, 2


# numba keys a cached kernel by its own source file only: a kernel of another file it calls
# (world/epuck/kernels.py: step_tick, agents/epuck/kernels.py: brain_tick) can change without
# invalidating it: edit this file too when one does (issue 18 changed both), so that it recompiles.
@njit(cache=True, error_model="numpy")
def batch_tick(
    step_first,
    # world/epuck/kernels.py: step_tick's arguments (unused unless step_first)
    s_pose, s_cmd, s_alive, s_sending, s_on_path, s_params, s_discs, s_rng_fn, s_rng_state, s_math_fns,
    s_pair_ij, s_pair_f, s_snapshot, s_counts, s_pose_out, s_encoder_out, s_crossed_ij, s_crossed_f, s_tick,
    s_first_visit_tick, s_round_trips, s_stage, s_stage_codes, s_trig, s_trig_pose, s_per_robot, s_work_i,
    s_work_f, s_step_u,
    # world/epuck/kernels.py: observe_tick's arguments
    o_pose, o_params, o_cos_a, o_sin_a, o_offsets, o_discs, o_reflectance, o_rng_fn, o_rng_state, o_ir,
    o_ground, o_pair_ij, o_pair_f, o_pair_scratch, o_snapshot, o_counts, o_crossed_ij, o_crossed_f, o_alive,
    o_sender, o_receiver, o_range_m, o_bearing_rad, o_trig, o_trig_pose, o_noise_u,
    # agents/epuck/kernels.py: brain_tick's arguments but the percepts and the inbox's deliveries
    b_encoder_steps, b_tick,
    b_previous_pose, b_pose, b_frame_pose, b_robot_ids, b_known, b_goal_xy, b_goal_p_m, b_goal_cov, b_target,
    b_searching, b_search_left_m, b_lost_count, b_visit_ticks, b_turn_ticks, b_straight_ticks, b_turn_dir,
    b_heard_ids, b_heard_bearing_rad, b_heard_range_m, b_partner_ids, b_partner_until, b_encounter_acc, b_adopted,
    c_known, c_distance, c_angle, c_p, c_heard_ids, c_heard_bearing,
    b_params, b_settings, b_math_fns, b_rng_fn, b_rng_state, b_cos_ir, b_sin_ir, b_geometry, b_atan, b_need,
    b_n_need,
    b_cmd, b_known_out, b_distance, b_angle, b_p, b_heard_ids_out, b_heard_bearing_out, b_state, b_pose_out,
    b_on_path,
):
    """``world.step`` (if ``step_first``), ``world.observe`` then ``brain.step`` of the whole
    swarm (robot ``i`` at index ``i``, so a delivery's sender index is its id and its content
    row), in one call; returns ``TICK_*``."""
    if step_first and world_kernels.step_tick(
        s_pose, s_cmd, s_alive, s_sending, s_on_path, s_params, s_discs, s_rng_fn, s_rng_state, s_math_fns,
        s_pair_ij, s_pair_f, s_snapshot, s_counts, s_pose_out, s_encoder_out, s_crossed_ij, s_crossed_f, s_tick,
        s_first_visit_tick, s_round_trips, s_stage, s_stage_codes, s_trig, s_trig_pose, s_per_robot, s_work_i,
        s_work_f, s_step_u,
    ) < 0:
        return TICK_CROWD
    kept = world_kernels.observe_tick(
        o_pose, o_params, o_cos_a, o_sin_a, o_offsets, o_discs, o_reflectance, o_rng_fn, o_rng_state, o_ir,
        o_ground, o_pair_ij, o_pair_f, o_pair_scratch, o_snapshot, o_counts, o_crossed_ij, o_crossed_f, o_alive,
        o_sender, o_receiver, o_range_m, o_bearing_rad, o_trig, o_trig_pose, o_noise_u,
    )
    if kept < 0:
        return TICK_NO_ROOM
    sender = o_sender[:kept]
    agent_kernels.brain_tick(
        b_encoder_steps, o_ir, o_ground, b_tick,
        b_previous_pose, b_pose, b_frame_pose, b_robot_ids, b_known, b_goal_xy, b_goal_p_m, b_goal_cov, b_target,
        b_searching, b_search_left_m, b_lost_count, b_visit_ticks, b_turn_ticks, b_straight_ticks, b_turn_dir,
        b_heard_ids, b_heard_bearing_rad, b_heard_range_m, b_partner_ids, b_partner_until, b_encounter_acc, b_adopted,
        o_receiver[:kept], sender, o_range_m[:kept], o_bearing_rad[:kept], sender,
        c_known, c_distance, c_angle, c_p, c_heard_ids, c_heard_bearing,
        b_params, b_settings, b_math_fns, b_rng_fn, b_rng_state, b_cos_ir, b_sin_ir, b_geometry, b_atan, b_need,
        b_n_need,
        b_cmd, b_known_out, b_distance, b_angle, b_p, b_heard_ids_out, b_heard_bearing_out, b_state, b_pose_out,
        b_on_path,
    )
    return TICK_DONE


class CompiledTicks:
    """Drives :func:`batch_tick` for a world and the brain of its whole swarm, leaving both
    objects as their methods would: ``world.pose``, ``world.encoder_steps``, ``world.tick``, the
    metrics, ``brain.pose``, ``brain.pose_history``, ``brain.tick`` and the state arrays. The
    percepts, deliveries and the brains' answers stay in buffers of this object (two sets of
    answers: a tick reads the messages of the one before)."""

    def __init__(self, world: ForagingWorld, brain: ForagingBrain):
        if not self.usable(world, brain):
            raise ValueError("brain: the compiled ticks need a brain of the whole swarm, without covariances")
        self.world, self.brain = world, brain
        n, capacity = world.n_robots, world._crossed_ij.shape[1]
        self._percepts = (np.empty((n, 8)), np.empty((n, 3)), np.empty(capacity, np.int64),
                          np.empty(capacity, np.int64), np.empty(capacity), np.empty(capacity))
        self._answers = [brain._outputs(), brain._outputs()]  # this tick's, the last tick's
        brain._settings[agent_kernels.S_MOTORS] = 1

    @staticmethod
    def usable(world: ForagingWorld, brain: ForagingBrain) -> bool:
        """A brain of the whole swarm in index order, its odometry in the kernel (no SIKF
        covariances, which are numpy), driving its own wheels."""
        return (brain.goal_cov is None and brain._motors is None and brain.n == world.n_robots
                and bool(np.array_equal(brain.robot_ids, np.arange(brain.n))))

    def think(self) -> None:
        """``world.observe()`` and ``brain.step(...)`` of the current tick."""
        self._call(False)

    def step_and_think(self) -> None:
        """``world.step(...)`` with the brains' answer, then :meth:`think` for the next tick."""
        self._call(True)

    def last_step(self) -> None:
        """``world.step(...)`` with the brains' answer, the world's method."""
        answer = self._answers[1]  # the last think's
        self.world.step(answer[0], self.brain._sending, answer[9])

    def _call(self, step_first: bool) -> None:
        world, brain = self.world, self.brain
        answer, last = self._answers
        n = world._n
        if step_first:  # the world's state after it: as ForagingWorld.step leaves it
            pose, encoder = np.empty((n, 3)), np.empty((n, 2))
            step = world._step_args(last[0], brain._sending, last[9], pose, encoder)
        else:
            pose, encoder = world.pose, world.encoder_steps
            step = world._step_args(answer[0], brain._sending, answer[9], answer[8], encoder)  # unused
        new_pose = np.empty((n, 3))
        # the last tick's answer is read (its messages); this tick's is written
        status = batch_tick(
            step_first, *step, *world._observe_args(pose, *self._percepts), encoder, brain.tick + 1,
            *brain._tick_state(new_pose), *last[1:7], *brain._tick_constants(), *answer,
        )
        if step_first:
            world._finish_step(pose, encoder, world.tick + 1,
                               -1 if status == TICK_CROWD else int(world._counts[world_kernels.C_ON_PATH]), last[9])
        if status != TICK_DONE:
            if status == TICK_NO_ROOM:
                world._grow_pairs()
            self._call(False)
            return
        brain._commit_tick(new_pose)
        brain._heard_clear = not world._counts[world_kernels.C_DELIVERED]
        self._answers = [last, answer]
