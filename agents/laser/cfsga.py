"""CFS-GA: the collaborative fitness-sharing genetic algorithm for multi-robot localization.

Seed ``003_5278cbbbf8cc61de.txt`` (Bori, Gasparri, Panzieri), §III-B, §IV and table I. Each robot
runs one population of ``m`` pose hypotheses ``p = (x_m, y_m, theta_rad)`` (§IV-A). One step:

1. **Kinematic update** (§IV-A): every individual is moved by the odometry ``(delta_s, delta_phi)``
   with the unicycle of eq. 3 of seed 002 (:func:`swarmloc.world.laser.laser.unicycle_model`), each
   with its own draw of the odometry noise the robot declares
   (``LocalizerSetup.speed_std_mps``/``turn_rate_std_rad_s`` times ``dt_s``; option
   ``motion_diffusion``, on by default) while the odometry reports a move; a robot whose
   odometry reports no move stood still and the update is exact. See "Readings" below.
2. **Raw fitness** (§IV-A): ``f = 1/L sum_i N(z^i - z^_i; 0, sigma)``, the mean over the ``L``
   beams of a Gaussian of the difference between the measured range and the one expected from the
   hypothesis (:class:`LaserFitness`, sigma = 0.5 m of table I). Poses outside the map get 0.
3. **Shared fitness** (§III-B): ``f_sh,i = f_i / n_i`` with the niche count
   ``n_i = sum_j sh(d_ij)`` over the population and the sharing function
   ``sh(d) = 1 - (d / sigma_s)^alpha`` if ``d < sigma_s`` else 0 (:func:`sharing_function`,
   :func:`niche_counts`); ``d_ij`` is the Euclidean distance between the positions, sigma_s is 5 %
   of the size of the environment (table I; we take the diagonal of the map bounds).
4. **Collaboration** (§IV-B): every robot broadcasts the individuals whose raw fitness is above the
   population average (:meth:`CFSGALocalizer.outgoing`, :func:`encode_individuals`). A receiver
   that sees the sender (a :class:`Sighting`: distance, bearing, relative heading) roto-translates
   them into hypotheses of its own pose, ``P_v = U_i R(P_b^(i), Delta(r_1, r_i))``
   (:func:`roto_translate`), counts the virtual niches ``n_v,i = sum_j sh(d_ij)`` over ``P_v``
   and strengthens ``f~_sh,i = f_sh,i * n_v,i``. A message from a teammate the robot does not see
   carries no relative pose and is ignored. A payload arrives one step after it was sent (the
   medium delivers at the next tick) while the sighting is of this step, so the virtual
   population lags by one step of the teammate's motion, small against sigma_s. Our choice where
   003 is silent: when no local individual lies within sigma_s of any virtual one (all
   ``n_v = 0``) the strengthening is skipped for that step, since it would cancel the selection
   pressure altogether.
5. **Evolution** (§IV-A, table I): the ``p_b`` = 80 % best individuals by raw fitness are kept
   (elitism); the other ``p_s`` = 20 % are replaced: ``p_r`` = 5 % of ``m`` by random individuals
   drawn over the free space, the rest by offspring of parents chosen by tournaments of size
   ``T`` = 2 over the (strengthened) shared fitness of the kept individuals (option
   ``parent_pool``, see "Readings" below). An offspring is, with probability
   ``p_c`` = 80 %, a crossover of its two parents (each gene a random convex combination of the
   parents' genes, the heading along the shorter arc), otherwise a copy of the first; then, with
   probability ``p_m`` = 10 %, a mutation (Gaussian perturbation of its genes).
6. **Best individual** (§IV-A): among the individuals whose raw fitness is known (the elites), the
   one that maximises raw fitness times the aging factor (a memory effect against the chattering
   of the best individual, which 003 names without a formula): individuals within sigma_s of the
   last estimate (moved since by the odometry) get ``min(1 + aging_rate * estimate_age,
   aging_max)``, the others 1. ``estimate_age`` counts the consecutive generations whose best
   individual stayed within sigma_s of the previous one; it restarts at 0 when the estimate moves
   to another niche, and when a teammate's virtual population supports some local individuals
   but none near the estimate (:meth:`FitnessSharingGA.aging_factors`,
   :meth:`FitnessSharingGA.hold_estimate`, :meth:`FitnessSharingGA.doubt_estimate`).

**Readings where 003 is silent, and why** (measured on the robustness runs of 003 §V with
``deploy/scenarios/laser/laser-robust-*.toml``, seeds not those of the report):

- *Kinematic update with noise.* 003 says only that the odometry is applied to the kinematic
  (unicycle) model; that model in the same group's GA (eq. 3 of 002) has a white-noise term. Without
  it every individual moves rigidly with the commanded odometry, the kept 80 % never change, and
  the population cannot follow the true heading's random walk (0.05 rad a step here, enough to
  cost 9 % of the raw fitness at the true position): with the earlier code, started on the true
  pose, 4 of 10 office runs lost the track; with diffusion none did (median error 6 cm).
- *Parents from the kept individuals.* 003 uses the raw fitness to split the population into the
  individuals preserved and those replaced, and builds the intermediate population by tournaments
  over the shared fitness, without saying over which individuals. Drawn over everyone, 21 % of the
  tournament winners were individuals that elitism discarded in the same generation (an isolated
  individual's niche count of about 1 makes up for its low raw fitness); we draw them from the
  kept ones (``parent_pool = "elites"``; ``"population"`` is the other reading).
- *Aging factor of the estimate's niche.* Our earlier formula aged individuals
  (``min(1 + 0.01 age, 1.1)``, ``age`` = generations survived); half of the kept individuals,
  and two thirds of the chosen best ones, were past the 10 generations at which it saturates, so
  it did not tell the hypothesis the estimate had held from any other survivor, and the estimate
  chattered between rooms of similar fitness. The factor now rewards staying in the niche of the
  last estimate. ``aging_max`` = 1.2: one step of unmodelled turn at twice the noise of table I
  (0.1 rad) costs a well-placed individual about 18 % of its raw fitness, so another niche must
  do better than that to take the estimate from one held for 20 generations (10 s here). 003
  §IV-B lets a teammate's suggestion "diminish the confidence of local hypothesis": without the
  reset on an unsupported estimate, a collaborating robot on the symmetric map kept an unsupported
  copy of its pose after the virtual niches had moved 284 of its 300 individuals to the true one.
  (A variant where the age also shrank by one for each generation the niche kept the estimate
  only thanks to its factor ended more three-rooms runs in an identical wrong room.)

Each of the three, taken out while the other two stay, raised the failure rate of 40 office runs
from 15 % to 20-30 % (the earlier version, with none of them: 60 % of 20 runs).

**The seam for other sensors.** The GA core, :class:`FitnessSharingGA`, knows nothing of lasers
or maps. It takes

- ``kinematic_update(delta_s_m, delta_phi_rad, ...)``: the odometry increments;
- ``evaluate(raw_fitness)``: ``raw_fitness`` is any callable ``poses (P, 3) -> (P,)`` of finite
  values ``>= 0``, built per step from that step's observation (here by :class:`LaserFitness`
  from a :class:`LaserObservation`; a landmark range-and-bearing fitness is another such
  callable);
- ``evolve(virtual_population)``: the virtual population ``(Q, 3)`` already roto-translated
  (:func:`virtual_population` builds it from decoded payloads and relative poses);
- a ``sample_poses(n, rng) -> (n, 3)`` callable for the random individuals and the initial
  population (:func:`map_sampler` for a map, :func:`box_sampler` for a bare rectangle).

:class:`CFSGALocalizer` is the :class:`~swarmloc.agents.laser.localizer.Localizer` that wires the core to
the laser robots: ``CFSGALocalizer(setup, params, rng)`` or
``CFSGALocalizer.from_config(setup, {...}, rng)``.

Radio payload (msgpack map, at most ``MAX_RADIO_PAYLOAD_BYTES``):
``{"v": 1, "t": "cfsga", "poses": <bin: Q x 3 little-endian float32>}``. :func:`decode_individuals`
rejects anything else with ``ValueError`` naming the field. A localizer never raises on a bad
payload inside :meth:`CFSGALocalizer.step`: it skips the message and lists it in
:attr:`CFSGALocalizer.rejected` (``(sender_id, error)`` of the last step) for the shell to count.

Wrong types in a config or a payload raise ``ValueError`` too (one error type for "bad input").

Random draws, in this order each step (so a run is a function of the generator's seed):
kinematic update ``normal((m, 2))`` (drawn even without diffusion); tournaments; crossover coin and weights; mutation coin and
perturbations; random individuals (``sample_poses``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, fields

import msgpack
import numpy as np

from swarmloc.agents.laser.localizer import (
    MAX_RADIO_PAYLOAD_BYTES,
    LaserObservation,
    LocalizerSetup,
    RadioMessage,
    Sighting,
    evenly_spaced,
)
from swarmloc.agents.laser.refine import check_refine_options, compass_search
from swarmloc.config import did_you_mean
from swarmloc.world.laser.laser import cast_rays, unicycle_model, wrap_angle
from swarmloc.world.laser.maps import SegmentMap, build_map, free_space_sample

RawFitness = Callable[[np.ndarray], np.ndarray]
PoseSampler = Callable[[int, np.random.Generator], np.ndarray]

PAYLOAD_VERSION = 1
PAYLOAD_TYPE = "cfsga"
#: Bytes of one individual on the wire: three float32.
_BYTES_PER_INDIVIDUAL = 12
#: msgpack overhead of the payload map around the pose bytes (generous upper bound).
_PAYLOAD_OVERHEAD_BYTES = 32
#: The most individuals one payload can carry within ``MAX_RADIO_PAYLOAD_BYTES``.
MAX_SHARED_INDIVIDUALS = (
    MAX_RADIO_PAYLOAD_BYTES - _PAYLOAD_OVERHEAD_BYTES
) // _BYTES_PER_INDIVIDUAL
#: Decoded coordinates beyond this are rejected (no map is that large).
_MAX_COORDINATE_M = 1e5
_HEADING_TOLERANCE_RAD = 1e-5
#: Poses x beams x 2 segments per ``cast_rays`` call of :class:`LaserFitness` (256 KB of float32;
#: measured: 300 x 18 rays on the office map cost 2.0 ms a step in blocks of this size, 4.7 ms in
#: blocks of 4 or 8 times it, the difference being system time).
_CAST_BLOCK_ELEMENTS = 1 << 16
#: Upper bound on elements of one (rows, Q) block of pairwise distances (256 KB in float32).
_PAIR_CHUNK_ELEMENTS = 1 << 16
#: Values of :attr:`CFSGAParams.parent_pool`.
PARENT_POOLS = ("elites", "population")


# --------------------------------------------------------------------------------------------
# Parameters
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CFSGAParams:
    """CFS-GA parameters; defaults from table I of seed 003 where it gives them."""

    #: m: population size.
    population_size: int = 300
    #: sigma: confidence of the pattern fitness, metres.
    confidence_std_m: float = 0.5
    #: p_b: fraction of the population kept by elitism (best raw fitness).
    elite_fraction: float = 0.80
    #: p_s: fraction replaced each generation (offspring + random); p_b + p_s = 1.
    selected_fraction: float = 0.20
    #: p_r: fraction of the population replaced by random individuals each generation.
    random_fraction: float = 0.05
    #: T: tournament size.
    tournament_size: int = 2
    #: p_c: crossover probability.
    crossover_probability: float = 0.80
    #: p_m: mutation probability.
    mutation_probability: float = 0.10
    #: sigma_s as a fraction of the size of the environment (the map bounds' diagonal).
    niche_radius_fraction: float = 0.05
    #: alpha: shape of the sharing function.
    sharing_alpha: float = 1.0
    #: Mutation: standard deviations of the Gaussian perturbation of position and heading (ours).
    mutation_std_m: float = 0.20
    mutation_std_rad: float = 0.10
    #: Aging factor ``min(1 + aging_rate * estimate_age, aging_max)`` of the individuals in the
    #: niche of the last estimate (ours; 003 gives no formula; see the module docstring).
    aging_rate: float = 0.01
    aging_max: float = 1.20
    #: Spread each individual by its own draw of the declared odometry noise while the robot
    #: moves (the noise term of the unicycle model, eq. 3 of 002; see the module docstring).
    motion_diffusion: bool = True
    #: Who enters the tournaments: ``"elites"`` (the individuals elitism keeps this generation)
    #: or ``"population"`` (everyone, also the ones it replaces). See the module docstring.
    parent_pool: str = "elites"
    #: Random individuals keep this far from walls (free_space_sample's clearance).
    random_clearance_m: float = 0.3
    #: At most this many above-average individuals per radio payload (the fittest first).
    max_shared_individuals: int = 1000
    #: Not in 003 (issue 43; 0: off, the paper's algorithm): compass-search iterations on this
    #: step's raw fitness from the ``refine_individuals`` fittest individuals, which replace them
    #: (:mod:`swarmloc.agents.laser.refine`), with initial steps ``refine_step_m``/``_rad``.
    refine_iterations: int = 0
    refine_individuals: int = 1
    refine_step_m: float = 0.05
    refine_step_rad: float = 0.02

    def __post_init__(self) -> None:
        check_refine_options(self.refine_iterations, self.refine_individuals,
                             self.refine_step_m, self.refine_step_rad)
        _require_int(self.population_size, "population_size", 2, 1_000_000)
        _require_int(self.tournament_size, "tournament_size", 1, self.population_size)
        _require_int(
            self.max_shared_individuals, "max_shared_individuals", 0, MAX_SHARED_INDIVIDUALS
        )
        for name in ("confidence_std_m", "sharing_alpha", "niche_radius_fraction"):
            _require_real(getattr(self, name), name, positive=True)
        for name in ("mutation_std_m", "mutation_std_rad", "aging_rate", "random_clearance_m"):
            _require_real(getattr(self, name), name)
        for name in (
            "elite_fraction",
            "selected_fraction",
            "random_fraction",
            "crossover_probability",
            "mutation_probability",
        ):
            _require_real(getattr(self, name), name, upper=1.0)
        _require_real(self.aging_max, "aging_max")
        if self.aging_max < 1.0:
            raise ValueError(f"aging_max: must be >= 1, got {self.aging_max!r}")
        if not isinstance(self.motion_diffusion, bool):
            msg = f"motion_diffusion: must be true or false, got {self.motion_diffusion!r}"
            raise ValueError(msg)  # noqa: TRY004
        if self.parent_pool not in PARENT_POOLS:
            raise ValueError(
                f"parent_pool: must be one of {', '.join(map(repr, PARENT_POOLS))}, "
                f"got {self.parent_pool!r}"
            )
        if abs(self.elite_fraction + self.selected_fraction - 1.0) > 1e-9:
            raise ValueError(
                "elite_fraction + selected_fraction: must add up to 1 (p_b + p_s of table I), got "
                f"{self.elite_fraction!r} + {self.selected_fraction!r}"
            )
        if self.random_fraction > self.selected_fraction + 1e-12:
            raise ValueError(
                f"random_fraction: must be <= selected_fraction ({self.selected_fraction!r}), "
                f"got {self.random_fraction!r}"
            )
        if self.n_elite < 1:
            raise ValueError(
                f"elite_fraction: keeps no individual of a population of {self.population_size}"
            )
        if self.parent_pool == "elites" and self.tournament_size > self.n_elite:
            raise ValueError(
                f"tournament_size: must be <= the {self.n_elite} elites that enter the "
                f"tournaments (parent_pool 'elites'), got {self.tournament_size!r}"
            )

    @property
    def n_elite(self) -> int:
        """Individuals kept by elitism each generation."""
        return round(self.elite_fraction * self.population_size)

    @property
    def n_random(self) -> int:
        """Random individuals injected each generation."""
        return min(
            round(self.random_fraction * self.population_size),
            self.population_size - self.n_elite,
        )

    @property
    def n_offspring(self) -> int:
        """Offspring of selection, crossover and mutation each generation."""
        return self.population_size - self.n_elite - self.n_random

    @classmethod
    def from_dict(cls, config: Mapping) -> CFSGAParams:
        """Parameters from a mapping (TOML table): unknown keys are rejected with a suggestion."""
        if not isinstance(config, Mapping):
            raise ValueError(f"CFS-GA config must be a mapping, got {type(config).__name__}")  # noqa: TRY004
        known = [f.name for f in fields(cls)]
        for key in config:
            if key not in known:
                hint = did_you_mean(str(key), known, 0.5)
                raise ValueError(f"{key}: unknown CFS-GA parameter{hint}")
        return cls(**dict(config))


def _require_int(value, name: str, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: must be an integer, got {value!r}")  # noqa: TRY004
    if not lo <= value <= hi:
        raise ValueError(f"{name}: must be in [{lo}, {hi}], got {value!r}")


def _require_real(value, name: str, positive: bool = False, upper: float | None = None) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name}: must be a number, got {value!r}")  # noqa: TRY004
    if not math.isfinite(value) or value < 0.0 or (positive and value == 0.0):
        raise ValueError(
            f"{name}: must be a finite number {'>' if positive else '>='} 0, got {value!r}"
        )
    if upper is not None and value > upper:
        raise ValueError(f"{name}: must be <= {upper}, got {value!r}")


# --------------------------------------------------------------------------------------------
# Operators (pure functions)
# --------------------------------------------------------------------------------------------


def sharing_function(distance_m, niche_radius_m: float, alpha: float) -> np.ndarray:
    """003 §III-B: ``sh(d) = 1 - (d / sigma_s)^alpha`` if ``d < sigma_s``, else 0."""
    ratio = np.asarray(distance_m, dtype=np.float64) / niche_radius_m
    return np.where(ratio < 1.0, 1.0 - np.power(np.minimum(ratio, 1.0), alpha), 0.0)


def niche_counts(
    poses_m: np.ndarray, others_m: np.ndarray, niche_radius_m: float, alpha: float
) -> np.ndarray:
    """``n_i = sum_j sh(d_ij)`` (003 §III-B; the virtual niches of §IV-B when ``others_m`` is the
    virtual population): ``(P,)`` for poses ``(P, >=2)`` against ``others_m`` ``(Q, >=2)``, with
    ``d_ij`` the distance between positions. ``others_m is poses_m`` gives the niche count of the
    population itself, each individual counting itself (``sh(0) = 1``). Computed in float32
    (relative error about 1e-6), equal to summing :func:`sharing_function` over the pairs."""
    # float32 and in-place arithmetic over cache-sized blocks: the O(m^2) part of 003 §IV-C.
    a = (np.asarray(poses_m, dtype=np.float64)[:, :2] / niche_radius_m).astype(np.float32)
    b = (np.asarray(others_m, dtype=np.float64)[:, :2] / niche_radius_m).astype(np.float32)
    out = np.zeros(a.shape[0])
    if a.shape[0] == 0 or b.shape[0] == 0:
        return out
    bx, by = b[:, 0], b[:, 1]
    rows = max(1, _PAIR_CHUNK_ELEMENTS // b.shape[0])
    for start in range(0, a.shape[0], rows):
        stop = min(start + rows, a.shape[0])
        share = a[start:stop, 0:1] - bx
        dy = a[start:stop, 1:2] - by
        share *= share
        dy *= dy
        share += dy  # (d / sigma_s)^2
        if alpha == 1.0:
            np.sqrt(share, out=share)
        elif alpha != 2.0:
            np.power(share, alpha / 2.0, out=share)
        np.subtract(1.0, share, out=share)
        np.maximum(share, 0.0, out=share)
        out[start:stop] = share.sum(axis=1, dtype=np.float64)
    return out


def tournament_select(
    fitness: np.ndarray, n_winners: int, tournament_size: int, rng: np.random.Generator
) -> np.ndarray:
    """Indices of ``n_winners`` tournament winners: each tournament draws ``tournament_size``
    distinct individuals uniformly and keeps the fittest (the first drawn on a tie)."""
    fitness = np.asarray(fitness, dtype=np.float64)
    size = fitness.shape[0]
    if not 1 <= tournament_size <= size:
        raise ValueError(f"tournament_size: must be in [1, {size}], got {tournament_size}")
    # Distinct draws without a (n, P) permutation: draw from the P - t indices left, then step over
    # the ones already drawn (in increasing order).
    drawn = np.empty((n_winners, tournament_size), dtype=np.int64)
    for t in range(tournament_size):
        pick = rng.integers(0, size - t, size=n_winners)
        if t:
            taken = np.sort(drawn[:, :t], axis=1)
            for k in range(t):
                pick += pick >= taken[:, k]
        drawn[:, t] = pick
    best = np.argmax(fitness[drawn], axis=1)
    return drawn[np.arange(n_winners), best]


def crossover(first: np.ndarray, second: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Offspring genes ``first + w (second - first)`` per gene, ``weights`` ``(N, 3)`` in [0, 1];
    the heading moves along the shorter arc and is wrapped."""
    delta = second - first
    delta[:, 2] = wrap_angle(delta[:, 2])
    child = first + weights * delta
    child[:, 2] = wrap_angle(child[:, 2])
    return child


