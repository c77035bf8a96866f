"""Social odometry filters: NC, SGIKF and SGIFF, single and double (seed 000 §4, table 1).

A robot keeps, for each goal area (nest, prey), an estimated location and ``p``, the inverse of its
confidence: the distance travelled since it last left that area (seed 000 eq. 23). When it hears a
neighbour that knows the same goal it fuses the two estimates with a scalar gain ``g``:

- SGIKF: ``g = p_i / (p_i + p_j)`` (eq. 20), ``x_i <- (1-g) x_i + g x_j`` (eq. 21),
  ``p_i <- (1-g) p_i`` (eq. 22);
- SGIFF: ``g = 1 / (1 + exp(-beta (p_i - p_j)))`` (eq. 24, the Fermi rule of seed 001 eq. 8),
  ``x_i <- (1-g) x_i + g x_j`` (eq. 25), ``p_i <- (1-g) p_i + g p_j`` (eq. 26).

A robot that does not know a goal adopts the neighbour's estimate and confidence (eq. 14). "Single"
strategies fuse only the goal the robot is heading to, "double" ones both (seed 000 §6.1).

SSIKF/DSIKF are the SIKF of eq. 18-22, whose ``p`` is the spectral norm of the odometry
covariance (eq. 19) instead of the distance travelled: seed 001's "covariance knowledge"
comparison, where robots know their odometry error model.

GLOBAL and GLOBAL_RB are seed 001's global imitation, by the two means the paper names: no
messages over the 15 cm medium; each tick every robot takes the mean of the whole group's
estimates, carried exactly by a central system (GLOBAL) or by long-range boards with the medium's
range and bearing noise (GLOBAL_RB) (:mod:`swarmloc.agents.epuck.global_imitation`).

What ``p`` is after a fusion is where seed 000 contradicts itself: table 1 and eq. 13 keep the
fused ``p`` of eq. 22 / 26 and add the distance travelled to it ("fused", the default), eq. 23
defines the prior as the distance travelled since the robot left the area ("distance"): the
updates below return ``p`` either way (``AgentConfig.p_after_fusion`` quotes both texts).
:func:`sent_goals` is which goals a robot sends: all it knows, or, as seed 001 §4.2 reads, "its
estimated location of the last visited area" (``AgentConfig.sends``).

The neighbour's estimate arrives in the neighbour's body frame; :func:`transform_received` turns it
into the receiver's body frame from the range and the two bearings (eq. 27).

All functions are pure and work on arrays with a leading message axis.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from swarmloc.agents.epuck.fusion import FUSION_RULES
from swarmloc.registry import Registry


@dataclass(frozen=True)
class Strategy:
    """One social odometry strategy of seed 000 §6.1 (and seed 001 §5)."""

    name: str
    communicates: bool
    double: bool
    gain: str  # "none", "kalman", "fermi" or a registered fusion rule's name (fusion.py)
    #: What ``p`` (inverse confidence) is: "distance" travelled since the area (eq. 23, the
    #: SGI filters), or "covariance": the spectral norm of the odometry covariance propagated
    #: with eq. 9-11 (eq. 19, the SIKF; seed 001's "covariance knowledge").
    confidence: str = "distance"
    #: Seed 001's global imitation (:mod:`swarmloc.agents.epuck.global_imitation`): every robot takes
    #: the mean of the whole group's estimates each tick, shared by a central system that knows
    #: every robot's true pose ("system": exact transfer) or by range-and-bearing boards of
    #: unlimited range with the medium's noise ("boards"). Only the batch engine's world has the
    #: true poses either needs. None: the robots' own 15 cm medium.
    central: str | None = None


#: What the compiled brain implements (agents/epuck/kernels.py): a strategy combines these.
GAINS = ("none", "kalman", "fermi")
CONFIDENCES = ("distance", "covariance")
CENTRALS = (None, "system", "boards")


def check_strategy(name: str, strategy: Strategy) -> None:
    """Refuse, at registration, a strategy the engines could not run (ValueError naming the
    field and the valid values): ``Strategy(gain="ci")`` would otherwise register and then fail
    inside the first tick."""
    if not isinstance(strategy, Strategy):
        raise ValueError(  # noqa: TRY004 -- the registry's contract is ValueError
            f"expected a Strategy, got {type(strategy).__name__}")
    if strategy.name != name:
        raise ValueError(f"registered as {name!r} but named {strategy.name!r}")
    gains = (*GAINS, *FUSION_RULES.names())
    for field, value, valid in (("gain", strategy.gain, gains), ("confidence", strategy.confidence, CONFIDENCES),
                                ("central", strategy.central, CENTRALS)):
        if value not in valid:
            hint = (" or a fusion rule registered before the strategy (agents/epuck/fusion.py)"
                    if field == "gain" else "")
            raise ValueError(f"{field}: {value!r} is not one the compiled brain implements "
                             f"(valid: {', '.join(map(repr, valid))}{hint})")
    if strategy.communicates and strategy.gain == "none":
        raise ValueError("gain: a strategy that communicates needs a gain ('kalman', 'fermi' or a fusion rule)")


#: The registry of strategies, by the names the papers use. A strategy combines the built-in
#: gains and confidences that the compiled brain implements, or a registered fusion rule of the
#: user's as its gain (:func:`check_strategy` refuses others at registration; docs/extending.md).
STRATEGIES: Registry[Strategy] = Registry("strategy", check_strategy)
for _s in (
        Strategy("NC", communicates=False, double=False, gain="none"),
        Strategy("SSGIKF", communicates=True, double=False, gain="kalman"),
        Strategy("DSGIKF", communicates=True, double=True, gain="kalman"),
        Strategy("SSGIFF", communicates=True, double=False, gain="fermi"),
        Strategy("DSGIFF", communicates=True, double=True, gain="fermi"),
        Strategy("SSIKF", communicates=True, double=False, gain="kalman", confidence="covariance"),
        Strategy("DSIKF", communicates=True, double=True, gain="kalman", confidence="covariance"),
        Strategy("GLOBAL", communicates=False, double=False, gain="none", central="system"),
        Strategy("GLOBAL_RB", communicates=False, double=False, gain="none", central="boards"),
):
    STRATEGIES.register(_s)


def kalman_gain(p_own: np.ndarray, p_other: np.ndarray) -> np.ndarray:
    """Induced Kalman gain, seed 000 eq. 20. Two perfect estimates (p = 0 both) average."""
    total = p_own + p_other
    safe = np.where(total > 0.0, total, 1.0)
    return np.where(total > 0.0, p_own / safe, 0.5)


def fermi_gain(p_own: np.ndarray, p_other: np.ndarray, beta: float) -> np.ndarray:
    """Fermi pairwise-comparison gain, seed 000 eq. 24 (seed 001 eq. 8).

    ``p`` must be in the unit ``beta`` is expressed in (see ``AgentConfig.confidence_unit_m``).
    """
    z = np.clip(-beta * (p_own - p_other), -500.0, 500.0)
    return 1.0 / (1.0 + np.exp(z))


#: What ``p`` is after a fusion: "fused" (table 1, eq. 13 with eq. 22 / 26) or "distance" (eq. 23).
P_AFTER_FUSION = ("fused", "distance")


def _p_after(p_fused, p_own, p_after_fusion: str):
    if p_after_fusion == "fused":
        return p_fused
    if p_after_fusion == "distance":  # eq. 23: p_{k|k-1} = d_k, whatever the fusion did
        return np.array(p_own, float, copy=True)
    raise ValueError(f"p_after_fusion: expected one of {P_AFTER_FUSION}, got {p_after_fusion!r}")


def sgikf_update(x_own, p_own, x_other, p_other, p_after_fusion: str = "fused"):
    """SGIKF correction, seed 000 eq. 20-22. ``x`` are ``(M, 2)`` locations, ``p`` ``(M,)``.
    ``p_after_fusion="distance"``: ``p`` stays the distance travelled (eq. 23)."""
    g = kalman_gain(p_own, p_other)
    x_new = (1.0 - g)[:, None] * x_own + g[:, None] * x_other
    return x_new, _p_after((1.0 - g) * p_own, p_own, p_after_fusion)


def sgiff_update(x_own, p_own, x_other, p_other, beta: float, p_after_fusion: str = "fused"):
    """SGIFF correction, seed 000 eq. 24-26 (``p`` in the unit ``beta`` is expressed in).
    ``p_after_fusion="distance"``: ``p`` stays the distance travelled (eq. 23, §4.2.2)."""
    g = fermi_gain(p_own, p_other, beta)
    x_new = (1.0 - g)[:, None] * x_own + g[:, None] * x_other
    return x_new, _p_after((1.0 - g) * p_own + g * p_other, p_own, p_after_fusion)


def fuse(strategy: Strategy, beta: float, p_after_fusion: str = "fused") -> Callable:
    """The update function of a strategy, as ``f(x_own, p_own, x_other, p_other)``."""
    if strategy.gain == "kalman":
        return lambda x_own, p_own, x_other, p_other: sgikf_update(
            x_own, p_own, x_other, p_other, p_after_fusion
        )
    if strategy.gain == "fermi":
        return lambda x_own, p_own, x_other, p_other: sgiff_update(
            x_own, p_own, x_other, p_other, beta, p_after_fusion
        )
    if strategy.gain in FUSION_RULES:
        rule = FUSION_RULES[strategy.gain]

        def update(x_own, p_own, x_other, p_other):
            x_new, p_new = rule.update(x_own, p_own, x_other, p_other, beta)
            return x_new, _p_after(p_new, p_own, p_after_fusion)

        return update
    raise ValueError(f"strategy {strategy.name} does not fuse estimates")


#: Which goals a robot sends: "both" it knows (seed 000 §4.1), or "last-visited" (seed 001 §4.2).
SENDS = ("both", "last-visited")


def sent_goals(known: np.ndarray, target: np.ndarray, sends: str = "both") -> np.ndarray:
    """Which goals each robot's message carries, ``(N, 2)`` bool, from what it knows ``(N, 2)``
    and its target ``(N,)`` (0 nest, 1 prey, -1 none). "last-visited": seed 001 §4.2, "it
    transmits its estimated location of the last visited area": a robot heading for a goal
    sends the other one, the area it comes from; a robot without a target sends what it knows."""
    known = np.asarray(known, bool)
    if sends == "both":
        return known.copy()
    if sends != "last-visited":
        raise ValueError(f"sends: expected one of {SENDS}, got {sends!r}")
    target = np.asarray(target)
    heading = np.arange(2)[None, :] == target[:, None]
    return known & ~heading


#: How a receiver combines the messages of one encounter (``AgentConfig.encounter_combine``).
COMBINE = ("mean", "each")


def encounter_estimate(points_m: np.ndarray, p_m: np.ndarray) -> tuple[np.ndarray, float]:
    """What one encounter of several messages gives a receiver that combines them by their mean
    (issue 42; seed 000 §6.2: the communication layer "repeat[s] some messages"): the mean of
    the partner's estimates, each transformed with eq. 27 from its own crossing, ``(M, 2)``, and
    the mean of the ``p`` they carried, ``(M,)``. The receiver then fuses that one estimate with
    its filter (eq. 14-16), as it would a single message."""
    points_m = np.asarray(points_m, float)
    p_m = np.asarray(p_m, float)
    if points_m.ndim != 2 or points_m.shape[0] == 0 or points_m.shape[0] != p_m.shape[0]:
        raise ValueError("encounter_estimate: need M >= 1 points (M, 2) and M values of p")
    return points_m.mean(axis=0), float(p_m.mean())


def transform_received(
    range_m: np.ndarray,
    bearing_receiver_rad: np.ndarray,
    bearing_sender_rad: np.ndarray,
    goal_distance_m: np.ndarray,
    goal_angle_rad: np.ndarray,
) -> np.ndarray:
    """A goal seen by the sender, expressed in the receiver's body frame (seed 000 eq. 27).

    - ``range_m``: lambda^ij, the range the receiver's board measured;
    - ``bearing_receiver_rad``: gamma^j, the bearing of the sender measured by the receiver;
    - ``bearing_sender_rad``: gamma^i, the bearing of the receiver measured by the sender;
    - ``goal_distance_m``, ``goal_angle_rad``: dy^i and phi^i, the goal in the sender's frame.

    The sender's direction relative to the communication beam is ``alpha = phi^i - gamma^i``; the
    receiver turns it into ``phi^j = gamma^j + alpha - pi`` and adds the two vectors (eq. 27).
    Returns ``(M, 2)`` points.
    """
    alpha = goal_angle_rad - bearing_sender_rad
    phi_j = bearing_receiver_rad + alpha - np.pi
    out = np.empty((np.shape(range_m)[0], 2))
    out[:, 0] = range_m * np.cos(bearing_receiver_rad) + goal_distance_m * np.cos(phi_j)
    out[:, 1] = range_m * np.sin(bearing_receiver_rad) + goal_distance_m * np.sin(phi_j)
    return out
