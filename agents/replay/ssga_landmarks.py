"""MR-SSGA (seed 002) on MRCLAM's landmark range-and-bearing readings: the ``ssga`` localizer.

Seed ``/work/shared/seeds/002_fe2ac635ba0eab3e.txt`` (Gasparri, Panzieri, Pascucci, *A
Spatially Structured Genetic Algorithm for Multi-Robot Localization*). The laser family's
MR-SSGA (``agents/laser/ssga.py``) implements it for laser scans; this module reuses its pure
pieces by import and replaces only what is about sensors:

- **Population on a complex network** (002 §2.1-2.2, §3): one pose hypothesis
  ``(x_m, y_m, theta_rad)`` per vertex of a Watts-Strogatz (small-world, the default) or
  Barabási-Albert network (:func:`~swarmloc.agents.laser.ssga.build_network`, networkx).
- **Mating rules, table 1 and Algorithm 1** (:func:`~swarmloc.agents.laser.ssga.network_mating`):
  HIGH (fitness above the population mean) or LOW; over every link, HIGH-HIGH: the lower is
  replaced with the crossover of the two; HIGH-LOW: the LOW one with a mutation of the HIGH
  one; LOW-LOW: both self-mutate. Mutation "inversely proportional to its fitness" (§2.1):
  the laser module's :func:`~swarmloc.agents.laser.ssga.mutation_std`, with the fitness taken
  relative to ``fitness_reference`` per term (below). Synchronous over the links, as the laser
  module reads Algorithm 1.
- **Fitness, eq. 1**: "a measure of similarity between data coming from a real robot and the
  expected one computed for a given hypothesis", the mean of Gaussians of the residuals
  ``(1/L) sum_j N(z_j - z^_j)`` over the L measurements; here over the landmark readings
  (range and bearing) of the last
  ``window_s`` seconds: :class:`~swarmloc.agents.replay.populations.ReadingWindow` (shared with
  CFS-GA) brings each reading to the present by the odometry since, and each term is
  :func:`~swarmloc.agents.replay.localizers.landmark_fitness_terms`'
  ``exp(-(z_r^2 + z_b^2) / 2)``, the residuals in units of the reading's std.
- **Cooperative fitness, eq. 2**: eq. 1 plus, for each teammate ``s`` "in the viewing area",
  ``(1/L_s) sum_l N(...)`` of that teammate's data against "the formation replicated around the
  i-th individual" (below: what a teammate's data is on MRCLAM).
- **Kinematic update, eq. 3**: every tick every individual moves by the unicycle with the
  tick's odometry ``(v dt, omega dt)`` plus its own draw of the white noise ``n_s``, with the
  standard deviations of :meth:`~swarmloc.agents.replay.localizers.MotionNoise.tick_std` (the
  odometry on MRCLAM is the velocity command, so this noise is what lets the population follow
  the true motion); with ``elite_exact_motion`` the last generation's best individual moves by
  the odometry alone (the laser module's option, off by default).
- **No prior** (§5.2: "hypotheses are spread uniformly over the whole environment"): from an
  unknown start the initial population is uniform over the start area and every heading
  (:meth:`~swarmloc.agents.replay.localizers.LandmarkSetup.initial_hypotheses`, which also
  draws it around the known pose for tracking).

Readings of the text for landmarks (the seed leaves them open, or is about laser scans):

- *sigma.* Eq. 1's ``sigma`` is "a measure of confidence", one value for every beam (the laser
  module's ``fitness_sigma_m``). A camera's range noise grows with the range and its bearing is
  an angle, so each residual is divided by that reading's own std (the camera model's, grown by
  the motion noise since the reading) and the Gaussian's ``1 / (sqrt(2 pi) sigma)`` factor is
  dropped: each term lies in ``[0, 1]`` and a near and a far landmark weigh alike (with one
  shared sigma the factor is a constant: the HIGH/LOW comparison with the mean does not see
  it, and the mutation takes the fitness relative to its scale). ``fitness_sigma_m`` is therefore not a parameter here (rejected, named).
- *The window.* A laser scan of 8 beams fixes a pose; one camera frame holds one to four
  landmark readings, and one reading fits a whole circle of poses. So eq. 1's ``L``
  measurements are the readings of the last ``window_s`` seconds (CFS-GA's landmark fitness,
  and its bookkeeping, :class:`~swarmloc.agents.replay.populations.ReadingWindow`).
- *Generations.* One generation (fitness, Algorithm 1) on each tick that brings a landmark
  reading (or, cooperative, a reading of or by a teammate); between them eq. 3 only (002's
  robots sense every step; MRCLAM's camera gives a few frames per second at 50 ticks per
  second).
- *Eq. 2 without teammates' scans.* In 002 a teammate sends its scan, and the receiver, knowing
  the relative distance and orientation, evaluates that scan at the teammate's pose replicated
  around each hypothesis. MRCLAM's robots measure range and bearing of each other, not the
  relative heading, and the replay's report (:class:`~swarmloc.agents.replay.localizers.TeammateReport`)
  carries the sender's pose estimate and covariance, not its readings. So teammate ``s``'s term
  is ``L_s = 1`` Gaussian: the density of the teammate's broadcast belief at the place the
  relative reading and the hypothesis put it,
  :func:`~swarmloc.agents.replay.populations.teammate_log_density` unnormalised
  (``exp(-maha^2 / 2)``, in ``[0, 1]`` like a landmark term; as CFS-GA's ``teammate_fitness``),
  for each teammate this robot measured this tick or that measured it
  (:func:`~swarmloc.agents.replay.localizers.relative_readings`). As in eq. 2 the teammates' terms
  are *added* to eq. 1's mean (CFS-GA instead averages them in as further terms), so the
  highest fitness is ``1 + R`` with ``R`` teammates (``R`` alone on a tick without landmark
  readings in the window); the mutation scale uses that maximum. ``teammate_fitness=false``
  leaves the teammates out (eq. 1 only).
- *Hypotheses off the field* (outside ``LandmarkSetup.bounds_m``) have fitness 0, as the laser
  module's off the map.
- *Estimate* (002 names only "the estimate"; the laser module uses the best individual):
  ``estimate="best"``, the best individual of the last generation (it survives reproduction),
  moved by the odometry between generations; or ``"median"``, CFS-GA's landmark estimate:
  the population's coordinate-wise median position with the circular mean heading of the
  individuals within ``median_radius_m`` of it
  (:func:`~swarmloc.agents.replay.populations.median_pose`). Default and why: below.
- *Report* (cooperative): the estimate and the population's covariance about it (uniform
  weights; grown by the motion noise between generations), as CFS-GA reports; no individuals
  are shared (002 shares sensor data, not hypotheses; CFS-GA's virtual population is 003's).

Defaults, measured on MRCLAM Dataset 6 (``deploy/lab/replay/mrclam.py``'s ``run_replay`` and
``score``; unknown start, the first 180 s, self-calibrating camera; "robot-seeds" are those under
0.3 m within 60 s and staying there to 180 s, five robots a seed). They were chosen on the seeds
they are measured on (Dataset 6 is the only data set here):

- *Mutation scale* (``fitness_reference``, 0.5): with the laser module's scale (1, the highest
  fitness) an individual at the true pose, worth about 0.5, mutates with about half of
  ``mutation_std_max`` every generation. From the known start over the whole run (seed 0,
  population 100, 1 s window, ``mutation_std_max`` 0.5): mean position RMSE 0.350 m alone and
  0.201 m cooperative with 1, 0.273 / 0.169 m with 0.5.
- *Population, window, mutation* (:data:`SSGA_MRCLAM_DEFAULTS`, ``window_s``). The laser
  module's defaults (population 100, ``mutation_std_max`` 0.5 m / 0.5 rad) with CFS-GA's 1 s
  window: 12/100 robot-seeds alone, 6/100 cooperative (seeds 0-19). Population 200, a 2 s
  window and ``mutation_std_max`` 0.2 m / 0.2 rad: 21/100 alone, 23/100 cooperative. On seeds
  0-4, cooperative (of 25): each change alone 2-5, windows 2 and 3 s x mutation 0.1 and 0.2 x
  population 100 and 200 between 3 and 8; the network (on the defaults): Watts-Strogatz with 2
  or 6 neighbours 8 and 4, rewiring 0.02 9, Barabási-Albert 5 (kept: 4 neighbours, 0.1).
- *Estimate*: the median (seeds 0-9: 10/50 alone, 13/50 cooperative) against the best
  individual (2/50 and 1/50): the best individual jumps between the individuals that explain
  the window about equally well.
- *Eq. 2 as printed*: the teammates' terms averaged with the landmark terms (CFS-GA's way) 1
  of 25 cooperative robot-seeds (seeds 0-4) against 2-8; each teammate term weighted 0.5:
  23/100 (seeds 0-19, as with 1), weighted 0.25: 16/100.

What limits it on Dataset 6 is tracking, not search: cooperative, 98 of the 100 robot-seeds
are under 0.3 m to stay by 180 s, but most get there after 60 s or leave 0.3 m again in the
gaps without landmark readings (robot 2's 45 s from 111 s; the odometry is the velocity
command). From the known start over the whole run (seeds 0-2) the mean position RMSE is
0.188 m alone, 0.134 m cooperative (CFS-GA 0.191 / 0.146 m, the particle filter 0.201 / 0.115 m,
``docs/mrclam/README.md``).

Parameters: the keys of :class:`SsgaMrclamParams` are this module's; those of
:class:`~swarmloc.agents.laser.ssga.SSGAParams` but ``fitness_sigma_m`` and
``init_clearance_m`` (laser-map notions) go to the GA (over :data:`SSGA_MRCLAM_DEFAULTS`). An
unknown key, or an impossible value, is a ``ValueError`` naming it.

Random draws (a run is deterministic given the robot's generator): the network (one integer
for networkx), the initial population, then each tick the eq. 3 noise ``(N, 2)``, and on a
generation's tick :func:`~swarmloc.agents.laser.ssga.network_mating`'s draws.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from swarmloc.agents.laser.ssga import SSGAParams, build_network, network_mating
from swarmloc.agents.replay.localizers import (
    LandmarkSetup,
    _real,
    calibrated,
    check_observation,
    reject_unknown_keys,
    unicycle,
)
from swarmloc.agents.replay.populations import (
    ReadingWindow,
    _Cooperation,
    _motion_growth,
    _weighted_pose_covariance,
    median_pose,
    teammate_log_density,
    tick_motion,
)
from swarmloc.world.replay.replay import LandmarkObservation

#: Keys of :class:`SSGAParams` that mean nothing for landmarks, and why.
NOT_FOR_LANDMARKS = {
    "fitness_sigma_m": "each residual is scaled by its reading's std from the camera model",
    "init_clearance_m": "the initial population is the setup's (known pose or start area)",
}
#: The GA's defaults on MRCLAM (the others are :class:`SSGAParams`' own).
SSGA_MRCLAM_DEFAULTS = {"population_size": 200, "mutation_std_max_m": 0.2,
                        "mutation_std_max_rad": 0.2}


@dataclass(frozen=True)
class SsgaMrclamParams:
    """The landmark MR-SSGA's own parameters (the module docstring says why each)."""

    #: Eq. 1 covers the landmark readings of the last ``window_s`` seconds.
    window_s: float = 2.0
    #: Eq. 2: the teammates' relative readings as further terms (False: eq. 1 only).
    teammate_fitness: bool = True
    #: "best": the best individual; "median": the median position, circular mean heading of
    #: the individuals within ``median_radius_m`` of it.
    estimate: str = "median"
    median_radius_m: float = 0.5
    #: The fitness of one term (a landmark reading, a teammate) that the mutation takes as
    #: full: an individual of fitness ``f`` with ``R`` teammates in eq. 2 mutates with the
    #: stds of :func:`~swarmloc.agents.laser.ssga.mutation_std` at ``f / (fitness_reference
    #: (1 + R))``. 0.5: what a term is worth on average at the true pose (``E exp(-chi2_2 / 2)
    #: = 1/2`` for Gaussian residuals); 1: the highest a term can give (the laser module's).
    fitness_reference: float = 0.5

    def __post_init__(self):
        _real(self.window_s, "window_s")
        if not 0.0 < _real(self.fitness_reference, "fitness_reference") <= 1.0:
            raise ValueError(f"fitness_reference must be in (0, 1], got {self.fitness_reference!r}")
        if not isinstance(self.teammate_fitness, bool):
            raise TypeError(f"teammate_fitness must be true or false, got {self.teammate_fitness!r}")
        if self.estimate not in ("best", "median"):
            raise ValueError(f"estimate: expected 'best' or 'median', got {self.estimate!r}")
        _real(self.median_radius_m, "median_radius_m", positive=True)


