"""Compiled (numba) kernels of the foraging brain (``agents/epuck/foraging.py``), over a batch of robots.

:class:`swarmloc.agents.epuck.foraging.ForagingBrain` calls them, so an agent process (a batch of one)
and the batch engine (the whole swarm) run exactly this code. Each kernel evaluates the same
floating-point expressions, in the same order, as the numpy formulation it replaced, so seeded
runs are bit-identical to it (``benchmarks/fingerprint.py``):

- :func:`odometry`: dead reckoning of the encoder counts, seed 000 eq. 3-7, and ``p`` as the
  distance travelled, eq. 23;
- :func:`brain_update`: ground classification, goal storing on arrival, the lost rule,
  social odometry fusion of what neighbours sent (eq. 14-16, 20-22, 24-27) and the table of
  neighbours heard;
- :func:`goal_vectors`, :func:`wander_draws`, :func:`motor_commands`: the forage / wander /
  avoid layers (§5);
- :func:`report_into`, :func:`state_codes`: what a robot sends and reports;
- :func:`brain_tick`: all of that for one tick in one call (:func:`act_tick`: the part after
  the goal vectors' angles). numba checks the type of every argument of every call and boxes
  every array it returns, which for a swarm of 100 costs as much as the work: so the brain
  makes one call per tick, with preallocated outputs and its constants packed in two arrays.

Exactness, as in ``world/epuck/kernels.py``:

- each robot's random walk draws from its own ``numpy.random.Generator``, through the
  ``next_double`` function of its bit generator (:func:`~swarmloc.numerics.generator_address`): the very function
  ``Generator.random`` calls, so the numbers and the generator's state are numpy's;
- ``arctan2`` and ``exp``: numpy evaluates them with its own SIMD routines on this hardware, which
  differ from the C library's in the last bit; :func:`~swarmloc.numerics.np_arctan2` and :func:`~swarmloc.numerics.np_exp` call those
  very routines (:func:`~swarmloc.numerics.numpy_math` finds them and checks them against numpy once per process),
  else the C library's if it agrees with numpy here, else numpy itself from the kernel;
  ``sin``, ``cos``, ``hypot`` and ``sqrt`` agree bit for bit and are used as they are.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarmloc.numerics import (
    M_CONFIDENCE,
    M_GAIN,
    call_f64_3,
    call_f64_4,
    call_next_double,
    np_arctan2,
    np_exp,
)
from swarmloc.numerics import wrap as _wrap

_PI = math.pi
_TWO_PI = 2.0 * math.pi

#: Goal indices and "no target".
NEST, PREY, NONE = 0, 1, -1
#: Gains of :func:`brain_update`; GAIN_CUSTOM: a registered fusion rule of the user's
#: (``agents/epuck/fusion.py``), called through the addresses in ``math_fns[M_GAIN]`` and
#: ``math_fns[M_CONFIDENCE]``.
GAIN_NONE, GAIN_KALMAN, GAIN_FERMI, GAIN_CUSTOM = 0, 1, 2, 3
#: Who waits while an encounter collects messages (:func:`motor_commands`).
STOP_NONE, STOP_WANDERING, STOP_ALL = 0, 1, 2


@njit(cache=True, inline="always", error_model="numpy")
def _clip(value, lo, hi):
    v = max(lo, value)
    return min(hi, v)


@njit(cache=True, inline="always", error_model="numpy")
def _f32(value):
    """Round to the float32 a value crosses the wire with."""
    return np.float64(np.float32(value))


@njit(cache=True, error_model="numpy")
def odometry(pose, encoder_steps, metres_per_step, wheelbase_m, search_left_m, goal_p_m, add_p, out):
    """Dead-reckoned poses ``out`` after one tick of encoder counts from ``pose``;
    ``search_left_m`` and, if ``add_p``, ``goal_p_m`` (eq. 23) decrease / grow by the distance
    travelled, in place."""
    n = pose.shape[0]
    for i in range(n):
        du_left = encoder_steps[i, 0] * metres_per_step
        du_right = encoder_steps[i, 1] * metres_per_step
        d_theta = (du_right - du_left) / wheelbase_m
        d_rho = (du_right + du_left) / 2.0
        zeta = pose[i, 2] + d_theta / 2.0
        out[i, 0] = pose[i, 0] + d_rho * math.cos(zeta)
        out[i, 1] = pose[i, 1] + d_rho * math.sin(zeta)
        out[i, 2] = _wrap(pose[i, 2] + d_theta)
        travelled = abs(du_left + du_right) / 2.0
        search_left_m[i] -= travelled
        if add_p:
            goal_p_m[i, 0] += travelled
            goal_p_m[i, 1] += travelled


@njit(cache=True, error_model="numpy")
def classify_ground(ground, black_below, grey_below):
    """-1 floor, NEST (any sensor black) or PREY (any sensor grey), per robot."""
    n = ground.shape[0]
    out = np.empty(n, np.int64)
    for i in range(n):
        black = False
        grey = False
        for g in range(ground.shape[1]):
            v = ground[i, g]
            if v < black_below:
                black = True
            elif v < grey_below:
                grey = True
        out[i] = NEST if black else (PREY if grey else NONE)
    return out


#: Slots of an encounter's record, ``encounter_acc[robot, partner slot]``: per goal the sums of
#: the partner's estimates (x, y in the receiver's odometric frame) and ``p`` and how many
#: messages carried it (4 slots a goal), then the messages received so far (0: no encounter
#: collecting) and the tick the encounter began.
E_MESSAGES, E_START, N_ENCOUNTER = 8, 9, 10


@njit(cache=True, inline="always", error_model="numpy")
def _receive_goal(rec, goal, x_other, y_other, p_other, known, goal_xy, goal_p_m, goal_cov, use_cov, target,
                  adopted, double, gain, beta, confidence_unit_m, math_fns, p_is_distance):
    """Robot ``rec`` receives a neighbour's estimate of ``goal`` (in its own odometric frame):
    eq. 14 if it does not know the goal, else eq. 15-16 with the strategy's gain (eq. 20-22,
    24-26); single strategies fuse only the goal they head to."""
    if not known[rec, goal]:
        # eq. 14: a robot that does not know the goal takes the neighbour's estimate
        goal_xy[rec, goal, 0] = x_other
        goal_xy[rec, goal, 1] = y_other
        goal_p_m[rec, goal] = p_other
        if use_cov:
            goal_cov[rec, goal] = 0.0
            goal_cov[rec, goal, 0, 0] = p_other * 1.0
            goal_cov[rec, goal, 1, 1] = p_other * 1.0
        known[rec, goal] = True
        adopted[rec, goal] = True
        return
    # eq. 15-16: both know it; single strategies fuse only the goal they head to
    if not (double or target[rec] == goal):
        return
    p_own = goal_p_m[rec, goal] / confidence_unit_m
    p_oth = p_other / confidence_unit_m
    if gain == GAIN_KALMAN:  # eq. 20-22
        total = p_own + p_oth
        g = p_own / total if total > 0.0 else 0.5
        p_new = (1.0 - g) * p_own
    elif gain == GAIN_CUSTOM:  # a user's rule (fusion.py): g, then p after the fusion
        g = call_f64_3(math_fns[M_GAIN], p_own, p_oth, beta)
        p_new = call_f64_4(math_fns[M_CONFIDENCE], p_own, p_oth, g, beta)
    else:  # eq. 24-26, the Fermi rule, with numpy's exp
        g = 1.0 / (1.0 + np_exp(_clip(-beta * (p_own - p_oth), -500.0, 500.0), math_fns))
        p_new = (1.0 - g) * p_own + g * p_oth
    if use_cov:  # eq. 22 on the whole matrix: P <- (1 - g) P
        scale = p_new / p_own if p_own > 0.0 else 0.0
        for r in range(3):
            for c in range(3):
                goal_cov[rec, goal, r, c] *= scale
    goal_xy[rec, goal, 0] = (1.0 - g) * goal_xy[rec, goal, 0] + g * x_other
    goal_xy[rec, goal, 1] = (1.0 - g) * goal_xy[rec, goal, 1] + g * y_other
    if use_cov or not p_is_distance:  # eq. 22 / 26 (table 1); else p stays d_k, eq. 23
        goal_p_m[rec, goal] = p_new * confidence_unit_m


@njit(cache=True, error_model="numpy")
def _end_encounter(rec, slot, tick, gap_ticks, combine_each, encounter_acc, partner_until, known, goal_xy,
                   goal_p_m, goal_cov, use_cov, target, adopted, double, gain, beta, confidence_unit_m, math_fns,
                   p_is_distance):
    """The end of robot ``rec``'s encounter in partner slot ``slot``: unless each message was
    fused as it came (``combine_each``), the mean of the collected estimates and ``p`` of each
    goal is received once (:func:`_receive_goal`); the partner is then ignored for ``gap_ticks``."""
    if not combine_each:
        for goal in range(2):
            base = 4 * goal
            count = encounter_acc[rec, slot, base + 3]
            if count > 0.0:
                _receive_goal(rec, goal, encounter_acc[rec, slot, base] / count,
                              encounter_acc[rec, slot, base + 1] / count, encounter_acc[rec, slot, base + 2] / count,
                              known, goal_xy, goal_p_m, goal_cov, use_cov, target, adopted, double, gain, beta,
                              confidence_unit_m, math_fns, p_is_distance)
    encounter_acc[rec, slot, E_MESSAGES] = 0.0
    partner_until[rec, slot] = tick + gap_ticks


@njit(cache=True, error_model="numpy")
def brain_update(
    # odometry first (else done by the caller): encoder counts from the previous pose into pose
    do_odometry, encoder_steps, previous_pose, metres_per_step, wheelbase_m,
    # state, updated in place
    pose, frame_pose, robot_ids, known, goal_xy, goal_p_m, goal_cov, use_cov, target, searching,
    search_left_m, lost_count, visit_ticks, turn_ticks, straight_ticks, heard_ids, heard_bearing_rad, heard_range_m,
    partner_ids, partner_until, encounter_acc, adopted,
    # this tick's percepts
    ground, black_below, grey_below, ground_ahead_m, tick,
    # inbox, sorted by (receiver, sender); content row of each message
    receiver, sender_id, range_m, bearing_rad, content_row, c_known, c_distance, c_angle, c_p,
    c_heard_ids, c_heard_bearing,
    # strategy; numpy's exp for the Fermi gain (see numpy_math)
    communicates, double, gain, beta, confidence_unit_m, gap_ticks, math_fns,
    # readings of the seeds (AgentConfig.p_after_fusion, give_up_factor): keep p = distance
    # travelled after a fusion (eq. 23), the travel budget towards a target (0: none)
    p_is_distance, give_up_factor,
    # the communication process of an encounter (AgentConfig.encounter_messages, _combine,
    # _window_s): messages combined per encounter, fuse each (else their mean), longest collection
    n_messages, combine_each, window_ticks,
    # outputs for the motor and send layers: goal vectors (2, N, 3) and who draws a new walk
    geometry, need, n_need,
):
    """Odometry, arrive, lost, receive (fusion) and remember-heard layers for one tick, then the
    vectors the motor and send layers need (:func:`goal_vectors`)."""
    n = pose.shape[0]
    m_total = receiver.shape[0]
    if do_odometry:
        odometry(previous_pose, encoder_steps, metres_per_step, wheelbase_m, search_left_m,
                 goal_p_m, True, pose)
    area = classify_ground(ground, black_below, grey_below)
    # -- arrive: store goal locations seen by the ground sensors, switch target
    for i in range(n):
        a = area[i]
        for goal in range(2):
            if a != goal:
                visit_ticks[i, goal] = 0
                continue
            entering = visit_ticks[i, goal] == 0
            count = visit_ticks[i, goal] + 1
            visit_ticks[i, goal] = count
            sx = pose[i, 0] + ground_ahead_m * math.cos(pose[i, 2])
            sy = pose[i, 1] + ground_ahead_m * math.sin(pose[i, 2])
            px = sx if entering else goal_xy[i, goal, 0]
            py = sy if entering else goal_xy[i, goal, 1]
            goal_xy[i, goal, 0] = px + (sx - px) / count
            goal_xy[i, goal, 1] = py + (sy - py) / count
            known[i, goal] = True
            goal_p_m[i, goal] = 0.0
            if use_cov:
                goal_cov[i, goal] = 0.0
            if target[i] == goal or target[i] < 0:
                other = 1 - goal
                target[i] = other if known[i, other] else NONE
                searching[i] = False
                if give_up_factor > 0.0 and target[i] >= 0:
                    search_left_m[i] = give_up_factor * math.hypot(
                        goal_xy[i, other, 0] - pose[i, 0], goal_xy[i, other, 1] - pose[i, 1])
    # -- lost: arrived where the goal should be, and it is not there; or (give_up_factor > 0)
    # travelled its budget towards the target without arriving near the estimate
    for i in range(n):
        gave_up = give_up_factor > 0.0 and target[i] >= 0 and not searching[i] and search_left_m[i] <= 0.0
        if (searching[i] or gave_up) and search_left_m[i] <= 0.0 and area[i] != target[i]:
            known[i, 0] = False
            known[i, 1] = False
            goal_p_m[i, 0] = 0.0
            goal_p_m[i, 1] = 0.0
            if use_cov:
                goal_cov[i] = 0.0
            target[i] = NONE
            searching[i] = False
            lost_count[i] += 1
    adopted[:] = False

    # -- receive: messages in (receiver, sender) order = the rank order of each receiver
    if communicates:
        n_heard = heard_ids.shape[1]
        n_partner = partner_ids.shape[1]
        for m in range(m_total):
            rec = receiver[m]
            row = content_row[m]
            sender = sender_id[m]
            theirs = -1
            for k in range(c_heard_ids.shape[1]):
                if c_heard_ids[row, k] == robot_ids[rec]:
                    theirs = k
                    break
            ours = -1
            for k in range(n_heard):
                if heard_ids[rec, k] == sender:
                    ours = k
                    break
            if theirs < 0 or ours < 0:
                continue
            # One exchange per encounter: a recent partner still around is ignored (n_messages
            # 1); else the encounter collects up to n_messages of the partner's messages.
            recent = -1
            for k in range(n_partner):
                if partner_ids[rec, k] == sender and partner_until[rec, k] > tick:
                    recent = k
                    break
            if n_messages > 1 and recent >= 0 and encounter_acc[rec, recent, E_MESSAGES] == 0.0:
                partner_until[rec, recent] = tick + gap_ticks  # this encounter's exchange is done
                continue
            slot = recent
            if slot < 0:
                slot = 0
                for k in range(1, n_partner):
                    if partner_until[rec, k] < partner_until[rec, slot]:
                        slot = k
            partner_ids[rec, slot] = sender
            if n_messages <= 1:
                partner_until[rec, slot] = tick + gap_ticks
                if recent >= 0:
                    continue
            elif recent < 0:  # a new encounter: collect until n_messages or the window's end
                partner_until[rec, slot] = tick + window_ticks + gap_ticks
                for q in range(N_ENCOUNTER):
                    encounter_acc[rec, slot, q] = 0.0
                encounter_acc[rec, slot, E_START] = tick
            gamma_sender = c_heard_bearing[row, theirs]
            gamma_own = heard_bearing_rad[rec, ours]
            range_own = heard_range_m[rec, ours]
            cos_t = math.cos(frame_pose[rec, 2])
            sin_t = math.sin(frame_pose[rec, 2])
            for goal in range(2):
                if not c_known[row, goal]:
                    continue
                # eq. 27: the neighbour's goal in our body frame (of the crossing), then ours
                alpha = c_angle[row, goal] - gamma_sender
                phi_j = gamma_own + alpha - _PI
                d = c_distance[row, goal]
                lx = range_own * math.cos(gamma_own) + d * math.cos(phi_j)
                ly = range_own * math.sin(gamma_own) + d * math.sin(phi_j)
                x_other = frame_pose[rec, 0] + (cos_t * lx - sin_t * ly)
                y_other = frame_pose[rec, 1] + (sin_t * lx + cos_t * ly)
                p_other = c_p[row, goal]
                if n_messages > 1 and not combine_each:  # the mean of the encounter's messages
                    base = 4 * goal
                    encounter_acc[rec, slot, base] += x_other
                    encounter_acc[rec, slot, base + 1] += y_other
                    encounter_acc[rec, slot, base + 2] += p_other
                    encounter_acc[rec, slot, base + 3] += 1.0
                    continue
                _receive_goal(rec, goal, x_other, y_other, p_other, known, goal_xy, goal_p_m, goal_cov, use_cov,
                              target, adopted, double, gain, beta, confidence_unit_m, math_fns, p_is_distance)
            if n_messages > 1:
                encounter_acc[rec, slot, E_MESSAGES] += 1.0
                if encounter_acc[rec, slot, E_MESSAGES] >= n_messages:
                    _end_encounter(rec, slot, tick, gap_ticks, combine_each, encounter_acc, partner_until,
                                   known, goal_xy, goal_p_m, goal_cov, use_cov, target, adopted, double, gain,
                                   beta, confidence_unit_m, math_fns, p_is_distance)
        # Encounters whose window ended before n_messages crossed fuse what they collected.
        if n_messages > 1:
            for i in range(n):
                for k in range(n_partner):
                    if encounter_acc[i, k, E_MESSAGES] > 0.0 and tick - encounter_acc[i, k, E_START] >= window_ticks:
                        _end_encounter(i, k, tick, gap_ticks, combine_each, encounter_acc, partner_until,
                                       known, goal_xy, goal_p_m, goal_cov, use_cov, target, adopted, double, gain,
                                       beta, confidence_unit_m, math_fns, p_is_distance)

        # A wandering robot recruited to a goal heads for it (seed 000 §6.1.1); of two, the nearer.
        for i in range(n):
            if target[i] >= 0 or not (adopted[i, 0] or adopted[i, 1]):
                continue
            best = -1
            best_d = np.inf
            for goal in range(2):
                dx = goal_xy[i, goal, 0] - pose[i, 0]
                dy = goal_xy[i, goal, 1] - pose[i, 1]
                d = math.sqrt(dx * dx + dy * dy) if adopted[i, goal] else np.inf
                if best < 0 or d < best_d:
                    best, best_d = goal, d
            target[i] = best
            searching[i] = False
            if give_up_factor > 0.0:
                search_left_m[i] = give_up_factor * best_d

    # -- remember the nearest neighbours heard this tick: (range, sender id) order
    heard_ids[:] = -1
    heard_bearing_rad[:] = 0.0
    heard_range_m[:] = 0.0
    cap = heard_ids.shape[1]
    if cap > 0:
        lo = 0
        while lo < m_total:
            hi = lo
            while hi < m_total and receiver[hi] == receiver[lo]:
                hi += 1
            rec = receiver[lo]
            filled = 0
            for q in range(lo, hi):
                # insertion into the sorted table of this receiver, dropping what falls off
                pos = filled
                while pos > 0 and (
                    range_m[q] < heard_range_m[rec, pos - 1]
                    or (range_m[q] == heard_range_m[rec, pos - 1] and sender_id[q] < heard_ids[rec, pos - 1])
                ):
                    pos -= 1
                if pos >= cap:
                    continue
                last = min(filled, cap - 1)
                for k in range(last, pos, -1):
                    heard_ids[rec, k] = heard_ids[rec, k - 1]
                    heard_range_m[rec, k] = heard_range_m[rec, k - 1]
                    heard_bearing_rad[rec, k] = heard_bearing_rad[rec, k - 1]
                heard_ids[rec, pos] = sender_id[q]
                heard_range_m[rec, pos] = range_m[q]
                heard_bearing_rad[rec, pos] = _f32(bearing_rad[q])
                if filled < cap:
                    filled += 1
            lo = hi
    n_need[0] = goal_vectors(pose, previous_pose, goal_xy, target, turn_ticks, straight_ticks, geometry, need)


@njit(cache=True, error_model="numpy")
def goal_vectors(pose, frame_pose, goal_xy, target, turn_ticks, straight_ticks, geometry, need):
    """Vectors the motor and send layers turn into angles (with numpy's ``arctan2``), x
    components in ``geometry[0]``, y in ``geometry[1]``, each ``(N, 3)``: column 0 from robot
    ``i`` to its target's estimate (goal 0 for robots without one), column ``1 + g`` from its pose
    ``frame_pose`` to goal ``g``. Writes the wandering robots
    that start a new random-walk segment this tick into ``need``; returns how many."""
    n = pose.shape[0]
    n_need = 0
    for i in range(n):
        g = max(0, target[i])
        geometry[0, i, 0] = goal_xy[i, g, 0] - pose[i, 0]
        geometry[1, i, 0] = goal_xy[i, g, 1] - pose[i, 1]
        for g in range(2):
            geometry[0, i, 1 + g] = goal_xy[i, g, 0] - frame_pose[i, 0]
            geometry[1, i, 1 + g] = goal_xy[i, g, 1] - frame_pose[i, 1]
        if target[i] < 0 and turn_ticks[i] <= 0 and straight_ticks[i] <= 0:
            need[n_need] = i
            n_need += 1
    return n_need


@njit(cache=True, error_model="numpy")
def motor_commands(
    pose, target, searching, search_left_m, turn_ticks, straight_ticks, turn_dir, geometry,
    atan, ir, cos_ir, sin_ir, cruise, spin, steering_gain, turn_in_place_rad,
    arrival_tolerance_m, search_overshoot_m, avoid_threshold, vmax, encounter_acc, stop_mode, cmd,
):
    """Wheel speeds ``cmd`` ``(N, 2)`` of the forage, wander and avoid layers (seed 000 §5).

    A robot whose encounter is collecting messages waits, wheels still, if ``stop_mode`` says
    so (:data:`STOP_WANDERING`: robots without a target, :data:`STOP_ALL`: every robot;
    ``AgentConfig.encounter_stop``); its random walk is frozen meanwhile, and avoid still
    subsumes it."""
    n = pose.shape[0]
    half_pi = _PI / 2
    for i in range(n):
        err = 0.0
        in_place = False
        spin_dir = 0.0
        waiting = False
        if stop_mode != STOP_NONE and (stop_mode == STOP_ALL or target[i] < 0):
            for k in range(encounter_acc.shape[1]):
                if encounter_acc[i, k, E_MESSAGES] > 0.0:
                    waiting = True
                    break
        if waiting:
            pass
        elif target[i] >= 0:  # forage: steer to the target's estimate
            dist = math.hypot(geometry[0, i, 0], geometry[1, i, 0])
            if not searching[i] and dist < arrival_tolerance_m:
                searching[i] = True
                search_left_m[i] = search_overshoot_m
            if not searching[i]:
                err = _wrap(atan[i, 0] - pose[i, 2])
            in_place = abs(err) > turn_in_place_rad
            spin_dir = 1.0 if err > 0.0 else (-1.0 if err < 0.0 else 0.0)
        else:  # wander: random walk
            if turn_ticks[i] > 0:
                turn_ticks[i] -= 1
                spin_dir = turn_dir[i]
                in_place = True
            else:
                straight_ticks[i] -= 1
        steer = _clip(steering_gain * err, -1.0, 1.0)
        left = cruise * (1.0 - steer)
        right = cruise * (1.0 + steer)
        if in_place:
            left = -spin * spin_dir
            right = spin * spin_dir
        if waiting:
            left = 0.0
            right = 0.0
        # avoid: subsumes the layers below
        avoiding = False
        for k in range(ir.shape[1]):
            if ir[i, k] > avoid_threshold:
                avoiding = True
        if avoiding:
            vx = 0.0
            vy = 0.0
            for k in range(ir.shape[1]):
                vx += ir[i, k] * cos_ir[k]
                vy += ir[i, k] * sin_ir[k]
            obstacle = math.atan2(vy, vx)
            if abs(obstacle) < half_pi:
                away = -1.0 if obstacle > 0 else 1.0  # obstacle on the left: turn right
                left = -spin * away
                right = spin * away
            else:
                left = cruise
                right = cruise
        cmd[i, 0] = _clip(left, -vmax, vmax)
        cmd[i, 1] = _clip(right, -vmax, vmax)


@njit(cache=True, error_model="numpy")
def report_into(frame_pose, geometry, atan, known, goal_p_m, heard_ids, heard_bearing_rad, target, knows_both, pose,
                sends_last, known_out, distance, angle, p, heard_ids_out, heard_bearing_out, state, pose_out):
    """What the brains answer, into preallocated arrays: the fields of the messages they send,
    their state codes (:func:`state_codes`) and a copy of their poses.

    Messages: each goal in the body frame of ``frame_pose`` (vectors ``geometry[:, :, 1:]`` and their
    ``atan``, see :func:`goal_vectors`), float32-rounded, zero where unknown, and copies of the
    tables ``(known, distance_m, angle_rad, p_m, heard_ids, heard_bearing_rad)``, written for as
    many robots as they have rows (none for a strategy that does not communicate). If
    ``sends_last`` (``AgentConfig.sends = "last-visited"``), a robot with a target leaves it out:
    it sends only the area it comes from (seed 001 §4.2)."""
    for i in range(known_out.shape[0]):
        for g in range(2):
            sent = known[i, g] and not (sends_last and target[i] == g)
            known_out[i, g] = sent
            if sent:
                distance[i, g] = _f32(math.hypot(geometry[0, i, 1 + g], geometry[1, i, 1 + g]))
                angle[i, g] = _f32(_wrap(atan[i, 1 + g] - frame_pose[i, 2]))
                p[i, g] = _f32(goal_p_m[i, g])
            else:
                distance[i, g] = 0.0
                angle[i, g] = 0.0
                p[i, g] = 0.0
        for k in range(heard_ids.shape[1]):
            heard_ids_out[i, k] = heard_ids[i, k]
            heard_bearing_out[i, k] = heard_bearing_rad[i, k]
    state_codes_into(target, known, knows_both, state)
    pose_out[:] = pose


#: Slots of the brain's constants in the ``params`` of :func:`act_tick` (the motor layers) and
#: :func:`brain_tick` (all layers).
(A_CRUISE, A_SPIN, A_STEERING_GAIN, A_TURN_IN_PLACE, A_ARRIVAL_TOLERANCE, A_SEARCH_OVERSHOOT, A_AVOID_THRESHOLD,
 A_VMAX, A_TURN_LO, A_TURN_SPAN, A_STRAIGHT_LO, A_STRAIGHT_SPAN, A_SPIN_PER_TICK, A_TICK,
 U_METRES_PER_STEP, U_WHEELBASE, U_BLACK_BELOW, U_GREY_BELOW, U_GROUND_AHEAD, U_BETA, U_CONFIDENCE_UNIT,
 U_GIVE_UP_FACTOR, N_BRAIN_PARAMS) = range(23)
#: Slots of the brain's integer settings in :func:`brain_tick`'s ``settings``.
(S_DO_ODOMETRY, S_USE_COV, S_COMMUNICATES, S_DOUBLE, S_GAIN, S_GAP_TICKS, S_KNOWS_BOTH, S_MOTORS, S_P_IS_DISTANCE,
 S_SENDS_LAST, S_ENCOUNTER_MESSAGES, S_COMBINE_EACH, S_WINDOW_TICKS, S_STOP_MODE, N_SETTINGS) = range(15)


@njit(cache=True, error_model="numpy")
def wander_draws(need, n_need, rng_fn, rng_state, params, turn_ticks, turn_dir, straight_ticks):
    """Start a new random-walk segment for the robots ``need[:n_need]``: a turn in place by
    ``U(-pi, pi)``, then a straight run of ``U(lo, hi)`` seconds, from each robot's own generator
    (``rng_fn[i]``, ``rng_state[i]``: see :func:`~swarmloc.numerics.generator_address`), as its ``random(2)``
    would give them: ``low + (high - low) * u`` is how numpy's ``uniform`` computes them. Ticks
    are rounded half to even, as Python's ``round``."""
    for q in range(n_need):
        i = need[q]
        u0 = call_next_double(rng_fn[i], rng_state[i])
        u1 = call_next_double(rng_fn[i], rng_state[i])
        angle = params[A_TURN_LO] + params[A_TURN_SPAN] * u0
        straight_s = params[A_STRAIGHT_LO] + params[A_STRAIGHT_SPAN] * u1
        turn_ticks[i] = round(abs(angle) / params[A_SPIN_PER_TICK])
        turn_dir[i] = 1.0 if angle >= 0 else -1.0
        straight_ticks[i] = round(straight_s / params[A_TICK])


@njit(cache=True, error_model="numpy")
def act_tick(pose, target, searching, search_left_m, turn_ticks, straight_ticks, turn_dir, geometry, atan, ir,
             cos_ir, sin_ir, params, need, n_need, rng_fn, rng_state, frame_pose, known, goal_p_m, heard_ids,
             heard_bearing_rad, knows_both, sends_last, encounter_acc, stop_mode, cmd, known_out, distance, angle,
             p, heard_ids_out, heard_bearing_out, state, pose_out, on_path):
    """The brains' answer for one tick in one call: :func:`wander_draws` for the robots
    :func:`goal_vectors` put in ``need``, :func:`motor_commands` into ``cmd``,
    :func:`report_into` and ``on_path`` (a target and both goals known: state bits 0-1 and
    ``knows_both``, as ``protocol.epuck.on_path`` reads the state codes)."""
    wander_draws(need, n_need[0], rng_fn, rng_state, params, turn_ticks, turn_dir, straight_ticks)
    motor_commands(pose, target, searching, search_left_m, turn_ticks, straight_ticks, turn_dir, geometry, atan, ir,
                   cos_ir, sin_ir, params[A_CRUISE], params[A_SPIN], params[A_STEERING_GAIN],
                   params[A_TURN_IN_PLACE], params[A_ARRIVAL_TOLERANCE], params[A_SEARCH_OVERSHOOT],
                   params[A_AVOID_THRESHOLD], params[A_VMAX], encounter_acc, stop_mode, cmd)
    report_into(frame_pose, geometry, atan, known, goal_p_m, heard_ids, heard_bearing_rad, target, knows_both, pose,
                sends_last, known_out, distance, angle, p, heard_ids_out, heard_bearing_out, state, pose_out)
    for i in range(state.shape[0]):
        on_path[i] = (state[i] & 3) != 0 and (state[i] & knows_both) != 0


@njit(cache=True, error_model="numpy")
def brain_tick(
    # this tick's percepts and the tick number
    encoder_steps, ir, ground, tick,
    # state, updated in place (see ForagingBrain); pose is written, from previous_pose
    previous_pose, pose, frame_pose, robot_ids, known, goal_xy, goal_p_m, goal_cov, target, searching,
    search_left_m, lost_count, visit_ticks, turn_ticks, straight_ticks, turn_dir, heard_ids, heard_bearing_rad,
    heard_range_m, partner_ids, partner_until, encounter_acc, adopted,
    # inbox, sorted by (receiver, sender); content row of each message
    receiver, sender_id, range_m, bearing_rad, content_row, c_known, c_distance, c_angle, c_p, c_heard_ids,
    c_heard_bearing,
    # constants (slots A_*, U_* and S_*), numpy's math (numpy_math), each robot's generator
    params, settings, math_fns, rng_fn, rng_state, cos_ir, sin_ir,
    # scratch: goal vectors (2, N, 3), their angles (N, 3), robots drawing a new walk
    geometry, atan, need, n_need,
    # the answer (see act_tick)
    cmd, known_out, distance, angle, p, heard_ids_out, heard_bearing_out, state, pose_out, on_path,
):
    """One controller tick of every brain of the batch in one call: :func:`brain_update`, the
    angles of its goal vectors (numpy's ``arctan2``: :func:`~swarmloc.numerics.np_arctan2`), then :func:`act_tick`,
    or, if ``settings[S_MOTORS]`` is 0 (the caller drives the wheels itself), only the report
    (:func:`report_into`) and ``on_path``."""
    brain_update(
        settings[S_DO_ODOMETRY] != 0, encoder_steps, previous_pose, params[U_METRES_PER_STEP], params[U_WHEELBASE],
        pose, frame_pose, robot_ids, known, goal_xy, goal_p_m, goal_cov, settings[S_USE_COV] != 0, target, searching,
        search_left_m, lost_count, visit_ticks, turn_ticks, straight_ticks, heard_ids, heard_bearing_rad,
        heard_range_m, partner_ids, partner_until, encounter_acc, adopted,
        ground, params[U_BLACK_BELOW], params[U_GREY_BELOW], params[U_GROUND_AHEAD], tick,
        receiver, sender_id, range_m, bearing_rad, content_row, c_known, c_distance, c_angle, c_p, c_heard_ids,
        c_heard_bearing,
        settings[S_COMMUNICATES] != 0, settings[S_DOUBLE] != 0, settings[S_GAIN], params[U_BETA],
        params[U_CONFIDENCE_UNIT], settings[S_GAP_TICKS], math_fns,
        settings[S_P_IS_DISTANCE] != 0, params[U_GIVE_UP_FACTOR],
        settings[S_ENCOUNTER_MESSAGES], settings[S_COMBINE_EACH] != 0, settings[S_WINDOW_TICKS],
        geometry, need, n_need,
    )
    m = atan.shape[0] * atan.shape[1]
    np_arctan2(geometry[1].reshape(m), geometry[0].reshape(m), atan.reshape(m), math_fns)
    if settings[S_MOTORS] != 0:
        act_tick(pose, target, searching, search_left_m, turn_ticks, straight_ticks, turn_dir, geometry, atan, ir,
                 cos_ir, sin_ir, params, need, n_need, rng_fn, rng_state, previous_pose, known, goal_p_m, heard_ids,
                 heard_bearing_rad, settings[S_KNOWS_BOTH], settings[S_SENDS_LAST] != 0, encounter_acc,
                 settings[S_STOP_MODE], cmd, known_out, distance, angle, p, heard_ids_out, heard_bearing_out, state,
                 pose_out, on_path)
    else:
        knows_both = settings[S_KNOWS_BOTH]
        report_into(previous_pose, geometry, atan, known, goal_p_m, heard_ids, heard_bearing_rad, target, knows_both,
                    pose, settings[S_SENDS_LAST] != 0, known_out, distance, angle, p, heard_ids_out, heard_bearing_out,
                    state, pose_out)
        for i in range(state.shape[0]):
            on_path[i] = (state[i] & 3) != 0 and (state[i] & knows_both) != 0


@njit(cache=True, error_model="numpy")
def state_codes(target, known, knows_both):
    """Controller state codes: target + 1 (0 = none) in bits 0-1, ``knows_both`` if both known."""
    out = np.empty(target.shape[0], np.int64)
    state_codes_into(target, known, knows_both, out)
    return out


@njit(cache=True, error_model="numpy")
def state_codes_into(target, known, knows_both, out):
    for i in range(target.shape[0]):
        code = 0 if target[i] < 0 else target[i] + 1
        if known[i, 0] and known[i, 1]:
            code |= knows_both
        out[i] = code