def aging_factor(age, aging_rate: float, aging_max: float) -> np.ndarray:
    """Memory effect of the best-individual choice (003 §IV-A): ``min(1 + rate * age, max)``,
    ``age`` being how many generations the estimate has stayed in its niche
    (:attr:`FitnessSharingGA.estimate_age`)."""
    return np.minimum(1.0 + aging_rate * np.asarray(age, dtype=np.float64), aging_max)


def roto_translate(
    teammate_poses_m: np.ndarray, distance_m: float, bearing_rad: float, relative_heading_rad: float
) -> np.ndarray:
    """The roto-translation R of 003 §IV-B: a teammate's pose hypotheses ``(Q, 3)`` turned into
    hypotheses of this robot's pose, given how this robot sees the teammate (distance, bearing of
    the teammate in this robot's frame, teammate heading minus this robot's heading).

    ``theta = theta_j - relative_heading``; ``(x, y) = (x_j, y_j) - distance (cos, sin)(theta +
    bearing)``.
    """
    poses = np.asarray(teammate_poses_m, dtype=np.float64)
    theta = wrap_angle(poses[:, 2] - relative_heading_rad)
    direction = theta + bearing_rad
    out = np.empty_like(poses)
    out[:, 0] = poses[:, 0] - distance_m * np.cos(direction)
    out[:, 1] = poses[:, 1] - distance_m * np.sin(direction)
    out[:, 2] = theta
    return out


