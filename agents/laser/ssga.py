"""MR-SSGA: the spatially structured genetic algorithm for multi-robot localization (seed 002).

Seed ``/work/shared/seeds/002_fe2ac635ba0eab3e.txt`` (Gasparri, Panzieri, Pascucci), §2-4:

- **Population on a complex network** (§2.1-2.2, §3): each individual is a pose hypothesis
  ``(x_m, y_m, theta_rad)``, laid on the vertices of a Watts-Strogatz (small-world) or
  Barabási-Albert (scale-free) network built with networkx (:func:`build_network`).
- **Mating rules, table 1 and Algorithm 1** (:func:`network_mating`): an individual is HIGH when
  its fitness is above the population mean, LOW otherwise; for every linked pair: HIGH-HIGH, the
  lower is replaced with the crossover of the two; HIGH-LOW, the LOW one is replaced with a
  mutation of the HIGH one; LOW-LOW, both self-mutate. Crossover is a convex combination of the
  two parents (§2.1); mutation perturbs a chromosome "inversely proportional to its fitness"
  (§2.1): Gaussian noise whose standard deviation falls linearly from ``mutation_std_max`` at zero
  fitness to ``mutation_std_min`` at the highest fitness the model can give.
- **Fitness eq. 1** (:meth:`FitnessModel.scan_fitness`): mean over the L beams of a Gaussian of
  the difference between the measured range and the range expected at the hypothesis (eq. 4,
  :func:`swarmloc.world.laser.laser.cast_rays`).
- **Collaborative fitness eq. 2** (:meth:`FitnessModel.team_fitness`): for every teammate ``s``
  this robot both sees (:class:`~swarmloc.agents.laser.localizer.Sighting`: distance, bearing, relative
  heading) and hears (its scan, sent by :meth:`SSGALocalizer.outgoing`), the teammate's pose is
  replicated around hypothesis ``i`` from the relative measurement, and eq. 1 of the teammate's
  scan at that replicated pose is added. A teammate heard but not seen cannot enter eq. 2
  (its pose relative to the hypothesis is unknown): eq. 1 only.
- **Kinematic update, eq. 3**: every individual moves with the robot's odometry through
  :func:`swarmloc.world.laser.laser.unicycle_model`, plus Gaussian noise of the motion model's standard
  deviations (table 2: sigma_s), which keeps the population diverse and covers the true motion's
  noise; with ``elite_exact_motion`` (table 3's spec sets it) the last step's best individual
  moves without that noise (readings below).
- **Estimate**: the best individual (highest fitness at this step; the mating rules never replace
  it, so it is still in the population after reproduction). 002 §6 names only "the estimate";
  §3 speaks of individuals as hypotheses and of "monitoring the formation of a single cluster",
  not of averaging them. On table 3's floor (seeds 1001-1010, MR-SSGA 100, converged robots,
  steps >= 250) the fitness-weighted mean of the best individual's niche (within 0.5 m and
  0.5 rad, or 0.25 m) erred by the same as the best individual to within 0.01 m, so we keep
  the best individual.

Readings of the text (the seed leaves them open):

- eq. 1 prints ``exp(-(z - z^)^2 / 2 sigma)`` with ``1 / (sqrt(2 pi) sigma)`` in front, eq. 2
  ``1 / sqrt(2 pi sigma)``; we use the normal density with standard deviation
  ``fitness_sigma_m`` (``sigma`` as a length, "a measure of confidence"; not in table 2). The
  default 0.2 m is twice table 2's beam noise sigma_b; sigma = sigma_b = 0.1 m was worse on table
  3's floor (seeds 1001-1010, MR-SSGA 100, 2 % rewiring: 3 of 10 trials converged instead of
  6, converged robots 0.207 m instead of 0.148 m).
- Algorithm 1 visits the links one after the other and overwrites individuals in place. Here all
  links are evaluated at once on generation ``k`` (synchronous update, vectorised): every link
  proposes an offspring for its target, and a target with several proposals takes one at random,
  an offspring of a HIGH parent always before a self-mutation (in the sequential loop a
  self-mutation after a replacement would only mutate the HIGH parent's copy). Ties in HIGH-HIGH
  follow Algorithm 1: ``p_i`` is replaced unless ``Phi_i > Phi_j``.
- *The elite moves noise-free* (``elite_exact_motion``, off by default, on in table 3's spec).
  Table 1 names elitism: the best individual survives reproduction. Eq. 3's noise then still
  jittered it (0.1 rad a step: table 2's 0.2 rad/s over 0.5 s, which turns a 6 m beam's end by
  0.6 m, three times the fitness sigma), so the best hypothesis of step ``k`` was no longer
  itself at ``k + 1``. The individual equal to the last step's best (after reproduction) is moved
  by the odometry alone; the others diffuse, so the population still follows the true motion's
  noise. Table 3's floor, MR-SSGA 100 on a ring, seeds 1001-1024 (instrumented previews):
  converged robots' final error 0.129 m mean without it, 0.113 m with it (medians 0.131, 0.104),
  and 21 of 24 trials converged with it against 17 of 24 without.
- *Noise while the robot stands* (kept). Eq. 3's noise is white and additive, so the individuals
  diffuse even when the odometry reads zero, although our world's robot, held still by its
  driver, does not move at all. Switching the noise off for zero odometry sharpened the converged
  robots (table 3's robots stand for the whole final window: 0.129 -> 0.083 m mean, same seeds
  and network) but cost convergence (11 of 24 trials instead of 17; with the elite rule too, 10
  of 24 at 0.071 m): a standing robot's diffusion keeps a population that has taken over a
  wrong room diverse until a teammate disambiguates it.
- *What bounds the accuracy.* With 8 beams of 0.1 m noise the argmax of eq. 1 over a dense grid
  around a standing robot's true pose (fresh noise each time) is 0.05-0.14 m from it, and 0.09-
  0.10 m with eq. 2's teammates (3 deg of bearing noise moves a teammate 8 m away by 0.4 m); an
  individual that keeps winning over many steps averages some of that noise out, which is how
  the GA gets below it. 002's 1-2 cm mean (table 3) is below these figures.
- Hypotheses outside the map bounds have fitness 0 (a laser from outside a closed map would
  still see walls).
- Timing of eq. 2: teammates broadcast their scan of step ``k``; it arrives at step ``k + 1``.
  The receiver keeps the sightings of the previous step and pairs a scan of step ``k`` with the
  sighting of step ``k``, moving each hypothesis back to step ``k`` by inverting eq. 3 with its own
  odometry of step ``k + 1``. A scan stamped with the current step (a runner that delivers at
  once) pairs with the current sightings. Older scans are dropped.

The radio payload (:func:`encode_scan_payload`, :func:`decode_scan_payload`) is a msgpack map
``{"v": 1, "t": "ga_scan", "step": int, "max_range_m": float, "ranges_m": bin}`` with the ranges
as little-endian float32 (beam ``j`` at the sender's heading plus ``j * 2 pi / L``); 8 beams make
84 bytes. Decoding is strict and raises ``ValueError`` naming the bad field.

The simple GA baseline of table 3 (``swarmloc.agents.laser.simple_ga``) shares :class:`FitnessModel`,
the kinematic update, the collaboration and the codec through :class:`GeneticLocalizer`.

Random draws (fixed order, so a run is deterministic given the generator): network construction
draws one integer seed for networkx; initialisation calls ``free_space_sample``; each step draws
the kinematic noise ``(N, 2)``, then the reproduction's draws.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import msgpack
import networkx as nx
import numpy as np

from swarmloc.agents.laser.localizer import (
    MAX_RADIO_PAYLOAD_BYTES,
    LaserObservation,
    LocalizerSetup,
    Sighting,
    evenly_spaced,
)
from swarmloc.agents.laser.refine import check_refine_options, compass_search
from swarmloc.config import did_you_mean
from swarmloc.world.laser.laser import cast_rays, unicycle_model, wrap_angle
from swarmloc.world.laser.maps import SegmentMap, build_map, free_space_sample

#: Networks a population can be laid on (002 §2.2).
NETWORKS = ("watts_strogatz", "barabasi_albert")
#: Upper bound on the beams of a teammate's scan in a payload.
MAX_PAYLOAD_BEAMS = 1024
#: Upper bound on a payload's max_range_m (metres).
MAX_PAYLOAD_RANGE_M = 1000.0
PAYLOAD_VERSION = 1
PAYLOAD_TYPE = "ga_scan"
_PAYLOAD_KEYS = ("v", "t", "step", "max_range_m", "ranges_m")
_MAX_STEP = 2**53 - 1
_SQRT_2PI = math.sqrt(2.0 * math.pi)


# --------------------------------------------------------------------------------------------
# Parameters
# --------------------------------------------------------------------------------------------


def _positive_int(value, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name}: must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name}: must be >= {minimum}, got {value}")
    return int(value)


def _real(value, name: str, lo: float = 0.0, hi: float = math.inf, open_lo: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}: must be a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number) or number < lo or number > hi or (open_lo and number == lo):
        bound = f"> {lo}" if open_lo else f">= {lo}"
        upper = f" and <= {hi}" if math.isfinite(hi) else ""
        raise ValueError(f"{name}: must be a finite number {bound}{upper}, got {value!r}")
    return number


@dataclass(frozen=True)
class GeneticParams:
    """What every GA localizer of seed 002 shares.

    ``fitness_sigma_m``: sigma of eq. 1-2 (the Gaussian's standard deviation, metres).
    ``mutation_std_min_m``/``_max_m`` and ``mutation_std_min_rad``/``_max_rad``: standard
    deviations of a mutation of an individual of the highest possible / of zero fitness (linear in
    between: "inversely proportional to its fitness", 002 §2.1).
    ``init_clearance_m``: the initial population is uniform over the free space at least this far
    from walls (no prior, 002 §5.2).
    ``elite_exact_motion``: eq. 3 moves the last step's best individual by the odometry alone,
    without the motion noise every other individual gets (module docstring, readings).
    ``refine_iterations`` (0: off, the papers' algorithm), ``refine_individuals``,
    ``refine_step_m``, ``refine_step_rad``: not in 002; a compass search on eq. 1-2 of this
    step from the ``refine_individuals`` fittest individuals before reproduction, which replace
    them (:mod:`swarmloc.agents.laser.refine`, issue 43).
    """

    population_size: int = 100
    fitness_sigma_m: float = 0.2
    mutation_std_min_m: float = 0.02
    mutation_std_max_m: float = 0.5
    mutation_std_min_rad: float = 0.02
    mutation_std_max_rad: float = 0.5
    init_clearance_m: float = 0.1
    elite_exact_motion: bool = False
    refine_iterations: int = 0
    refine_individuals: int = 1
    refine_step_m: float = 0.05
    refine_step_rad: float = 0.02

    def __post_init__(self) -> None:
        _positive_int(self.population_size, "population_size", minimum=2)
        check_refine_options(self.refine_iterations, self.refine_individuals,
                             self.refine_step_m, self.refine_step_rad)
        if not isinstance(self.elite_exact_motion, (bool, np.bool_)):
            raise TypeError(
                f"elite_exact_motion: must be true or false, got {self.elite_exact_motion!r}"
            )
        _real(self.fitness_sigma_m, "fitness_sigma_m", open_lo=True)
        for kind in ("m", "rad"):
            lo_name, hi_name = f"mutation_std_min_{kind}", f"mutation_std_max_{kind}"
            lo = _real(getattr(self, lo_name), lo_name)
            hi = _real(getattr(self, hi_name), hi_name)
            if hi < lo:
                raise ValueError(f"{hi_name}: must be >= {lo_name} ({lo}), got {hi}")
        _real(self.init_clearance_m, "init_clearance_m")

    @classmethod
    def from_dict(cls, config: dict[str, Any]):
        """Parameters from a dict; an unknown key is a ValueError suggesting the closest name."""
        if not isinstance(config, dict):
            raise TypeError(f"algorithm parameters must be a dict, got {type(config).__name__}")
        known = [f.name for f in fields(cls)]
        for key in config:
            if key not in known:
                hint = did_you_mean(str(key), known, 0.6)
                raise ValueError(f"{key}: unknown parameter of {cls.__name__}{hint}")
        return cls(**config)


@dataclass(frozen=True)
class SSGAParams(GeneticParams):
    """MR-SSGA parameters. Table 2 of 002 fixes the sensors and noises (they come in
    :class:`~swarmloc.agents.laser.localizer.LocalizerSetup`); the network's parameters are not given
    (fig. 1 shows both models with 30 nodes), so these are ordinary choices: Watts-Strogatz ring of
    ``ws_neighbours`` nearest neighbours rewired with probability ``ws_rewire_prob``;
    Barabási-Albert attaching each new node with ``ba_edges`` links."""

    network: str = "watts_strogatz"
    ws_neighbours: int = 4
    ws_rewire_prob: float = 0.1
    ba_edges: int = 2

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.network not in NETWORKS:
            hint = did_you_mean(str(self.network), NETWORKS, 0.6)
            raise ValueError(f"network: unknown network {self.network!r}{hint} (known: {NETWORKS})")
        k = _positive_int(self.ws_neighbours, "ws_neighbours", minimum=2)
        if k % 2 or k >= self.population_size:
            raise ValueError(
                f"ws_neighbours: must be even and < population_size ({self.population_size}), "
                f"got {k}"
            )
        _real(self.ws_rewire_prob, "ws_rewire_prob", hi=1.0)
        m = _positive_int(self.ba_edges, "ba_edges")
        if m >= self.population_size:
            raise ValueError(
                f"ba_edges: must be < population_size ({self.population_size}), got {m}"
            )


# --------------------------------------------------------------------------------------------
# Complex networks (002 §2.2)
# --------------------------------------------------------------------------------------------


def build_network(params: SSGAParams, rng: np.random.Generator) -> np.ndarray:
    """The population's links as an ``(E, 2)`` int array of pairs ``i < j``, sorted (the order of
    Algorithm 1's double loop). One integer drawn from ``rng`` seeds networkx."""
    n = params.population_size
    seed = int(rng.integers(0, 2**31 - 1))
    if params.network == "watts_strogatz":
        graph = nx.watts_strogatz_graph(n, params.ws_neighbours, params.ws_rewire_prob, seed=seed)
    else:
        graph = nx.barabasi_albert_graph(n, params.ba_edges, seed=seed)
    return edges_of(graph)


def edges_of(graph: nx.Graph) -> np.ndarray:
    """The links of a graph on nodes ``0..N-1`` as sorted ``(E, 2)`` pairs ``i < j``."""
    edges = np.array(sorted(graph.edges()), dtype=np.int64).reshape(-1, 2)
    edges.sort(axis=1)
    if edges.size:
        edges = edges[np.lexsort((edges[:, 1], edges[:, 0]))]
    return edges


# --------------------------------------------------------------------------------------------
# Genetic operators
# --------------------------------------------------------------------------------------------


def mutation_std(
    relative_fitness: np.ndarray, params: GeneticParams
) -> tuple[np.ndarray, np.ndarray]:
    """Mutation standard deviations (position m, heading rad) for individuals of
    ``relative_fitness`` = fitness / highest possible fitness, clipped to ``[0, 1]``: linear from
    the ``_max`` value at 0 to the ``_min`` value at 1 (002 §2.1)."""
    badness = 1.0 - np.clip(relative_fitness, 0.0, 1.0)
    std_m = (
        params.mutation_std_min_m
        + (params.mutation_std_max_m - params.mutation_std_min_m) * badness
    )
    std_rad = (
        params.mutation_std_min_rad
        + (params.mutation_std_max_rad - params.mutation_std_min_rad) * badness
    )
    return std_m, std_rad


def mutate(
    poses_m: np.ndarray, std_m: np.ndarray, std_rad: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Gaussian mutation of ``(K, 3)`` poses with per-individual standard deviations ``(K,)``.
    One ``rng.normal`` draw of shape ``(K, 3)``."""
    noise = rng.normal(0.0, 1.0, size=poses_m.shape)
    out = np.empty_like(poses_m)
    out[:, :2] = poses_m[:, :2] + noise[:, :2] * np.asarray(std_m)[:, None]
    out[:, 2] = wrap_angle(poses_m[:, 2] + noise[:, 2] * std_rad)
    return out


def crossover(parent_a: np.ndarray, parent_b: np.ndarray, weight_a: np.ndarray) -> np.ndarray:
    """Convex combination ``w a + (1 - w) b`` of ``(K, 3)`` poses (002 §2.1); the heading is
    combined along the shorter arc between the two parents' headings."""
    w = np.asarray(weight_a, dtype=np.float64)
    out = np.empty_like(parent_a)
    out[:, :2] = w[:, None] * parent_a[:, :2] + (1.0 - w[:, None]) * parent_b[:, :2]
    out[:, 2] = wrap_angle(parent_b[:, 2] + w * wrap_angle(parent_a[:, 2] - parent_b[:, 2]))
    return out


def network_mating(
    population_m: np.ndarray,
    fitness: np.ndarray,
    edges: np.ndarray,
    fitness_peak: float,
    params: GeneticParams,
    rng: np.random.Generator,
) -> np.ndarray:
    """One reproduction of MR-SSGA: the mating rules of table 1 over every link (Algorithm 1).

    ``population_m`` ``(N, 3)``, ``fitness`` ``(N,)``, ``edges`` ``(E, 2)`` pairs ``i < j``;
    ``fitness_peak`` is the highest fitness the model can give (scales the mutation, see
    :func:`mutation_std`). Returns the new population ``(N, 3)``. Synchronous: every offspring is
    built from generation ``k`` (see the module docstring for how several proposals for one
    individual are resolved). Draws: ``rng.random(M)`` (choice among proposals),
    ``rng.random(K)`` (crossover weights), ``rng.normal(size=(K, 3))`` (mutations), ``K`` the
    number of individuals replaced.
    """
    population = np.asarray(population_m, dtype=np.float64)
    fitness = np.asarray(fitness, dtype=np.float64)
    new_population = population.copy()
    if edges.size == 0:
        return new_population
    high = fitness > fitness.mean()
    node_i, node_j = edges[:, 0], edges[:, 1]
    high_i, high_j = high[node_i], high[node_j]

    # HIGH-HIGH: the lower one (p_i unless Phi_i > Phi_j) becomes the crossover of the two.
    both_high = high_i & high_j
    i_wins = fitness[node_i] > fitness[node_j]
    hh_target = np.where(i_wins, node_j, node_i)[both_high]
    hh_partner = np.where(i_wins, node_i, node_j)[both_high]
    # HIGH-LOW: the LOW one becomes a mutation of the HIGH one.
    one_high = high_i ^ high_j
    hl_target = np.where(high_i, node_j, node_i)[one_high]
    hl_source = np.where(high_i, node_i, node_j)[one_high]
    # LOW-LOW: both self-mutate.
    both_low = ~(high_i | high_j)
    ll_nodes = np.concatenate([node_i[both_low], node_j[both_low]])

    n_hh, n_hl, n_ll = hh_target.size, hl_target.size, ll_nodes.size
    target = np.concatenate([hh_target, hl_target, ll_nodes])
    source = np.concatenate([hh_partner, hl_source, ll_nodes])
    kind = np.concatenate(  # 0 crossover, 1 mutation of a HIGH parent, 2 self-mutation
        [np.zeros(n_hh, np.int8), np.ones(n_hl, np.int8), np.full(n_ll, 2, np.int8)]
    )
    # One proposal per target: offspring of a HIGH parent first, then at random.
    priority = (kind < 2) + rng.random(target.size)
    order = np.lexsort((priority, target))
    last = np.ones(order.size, dtype=bool)
    last[:-1] = target[order][1:] != target[order][:-1]
    chosen = order[last]
    target, source, kind = target[chosen], source[chosen], kind[chosen]

    weights = rng.random(target.size)
    relative = fitness[source] / fitness_peak
    std_m, std_rad = mutation_std(relative, params)
    mutated = mutate(population[source], std_m, std_rad, rng)
    crossed = crossover(population[source], population[target], weights)
    new_population[target] = np.where((kind == 0)[:, None], crossed, mutated)
    return new_population


# --------------------------------------------------------------------------------------------
# Radio payload: a teammate's scan
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TeammateScan:
    """A teammate's laser scan as decoded from its payload: taken at ``step``, beams evenly
    spread over 360 deg from its heading."""

    step: int
    max_range_m: float
    ranges_m: np.ndarray

    @property
    def beam_angles_rad(self) -> np.ndarray:
        return np.arange(self.ranges_m.size) * (2.0 * math.pi / self.ranges_m.size)


def _check_ranges(ranges_m: np.ndarray, max_range_m: float, name: str) -> None:
    if ranges_m.ndim != 1 or not 1 <= ranges_m.size <= MAX_PAYLOAD_BEAMS:
        raise ValueError(f"{name}: must hold 1 to {MAX_PAYLOAD_BEAMS} ranges, got {ranges_m.shape}")
    if not np.all(np.isfinite(ranges_m)) or ranges_m.min() < 0.0:
        raise ValueError(f"{name}: ranges must be finite and >= 0")
    # float32 rounding may put a max-range reading a hair above max_range_m.
    if ranges_m.max() > max_range_m * (1.0 + 1e-6):
        raise ValueError(f"{name}: a range exceeds max_range_m ({max_range_m})")


def encode_scan_payload(step: int, ranges_m: np.ndarray, max_range_m: float) -> bytes:
    """The radio payload carrying this robot's scan of ``step`` (validated like a decode)."""
    step = _positive_int(step, "step", minimum=0)
    if step > _MAX_STEP:
        raise ValueError(f"step: must be <= {_MAX_STEP}, got {step}")
    max_range_m = _real(max_range_m, "max_range_m", hi=MAX_PAYLOAD_RANGE_M, open_lo=True)
    ranges = np.asarray(ranges_m, dtype=np.float64)
    _check_ranges(ranges, max_range_m, "ranges_m")
    payload = msgpack.packb(
        {
            "v": PAYLOAD_VERSION,
            "t": PAYLOAD_TYPE,
            "step": step,
            "max_range_m": max_range_m,
            "ranges_m": ranges.astype("<f4").tobytes(),
        },
        use_bin_type=True,
    )
    if len(payload) > MAX_RADIO_PAYLOAD_BYTES:
        raise ValueError(f"payload: {len(payload)} bytes exceeds {MAX_RADIO_PAYLOAD_BYTES}")
    return payload


def decode_scan_payload(payload: bytes) -> TeammateScan:
    """A teammate's scan from its payload; anything malformed raises ``ValueError`` naming the
    field (``payload``, ``v``, ``t``, ``step``, ``max_range_m``, ``ranges_m``)."""
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        # ValueError, not TypeError: the shell counts every undecodable payload the same way.
        raise ValueError(f"payload: must be bytes, got {type(payload).__name__}")  # noqa: TRY004
    if len(payload) > MAX_RADIO_PAYLOAD_BYTES:
        raise ValueError(f"payload: {len(payload)} bytes exceeds {MAX_RADIO_PAYLOAD_BYTES}")
    try:
        message = msgpack.unpackb(
            bytes(payload),
            raw=False,
            strict_map_key=True,
            max_str_len=64,
            max_bin_len=MAX_RADIO_PAYLOAD_BYTES,
            max_array_len=16,
            max_map_len=16,
            max_ext_len=0,
        )
    except (ValueError, TypeError, msgpack.UnpackException) as error:
        raise ValueError(f"payload: not a valid msgpack message ({error})") from None
    if not isinstance(message, dict):
        raise ValueError(f"payload: must be a map, got {type(message).__name__}")  # noqa: TRY004
    for key in _PAYLOAD_KEYS:
        if key not in message:
            raise ValueError(f"{key}: missing from payload")
    extra = sorted(str(k) for k in message if k not in _PAYLOAD_KEYS)
    if extra:
        raise ValueError(f"{extra[0]}: unknown field in payload")
    version = message["v"]
    if isinstance(version, bool) or not isinstance(version, int) or version != PAYLOAD_VERSION:
        raise ValueError(f"v: unsupported payload version {message['v']!r}")
    if message["t"] != PAYLOAD_TYPE:
        raise ValueError(f"t: expected {PAYLOAD_TYPE!r}, got {message['t']!r}")
    step = message["step"]
    if isinstance(step, bool) or not isinstance(step, int) or not 0 <= step <= _MAX_STEP:
        raise ValueError(f"step: must be an integer in [0, {_MAX_STEP}], got {step!r}")
    try:
        max_range_m = _real(
            message["max_range_m"], "max_range_m", hi=MAX_PAYLOAD_RANGE_M, open_lo=True
        )
    except TypeError as error:
        raise ValueError(str(error)) from None
    raw = message["ranges_m"]
    if not isinstance(raw, bytes) or len(raw) % 4:
        raise ValueError("ranges_m: must be bytes of little-endian float32 values")
    ranges = np.frombuffer(raw, dtype="<f4").astype(np.float64)
    _check_ranges(ranges, max_range_m, "ranges_m")
    ranges = np.minimum(ranges, max_range_m)
    ranges.flags.writeable = False
    return TeammateScan(step=step, max_range_m=max_range_m, ranges_m=ranges)


# --------------------------------------------------------------------------------------------
# Fitness (eq. 1 and eq. 2)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TeammateView:
    """One teammate as eq. 2 needs it: its scan and where it stands relative to this robot
    (the sighting: distance, bearing in this robot's frame, heading relative to this robot's)."""

    distance_m: float
    bearing_rad: float
    relative_heading_rad: float
    scan: TeammateScan


def replicate_teammate(poses_m: np.ndarray, view: TeammateView) -> np.ndarray:
    """The teammate's pose replicated around each hypothesis ``(N, 3)`` from the relative
    measurement (002 §3.2: "the formation replicated around the i-th individual")."""
    direction = poses_m[:, 2] + view.bearing_rad
    out = np.empty_like(poses_m)
    out[:, 0] = poses_m[:, 0] + view.distance_m * np.cos(direction)
    out[:, 1] = poses_m[:, 1] + view.distance_m * np.sin(direction)
    out[:, 2] = wrap_angle(poses_m[:, 2] + view.relative_heading_rad)
    return out


class FitnessModel:
    """Eq. 1 and eq. 2 of 002 on a map, for a robot with ``beam_angles_rad`` and ``max_range_m``.

    ``peak`` = ``1 / (sqrt(2 pi) sigma)`` is the highest value of one term of eq. 1 (a scan that
    matches exactly), so eq. 2 with ``R`` teammates is at most ``(1 + R) * peak``.
    """

    def __init__(
        self,
        world_map: SegmentMap,
        beam_angles_rad: np.ndarray,
        max_range_m: float,
        sigma_m: float,
    ) -> None:
        self.world_map = world_map
        self.beam_angles_rad = np.asarray(beam_angles_rad, dtype=np.float64)
        self.max_range_m = float(max_range_m)
        self.sigma_m = float(sigma_m)
        self.peak = 1.0 / (_SQRT_2PI * self.sigma_m)
        self._half_inv_var = 0.5 / (self.sigma_m * self.sigma_m)
        x_min, y_min, x_max, y_max = world_map.bounds_m
        self._bounds = (x_min, y_min, x_max, y_max)

    def inside(self, poses_m: np.ndarray) -> np.ndarray:
        x_min, y_min, x_max, y_max = self._bounds
        x, y = poses_m[:, 0], poses_m[:, 1]
        return (x >= x_min) & (x <= x_max) & (y >= y_min) & (y <= y_max)

    def agreement(self, expected_m: np.ndarray, measured_m: np.ndarray) -> np.ndarray:
        """``(1/L) sum_j N(z_j - z^_j; 0, sigma)`` over the last axis: the sum of eq. 1."""
        diff = expected_m - measured_m
        return self.peak * np.mean(np.exp(-self._half_inv_var * diff * diff), axis=-1)

    def scan_fitness(self, poses_m: np.ndarray, ranges_m: np.ndarray) -> np.ndarray:
        """Eq. 1: agreement of the scan expected at each hypothesis ``(N, 3)`` with the measured
        ``ranges_m`` ``(L,)``; 0 outside the map bounds. Returns ``(N,)``."""
        expected = cast_rays(self.world_map, poses_m, self.beam_angles_rad, self.max_range_m)
        return np.where(self.inside(poses_m), self.agreement(expected, ranges_m), 0.0)

    def teammate_term(self, poses_m: np.ndarray, view: TeammateView) -> np.ndarray:
        """One addend of eq. 2's second sum: eq. 1 of the teammate's scan at its pose replicated
        around each hypothesis; 0 where the hypothesis or the replicated pose is off the map."""
        mates = replicate_teammate(poses_m, view)
        expected = cast_rays(
            self.world_map, mates, view.scan.beam_angles_rad, view.scan.max_range_m
        )
        on_map = self.inside(mates) & self.inside(poses_m)
        return np.where(on_map, self.agreement(expected, view.scan.ranges_m), 0.0)

    def team_fitness(
        self,
        poses_m: np.ndarray,
        ranges_m: np.ndarray,
        views: tuple[TeammateView, ...] | list[TeammateView] = (),
        view_poses_m: list[np.ndarray] | None = None,
    ) -> np.ndarray:
        """Eq. 2: eq. 1 plus one term per teammate in ``views``. With no teammate, eq. 1.

        ``view_poses_m[s]`` (optional) are the hypotheses from which teammate ``s`` is replicated
        when they differ from ``poses_m`` (the receiver's poses at the step of that scan)."""
        fitness = self.scan_fitness(poses_m, ranges_m)
        for s, view in enumerate(views):
            anchor = poses_m if view_poses_m is None else view_poses_m[s]
            fitness = fitness + self.teammate_term(anchor, view)
        return fitness


def inverse_unicycle(poses_m: np.ndarray, delta_s_m: float, delta_phi_rad: float) -> np.ndarray:
    """The poses from which eq. 3 (noise-free) with ``(delta_s, delta_phi)`` leads to
    ``poses_m``: heading ``phi - delta_phi``, position minus ``delta_s`` along
    ``phi - delta_phi / 2``."""
    out = np.empty_like(poses_m)
    heading_mid = poses_m[:, 2] - delta_phi_rad / 2.0
    out[:, 0] = poses_m[:, 0] - delta_s_m * np.cos(heading_mid)
    out[:, 1] = poses_m[:, 1] - delta_s_m * np.sin(heading_mid)
    out[:, 2] = wrap_angle(poses_m[:, 2] - delta_phi_rad)
    return out


# --------------------------------------------------------------------------------------------
# The localizers
# --------------------------------------------------------------------------------------------


def _check_setup(setup: LocalizerSetup) -> SegmentMap:
    if not isinstance(setup, LocalizerSetup):
        raise TypeError(f"setup must be a LocalizerSetup, got {type(setup).__name__}")
    try:
        world_map = build_map(setup.map_name)
    except KeyError as error:
        raise ValueError(f"map_name: {error.args[0]}") from None
    _positive_int(setup.n_beams, "n_beams")
    _real(setup.max_range_m, "max_range_m", open_lo=True)
    for name in (
        "laser_noise_std_m",
        "speed_std_mps",
        "turn_rate_std_rad_s",
        "relative_distance_std_m",
        "relative_orientation_std_rad",
    ):
        _real(getattr(setup, name), name)
    _real(setup.dt_s, "dt_s", open_lo=True)
    return world_map


class GeneticLocalizer:
    """What MR-SSGA and the simple GA share: the population, eq. 3 kinematic update, eq. 1-2
    fitness with teammates' scans, the best-individual estimate and the scan payload.
    Subclasses implement :meth:`_reproduce`."""

    params_type: ClassVar[type[GeneticParams]] = GeneticParams

    def __init__(
        self, setup: LocalizerSetup, params: GeneticParams, rng: np.random.Generator
    ) -> None:
        if not isinstance(params, self.params_type):
            raise TypeError(
                f"params must be a {self.params_type.__name__}, got {type(params).__name__}"
            )
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        self.setup = setup
        self.params = params
        self.rng = rng
        self.world_map = _check_setup(setup)
        beam_angles = np.arange(setup.n_beams) * (2.0 * math.pi / setup.n_beams)
        self.fitness_model = FitnessModel(
            self.world_map, beam_angles, setup.max_range_m, params.fitness_sigma_m
        )
        self._motion_std = np.array(
            [setup.speed_std_mps * setup.dt_s, setup.turn_rate_std_rad_s * setup.dt_s]
        )
        self._init_network()
        self.population = free_space_sample(
            self.world_map, params.population_size, rng, clearance_m=params.init_clearance_m
        )
        self.fitness = np.zeros(params.population_size)
        self._best = self.population[0].copy()
        self._elite: int | None = None
        self._step: int | None = None
        self._last_ranges: np.ndarray | None = None
        # Sightings of the current and the previous step, by robot id; own odometry of this step.
        self._sightings: dict[int, Sighting] = {}
        self._previous_sightings: dict[int, Sighting] = {}
        self._previous_step: int | None = None
        self._odometry = (0.0, 0.0)
        #: How many teammates entered eq. 2 at the last step.
        self.n_collaborators = 0
        #: Payloads that failed to decode, in all.
        self.rejected_payloads = 0
        #: ``(sender_id, ValueError)`` of the payloads skipped at the last step (the Localizer
        #: contract: the shell counts them).
        self.rejected: tuple[tuple[int, ValueError], ...] = ()

    @classmethod
    def from_config(cls, setup: LocalizerSetup, config: dict, rng: np.random.Generator):
        """Build from an algorithm-parameter dict (keys of :attr:`params_type`; an unknown key or
        an impossible value is a ValueError naming it)."""
        try:
            params = cls.params_type.from_dict(dict(config) if config is not None else {})
        except TypeError as error:
            raise ValueError(str(error)) from None
        return cls(setup, params, rng)

    def _init_network(self) -> None:
        """Hook for subclasses that lay the population on a network."""

    # -- Localizer protocol -------------------------------------------------------------------

    def step(self, obs: LaserObservation) -> None:
        ranges = self._check_observation(obs)
        self.rejected = ()
        self._advance_sightings(obs)
        self.population = self._kinematic_update(
            self.population, obs.odometry_delta_s_m, obs.odometry_delta_phi_rad
        )
        views, anchors = self._teammate_views(obs)
        self.n_collaborators = len(views)
        self.fitness = self.fitness_model.team_fitness(self.population, ranges, views, anchors)
        if self.params.refine_iterations > 0 and self.params.refine_individuals > 0:
            self._refine(ranges, views, anchors)
        self._best = self.population[int(np.argmax(self.fitness))].copy()
        peak = self.fitness_model.peak * (1 + len(views))
        self.population = self._reproduce(self.population, self.fitness, peak)
        # The elite: the best individual, copied unchanged by reproduction (MR-SSGA's mating
        # rules never replace it; the simple GA copies its elites); eq. 3 moves it noise-free.
        if self.params.elite_exact_motion:
            kept = np.flatnonzero(np.all(self.population == self._best, axis=1))
            self._elite = int(kept[0]) if kept.size else None
        self._last_ranges = ranges
        self._step = obs.step

    def estimate(self) -> np.ndarray:
        """The best individual of the last step ``(x_m, y_m, theta_rad)`` (before any step: an
        individual of the uniform initial population)."""
        return self._best.copy()

    def samples(self, n: int) -> np.ndarray:
        """At most ``n`` individuals of the population, evenly spaced through it (for observers)."""
        return evenly_spaced(self.population, n)

    def outgoing(self) -> bytes | None:
        """This step's scan for teammates' eq. 2 (None before the first step or when the robot
        does not cooperate)."""
        if not self.setup.cooperative or self._last_ranges is None or self._step is None:
            return None
        return encode_scan_payload(self._step, self._last_ranges, self.setup.max_range_m)

    # -- parts ----------------------------------------------------------------------------------

    def _check_observation(self, obs: LaserObservation) -> np.ndarray:
        if not isinstance(obs, LaserObservation):
            raise TypeError(f"obs must be a LaserObservation, got {type(obs).__name__}")
        if isinstance(obs.step, bool) or not isinstance(obs.step, (int, np.integer)):
            raise TypeError(f"step: must be an integer, got {obs.step!r}")
        for name in ("odometry_delta_s_m", "odometry_delta_phi_rad"):
            value = getattr(obs, name)
            if not isinstance(value, (int, float, np.number)) or not math.isfinite(value):
                raise ValueError(f"{name}: must be a finite number, got {value!r}")
        ranges = np.asarray(obs.ranges_m, dtype=np.float64)
        if ranges.shape != (self.setup.n_beams,):
            raise ValueError(
                f"ranges_m: expected shape ({self.setup.n_beams},), got {ranges.shape}"
            )
        if not np.all(np.isfinite(ranges)) or ranges.min() < 0.0:
            raise ValueError("ranges_m: ranges must be finite and >= 0")
        return ranges

    def _kinematic_update(self, poses_m: np.ndarray, delta_s_m: float, delta_phi_rad: float):
        """Eq. 3 on every individual with the odometry plus Gaussian noise of the motion
        model's standard deviations; with ``elite_exact_motion``, none for the last step's best
        individual (see the module docstring). One ``rng.normal`` draw ``(N, 2)`` in every case."""
        noise = self.rng.normal(0.0, 1.0, size=(poses_m.shape[0], 2)) * self._motion_std
        if self._elite is not None and self._elite < noise.shape[0]:  # elite_exact_motion
            noise[self._elite] = 0.0
        self._odometry = (float(delta_s_m), float(delta_phi_rad))
        return unicycle_model(poses_m, delta_s_m + noise[:, 0], delta_phi_rad + noise[:, 1])

    def _advance_sightings(self, obs: LaserObservation) -> None:
        self._previous_sightings, self._previous_step = self._sightings, self._step
        self._sightings = {}
        for sighting in obs.sightings:
            if not isinstance(sighting, Sighting):
                raise TypeError(f"sightings: must hold Sighting, got {type(sighting).__name__}")
            values = (sighting.distance_m, sighting.bearing_rad, sighting.relative_heading_rad)
            if not all(isinstance(v, (int, float, np.number)) and math.isfinite(v) for v in values):
                raise ValueError(f"sightings: robot {sighting.robot_id} has a non-finite value")
            self._sightings[sighting.robot_id] = sighting

    def _teammate_views(self, obs: LaserObservation) -> tuple[list[TeammateView], list[np.ndarray]]:
        """Teammates that enter eq. 2 at this step: heard (a decodable scan of this step or the
        previous one) and seen at the step of that scan. For a scan of the previous step the
        hypotheses are moved back by inverting eq. 3 with this step's odometry."""
        views: list[TeammateView] = []
        anchors: list[np.ndarray] = []
        if not self.setup.cooperative:
            return views, anchors
        back: np.ndarray | None = None
        for message in obs.received:
            if message.sender_id == self.setup.robot_id:
                continue
            try:
                mate_scan = decode_scan_payload(message.payload)
            except ValueError as error:
                self.rejected_payloads += 1
                self.rejected += ((message.sender_id, error),)
                continue
            if mate_scan.step == obs.step:
                sighting, anchor = self._sightings.get(message.sender_id), self.population
            elif self._previous_step is not None and mate_scan.step == self._previous_step:
                sighting = self._previous_sightings.get(message.sender_id)
                if sighting is not None and back is None:
                    back = inverse_unicycle(self.population, *self._odometry)
                anchor = back
            else:
                continue
            if sighting is None:  # heard but not seen: eq. 2 cannot apply
                continue
            views.append(
                TeammateView(
                    distance_m=float(sighting.distance_m),
                    bearing_rad=float(sighting.bearing_rad),
                    relative_heading_rad=float(sighting.relative_heading_rad),
                    scan=mate_scan,
                )
            )
            anchors.append(anchor)
        return views, anchors

    def _refine(self, ranges: np.ndarray, views, anchors) -> None:
        """The option of :mod:`~swarmloc.agents.laser.refine`: climb eq. 1-2 of this step from the
        fittest individuals; each refined individual replaces its original."""
        p = self.params
        current = [anchor is self.population for anchor in anchors]
        odometry = self._odometry

        def score(poses: np.ndarray) -> np.ndarray:
            back = inverse_unicycle(poses, *odometry) if not all(current) else None
            return self.fitness_model.team_fitness(
                poses, ranges, views, [poses if now else back for now in current])

        top = np.argsort(-self.fitness, kind="stable")[: p.refine_individuals]
        poses, values = compass_search(score, self.population[top], self.fitness[top],
                                       p.refine_iterations, p.refine_step_m, p.refine_step_rad)
        self.population = self.population.copy()
        self.population[top] = poses
        self.fitness = self.fitness.copy()
        self.fitness[top] = values

    def _reproduce(self, population_m: np.ndarray, fitness: np.ndarray, peak: float):
        raise NotImplementedError


class SSGALocalizer(GeneticLocalizer):
    """MR-SSGA (002 §3, Algorithm 1): the population on a complex network, mating by table 1.

    ``SSGALocalizer(setup, SSGAParams(...), rng)`` or ``SSGALocalizer.from_config(setup,
    {"population_size": 50, "network": "barabasi_albert"}, rng)``.
    """

    params_type = SSGAParams

    def _init_network(self) -> None:
        #: The population's links ``(E, 2)``, pairs ``i < j``.
        self.edges = build_network(self.params, self.rng)

    def _reproduce(self, population_m: np.ndarray, fitness: np.ndarray, peak: float):
        return network_mating(population_m, fitness, self.edges, peak, self.params, self.rng)
