"""Player's ``amcl`` driver as seed 003 ran it: the Player-faithful AMCL baseline (``amcl-player``).

Seed 003 (``003_5278cbbbf8cc61de.txt``) §V compares CFS-GA with "the 'Adaptive Monte Carlo
Localization algorithm' (AMCL) [20], already available in the Player/Stage framework", "starting
with 10000 particles (adaptive population ranging from 10000 to 1000 particles)", and says that
"the AMCL, which simply adds a number of randomly placed samples at every time instant as detailed
in [21], often fails to re-locate the robot"; in the robustness runs it "showed a percentage of
failure of roughly 35%". The seed gives nothing else of the filter, so this module follows the
Player sources (``playerproject/player``, ``server/drivers/localization/amcl/``: ``amcl.cc``,
``amcl_laser.cc``, ``amcl_odom.cc``, ``pf/pf.c``, ``pf/pf_kdtree.c``; read, not copied). The
modern filter of :mod:`swarmloc.agents.laser.amcl` (``amcl``: likelihood field widened to 0.5 m,
Augmented_MCL injection, the parameters of ROS ``amcl``) stays beside it as the stronger baseline.

One filter update (Player's ``AdaptiveMCL::UpdateFilter``):

1. **Update threshold** (``update_thresh``, default 0.2 m, pi/6): the odometry is accumulated as a
   pose; the filter updates only once the pose change since the last update exceeds 0.2 m in x or
   y (robot frame) or pi/6 in heading. Between updates the estimate is the last best hypothesis
   composed with the odometry since (what Player's position2d interface publishes).
2. **Action** (``amcl_odom.cc``, odometric drift model): every particle moves by a draw of
   ``N(delta, diag(ux^2, uy^2, ua^2))`` composed with its pose, where ``delta = (dx, dy, da)`` is
   the odometric pose change in the frame of the last update and ``ux = d_xx dx``,
   ``uy = d_yy dy``, ``ua = d_ax |dx| + d_ay |dy| + d_aa |da|`` (``odom_drift`` defaults 0.2, 0.2,
   0.2, 0, 0.2). This is Player's model, not the world's true odometry noise.
3. **Sensor** (``amcl_laser.cc`` ``SensorModel``): the product over the used beams of
   ``pz = range_bad + (1 - range_bad) exp(-(z_obs - z_map)^2 / (2 c^2))`` with ``c =
   laser_range_var`` (0.1 m: Player reads the "variance" and uses it as a standard deviation)
   and ``range_bad`` 0.1 (the weight of the floor; Player's only z-weight: ``z_hit = 0.9`` for an
   unnormalised Gaussian); ``pz = 1`` when both the reading and the map's range are at maximum.
   Beams used: every ``(L - 1) // (laser_max_beams - 1)``-th from the first, ``laser_max_beams``
   6 (18 beams of table I of 003: beams 0, 3, ..., 15; an 8-beam scan: all 8, as Player's step
   rounds to 1). ``z_map`` is cast exactly on the segment map (``cast_rays``; Player ray-marches
   its occupancy grid).
4. **Resampling** with KLD-sampling (``pf_update_resample`` and ``pf_resample_limit``): particles
   are drawn one at a time into histogram bins of 0.5 m x 0.5 m x 10 deg (``pf_kdtree.c``);
   drawing stops once the count exceeds ``ceil((k-1)/(2 pop_err) (1 - 2/(9(k-1)) +
   sqrt(2/(9(k-1))) pop_z)^3)`` for the ``k`` bins hit, clamped to ``[min, max]``, with
   ``pop_err`` 0.01 and ``pop_z`` 3 (Player's defaults, not ROS's 0.01 / 0.99 quantile).
5. **Estimate**: the mean of the heaviest cluster (adjacent occupied bins) of the resampled set.

Choices the seed leaves open, each named (``PlayerAMCLParams``):

- ``resampler``: Player's ``pf.c`` drew multinomially (GSL's discrete sampler) until April 2008
  (commit "removed GSL dep", 2008-04-17), and with a low-variance resampler after that, which
  steps through the old set by ``1 / N_old`` and so, when the set shrinks, copies only the first
  ``N_new / N_old`` of its cumulative weight. 003 is a 2008 paper on Player 2.0/2.1; default
  ``"multinomial"``, ``"low_variance"`` as the later reading.
- ``injection``: ``"none"`` is Player's code (``pf.c`` injects nothing; the ``recovery_alpha``
  parameters belong to ROS ``amcl``). ``"fixed"`` is 003's text ("simply adds a number of
  randomly placed samples at every time instant"): after each update's resampling,
  ``injected_samples`` particles drawn at random are replaced by poses uniform in free space. 003
  gives no number; the default 100 is 1 % of the initial and 10 % of the smallest population.
  The filter changes only at updates, so "every time instant" is read as every filter update.
- The initial set: ``max_particles`` poses uniform in free space. 003: "the initial population was
  always drawn from a random uniform distribution of individuals over the whole environment";
  Player's default is a Gaussian around ``init_pose`` (1 m, 2 pi), which a global-localization run
  would widen to the map.
- ``min_particles``/``max_particles``: 1000/10000 from 003 (Player's defaults are 100/10000).
- Player's AMCL does not collaborate: with ``cooperative`` set the localizer still broadcasts
  nothing and ignores sightings (003's AMCL runs alone; the collaborative PF of 002 is ``amcl``).

All randomness comes from the generator given to the constructor, in a fixed order per update
(action draw, multinomial or low-variance draws, injection draws), so a run is reproducible.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from swarmloc.agents.laser.amcl_sampling import (
    TWO_PI,
    _integer,
    best_cluster_estimate,
    cluster_labels,
    histogram_bin_keys,
)
from swarmloc.agents.laser.localizer import LaserObservation, LocalizerSetup
from swarmloc.config import did_you_mean
from swarmloc.world.laser.laser import cast_rays, unicycle_model, wrap_angle
from swarmloc.world.laser.maps import SegmentMap, build_map, free_space_sample

RESAMPLERS = ("multinomial", "low_variance")
INJECTIONS = ("none", "fixed")
#: Poses x beams per ``cast_rays`` call (bounds the temporaries of the sensor model).
_CAST_BLOCK_POSES = 2000


@dataclass(frozen=True)
class PlayerAMCLParams:
    """Player ``amcl`` driver settings (names after Player's configuration keys), with 003's
    population. See the module docstring for each one's source."""

    min_particles: int = 1000  #: 003 (Player: pf_min_samples 100)
    max_particles: int = 10000  #: 003 and Player's pf_max_samples
    pop_err: float = 0.01  #: Player pf_err
    pop_z: float = 3.0  #: Player pf_z (upper standard normal quantile)
    bin_size_m: float = 0.5  #: pf_kdtree.c
    bin_size_rad: float = math.radians(10.0)
    laser_max_beams: int = 6
    laser_range_sigma_m: float = 0.1  #: Player laser_range_var, used as sigma
    laser_range_bad: float = 0.1
    odom_drift_xx: float = 0.2
    odom_drift_yy: float = 0.2
    odom_drift_ax: float = 0.2
    odom_drift_ay: float = 0.0
    odom_drift_aa: float = 0.2
    update_min_distance_m: float = 0.2  #: Player update_thresh[0]
    update_min_angle_rad: float = math.pi / 6.0  #: Player update_thresh[1]
    resampler: str = "multinomial"
    injection: str = "none"
    injected_samples: int = 100
    sample_clearance_m: float = 0.2

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.type == "int" or f.name in (
                "min_particles", "max_particles", "laser_max_beams", "injected_samples"
            ):
                _integer(value, f.name)
            elif f.name in ("resampler", "injection"):
                if not isinstance(value, str):
                    raise TypeError(f"{f.name} must be a string, got {value!r}")
            else:
                if isinstance(value, (bool, str)) or not isinstance(
                    value, (int, float, np.integer, np.floating)
                ) or not math.isfinite(float(value)):
                    raise ValueError(f"{f.name} must be a finite number, got {value!r}")
        if not 1 <= self.min_particles <= self.max_particles <= 1_000_000:
            raise ValueError(
                f"need 1 <= min_particles <= max_particles <= 1000000, got "
                f"{self.min_particles}, {self.max_particles}"
            )
        if not 0.0 < self.pop_err < 1.0 or self.pop_z <= 0.0:
            raise ValueError("pop_err must lie in (0, 1) and pop_z be > 0")
        if self.laser_max_beams < 2:
            raise ValueError(f"laser_max_beams must be >= 2, got {self.laser_max_beams}")
        if not 0.0 <= self.laser_range_bad < 1.0:
            raise ValueError(f"laser_range_bad must lie in [0, 1), got {self.laser_range_bad}")
        for name in ("bin_size_m", "bin_size_rad", "laser_range_sigma_m"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("odom_drift_xx", "odom_drift_yy", "odom_drift_ax", "odom_drift_ay",
                     "odom_drift_aa", "update_min_distance_m", "update_min_angle_rad",
                     "sample_clearance_m"):
            if getattr(self, name) < 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.resampler not in RESAMPLERS:
            raise ValueError(f"resampler must be one of {RESAMPLERS}, got {self.resampler!r}")
        if self.injection not in INJECTIONS:
            raise ValueError(f"injection must be one of {INJECTIONS}, got {self.injection!r}")
        if self.injected_samples < 0:  # capped at the population when used
            raise ValueError(f"injected_samples must be >= 0, got {self.injected_samples}")

    @classmethod
    def from_dict(cls, data: Mapping) -> PlayerAMCLParams:
        """From a config mapping; an unknown key is a ValueError suggesting the closest one."""
        if not isinstance(data, Mapping):
            raise TypeError(f"amcl-player config must be a mapping, got {type(data).__name__}")
        known = [f.name for f in fields(cls)]
        for key in data:
            if key not in known:
                hint = did_you_mean(str(key), known, 0.5)
                raise ValueError(f"unknown amcl-player parameter {key!r}{hint}")
        return cls(**dict(data))


def resample_limit(k_bins: np.ndarray, params: PlayerAMCLParams) -> np.ndarray:
    """Player's ``pf_resample_limit``: KLD sample count for ``k_bins`` occupied bins (Fox 2003,
    Wilson-Hilferty form), clamped to ``[min_particles, max_particles]``; ``min`` for k <= 1."""
    k = np.asarray(k_bins, dtype=np.float64)
    km1 = np.maximum(k - 1.0, 1.0)
    b = 2.0 / (9.0 * km1)
    x = 1.0 - b + np.sqrt(b) * params.pop_z
    n = np.ceil(km1 / (2.0 * params.pop_err) * x**3)
    n = np.where(k <= 1.0, params.min_particles, n)
    return np.clip(n, params.min_particles, params.max_particles).astype(np.int64)


def _stop_count(keys_in_draw_order: np.ndarray, params: PlayerAMCLParams) -> int:
    """How many draws Player's loop keeps: it adds one sample, then stops once the count exceeds
    the limit for the bins hit so far (or at ``max_particles``)."""
    _, first = np.unique(keys_in_draw_order, return_index=True)
    new_bin = np.zeros(keys_in_draw_order.shape[0], dtype=np.int64)
    new_bin[first] = 1
    count = np.arange(1, keys_in_draw_order.shape[0] + 1)
    over = np.flatnonzero(count > resample_limit(np.cumsum(new_bin), params))
    return int(count[over[0]]) if over.size else int(keys_in_draw_order.shape[0])


def _pose_compose(origin: np.ndarray, local: np.ndarray) -> np.ndarray:
    """``pf_vector_coord_add(local, origin)``: ``local`` (N, 3) expressed in the frame of
    ``origin`` (N, 3) or (3,), returned in the world frame."""
    c, s = np.cos(origin[..., 2]), np.sin(origin[..., 2])
    out = np.empty(np.broadcast_shapes(origin.shape, local.shape))
    out[..., 0] = origin[..., 0] + c * local[..., 0] - s * local[..., 1]
    out[..., 1] = origin[..., 1] + s * local[..., 0] + c * local[..., 1]
    out[..., 2] = wrap_angle(origin[..., 2] + local[..., 2])
    return out


def _pose_difference(pose: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """``pf_vector_coord_sub(pose, origin)``: ``pose`` in the frame of ``origin`` (both (3,))."""
    c, s = math.cos(origin[2]), math.sin(origin[2])
    dx, dy = pose[0] - origin[0], pose[1] - origin[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, float(wrap_angle(pose[2] - origin[2]))])


class PlayerAMCLLocalizer:
    """Player's ``amcl`` as a :class:`~swarmloc.agents.laser.localizer.Localizer`
    (``amcl-player``). ``PlayerAMCLLocalizer(setup, params, rng)``."""

    def __init__(
        self,
        setup: LocalizerSetup,
        params: PlayerAMCLParams | None = None,
        rng: np.random.Generator | None = None,
        *,
        world_map: SegmentMap | None = None,
    ) -> None:
        params = PlayerAMCLParams() if params is None else params
        if not isinstance(params, PlayerAMCLParams):
            raise TypeError(f"params must be PlayerAMCLParams, got {type(params).__name__}")
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        _integer(setup.n_beams, "n_beams")
        if setup.n_beams < 1 or not setup.max_range_m > 0.0:
            raise ValueError("setup needs n_beams >= 1 and max_range_m > 0")
        self.setup = setup
        self.params = params
        self._rng = rng
        self.world_map = build_map(setup.map_name) if world_map is None else world_map
        step = max(1, (setup.n_beams - 1) // (params.laser_max_beams - 1))
        #: The beams Player's sensor model uses (indices into the scan).
        self.used_beams = np.arange(0, setup.n_beams, step)
        self._beam_angles = self.used_beams * (TWO_PI / setup.n_beams)
        self._particles = self._free_space(params.max_particles)
        self._odometry_pose = np.zeros(3)  # dead-reckoned pose, odometry frame
        self._odometry_at_update = np.zeros(3)
        self._best = self._cluster_estimate()
        self._estimate = self._best.copy()
        self.updates = 0  #: filter updates so far
        self.last_injected = 0
        self.rejected: tuple = ()

    @classmethod
    def from_config(
        cls, setup: LocalizerSetup, config: Mapping, rng: np.random.Generator, **kwargs
    ) -> PlayerAMCLLocalizer:
        return cls(setup, PlayerAMCLParams.from_dict(config), rng, **kwargs)

    @property
    def n_particles(self) -> int:
        return int(self._particles.shape[0])

    @property
    def particles(self) -> np.ndarray:
        view = self._particles.view()
        view.flags.writeable = False
        return view

    def _free_space(self, n: int) -> np.ndarray:
        return free_space_sample(self.world_map, n, self._rng,
                                 clearance_m=self.params.sample_clearance_m)

    # -- the three models --------------------------------------------------------------------

    def action_update(self, delta: np.ndarray) -> None:
        """Player's odometric drift model: one ``rng.normal`` draw of shape ``(P, 3)``."""
        p = self.params
        dx, dy, da = (float(v) for v in delta)
        std = np.array([
            p.odom_drift_xx * abs(dx),
            p.odom_drift_yy * abs(dy),
            p.odom_drift_ax * abs(dx) + p.odom_drift_ay * abs(dy) + p.odom_drift_aa * abs(da),
        ])
        draws = np.asarray(delta, dtype=np.float64) + self._rng.normal(
            0.0, 1.0, size=(self.n_particles, 3)) * std
        self._particles = _pose_compose(self._particles, draws)

    def sensor_log_likelihood(self, particles: np.ndarray, ranges_m: np.ndarray) -> np.ndarray:
        """``log prod_beams pz`` of Player's laser model for each particle ``(P,)``."""
        p = self.params
        observed = np.asarray(ranges_m, dtype=np.float64)[self.used_beams]
        max_range = self.setup.max_range_m
        out = np.empty(particles.shape[0])
        for start in range(0, particles.shape[0], _CAST_BLOCK_POSES):
            block = particles[start:start + _CAST_BLOCK_POSES]
            expected = cast_rays(self.world_map, block, self._beam_angles, max_range)
            z = observed - expected
            pz = p.laser_range_bad + (1.0 - p.laser_range_bad) * np.exp(
                -(z * z) / (2.0 * p.laser_range_sigma_m**2))
            both_max = (observed >= max_range) & (expected >= max_range)
            pz = np.where(both_max, 1.0, pz)
            out[start:start + block.shape[0]] = np.log(pz).sum(axis=1)
        return out

    def resample(self, weights: np.ndarray) -> np.ndarray:
        """Player's ``pf_update_resample``: KLD-limited draws from the weighted set (see the
        module docstring for the two resamplers). Returns the new particles."""
        p = self.params
        n_old = self.n_particles
        if p.resampler == "multinomial":
            index = self._rng.choice(n_old, size=p.max_particles, p=weights)
        else:  # Player >= 2.1.1: systematic steps of 1 / n_old, a new offset at each wrap
            cumulative = np.cumsum(weights)
            cumulative /= cumulative[-1]
            blocks = []
            while sum(b.size for b in blocks) < p.max_particles:
                u = (self._rng.random() + np.arange(n_old)) / n_old
                blocks.append(np.minimum(np.searchsorted(cumulative, u), n_old - 1))
            index = np.concatenate(blocks)[: p.max_particles]
        drawn = self._particles[index]
        keys = histogram_bin_keys(drawn, p.bin_size_m, p.bin_size_rad)
        return drawn[: _stop_count(keys, p)]

    def _cluster_estimate(self) -> np.ndarray:
        p = self.params
        labels = cluster_labels(self._particles, p.bin_size_m, p.bin_size_rad)
        weights = np.full(self.n_particles, 1.0 / self.n_particles)
        return best_cluster_estimate(self._particles, weights, labels)[0]

    # -- Localizer ---------------------------------------------------------------------------

    def step(self, obs: LaserObservation) -> None:
        """Accumulate the odometry; when past the update threshold: action, sensor, resample,
        (inject), estimate. A malformed observation raises before anything changes."""
        if not isinstance(obs, LaserObservation):
            raise TypeError(f"obs must be a LaserObservation, got {type(obs).__name__}")
        ranges = np.asarray(obs.ranges_m, dtype=np.float64)
        if ranges.shape != (self.setup.n_beams,):
            raise ValueError(f"ranges_m must have shape ({self.setup.n_beams},), got {ranges.shape}")
        if not np.all(np.isfinite(ranges)) or np.any(ranges < 0.0):
            raise ValueError("ranges_m must be finite and >= 0")
        delta_s, delta_phi = float(obs.odometry_delta_s_m), float(obs.odometry_delta_phi_rad)
        if not (math.isfinite(delta_s) and math.isfinite(delta_phi)):
            raise ValueError("odometry increments must be finite")
        self._odometry_pose = unicycle_model(self._odometry_pose[None, :], delta_s, delta_phi)[0]
        delta = _pose_difference(self._odometry_pose, self._odometry_at_update)
        p = self.params
        first = self.updates == 0
        if first or (abs(delta[0]) > p.update_min_distance_m or abs(delta[1]) >
                     p.update_min_distance_m or abs(delta[2]) > p.update_min_angle_rad):
            if not first:  # Player discards the first action and weighs the first scan
                self.action_update(delta)
            log_w = self.sensor_log_likelihood(self._particles, ranges)
            weights = np.exp(log_w - log_w.max())
            total = weights.sum()
            weights = weights / total if total > 0.0 else np.full(weights.size, 1.0 / weights.size)
            self._particles = self.resample(weights)
            self.last_injected = 0
            if p.injection == "fixed" and p.injected_samples > 0:
                n = min(p.injected_samples, self.n_particles)
                chosen = self._rng.choice(self.n_particles, size=n, replace=False)
                self._particles[chosen] = self._free_space(n)
                self.last_injected = n
            self._best = self._cluster_estimate()
            self._odometry_at_update = self._odometry_pose.copy()
            self.updates += 1
            delta = np.zeros(3)
        self._estimate = _pose_compose(self._best, delta)

    def estimate(self) -> np.ndarray:
        """The best cluster's mean at the last update, composed with the odometry since."""
        return self._estimate.copy()

    def samples(self, n: int) -> np.ndarray:
        """At most ``n`` particles, evenly spaced through the set (no random draw)."""
        count = self.n_particles
        if count <= n:
            return self._particles.copy()
        return self._particles[np.arange(n) * count // n]

    def outgoing(self) -> bytes | None:
        """Player's AMCL does not collaborate: nothing to broadcast."""
        return None


__all__ = ["INJECTIONS", "RESAMPLERS", "PlayerAMCLLocalizer", "PlayerAMCLParams",
           "resample_limit"]
