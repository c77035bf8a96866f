"""The modern AMCL (``amcl``): Monte Carlo localization as ROS ``amcl`` does it, the stronger
particle-filter baseline beside Player's (:mod:`swarmloc.agents.laser.amcl_player`,
``amcl-player``, the filter seed 003 actually ran; issue 43). Reports label the two apart.

Seed 002 (``002_fe2ac635ba0eab3e.txt``) §6, table 3, compares MR-SSGA with "a collaborative
particle filter (PF)" at populations of 50 and 100; seed 003 (``003_5278cbbbf8cc61de.txt``) §V
compares CFS-GA with the Player/Stage "Adaptive Monte Carlo Localization algorithm (AMCL)" (its
ref. [20], Fox 2003, KLD-sampling) that "simply adds a number of randomly placed samples at every
time instant as detailed in [21]" (Probabilistic Robotics, ch. 8, Augmented_MCL), with "adaptive
population ranging from 10000 to 1000 particles". Neither seed gives more of the filter, so this
module follows those references, and ROS ``amcl`` where they leave a choice open: a likelihood
field widened to 0.5 m and Augmented_MCL's adaptive injection, which make it stronger than the
Player driver 003 compared with (its ``recovery_alpha`` parameters are ROS's; Player's ``pf.c``
has none).

One step (:meth:`AugmentedMCL.update`, driven by :meth:`AMCLLocalizer.step`):

1. **Motion** (:meth:`AugmentedMCL.predict`): every particle moves by the odometry
   ``(delta_s, delta_phi)`` plus its own Gaussian noise, through the unicycle of eq. 3 of 002
   (``world.laser.laser.unicycle_model``). Noise standard deviations per step:
   ``speed_std_mps * dt_s`` and ``turn_rate_std_rad_s * dt_s`` of the setup, times
   ``AMCLParams.motion_noise_scale``.
2. **Measurement** (:meth:`AugmentedMCL.correct`): weights times ``exp(log_likelihood(particles))``.
   **The filter core never sees a sensor**: ``log_likelihood`` is any callable
   ``(P, 3) poses -> (P,)`` log-likelihoods (``-inf`` allowed, NaN not), built per step by the
   caller. :class:`AMCLLocalizer` builds the laser one (:class:`LaserLikelihoodField`, the
   likelihood-field model of Probabilistic Robotics §6.4: project each beam's end point, look up
   the distance ``d`` to the nearest wall in a grid precomputed once per map, and score
   ``z_hit N(d; 0, sigma_hit) + z_rand / max_range``; beams at maximum range carry no hit and are
   skipped, as in ``amcl``). A landmark range-and-bearing sensor, or any other, plugs into the same
   seam: build :class:`AugmentedMCL` with a pose sampler and call
   ``update(delta_s, delta_phi, my_log_likelihood)``.
3. **Recovery averages** (Augmented_MCL): ``w_avg`` is the mean measurement likelihood of the
   predicted particles, ``w_slow += alpha_slow (w_avg - w_slow)``,
   ``w_fast += alpha_fast (w_avg - w_fast)`` (kept in the log domain: exact, and safe for any
   scale of likelihood); the injection probability is ``max(0, 1 - w_fast / w_slow)``.
4. **Teammates** (the collaborative variant, Fox, Burgard, Kruppa, Thrun 2000, ref. [5] of 002 and
   [6] of 003): a robot that *sees* a teammate (a :class:`~swarmloc.agents.laser.localizer.Sighting`:
   distance, bearing, relative heading) and has its broadcast belief summary (a small set of
   weighted pose samples with a kernel, :class:`BeliefSummary`) multiplies each particle's
   weight by the density of the teammate's belief at the pose that particle predicts for the
   teammate through the measured relative pose
   (:func:`~swarmloc.agents.laser.amcl_belief.teammate_log_factor`), with the relative
   observation noise, mixed with a uniform density (``teammate_outlier_probability``) so that a
   teammate that is wrong cannot erase the true hypothesis. Optional, beyond the seeds' baseline
   (``teammate_reset_fraction`` > 0, off by default): when the teammate's belief contradicts this
   robot's, a fraction of the resampled particles is replaced by poses drawn from the teammate's
   belief through the inverse sighting (:func:`poses_from_teammate`), since reweighting cannot
   move a belief whose particles all sit in the wrong place.
5. **Resampling** (:meth:`AugmentedMCL.resample`): the size comes from KLD-sampling (Fox 2003):
   particles are drawn one at a time from the weighted set and counted into histogram bins
   (``bin_size_m`` x ``bin_size_m`` x ``bin_size_rad``); drawing stops once ``n >= n_chi(k)``
   (:func:`~swarmloc.agents.laser.amcl_sampling.kld_sample_count`, Wilson-Hilferty form of the
   chi-square quantile, ``k`` = bins hit),
   clamped to ``[min_particles, max_particles]``. That count of particles is then drawn with
   low-variance (systematic) resampling (:func:`low_variance_resample`), and each one is replaced
   with probability ``max(0, 1 - w_fast / w_slow)`` by a random pose from free space.
6. **Estimate**: particles are grouped into clusters of adjacent occupied histogram bins (the
   heading axis wraps around), as ``amcl`` clusters, and the estimate is the weighted mean of the
   heaviest cluster, headings by circular mean (:func:`best_cluster_estimate`). It is taken on the
   weighted posterior, before resampling adds its noise.

Parameters: :class:`AMCLParams` (defaults from ``amcl`` and Fox 2003; :meth:`AMCLParams.seed_003`
and :meth:`AMCLParams.fixed` give the two seeds' populations). All randomness comes from the
``numpy.random.Generator`` given to the constructor, in a fixed order per step, so a run is
reproducible; :meth:`AMCLLocalizer.outgoing` draws nothing.

Radio payload (msgpack map, about 1.1 KiB for the default 64 samples, at most
``MAX_RADIO_PAYLOAD_BYTES``): ``{"kind": "swarmloc.amcl.belief", "v": 1, "id": sender, "step": k,
"poses": <bin: K x 3 little-endian float32>, "weights": <bin: K float32>, "kernel": [std_m,
std_rad], "odom": [delta_s_m, delta_phi_rad]}``; :func:`decode_belief` rejects anything else with
``ValueError`` naming the field. :meth:`AMCLLocalizer.step` never raises on a bad payload: it skips
it and lists it in :attr:`AMCLLocalizer.rejected` (``(sender_id, error)`` of the last step).

The particle-set arithmetic (KLD sample sizes, low-variance resampling, histogram bins and
clusters, the recovery probability) is :mod:`swarmloc.agents.laser.amcl_sampling`; the belief
summaries teammates broadcast, their codec and the teammate factor are
:mod:`swarmloc.agents.laser.amcl_belief`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from statistics import NormalDist

import numpy as np
from scipy.special import logsumexp

from swarmloc.agents.laser.amcl_belief import (
    MAX_SHARED_SAMPLES,
    BeliefSummary,
    decode_belief,
    encode_belief,
    mix_with_uniform,
    poses_from_teammate,
    teammate_log_density,
)
from swarmloc.agents.laser.amcl_sampling import (
    TWO_PI,
    _integer,
    best_cluster_estimate,
    cluster_labels,
    histogram_bin_keys,
    kld_sample_size,
    low_variance_resample,
    recovery_probability,
)
from swarmloc.agents.laser.localizer import (
    LaserObservation,
    LocalizerSetup,
    RadioMessage,
    Sighting,
)
from swarmloc.config import did_you_mean
from swarmloc.world.laser.laser import unicycle_model, wrap_angle
from swarmloc.world.laser.maps import SegmentMap, build_map, distance_to_walls, free_space_sample

#: Upper bound on particle counts (memory: a few hundred bytes per particle and step).
MAX_PARTICLES_LIMIT = 1_000_000

LogLikelihood = Callable[[np.ndarray], np.ndarray]
PoseSampler = Callable[[int, np.random.Generator], np.ndarray]


# --------------------------------------------------------------------------------------------
# Parameters
# --------------------------------------------------------------------------------------------


def _number(value, name: str) -> float:
    if isinstance(value, (bool, str)) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        raise TypeError(f"{name} must be a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return number


@dataclass(frozen=True)
class AMCLParams:
    """Parameters of the AMCL-style filter. Defaults: ROS/Player ``amcl`` and Fox 2003.

    Seed 003 gives only the population range (1000 to 10000, :meth:`seed_003`); seed 002 only the
    population (50 or 100, :meth:`fixed`). Everything else is the references' usual setting.
    """

    #: KLD-sampling bounds on the particle count (Fox 2003; ``amcl`` min_particles/max_particles).
    #: The filter starts with ``max_particles`` spread over free space (global localization).
    min_particles: int = 500
    max_particles: int = 5000
    #: KLD bound: with probability ``1 - kld_delta`` the K-L divergence between the sample-based
    #: and the true posterior (on the histogram) stays below ``kld_epsilon`` (Fox 2003 §3).
    kld_epsilon: float = 0.05
    kld_delta: float = 0.01
    #: Histogram bins for KLD-sampling and clustering (``amcl``: 0.5 m, 0.5 m, 10 deg).
    bin_size_m: float = 0.5
    bin_size_rad: float = math.radians(10.0)
    #: Random-particle injection driven by the slow and fast likelihood averages (Augmented_MCL,
    #: Probabilistic Robotics table 8.3); ``0 < alpha_slow < alpha_fast < 1``.
    recovery: bool = True
    alpha_slow: float = 0.001
    alpha_fast: float = 0.1
    #: Multiplies the odometry noise of the setup in the motion update (1: the true noise).
    motion_noise_scale: float = 1.0
    #: Likelihood field (Probabilistic Robotics §6.4; ``amcl`` laser_sigma_hit, laser_z_hit,
    #: laser_z_rand, laser_likelihood_max_dist). ``z_hit + z_rand = 1``. ``sigma_hit_m`` is wider
    #: than ``amcl``'s 0.2 m: ``amcl`` adds the cubes of the beam likelihoods, far flatter than the
    #: product used here, and with the product 0.2 m collapses global localization onto the first
    #: scan's best guess (office map, 500-5000 particles, 10 seeds: 6 settled within 150 steps
    #: with 0.2 m, 10 with 0.5 m; tracking error about 3 cm vs 6 cm).
    sigma_hit_m: float = 0.5
    z_hit: float = 0.95
    z_rand: float = 0.05
    likelihood_max_distance_m: float = 2.0
    field_resolution_m: float = 0.05
    #: The laser log-likelihood is multiplied by this (0, 1]: beams are not independent, and a
    #: product of 18 sharp beam likelihoods collapses a sparse particle set on the first scan.
    likelihood_exponent: float = 1.0
    #: Clearance from walls of the poses drawn for the initial set and for recovery.
    sample_clearance_m: float = 0.2
    #: Collaborative variant: how many pose samples a robot broadcasts, the kernel put on
    #: each, the weight of its heaviest cluster needed before it shares at all (a spread-out
    #: belief carries no information worth the radio), and the probability with which a receiver
    #: treats a teammate's belief as wrong (mixed with a uniform density).
    share_samples: int = 64
    share_kernel_std_m: float = 0.25
    share_kernel_std_rad: float = 0.15
    share_min_cluster_weight: float = 0.5
    teammate_outlier_probability: float = 0.1
    #: Beyond Fox et al. 2000 (off by default, the seeds' baseline only reweights): when a seen
    #: teammate's belief contradicts this robot's (the weighted mean of the teammate density is
    #: below a uniform belief's), this fraction of the resampled particles is replaced by poses
    #: drawn from the teammate's belief through the inverse sighting (:func:`poses_from_teammate`,
    #: sensor resetting with the teammate as the sensor). Reweighting alone cannot move a robot
    #: whose particles all sit in the wrong place.
    teammate_reset_fraction: float = 0.0

    def __post_init__(self) -> None:
        for name in ("min_particles", "max_particles", "share_samples"):
            _integer(getattr(self, name), name)
        for f in fields(self):
            if f.name not in ("min_particles", "max_particles", "share_samples", "recovery"):
                _number(getattr(self, f.name), f.name)
        if not isinstance(self.recovery, bool):
            raise TypeError(f"recovery must be true or false, got {self.recovery!r}")
        if self.min_particles < 1:
            raise ValueError(f"min_particles must be >= 1, got {self.min_particles}")
        if self.max_particles > MAX_PARTICLES_LIMIT:
            raise ValueError(
                f"max_particles must be <= {MAX_PARTICLES_LIMIT}, got {self.max_particles}"
            )
        if self.min_particles > self.max_particles:
            raise ValueError(
                f"min_particles ({self.min_particles}) must not exceed "
                f"max_particles ({self.max_particles})"
            )
        for name in ("kld_epsilon", "kld_delta", "alpha_slow", "alpha_fast"):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                raise ValueError(f"{name} must lie in (0, 1), got {value!r}")
        if not self.alpha_slow < self.alpha_fast:
            raise ValueError(
                f"alpha_slow ({self.alpha_slow}) must be smaller than alpha_fast "
                f"({self.alpha_fast}): the slow average must be the slower one"
            )
        for name in (
            "bin_size_m",
            "bin_size_rad",
            "sigma_hit_m",
            "likelihood_max_distance_m",
            "field_resolution_m",
            "share_kernel_std_m",
            "share_kernel_std_rad",
        ):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if self.bin_size_rad > TWO_PI:
            raise ValueError(f"bin_size_rad must be <= 2 pi, got {self.bin_size_rad!r}")
        if self.field_resolution_m > 1.0:
            raise ValueError(f"field_resolution_m must be <= 1 m, got {self.field_resolution_m!r}")
        for name in ("motion_noise_scale", "sample_clearance_m"):
            if getattr(self, name) < 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0.0 < self.likelihood_exponent <= 1.0:
            raise ValueError(
                f"likelihood_exponent must lie in (0, 1], got {self.likelihood_exponent!r}"
            )
        for name in ("z_hit", "z_rand"):
            if not 0.0 < getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must lie in (0, 1], got {getattr(self, name)!r}")
        if abs(self.z_hit + self.z_rand - 1.0) > 1e-6:
            raise ValueError(f"z_hit + z_rand must be 1, got {self.z_hit!r} + {self.z_rand!r}")
        if not 1 <= self.share_samples <= MAX_SHARED_SAMPLES:
            raise ValueError(
                f"share_samples must lie in [1, {MAX_SHARED_SAMPLES}], got {self.share_samples}"
            )
        if not 0.0 <= self.share_min_cluster_weight <= 1.0:
            raise ValueError(
                f"share_min_cluster_weight must lie in [0, 1], got {self.share_min_cluster_weight!r}"
            )
        if not 0.0 <= self.teammate_reset_fraction <= 1.0:
            raise ValueError(
                f"teammate_reset_fraction must lie in [0, 1], got {self.teammate_reset_fraction!r}"
            )
        if not 0.0 < self.teammate_outlier_probability <= 1.0:
            raise ValueError(
                "teammate_outlier_probability must lie in (0, 1], got "
                f"{self.teammate_outlier_probability!r}"
            )

    @property
    def kld_z(self) -> float:
        """The upper ``1 - kld_delta`` quantile of the standard normal (``z_{1-delta}``)."""
        return NormalDist().inv_cdf(1.0 - self.kld_delta)

    @classmethod
    def from_dict(cls, data: Mapping) -> AMCLParams:
        """Parameters from a config mapping; an unknown key is a ValueError that suggests the
        closest valid one, a bad value a ValueError/TypeError naming the field."""
        if not isinstance(data, Mapping):
            raise TypeError(f"AMCL config must be a mapping, got {type(data).__name__}")
        known = [f.name for f in fields(cls)]
        for key in data:
            if key not in known:
                hint = did_you_mean(str(key), known, 0.5)
                raise ValueError(f"unknown AMCL parameter {key!r}{hint}")
        return cls(**dict(data))

    @classmethod
    def seed_003(cls, **overrides) -> AMCLParams:
        """Seed 003 §V: "adaptive population ranging from 10000 to 1000 particles"."""
        return cls(**{"min_particles": 1000, "max_particles": 10000, **overrides})

    @classmethod
    def fixed(cls, n_particles: int, **overrides) -> AMCLParams:
        """A constant population (seed 002 table 3: PF with 50 or 100 particles)."""
        return cls(**{"min_particles": n_particles, "max_particles": n_particles, **overrides})


# --------------------------------------------------------------------------------------------
# The sensor-independent filter core
# --------------------------------------------------------------------------------------------


class AugmentedMCL:
    """Monte Carlo localization with KLD-sampling and random-particle recovery, independent of
    the sensor: the measurement update takes a ``log_likelihood(particles (P, 3)) -> (P,)``
    callable (the seam a laser, a landmark sensor or a teammate plugs into).

    ``sample_poses(n, rng) -> (n, 3)`` draws poses where the robot may be (the initial set and
    recovery); ``motion_std`` is ``(std of delta_s in m, std of delta_phi in rad)`` per step.
    ``initial_particles`` overrides the initial ``max_particles`` draws from ``sample_poses``.
    """

    def __init__(
        self,
        params: AMCLParams,
        rng: np.random.Generator,
        sample_poses: PoseSampler,
        motion_std: tuple[float, float],
        initial_particles: np.ndarray | None = None,
    ) -> None:
        if not isinstance(params, AMCLParams):
            raise TypeError(f"params must be AMCLParams, got {type(params).__name__}")
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        if not callable(sample_poses):
            raise TypeError("sample_poses must be callable (n, rng) -> (n, 3) poses")
        std = tuple(_number(s, "motion_std") for s in motion_std)
        if len(std) != 2 or min(std) < 0.0:
            raise ValueError(f"motion_std must be two numbers >= 0, got {motion_std!r}")
        self.params = params
        self._rng = rng
        self._sample_poses = sample_poses
        self._motion_std = np.array(std) * params.motion_noise_scale
        self.log_w_slow: float | None = None
        self.log_w_fast: float | None = None
        self.last_injected = 0
        self.reset(initial_particles)

    # -- state --------------------------------------------------------------------------------

    @property
    def particles(self) -> np.ndarray:
        """Current particles ``(P, 3)`` (read-only view)."""
        view = self._particles.view()
        view.flags.writeable = False
        return view

    @property
    def weights(self) -> np.ndarray:
        """Current normalised weights ``(P,)`` (read-only view)."""
        view = self._weights.view()
        view.flags.writeable = False
        return view

    @property
    def n_particles(self) -> int:
        return int(self._particles.shape[0])

    @property
    def injection_probability(self) -> float:
        """Probability with which the next resampling replaces a particle by a random pose."""
        if not self.params.recovery:
            return 0.0
        return recovery_probability(self.log_w_slow, self.log_w_fast)

    def _draw_poses(self, n: int) -> np.ndarray:
        poses = np.asarray(self._sample_poses(n, self._rng), dtype=np.float64)
        if poses.shape != (n, 3) or not np.all(np.isfinite(poses)):
            raise ValueError(f"sample_poses({n}) must return finite poses of shape ({n}, 3)")
        return poses

    def reset(self, particles: np.ndarray | None = None) -> None:
        """Restart: ``max_particles`` poses from ``sample_poses`` (global localization), or the
        given ``(P, 3)`` particles, with equal weights; the recovery averages are forgotten."""
        if particles is None:
            poses = self._draw_poses(self.params.max_particles)
        else:
            poses = np.array(particles, dtype=np.float64)
            if poses.ndim != 2 or poses.shape[1] != 3 or poses.shape[0] < 1:
                raise ValueError(f"particles must have shape (P, 3), P >= 1, got {poses.shape}")
            if not np.all(np.isfinite(poses)):
                raise ValueError("particles must be finite")
            poses[:, 2] = wrap_angle(poses[:, 2])
        self._particles = poses
        self._weights = np.full(poses.shape[0], 1.0 / poses.shape[0])
        self.log_w_slow = self.log_w_fast = None
        self._estimate: tuple[np.ndarray, float] | None = None

    def reset_gaussian(self, pose, std) -> None:
        """Restart around a known pose: ``max_particles`` draws of ``pose + N(0, diag(std^2))``
        (``amcl``'s initial pose)."""
        mean = np.array([_number(v, "pose") for v in np.asarray(pose, dtype=object).ravel()])
        sd = np.array([_number(v, "std") for v in np.asarray(std, dtype=object).ravel()])
        if mean.shape != (3,) or sd.shape != (3,) or np.any(sd < 0.0):
            raise ValueError("pose must be (x_m, y_m, theta_rad) and std three numbers >= 0")
        draws = self._rng.normal(0.0, 1.0, size=(self.params.max_particles, 3))
        self.reset(mean + draws * sd)

    # -- one update ---------------------------------------------------------------------------

    def predict(self, delta_s_m: float, delta_phi_rad: float) -> None:
        """Motion update: eq. 3 of 002 with per-particle noise on ``(delta_s, delta_phi)``.
        One ``rng.normal`` draw of shape ``(P, 2)``."""
        delta_s = _number(delta_s_m, "delta_s_m")
        delta_phi = _number(delta_phi_rad, "delta_phi_rad")
        noise = self._rng.normal(0.0, 1.0, size=(self.n_particles, 2)) * self._motion_std
        self._particles = unicycle_model(
            self._particles, delta_s + noise[:, 0], delta_phi + noise[:, 1]
        )
        self._estimate = None

    def _log_factor(self, log_likelihood: LogLikelihood, name: str) -> np.ndarray:
        values = np.asarray(log_likelihood(self.particles), dtype=np.float64)
        if values.shape != (self.n_particles,):
            raise ValueError(f"{name} must return shape ({self.n_particles},), got {values.shape}")
        if np.any(np.isnan(values)) or np.any(values == math.inf):
            raise ValueError(f"{name} returned NaN or +inf")
        return values

    def _apply(self, log_factor: np.ndarray) -> float:
        """Multiply the weights by ``exp(log_factor)`` and normalise; return
        ``log(sum_i w_i exp(log_factor_i))`` (``-inf`` if every factor is 0: weights kept)."""
        log_w = (
            np.log(
                self._weights,
                where=self._weights > 0.0,
                out=np.full(self._weights.shape, -math.inf),
            )
            + log_factor
        )
        log_total = float(logsumexp(log_w)) if np.any(np.isfinite(log_w)) else -math.inf
        if log_total > -math.inf:
            self._weights = np.exp(log_w - log_total)
            self._weights /= self._weights.sum()
        self._estimate = None
        return log_total

    def correct(self, log_likelihood: LogLikelihood) -> float:
        """Measurement update with ``log_likelihood(particles (P, 3)) -> (P,)``; updates the slow
        and fast averages of the likelihood. Returns ``log w_avg``."""
        log_w_avg = self._apply(self._log_factor(log_likelihood, "log_likelihood"))
        alpha_slow, alpha_fast = self.params.alpha_slow, self.params.alpha_fast
        if self.log_w_slow is None:
            self.log_w_slow = self.log_w_fast = log_w_avg
        else:
            self.log_w_slow = float(
                np.logaddexp(
                    math.log1p(-alpha_slow) + self.log_w_slow, math.log(alpha_slow) + log_w_avg
                )
            )
            self.log_w_fast = float(
                np.logaddexp(
                    math.log1p(-alpha_fast) + self.log_w_fast, math.log(alpha_fast) + log_w_avg
                )
            )
        return log_w_avg

    def reweight(self, log_factor: np.ndarray) -> None:
        """Multiply the weights by ``exp(log_factor)`` (a teammate's evidence) without touching
        the recovery averages."""
        self._apply(self._log_factor(lambda _: log_factor, "log_factor"))

    def estimate_with_share(self) -> tuple[np.ndarray, float]:
        """Best-cluster estimate of the current weighted set, and the cluster's weight share."""
        if self._estimate is None:
            labels = cluster_labels(
                self._particles, self.params.bin_size_m, self.params.bin_size_rad
            )
            self._estimate = best_cluster_estimate(self._particles, self._weights, labels)
        return self._estimate[0].copy(), self._estimate[1]

    def estimate(self) -> np.ndarray:
        """The weighted mean of the heaviest cluster: ``(x_m, y_m, theta_rad)``."""
        return self.estimate_with_share()[0]

    def kld_particle_count(self) -> int:
        """KLD-sampling: draw (multinomially) from the weighted set, one at a time, until ``n``
        reaches the count for the bins hit so far; clamped to ``[min, max]``. One
        ``rng.choice`` of ``max_particles`` indices."""
        params = self.params
        keys = histogram_bin_keys(self._particles, params.bin_size_m, params.bin_size_rad)
        draws = self._rng.choice(self.n_particles, size=params.max_particles, p=self._weights)
        drawn_keys = keys[draws]
        _, first = np.unique(drawn_keys, return_index=True)
        new_bin = np.zeros(params.max_particles, dtype=np.int64)
        new_bin[first] = 1
        bins_hit = np.cumsum(new_bin)  # k after n = 1, 2, ... draws
        n = np.arange(1, params.max_particles + 1)
        needed = kld_sample_size(bins_hit, params)
        enough = np.flatnonzero(n >= needed)
        return int(n[enough[0]]) if enough.size else params.max_particles

    def resample(self) -> int:
        """KLD-sized low-variance resampling with random injection; returns how many particles
        were injected. Draws: the KLD ``rng.choice``, the low-variance offset, one
        ``rng.random(n)`` for injection (when recovery is on), then the sampler's draws."""
        n = self.kld_particle_count()
        index = low_variance_resample(self._weights, n, self._rng)
        new = self._particles[index]
        injected = 0
        if self.params.recovery:
            inject = self._rng.random(n) < self.injection_probability
            injected = int(inject.sum())
            if injected:
                new[inject] = self._draw_poses(injected)
        self._particles = new
        self._weights = np.full(n, 1.0 / n)
        self._estimate = None
        self.last_injected = injected
        return injected

    def replace_random(self, n: int, sample_poses: PoseSampler) -> int:
        """Replace ``n`` distinct particles, chosen uniformly, by ``sample_poses(n, rng)``
        (sensor resetting); weights are kept. Returns how many were replaced. Draws: one
        ``rng.choice`` without replacement, then the sampler's."""
        n = min(_integer(n, "n"), self.n_particles)
        if n <= 0:
            return 0
        chosen = self._rng.choice(self.n_particles, size=n, replace=False)
        poses = np.asarray(sample_poses(n, self._rng), dtype=np.float64)
        if poses.shape != (n, 3) or not np.all(np.isfinite(poses)):
            raise ValueError(f"sample_poses({n}) must return finite poses of shape ({n}, 3)")
        self._particles = self._particles.copy()
        self._particles[chosen] = poses
        self._particles[chosen, 2] = wrap_angle(poses[:, 2])
        self._estimate = None
        return n

    def update(self, delta_s_m: float, delta_phi_rad: float, log_likelihood: LogLikelihood):
        """One filter step: predict, correct, estimate (on the weighted set), resample.
        Returns the estimate."""
        self.predict(delta_s_m, delta_phi_rad)
        self.correct(log_likelihood)
        estimate = self.estimate()
        self.resample()
        return estimate


# --------------------------------------------------------------------------------------------
# The laser likelihood field
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class DistanceField:
    """Distance to the nearest wall on a grid of cells: cell ``(i, j)`` covers
    ``[x0 + i res, x0 + (i+1) res) x [y0 + j res, y0 + (j+1) res)`` and holds the exact distance
    from its centre (``world.laser.maps.distance_to_walls``), capped at ``max_distance_m``. The grid
    extends ``max_distance_m`` beyond the map bounds, so every point off the grid is at least
    ``max_distance_m`` from any wall."""

    origin_m: tuple[float, float]
    resolution_m: float
    max_distance_m: float
    distances_m: np.ndarray  #: (NX, NY) float32, read-only

    @property
    def shape(self) -> tuple[int, int]:
        return self.distances_m.shape

    def cell_centres_m(self) -> tuple[np.ndarray, np.ndarray]:
        nx, ny = self.shape
        x0, y0 = self.origin_m
        return (
            x0 + (np.arange(nx) + 0.5) * self.resolution_m,
            y0 + (np.arange(ny) + 0.5) * self.resolution_m,
        )

    def flat_index(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Flat cell index of each point; ``NX * NY`` (one past the end) for points off the grid."""
        nx, ny = self.shape
        gx = np.floor((x_m - self.origin_m[0]) / self.resolution_m)
        gy = np.floor((y_m - self.origin_m[1]) / self.resolution_m)
        on_grid = (gx >= 0) & (gx < nx) & (gy >= 0) & (gy < ny)
        return np.where(on_grid, gx * ny + gy, nx * ny).astype(np.intp)

    def lookup(self, points_m: np.ndarray) -> np.ndarray:
        """Distance to the nearest wall (capped) of points ``(N, 2)``: the value of their cell.
        Error at most ``resolution_m / sqrt(2)`` (the distance is 1-Lipschitz)."""
        points = np.asarray(points_m, dtype=np.float64)
        table = np.append(self.distances_m.ravel(), np.float32(self.max_distance_m))
        return table[self.flat_index(points[:, 0], points[:, 1])].astype(np.float64)


def build_distance_field(
    world_map: SegmentMap, resolution_m: float, max_distance_m: float
) -> DistanceField:
    """The :class:`DistanceField` of ``world_map`` (not cached; see :func:`distance_field`)."""
    resolution_m = _number(resolution_m, "resolution_m")
    max_distance_m = _number(max_distance_m, "max_distance_m")
    if resolution_m <= 0.0 or max_distance_m <= 0.0:
        raise ValueError("resolution_m and max_distance_m must be > 0")
    x_min, y_min, x_max, y_max = world_map.bounds_m
    x0, y0 = x_min - max_distance_m, y_min - max_distance_m
    nx = math.ceil((x_max + max_distance_m - x0) / resolution_m)
    ny = math.ceil((y_max + max_distance_m - y0) / resolution_m)
    xs = x0 + (np.arange(nx) + 0.5) * resolution_m
    ys = y0 + (np.arange(ny) + 0.5) * resolution_m
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
    out = np.empty(grid.shape[0])
    chunk = max(256, (1 << 18) // world_map.n_segments)  # bounded (chunk, S, 2) temporaries
    for start in range(0, grid.shape[0], chunk):
        out[start : start + chunk] = distance_to_walls(world_map, grid[start : start + chunk])
    distances = np.minimum(out, max_distance_m).astype(np.float32).reshape(nx, ny)
    distances.flags.writeable = False
    return DistanceField((x0, y0), resolution_m, max_distance_m, distances)


@functools.lru_cache(maxsize=16)
def _cached_field(name, segments_bytes, bounds, resolution_m, max_distance_m) -> DistanceField:
    segments = np.frombuffer(segments_bytes, dtype=np.float64).reshape(-1, 4)
    return build_distance_field(SegmentMap(name, segments, bounds), resolution_m, max_distance_m)


def distance_field(world_map: SegmentMap, resolution_m: float, max_distance_m: float):
    """:func:`build_distance_field`, computed once per map (name and walls) and grid."""
    return _cached_field(
        world_map.name,
        world_map.segments_m.tobytes(),
        world_map.bounds_m,
        float(resolution_m),
        float(max_distance_m),
    )


class LaserLikelihoodField:
    """The likelihood-field model of a ring of laser beams (Probabilistic Robotics §6.4).

    For pose ``(x, y, theta)`` and reading ``r_j`` of beam ``j`` (direction ``theta + alpha_j``),
    the end point ``(x + r_j cos(theta + alpha_j), y + r_j sin(theta + alpha_j))`` is looked up in
    the :class:`DistanceField`; the beam scores ``log(z_hit N(d; 0, sigma_hit^2) + z_rand /
    max_range)``, precomputed per grid cell, and beams multiply. Readings at or above
    ``max_range_m - skip_margin_m`` are skipped (no hit: the beam missed every wall).
    """

    def __init__(
        self,
        field: DistanceField,
        beam_angles_rad: np.ndarray,
        max_range_m: float,
        sigma_hit_m: float,
        z_hit: float,
        z_rand: float,
        skip_margin_m: float = 0.0,
        exponent: float = 1.0,
    ) -> None:
        self.field = field
        self.beam_angles_rad = np.asarray(beam_angles_rad, dtype=np.float64)
        self.max_range_m = float(max_range_m)
        self.skip_margin_m = float(skip_margin_m)
        self._cos_beam = np.cos(self.beam_angles_rad)
        self._sin_beam = np.sin(self.beam_angles_rad)
        d = np.append(field.distances_m.ravel().astype(np.float64), field.max_distance_m)
        p_hit = np.exp(-0.5 * (d / sigma_hit_m) ** 2) / (math.sqrt(TWO_PI) * sigma_hit_m)
        self._log_p = exponent * np.log(z_hit * p_hit + z_rand / self.max_range_m)

    def log_likelihood(self, particles: np.ndarray, ranges_m: np.ndarray) -> np.ndarray:
        """Log-likelihood ``(P,)`` of the scan ``ranges_m`` ``(L,)`` at each of ``particles``."""
        ranges = np.asarray(ranges_m, dtype=np.float64)
        used = ranges < self.max_range_m - self.skip_margin_m
        if not np.any(used):
            return np.zeros(particles.shape[0])
        r = ranges[used]
        local_x = r * self._cos_beam[used]  # end points in the robot frame
        local_y = r * self._sin_beam[used]
        cos_t = np.cos(particles[:, 2])[:, None]
        sin_t = np.sin(particles[:, 2])[:, None]
        end_x = particles[:, 0:1] + cos_t * local_x - sin_t * local_y
        end_y = particles[:, 1:2] + sin_t * local_x + cos_t * local_y
        return self._log_p[self.field.flat_index(end_x, end_y)].sum(axis=1)


# --------------------------------------------------------------------------------------------
# The localizer
# --------------------------------------------------------------------------------------------


def _check_setup(setup: LocalizerSetup) -> None:
    if not isinstance(setup, LocalizerSetup):
        raise TypeError(f"setup must be a LocalizerSetup, got {type(setup).__name__}")
    _integer(setup.n_beams, "n_beams")
    if setup.n_beams < 1:
        raise ValueError(f"n_beams must be >= 1, got {setup.n_beams}")
    for name in ("max_range_m", "dt_s"):
        if _number(getattr(setup, name), name) <= 0.0:
            raise ValueError(f"{name} must be > 0, got {getattr(setup, name)!r}")
    for name in (
        "laser_noise_std_m",
        "speed_std_mps",
        "turn_rate_std_rad_s",
        "relative_distance_std_m",
        "relative_orientation_std_rad",
    ):
        if _number(getattr(setup, name), name) < 0.0:
            raise ValueError(f"{name} must be >= 0, got {getattr(setup, name)!r}")


def _low_variance_index(weights: np.ndarray, k: int) -> np.ndarray:
    """Indices of ``k`` draws from ``weights`` by low-variance resampling with a fixed offset of
    one half: the ``(i + 1/2) / k`` quantiles of the weights' cumulative sum (no random draw)."""
    cumulative = np.cumsum(weights)
    cumulative /= cumulative[-1]
    return np.minimum(
        np.searchsorted(cumulative, (0.5 + np.arange(k)) / k, side="right"), weights.shape[0] - 1
    )


class AMCLLocalizer:
    """The AMCL-style particle filter as a :class:`~swarmloc.agents.laser.localizer.Localizer`.

    ``AMCLLocalizer(setup, params, rng)``: the map comes from ``setup.map_name`` (or
    ``world_map``), the laser from ``setup``; ``setup.cooperative`` turns on the collaborative
    variant (share a :class:`BeliefSummary`, use teammates' ones on sighting). The filter core is
    :attr:`filter` (:class:`AugmentedMCL`); ``log_likelihood_model``, if given, replaces the laser
    likelihood field: it maps each :class:`LaserObservation` to a ``(P, 3) -> (P,)`` callable.
    """

    def __init__(
        self,
        setup: LocalizerSetup,
        params: AMCLParams | None = None,
        rng: np.random.Generator | None = None,
        *,
        world_map: SegmentMap | None = None,
        log_likelihood_model: Callable[[LaserObservation], LogLikelihood] | None = None,
    ) -> None:
        _check_setup(setup)
        params = AMCLParams() if params is None else params
        if not isinstance(params, AMCLParams):
            raise TypeError(f"params must be AMCLParams, got {type(params).__name__}")
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        self.setup = setup
        self.params = params
        self.world_map = build_map(setup.map_name) if world_map is None else world_map
        if not isinstance(self.world_map, SegmentMap):
            raise TypeError("world_map must be a SegmentMap")
        beam_angles = np.arange(setup.n_beams) * (TWO_PI / setup.n_beams)
        self.likelihood_field = LaserLikelihoodField(
            distance_field(
                self.world_map, params.field_resolution_m, params.likelihood_max_distance_m
            ),
            beam_angles,
            setup.max_range_m,
            params.sigma_hit_m,
            params.z_hit,
            params.z_rand,
            skip_margin_m=2.0 * setup.laser_noise_std_m,
            exponent=params.likelihood_exponent,
        )
        self._log_likelihood_model = log_likelihood_model
        clearance = params.sample_clearance_m
        world = self.world_map

        def sample_free_space(n: int, generator: np.random.Generator) -> np.ndarray:
            return free_space_sample(world, n, generator, clearance_m=clearance)

        motion_std = (setup.speed_std_mps * setup.dt_s, setup.turn_rate_std_rad_s * setup.dt_s)
        self.filter = AugmentedMCL(params, rng, sample_free_space, motion_std)
        area = self.world_map.width_m * self.world_map.height_m
        self._log_uniform_density = -math.log(area * TWO_PI)
        self._estimate = self.filter.estimate()
        self._share = self.filter.estimate_with_share()[1]
        self._posterior = (self.filter.particles, self.filter.weights)
        self._last_step = -1
        self._last_odometry = (0.0, 0.0)
        self.teammate_updates = 0  #: sightings used so far (a belief received and applied)
        self.teammate_disagreements = 0  #: of which contradicted this robot's belief
        self.teammate_resets = 0  #: particles replaced from teammates' beliefs so far
        #: Teammate payloads of the last step that did not decode: ``(sender_id, ValueError)``.
        self.rejected: tuple[tuple[int, ValueError], ...] = ()

    @classmethod
    def from_config(
        cls, setup: LocalizerSetup, config: Mapping, rng: np.random.Generator, **kwargs
    ) -> AMCLLocalizer:
        """Build from a config mapping of :class:`AMCLParams` fields (unknown keys rejected)."""
        return cls(setup, AMCLParams.from_dict(config), rng, **kwargs)

    # -- Localizer ----------------------------------------------------------------------------

    def _check_observation(self, obs: LaserObservation) -> np.ndarray:
        if not isinstance(obs, LaserObservation):
            raise TypeError(f"obs must be a LaserObservation, got {type(obs).__name__}")
        _integer(obs.step, "step")
        ranges = np.asarray(obs.ranges_m, dtype=np.float64)
        if ranges.shape != (self.setup.n_beams,):
            raise ValueError(
                f"ranges_m must have shape ({self.setup.n_beams},), got {ranges.shape}"
            )
        if not np.all(np.isfinite(ranges)) or np.any(ranges < 0.0):
            raise ValueError("ranges_m must be finite and >= 0")
        _number(obs.odometry_delta_s_m, "odometry_delta_s_m")
        _number(obs.odometry_delta_phi_rad, "odometry_delta_phi_rad")
        for sighting in obs.sightings:
            if not isinstance(sighting, Sighting):
                raise TypeError(f"sightings must hold Sighting, got {type(sighting).__name__}")
            for name in ("distance_m", "bearing_rad", "relative_heading_rad"):
                _number(getattr(sighting, name), f"sighting.{name}")
            if sighting.distance_m < 0.0:
                raise ValueError(f"sighting.distance_m must be >= 0, got {sighting.distance_m}")
        for message in obs.received:
            if not isinstance(message, RadioMessage):
                raise TypeError(f"received must hold RadioMessage, got {type(message).__name__}")
        return ranges

    def _decode_received(self, obs: LaserObservation):
        beliefs: dict[int, BeliefSummary] = {}
        rejected: list[tuple[int, ValueError]] = []
        for message in obs.received:
            try:
                summary = decode_belief(message.payload)
                if summary.robot_id != message.sender_id:
                    raise ValueError(
                        f"id: payload says robot {summary.robot_id}, sender is {message.sender_id}"
                    )
            except (TypeError, ValueError) as error:
                rejected.append((message.sender_id, ValueError(str(error))))
                continue
            beliefs[message.sender_id] = summary  # the latest from a sender wins
        return beliefs, rejected

    def step(self, obs: LaserObservation) -> None:
        """Predict with the odometry, correct with the laser, reweight by seen teammates' beliefs
        (cooperative), estimate, resample.

        A malformed observation raises (ValueError/TypeError) before anything changes. A teammate
        payload that does not decode never raises here: it is skipped and listed in
        :attr:`rejected` (``(sender_id, ValueError)`` of this step) for the shell to count."""
        ranges = self._check_observation(obs)
        beliefs, rejected = self._decode_received(obs) if self.setup.cooperative else ({}, [])
        setup, params = self.setup, self.params
        core = self.filter
        core.predict(obs.odometry_delta_s_m, obs.odometry_delta_phi_rad)
        if self._log_likelihood_model is None:
            field = self.likelihood_field
            core.correct(lambda particles: field.log_likelihood(particles, ranges))
        else:
            core.correct(self._log_likelihood_model(obs))
        resets = []
        if setup.cooperative:
            for sighting in obs.sightings:
                summary = beliefs.get(sighting.robot_id)
                if summary is None or sighting.robot_id == setup.robot_id:
                    continue
                log_density = teammate_log_density(
                    core.particles,
                    sighting,
                    summary,
                    setup.relative_distance_std_m,
                    setup.relative_orientation_std_rad,
                )
                finite = np.isfinite(log_density)
                agreement = (
                    float(logsumexp(log_density[finite], b=core.weights[finite]))
                    if np.any(finite)
                    else -math.inf
                )
                if agreement < self._log_uniform_density:
                    self.teammate_disagreements += 1
                    resets.append((sighting, summary))
                core.reweight(
                    mix_with_uniform(
                        log_density,
                        params.teammate_outlier_probability,
                        self._log_uniform_density,
                    )
                )
                self.teammate_updates += 1
        self._estimate, self._share = core.estimate_with_share()
        self._posterior = (core.particles, core.weights)
        core.resample()
        if resets and params.teammate_reset_fraction > 0.0:
            self._reset_from_teammates(resets)
        self._last_step = int(obs.step)
        self._last_odometry = (float(obs.odometry_delta_s_m), float(obs.odometry_delta_phi_rad))
        self.rejected = tuple(rejected)

    def _reset_from_teammates(self, resets) -> None:
        setup = self.setup
        n_reset = round(self.params.teammate_reset_fraction * self.filter.n_particles)
        shares = np.diff(np.linspace(0, n_reset, len(resets) + 1).round().astype(int))
        for (sighting, summary), count in zip(resets, shares):  # split among the teammates

            def sample(n, rng, sighting=sighting, summary=summary):
                return poses_from_teammate(
                    summary,
                    sighting,
                    n,
                    rng,
                    setup.relative_distance_std_m,
                    setup.relative_orientation_std_rad,
                )

            self.teammate_resets += self.filter.replace_random(int(count), sample)

    def estimate(self) -> np.ndarray:
        """Weighted mean of the heaviest cluster of the last posterior: ``(x_m, y_m, theta_rad)``."""
        return self._estimate.copy()

    @property
    def main_cluster_weight(self) -> float:
        """Share of the posterior weight in the cluster :meth:`estimate` comes from."""
        return self._share

    def samples(self, n: int) -> np.ndarray:
        """At most ``n`` poses of the last posterior, drawn as :meth:`belief_summary` draws its
        poses (low-variance resampling with a fixed offset: no random draw), for observers."""
        particles, weights = self._posterior
        return particles[_low_variance_index(weights, min(n, particles.shape[0]))]

    def belief_summary(self) -> BeliefSummary:
        """``share_samples`` poses drawn from the last posterior by low-variance resampling with a
        fixed offset of one half (no random draw), equally weighted, with the sharing kernel
        widened by one step of odometry noise (the receiver uses it one step later)."""
        particles, weights = self._posterior
        k = self.params.share_samples
        index = _low_variance_index(weights, k)
        motion_std = self.filter._motion_std
        return BeliefSummary(
            robot_id=int(self.setup.robot_id),
            step=self._last_step,
            poses_m=particles[index],
            weights=np.full(k, 1.0 / k),
            kernel_std_m=math.hypot(self.params.share_kernel_std_m, motion_std[0]),
            kernel_std_rad=math.hypot(self.params.share_kernel_std_rad, motion_std[1]),
            odometry_delta_s_m=self._last_odometry[0],
            odometry_delta_phi_rad=self._last_odometry[1],
        )

    def outgoing(self) -> bytes | None:
        """The cooperative variant's broadcast: the encoded :meth:`belief_summary`, when this
        robot's heaviest cluster holds at least ``share_min_cluster_weight`` of its belief; else
        (and when not cooperative, or before the first step) None."""
        if not self.setup.cooperative or self._last_step < 0:
            return None
        if self._share < self.params.share_min_cluster_weight:
            return None
        return encode_belief(self.belief_summary())