def ssga_params(params: Mapping) -> tuple[SsgaMrclamParams, SSGAParams]:
    """``(SsgaMrclamParams, SSGAParams)`` from one mapping (see the module docstring); an
    unknown key is a ValueError naming it and the closest valid one."""
    if not isinstance(params, Mapping):
        raise TypeError(f"ssga parameters must be a mapping, got {type(params).__name__}")
    for key, why in NOT_FOR_LANDMARKS.items():
        if key in params:
            raise ValueError(f"{key}: not a parameter of the landmark ssga ({why})")
    own_names = {f.name for f in fields(SsgaMrclamParams)}
    core_names = {f.name for f in fields(SSGAParams)} - set(NOT_FOR_LANDMARKS)
    reject_unknown_keys(params, sorted(own_names | core_names), "ssga")
    own = SsgaMrclamParams(**{k: v for k, v in params.items() if k in own_names})
    core = SSGAParams(**{**SSGA_MRCLAM_DEFAULTS,
                         **{k: v for k, v in params.items() if k in core_names}})
    return own, core


class SsgaLocalizer:
    """MR-SSGA (seed 002) on landmark readings; see the module docstring.

    ``SsgaLocalizer(setup, {"population_size": 200, "network": "barabasi_albert"}, rng)``."""

    def __init__(self, setup: LandmarkSetup, params: Mapping, rng: np.random.Generator):
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        self.params, self.ga_params = ssga_params(params)
        self.setup = setup
        self.rng = rng
        n = self.ga_params.population_size
        #: The population's links ``(E, 2)``, pairs ``i < j`` (fixed for the run).
        self.edges = build_network(self.ga_params, rng)
        self.population = setup.initial_hypotheses(n, rng)
        #: Eq. 1-2 of the last generation, by individual (before its reproduction).
        self.fitness = np.zeros(n)
        self.window = ReadingWindow(self.params.window_s)
        self.coop = _Cooperation(setup)
        self._pose = setup.initial_pose.copy()
        self._cov = setup.initial_covariance()
        self._elite: int | None = None
        self.generations = 0
        #: Teammates in eq. 2 at the last generation.
        self.n_collaborators = 0

    @property
    def rejected(self):
        return self.coop.rejected

    @property
    def covariance(self) -> np.ndarray:
        """The pose covariance broadcast to the teammates: the population's about the estimate
        at the last generation, grown by the motion noise since."""
        return self._cov.copy()

    def _kinematic_update(self, distance_m: float, turn_rad: float, std_d: float,
                          std_t: float) -> None:
        """Eq. 3 with each individual's own draw of the noise (one ``(N, 2)`` normal draw);
        none for the elite with ``elite_exact_motion``."""
        noise = self.rng.normal(0.0, 1.0, size=(self.population.shape[0], 2))
        noise[:, 0] *= std_d
        noise[:, 1] *= std_t
        if self._elite is not None:
            noise[self._elite] = 0.0
        self.population = unicycle(self.population, distance_m + noise[:, 0],
                                   turn_rad + noise[:, 1])

    def _inside(self, poses: np.ndarray) -> np.ndarray:
        x0, y0, x1, y1 = self.setup.bounds_m
        return (poses[:, 0] >= x0) & (poses[:, 0] <= x1) & (poses[:, 1] >= y0) & \
            (poses[:, 1] <= y1)

    def step(self, obs: LandmarkObservation) -> None:
        setup = self.setup
        check_observation(obs, setup.robot_id)
        obs = calibrated(obs, setup.camera)
        distance, turn, std_d, std_t = tick_motion(obs, setup.motion)
        self._kinematic_update(distance, turn, std_d, std_t)
        self._cov = self._cov + _motion_growth(std_d, std_t)
        seen = self.window.record(obs, setup, distance, turn, std_d, std_t)
        readings = self.coop.readings(obs)
        teammates = readings if self.params.teammate_fitness else []
        if seen or teammates:
            self._generation(teammates)
        else:
            self._pose = unicycle(self._pose[None, :], distance, turn)[0]
        self.coop.publish(obs, self._pose, self._cov)

    def _generation(self, teammates) -> None:
        """Eq. 1-2 on the population, then Algorithm 1; the estimate and its covariance."""
        camera = self.setup.camera
        population = self.population
        window_terms, n_window = self.window.fitness_terms(camera)
        fitness = window_terms(population) / n_window if n_window else np.zeros(len(population))
        for reading in teammates:  # eq. 2's second sum, one term per teammate
            fitness = fitness + np.exp(teammate_log_density(
                population, reading, self._pose, self._cov, camera, normalised=False))
        fitness = np.where(self._inside(population), fitness, 0.0)
        peak = self.params.fitness_reference * ((1.0 if n_window else 0.0) + len(teammates))
        self.fitness = fitness
        self.n_collaborators = len(teammates)
        best = population[int(np.argmax(fitness))].copy()
        self.population = network_mating(population, fitness, self.edges, peak, self.ga_params,
                                         self.rng)
        if self.ga_params.elite_exact_motion:
            kept = np.flatnonzero(np.all(self.population == best, axis=1))
            self._elite = int(kept[0]) if kept.size else None
        self.generations += 1
        if self.params.estimate == "best":
            self._pose = best
        else:
            self._pose = median_pose(self.population, self.params.median_radius_m)
        n = self.population.shape[0]
        self._cov = _weighted_pose_covariance(self.population, np.full(n, 1.0 / n), self._pose)

    def estimate(self) -> np.ndarray:
        return self._pose.copy()

    def outgoing(self) -> bytes | None:
        return self.coop.out