def virtual_population(
    received: Iterable[tuple[np.ndarray, Sighting]],
) -> np.ndarray:
    """``P_v = U_i R(P_b^(i), Delta(r_1, r_i))`` (003 §IV-B) from pairs (decoded teammate
    individuals ``(Q_i, 3)``, the sighting of that teammate): ``(sum Q_i, 3)``."""
    parts = [
        roto_translate(poses, s.distance_m, s.bearing_rad, s.relative_heading_rad)
        for poses, s in received
        if poses.shape[0]
    ]
    return np.concatenate(parts, axis=0) if parts else np.empty((0, 3))


# --------------------------------------------------------------------------------------------
# Radio payload
# --------------------------------------------------------------------------------------------


def encode_individuals(poses_m: np.ndarray) -> bytes:
    """The radio payload carrying individuals ``(Q, 3)`` (float32 on the wire)."""
    poses = np.asarray(poses_m, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise ValueError(f"poses: must have shape (Q, 3), got {poses.shape}")
    if poses.shape[0] > MAX_SHARED_INDIVIDUALS:
        raise ValueError(
            f"poses: at most {MAX_SHARED_INDIVIDUALS} individuals, got {poses.shape[0]}"
        )
    if not np.all(np.isfinite(poses)):
        raise ValueError("poses: must be finite")
    body = np.ascontiguousarray(poses, dtype="<f4").tobytes()
    return msgpack.packb({"v": PAYLOAD_VERSION, "t": PAYLOAD_TYPE, "poses": body})


def decode_individuals(payload: bytes) -> np.ndarray:
    """Individuals ``(Q, 3)`` from a CFS-GA payload; ``ValueError`` naming what is wrong."""
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise ValueError(f"payload: must be bytes, got {type(payload).__name__}")  # noqa: TRY004
    if len(payload) > MAX_RADIO_PAYLOAD_BYTES:
        raise ValueError(
            f"payload: {len(payload)} bytes exceeds the limit of {MAX_RADIO_PAYLOAD_BYTES}"
        )
    try:
        body = msgpack.unpackb(
            bytes(payload),
            raw=False,
            max_str_len=64,
            max_bin_len=MAX_RADIO_PAYLOAD_BYTES,
            max_array_len=0,
            max_map_len=8,
            max_ext_len=0,
            strict_map_key=True,
        )
    except Exception as exc:  # noqa: BLE001 -- msgpack raises many unrelated types
        raise ValueError(f"payload: not a CFS-GA message ({type(exc).__name__}: {exc})") from None
    if not isinstance(body, dict):
        raise ValueError(f"payload: expected a map, got {type(body).__name__}")  # noqa: TRY004
    if set(body) != {"v", "t", "poses"}:
        raise ValueError(f"payload: expected keys v, t, poses, got {sorted(map(str, body))}")
    if type(body["v"]) is not int or body["v"] != PAYLOAD_VERSION:
        raise ValueError(f"payload.v: expected {PAYLOAD_VERSION}, got {body['v']!r}")
    if body["t"] != PAYLOAD_TYPE:
        raise ValueError(f"payload.t: expected {PAYLOAD_TYPE!r}, got {body['t']!r}")
    raw = body["poses"]
    if not isinstance(raw, bytes):
        raise ValueError(f"payload.poses: expected bytes, got {type(raw).__name__}")  # noqa: TRY004
    if len(raw) % _BYTES_PER_INDIVIDUAL:
        raise ValueError(
            f"payload.poses: {len(raw)} bytes is not a whole number of (x, y, theta) float32 triples"
        )
    poses = np.frombuffer(raw, dtype="<f4").reshape(-1, 3).astype(np.float64)
    if not np.all(np.isfinite(poses)):
        raise ValueError("payload.poses: must be finite")
    if np.any(np.abs(poses[:, :2]) > _MAX_COORDINATE_M):
        raise ValueError(f"payload.poses: a position is beyond {_MAX_COORDINATE_M:g} m")
    if np.any(np.abs(poses[:, 2]) > math.pi + _HEADING_TOLERANCE_RAD):
        raise ValueError("payload.poses: a heading is outside [-pi, pi]")
    return poses


# --------------------------------------------------------------------------------------------
# Pose samplers and the laser fitness
# --------------------------------------------------------------------------------------------


def map_sampler(world_map: SegmentMap, clearance_m: float = 0.3) -> PoseSampler:
    """Uniform poses over the free space of ``world_map`` (``free_space_sample``)."""

    def sample(n: int, rng: np.random.Generator) -> np.ndarray:
        return free_space_sample(world_map, n, rng, clearance_m=clearance_m)

    return sample


def box_sampler(bounds_m: Sequence[float]) -> PoseSampler:
    """Uniform poses in the rectangle ``(x_min, y_min, x_max, y_max)`` (no map needed)."""
    x_min, y_min, x_max, y_max = (float(b) for b in bounds_m)
    if not (x_max > x_min and y_max > y_min):
        raise ValueError(f"bounds_m: must have positive width and height, got {tuple(bounds_m)}")
    low = np.array([x_min, y_min, -math.pi])
    high = np.array([x_max, y_max, math.pi])

    def sample(n: int, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(low, high, size=(n, 3))

    return sample


class LaserFitness:
    """The raw fitness of 003 §IV-A for a laser scan: ``f = 1/L sum_i N(z^i - z^_i; 0, sigma)``
    with ``z^`` cast on ``world_map`` (eq. 4 of 002). Poses outside the map bounds get 0.

    Calling it with a :class:`LaserObservation` returns the per-step ``raw_fitness(poses)``.
    """

    def __init__(
        self,
        world_map: SegmentMap,
        n_beams: int,
        max_range_m: float,
        confidence_std_m: float,
    ) -> None:
        self.world_map = world_map
        self.n_beams = int(n_beams)
        self.max_range_m = float(max_range_m)
        self.confidence_std_m = float(confidence_std_m)
        self.beam_angles_rad = np.arange(self.n_beams) * (2.0 * math.pi / self.n_beams)
        self._peak = 1.0 / (math.sqrt(2.0 * math.pi) * self.confidence_std_m)

    def expected_ranges(self, poses_m: np.ndarray) -> np.ndarray:
        """Noise-free ranges ``(P, L)`` from each pose (eq. 4 of 002), cast in blocks of
        :data:`_CAST_BLOCK_ELEMENTS`: one ``cast_rays`` call on 300 poses x 18 beams of the
        office map allocates temporaries of a few MB, which glibc maps and unmaps at every call;
        the page faults that follow cost more than the casting itself."""
        poses = np.asarray(poses_m, dtype=np.float64)
        per_pose = self.n_beams * 2 * self.world_map.n_segments
        block = max(1, _CAST_BLOCK_ELEMENTS // per_pose)
        if poses.shape[0] <= block:
            return cast_rays(self.world_map, poses, self.beam_angles_rad, self.max_range_m)
        out = np.empty((poses.shape[0], self.n_beams))
        for start in range(0, poses.shape[0], block):
            stop = min(start + block, poses.shape[0])
            out[start:stop] = cast_rays(
                self.world_map, poses[start:stop], self.beam_angles_rad, self.max_range_m
            )
        return out

    def __call__(self, obs: LaserObservation) -> RawFitness:
        ranges = np.asarray(obs.ranges_m, dtype=np.float64)
        if ranges.shape != (self.n_beams,):
            raise ValueError(f"ranges_m: expected shape ({self.n_beams},), got {ranges.shape}")
        if not np.all(np.isfinite(ranges)) or np.any(ranges < 0.0):
            raise ValueError("ranges_m: must be finite and >= 0")
        measured = np.minimum(ranges, self.max_range_m)
        scale = -0.5 / self.confidence_std_m**2
        x_min, y_min, x_max, y_max = self.world_map.bounds_m

        def raw_fitness(poses_m: np.ndarray) -> np.ndarray:
            poses = np.asarray(poses_m, dtype=np.float64)
            expected = self.expected_ranges(poses)
            residual = expected - measured
            fitness = np.exp(scale * residual * residual).mean(axis=1) * self._peak
            inside = (
                (poses[:, 0] >= x_min)
                & (poses[:, 0] <= x_max)
                & (poses[:, 1] >= y_min)
                & (poses[:, 1] <= y_max)
            )
            return np.where(inside, fitness, 0.0)

        return raw_fitness


# --------------------------------------------------------------------------------------------
# The GA core (sensor-independent)
# --------------------------------------------------------------------------------------------


class FitnessSharingGA:
    """The sensor-independent core of CFS-GA (003 §III-B, §IV): one population of pose hypotheses.

    Per step call :meth:`kinematic_update`, :meth:`evaluate` (with that step's raw fitness),
    optionally :meth:`above_average` (what to broadcast), then :meth:`evolve` (with the virtual
    population, if any). :attr:`best_pose` is the estimate.
    """

    def __init__(
        self,
        params: CFSGAParams,
        niche_radius_m: float,
        sample_poses: PoseSampler,
        rng: np.random.Generator,
        initial_population: np.ndarray | None = None,
    ) -> None:
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng: must be a numpy.random.Generator, got {type(rng).__name__}")
        _require_real(niche_radius_m, "niche_radius_m", positive=True)
        self.params = params
        self.niche_radius_m = float(niche_radius_m)
        self.sample_poses = sample_poses
        self.rng = rng
        m = params.population_size
        if initial_population is None:
            population = np.asarray(sample_poses(m, rng), dtype=np.float64)
        else:
            population = np.array(initial_population, dtype=np.float64)
        if population.shape != (m, 3) or not np.all(np.isfinite(population)):
            raise ValueError(f"initial_population: must be finite with shape ({m}, 3)")
        population[:, 2] = wrap_angle(population[:, 2])
        self.population = population
        #: Raw fitness of each individual at the last evaluation; NaN for newborns not yet seen.
        self.raw_fitness = np.full(m, np.nan)
        #: Generations each individual has survived (elitism); 0 at birth.
        self.age = np.zeros(m, dtype=np.int64)
        self.shared_fitness = np.full(m, np.nan)
        self.best_index = 0
        #: The last estimate (best individual), moved since by the odometry without noise: the
        #: centre of the niche the aging factor favours; None before the first generation.
        self.estimate_anchor: np.ndarray | None = None
        #: Consecutive generations whose best individual lay within the niche radius of the
        #: previous estimate (0 after a jump to another niche).
        self.estimate_age = 0

    # -- step parts ----------------------------------------------------------------------------

    def kinematic_update(
        self,
        delta_s_m: float,
        delta_phi_rad: float,
        delta_s_std_m: float = 0.0,
        delta_phi_std_rad: float = 0.0,
    ) -> None:
        """Move every individual by the odometry (eq. 3 of 002), each with its own draw of the
        increments' noise (standard deviations; 0 gives the plain kinematic update of 003)."""
        for name, value in (("delta_s_m", delta_s_m), ("delta_phi_rad", delta_phi_rad)):
            if not math.isfinite(value):
                raise ValueError(f"{name}: must be finite, got {value!r}")
        m = self.population.shape[0]
        draws = self.rng.normal(0.0, 1.0, size=(m, 2))
        delta_s = delta_s_m + draws[:, 0] * delta_s_std_m
        delta_phi = delta_phi_rad + draws[:, 1] * delta_phi_std_rad
        self.population = unicycle_model(self.population, delta_s, delta_phi)
        if self.estimate_anchor is not None:
            self.estimate_anchor = unicycle_model(
                self.estimate_anchor[None, :], delta_s_m, delta_phi_rad
            )[0]

    def evaluate(self, raw_fitness: RawFitness) -> np.ndarray:
        """Raw fitness of the whole population (``raw_fitness(poses) -> (m,)``, finite ``>= 0``)
        and its shared fitness ``f / n`` (003 §III-B). Returns the raw fitness."""
        values = np.asarray(raw_fitness(self.population), dtype=np.float64)
        if values.shape != (self.population.shape[0],):
            raise ValueError(
                f"raw_fitness: must return shape ({self.population.shape[0]},), got {values.shape}"
            )
        if not np.all(np.isfinite(values)) or np.any(values < 0.0):
            raise ValueError("raw_fitness: must return finite values >= 0")
        counts = niche_counts(
            self.population, self.population, self.niche_radius_m, self.params.sharing_alpha
        )
        self.raw_fitness = values
        self.shared_fitness = values / counts
        return values

    def refine(self, raw_fitness: RawFitness) -> None:
        """The refinement option: compass search on ``raw_fitness`` from the fittest
        ``refine_individuals``; they take the refined poses and fitness, and the shared fitness
        is recomputed (niche counts move with them). After :meth:`evaluate`."""
        p = self.params
        top = np.argsort(-self.raw_fitness, kind="stable")[: p.refine_individuals]
        poses, values = compass_search(raw_fitness, self.population[top], self.raw_fitness[top],
                                       p.refine_iterations, p.refine_step_m, p.refine_step_rad)
        self.population[top] = poses
        self.raw_fitness[top] = values
        counts = niche_counts(
            self.population, self.population, self.niche_radius_m, p.sharing_alpha
        )
        self.shared_fitness = self.raw_fitness / counts

    def above_average(self, limit: int | None = None) -> np.ndarray:
        """Individuals whose raw fitness exceeds the population average (003 §IV-B), the fittest
        first, at most ``limit``: ``(Q, 3)``. Empty before the first evaluation."""
        known = np.isfinite(self.raw_fitness)
        if not np.all(known):
            return np.empty((0, 3))
        chosen = np.flatnonzero(self.raw_fitness > self.raw_fitness.mean())
        chosen = chosen[np.argsort(-self.raw_fitness[chosen], kind="stable")]
        if limit is not None:
            chosen = chosen[:limit]
        return self.population[chosen].copy()

    def virtual_niche_counts(self, virtual: np.ndarray | None) -> np.ndarray | None:
        """``n_v,i`` (003 §IV-B): each local individual's niche count in the virtual population,
        or None without one."""
        if virtual is None or len(virtual) == 0:
            return None
        return niche_counts(self.population, virtual, self.niche_radius_m, self.params.sharing_alpha)

    def strengthened_fitness(
        self, virtual: np.ndarray | None, counts: np.ndarray | None = None
    ) -> np.ndarray:
        """``f~_sh,i = f_sh,i * n_v,i`` (003 §IV-B), or ``f_sh`` when there is no virtual
        population or no local individual falls in any virtual niche. ``counts``: the
        :meth:`virtual_niche_counts` of ``virtual`` if the caller has them already."""
        if counts is None:
            counts = self.virtual_niche_counts(virtual)
        if counts is None or not np.any(counts > 0.0):
            return self.shared_fitness
        return self.shared_fitness * counts

    def evolve(self, virtual: np.ndarray | None = None) -> None:
        """One generation (003 §IV-A): elitism on raw fitness, tournaments on the (strengthened)
        shared fitness among the parent pool (:attr:`CFSGAParams.parent_pool`), crossover,
        mutation, random individuals; then the best individual."""
        if not np.all(np.isfinite(self.raw_fitness)):
            raise RuntimeError("evolve() needs evaluate() first")
        p, rng = self.params, self.rng
        counts = self.virtual_niche_counts(virtual)  # once, for both uses
        selection_fitness = self.strengthened_fitness(virtual, counts)
        self.doubt_estimate(virtual, counts)
        order = np.argsort(-self.raw_fitness, kind="stable")
        elites = order[: p.n_elite]

        n_off = p.n_offspring
        if p.parent_pool == "elites":
            winners = tournament_select(
                selection_fitness[elites], 2 * n_off, p.tournament_size, rng
            )
            parents = elites[winners]
        else:
            parents = tournament_select(selection_fitness, 2 * n_off, p.tournament_size, rng)
        first = self.population[parents[:n_off]]
        second = self.population[parents[n_off:]]
        cross = rng.random(n_off) < p.crossover_probability
        weights = rng.random((n_off, 3))
        offspring = np.where(cross[:, None], crossover(first, second, weights), first)
        mutate = rng.random(n_off) < p.mutation_probability
        perturbation = rng.normal(0.0, 1.0, size=(n_off, 3)) * np.array(
            [p.mutation_std_m, p.mutation_std_m, p.mutation_std_rad]
        )
        offspring = offspring + np.where(mutate[:, None], perturbation, 0.0)
        offspring[:, 2] = wrap_angle(offspring[:, 2])
        randoms = np.asarray(self.sample_poses(p.n_random, rng), dtype=np.float64).reshape(-1, 3)

        m = p.population_size
        self.population = np.concatenate([self.population[elites], offspring, randoms], axis=0)
        raw = np.full(m, np.nan)
        raw[: p.n_elite] = self.raw_fitness[elites]
        shared = np.full(m, np.nan)
        shared[: p.n_elite] = self.shared_fitness[elites]
        age = np.zeros(m, dtype=np.int64)
        age[: p.n_elite] = self.age[elites] + 1
        self.raw_fitness, self.shared_fitness, self.age = raw, shared, age
        self.hold_estimate(self.choose_best())

    def aging_factors(self) -> np.ndarray:
        """``(m,)``: :func:`aging_factor` of :attr:`estimate_age` for the individuals whose
        position lies within the niche radius of :attr:`estimate_anchor` (the niche of the last
        estimate), 1 for the others (and for all before the first estimate)."""
        m = self.population.shape[0]
        if self.estimate_anchor is None:
            return np.ones(m)
        distance = np.hypot(
            self.population[:, 0] - self.estimate_anchor[0],
            self.population[:, 1] - self.estimate_anchor[1],
        )
        p = self.params
        factor = float(aging_factor(self.estimate_age, p.aging_rate, p.aging_max))
        return np.where(distance < self.niche_radius_m, factor, 1.0)

    def choose_best(self) -> int:
        """Index of the individual with the highest raw fitness times aging factor
        (:meth:`aging_factors`), among those whose raw fitness is known (003 §IV-A)."""
        score = self.raw_fitness * self.aging_factors()
        score = np.where(np.isfinite(score), score, -np.inf)
        return int(np.argmax(score))

    def hold_estimate(self, index: int) -> None:
        """Make individual ``index`` the estimate: :attr:`estimate_age` grows by one if it lies
        within the niche radius of the previous estimate, else restarts at 0."""
        pose = self.population[index]
        anchor = self.estimate_anchor
        same_niche = anchor is not None and (
            math.hypot(pose[0] - anchor[0], pose[1] - anchor[1]) < self.niche_radius_m
        )
        self.estimate_age = self.estimate_age + 1 if same_niche else 0
        self.estimate_anchor = pose.copy()
        self.best_index = int(index)

    def doubt_estimate(self, virtual: np.ndarray | None, counts: np.ndarray | None = None) -> None:
        """003 §IV-B: a teammate's suggestion may "diminish the confidence of local hypothesis".
        When the virtual population supports some local individual (the strengthening applies)
        but has no individual within the niche radius of the held estimate, the estimate's age
        restarts at 0, so its aging factor no longer holds it. ``counts``: as for
        :meth:`strengthened_fitness`."""
        if virtual is None or len(virtual) == 0 or self.estimate_anchor is None:
            return
        p = self.params
        at_estimate = niche_counts(
            self.estimate_anchor[None, :], virtual, self.niche_radius_m, p.sharing_alpha
        )[0]
        if at_estimate > 0.0:
            return
        local = counts if counts is not None else self.virtual_niche_counts(virtual)
        if np.any(local > 0.0):
            self.estimate_age = 0

    @property
    def best_pose(self) -> np.ndarray:
        """The best individual ``(x_m, y_m, theta_rad)``; before any evolution, the first one."""
        return self.population[self.best_index].copy()


# --------------------------------------------------------------------------------------------
# The Localizer
# --------------------------------------------------------------------------------------------


class CFSGALocalizer:
    """CFS-GA for one laser robot (:class:`~swarmloc.agents.laser.localizer.Localizer`).

    ``fitness_model`` (default :class:`LaserFitness` on the setup's map and laser) turns each
    observation into the step's raw fitness; ``sample_poses`` (default: the map's free space)
    draws the random individuals.
    """

    def __init__(
        self,
        setup: LocalizerSetup,
        params: CFSGAParams | None = None,
        rng: np.random.Generator | None = None,
        *,
        world_map: SegmentMap | None = None,
        fitness_model: Callable[[LaserObservation], RawFitness] | None = None,
        sample_poses: PoseSampler | None = None,
        initial_population: np.ndarray | None = None,
    ) -> None:
        if not isinstance(setup, LocalizerSetup):
            raise TypeError(f"setup: must be a LocalizerSetup, got {type(setup).__name__}")
        if rng is None or not isinstance(rng, np.random.Generator):
            raise TypeError("rng: must be a numpy.random.Generator")
        params = CFSGAParams() if params is None else params
        if not isinstance(params, CFSGAParams):
            raise TypeError(f"params: must be CFSGAParams, got {type(params).__name__}")
        _require_int(setup.n_beams, "n_beams", 1, 100_000)
        _require_real(setup.max_range_m, "max_range_m", positive=True)
        _require_real(setup.dt_s, "dt_s")
        _require_real(setup.speed_std_mps, "speed_std_mps")
        _require_real(setup.turn_rate_std_rad_s, "turn_rate_std_rad_s")
        if world_map is None:
            try:
                world_map = build_map(setup.map_name)
            except KeyError as exc:
                raise ValueError(f"map_name: {exc.args[0]}") from None
        self.setup = setup
        self.params = params
        self.world_map = world_map
        self.fitness_model = fitness_model or LaserFitness(
            world_map, setup.n_beams, setup.max_range_m, params.confidence_std_m
        )
        sampler = sample_poses or map_sampler(world_map, params.random_clearance_m)
        self.ga = FitnessSharingGA(
            params,
            niche_radius_m=params.niche_radius_fraction * world_map.diagonal_m,
            sample_poses=sampler,
            rng=rng,
            initial_population=initial_population,
        )
        #: Payloads skipped at the last step: ``(sender_id, error)``.
        self.rejected: tuple[tuple[int, ValueError], ...] = ()
        #: Size of the virtual population used at the last step.
        self.virtual_size = 0
        self._outgoing: bytes | None = None

    @classmethod
    def from_config(
        cls, setup: LocalizerSetup, config: Mapping, rng: np.random.Generator, **kwargs
    ) -> CFSGALocalizer:
        """Build from a config mapping of :class:`CFSGAParams` fields (unknown keys and impossible
        values raise ``ValueError`` naming them)."""
        return cls(setup, CFSGAParams.from_dict(config), rng, **kwargs)

    # -- Localizer ---------------------------------------------------------------------------

    def step(self, obs: LaserObservation) -> None:
        """Kinematic update, raw and shared fitness, collaboration, one generation."""
        setup, p = self.setup, self.params
        raw_fitness = self.fitness_model(obs)  # validates the scan before any state changes
        delta_s = float(obs.odometry_delta_s_m)
        delta_phi = float(obs.odometry_delta_phi_rad)
        # Motion noise comes with motion: a robot whose odometry reports no move stood still.
        moving = delta_s != 0.0 or delta_phi != 0.0
        diffusion = setup.dt_s if p.motion_diffusion and moving else 0.0
        self.ga.kinematic_update(
            delta_s,
            delta_phi,
            setup.speed_std_mps * diffusion,
            setup.turn_rate_std_rad_s * diffusion,
        )
        self.ga.evaluate(raw_fitness)
        if p.refine_iterations > 0 and p.refine_individuals > 0:
            self.ga.refine(raw_fitness)
        virtual = None
        self.rejected = ()
        if setup.cooperative:
            virtual = self._virtual_population(obs.sightings, obs.received)
            shared = self.ga.above_average(p.max_shared_individuals)
            self._outgoing = encode_individuals(shared) if shared.shape[0] else None
        self.virtual_size = 0 if virtual is None else int(virtual.shape[0])
        self.ga.evolve(virtual)

    def estimate(self) -> np.ndarray:
        return self.ga.best_pose

    def samples(self, n: int) -> np.ndarray:
        """At most ``n`` individuals of the population, evenly spaced through it (for observers)."""
        return evenly_spaced(self.ga.population, n)

    def outgoing(self) -> bytes | None:
        return self._outgoing

    # -- collaboration ------------------------------------------------------------------------

    def _virtual_population(
        self, sightings: Sequence[Sighting], received: Sequence[RadioMessage]
    ) -> np.ndarray:
        seen: dict[int, Sighting] = {}
        for s in sightings:
            values = (s.distance_m, s.bearing_rad, s.relative_heading_rad)
            if s.robot_id not in seen and all(math.isfinite(v) for v in values):
                seen[s.robot_id] = s
        pairs, rejected = [], []
        for msg in received:
            if msg.sender_id == self.setup.robot_id:
                continue
            try:
                poses = decode_individuals(msg.payload)
            except ValueError as exc:
                rejected.append((msg.sender_id, exc))
                continue
            sighting = seen.get(msg.sender_id)
            if sighting is not None:  # no relative pose, no roto-translation (003 §IV-B)
                pairs.append((poses, sighting))
        self.rejected = tuple(rejected)
        return virtual_population(pairs)
