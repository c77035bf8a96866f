"""Foraging performance metrics of seed 000 §6.1.1-6.1.3, computed from ground truth.

- §6.1.1 *Recruitment*: the time it takes for every robot to have visited both the nest and the
  prey area at least once (fig. 13).
- §6.1.2 *Retrieval*: the number of round trips nest -> prey -> nest; each arrival back at the
  nest after the prey counts one, and the next leg starts from that nest visit (fig. 14, 15).
- §6.1.3 *Stability*: how many robots are on the path; the steady state is taken as the mean over
  the second half of the run (fig. 16). "On the path" is decided by the caller (e.g. robots in
  the forage behaviour) and passed in as a mask.

The world calls :meth:`ForagingMetrics.update` every tick with the *true* area under each robot's
middle ground sensor, 3 cm ahead of the body centre (``protocol.epuck.GROUND_SENSOR_OFFSETS_M``,
``world.epuck.kernels.sensor_areas``): where the robot itself can see an area (seed 000 §5,
"The nest and prey areas are detected with the ground sensors"), not what it believes. Tick ``k`` happens at time ``k * dt_s``.
Vectorised over robots; no randomness.
"""

from __future__ import annotations

import numpy as np

from swarmloc.world.epuck import kernels
from swarmloc.world.epuck.arena import AREA_NEST, AREA_PREY

# Round-trip stage of each robot.
_NO_NEST = 0  # has not been in the nest yet
_TO_PREY = 1  # left (or is in) the nest, heading for the prey
_TO_NEST = 2  # has been in the prey after the nest, heading back
#: The area and stage codes that the round-trip kernel compares with, in its argument order.
STAGE_CODES = np.array([AREA_NEST, AREA_PREY, _NO_NEST, _TO_PREY, _TO_NEST], np.int64)


class ForagingMetrics:
    """Accumulates recruitment, round trips and on-path counts over a run (seed 000 §6.1.1-3)."""

    def __init__(self, n_robots: int, dt_s: float, sample_every_ticks: int = 10) -> None:
        if int(n_robots) != n_robots or n_robots < 1:
            raise ValueError(f"n_robots must be an integer >= 1, got {n_robots!r}")
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s!r}")
        if int(sample_every_ticks) != sample_every_ticks or sample_every_ticks < 1:
            raise ValueError(
                f"sample_every_ticks must be an integer >= 1, got {sample_every_ticks!r}"
            )
        self.n_robots = int(n_robots)
        self.dt_s = float(dt_s)
        self.sample_every_ticks = int(sample_every_ticks)
        #: Tick of each robot's first visit to the nest (column 0) and the prey (column 1);
        #: -1 = never.
        self.first_visit_tick = np.full((self.n_robots, 2), -1, dtype=np.int64)
        #: Completed round trips per robot.
        self.round_trips = np.zeros(self.n_robots, dtype=np.int64)
        self._stage = np.full(self.n_robots, _NO_NEST, dtype=np.int8)
        self._series_tick: list[int] = []
        self._series_count: list[int] = []
        self._first_tick: int | None = None
        self._last_tick: int | None = None

    def update(self, tick: int, area: np.ndarray, on_path: np.ndarray) -> None:
        """Record one tick.

        ``area`` (N,): true AREA_* code under each middle ground sensor; ``on_path`` (N,) bool. Ticks must
        strictly increase from call to call.
        """
        tick = int(tick)
        if self._last_tick is not None and tick <= self._last_tick:
            raise ValueError(f"tick must increase: got {tick} after {self._last_tick}")
        area = np.asarray(area)
        on_path = np.asarray(on_path, dtype=bool)
        if area.shape != (self.n_robots,):
            raise ValueError(f"area must have shape ({self.n_robots},), got {area.shape}")
        if on_path.shape != (self.n_robots,):
            raise ValueError(f"on_path must have shape ({self.n_robots},), got {on_path.shape}")

        kernels.update_round_trips(
            tick, area.astype(np.int8, copy=False), self.first_visit_tick, self.round_trips,
            self._stage, *STAGE_CODES,
        )
        self._count_on_path(tick, int(np.count_nonzero(on_path)))

    def kernel_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(first_visit_tick, round_trips, stage, STAGE_CODES)``: the arrays that the world's
        compiled step (``world/epuck/kernels.py: step_tick``) updates in place, as :meth:`update`
        does, before it calls :meth:`counted`."""
        return self.first_visit_tick, self.round_trips, self._stage, STAGE_CODES

    def counted(self, tick: int, on_path_count: int) -> None:
        """Record one tick whose round trips the world's kernel has already updated (see
        :meth:`kernel_state`): ``on_path_count`` robots on the path."""
        tick = int(tick)
        if self._last_tick is not None and tick <= self._last_tick:
            raise ValueError(f"tick must increase: got {tick} after {self._last_tick}")
        self._count_on_path(tick, on_path_count)

    def _count_on_path(self, tick: int, on_path_count: int) -> None:
        if tick % self.sample_every_ticks == 0:
            self._series_tick.append(tick)
            self._series_count.append(on_path_count)
        if self._first_tick is None:
            self._first_tick = tick
        self._last_tick = tick

    def summary(self) -> dict:
        """Plain JSON-able results.

        ``recruitment_time_s`` (time at which every robot had visited both areas, None if not all
        did), ``robots_found_both``, ``round_trips_total``, ``round_trips_per_robot``,
        ``on_path_fraction_mean`` (mean of on-path count / N over the samples in the second half
        of the run, ticks >= midpoint of first and last updated tick; None without samples) and
        ``on_path_series`` (``[time_s, count]`` every ``sample_every_ticks`` ticks).
        """
        fv = self.first_visit_tick
        found_both = (fv >= 0).all(axis=1)
        recruitment_time_s = float(fv.max()) * self.dt_s if bool(found_both.all()) else None
        ticks = np.asarray(self._series_tick, dtype=np.int64)
        counts = np.asarray(self._series_count, dtype=float)
        fraction_mean = None
        if ticks.size and self._first_tick is not None and self._last_tick is not None:
            mid = self._first_tick + (self._last_tick - self._first_tick) / 2.0
            steady = ticks >= mid
            if steady.any():
                fraction_mean = float(counts[steady].mean() / self.n_robots)
        return {
            "recruitment_time_s": recruitment_time_s,
            "robots_found_both": int(np.count_nonzero(found_both)),
            "round_trips_total": int(self.round_trips.sum()),
            "round_trips_per_robot": [int(v) for v in self.round_trips],
            "on_path_fraction_mean": fraction_mean,
            "on_path_series": [
                [t * self.dt_s, int(c)] for t, c in zip(self._series_tick, self._series_count)
            ],
        }
