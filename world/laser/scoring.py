"""The laser family's scoring: pose errors and the summary figures of one run, shared by the
in-process runner (``deploy/lab/laser/runner.py``, whose docstring defines each figure) and the
world-server (``world/laser/service.py``), so that both score a run with the same code."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmloc.world.laser.laser import wrap_angle


@dataclass(frozen=True)
class MetricsConfig:
    """Thresholds of the run summary (see the module docstring)."""

    #: 003 §V, fig. 4: "settle around a value of 15cm".
    settle_error_m: float = 0.15
    final_window_steps: int = 20
    localized_error_m: float = 0.5

    def __post_init__(self) -> None:
        for name in ("settle_error_m", "localized_error_m"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0):
                raise ValueError(f"{name}: must be > 0, got {value!r}")
        if isinstance(self.final_window_steps, bool) or not isinstance(self.final_window_steps, int) \
                or self.final_window_steps < 1:
            raise ValueError(f"final_window_steps: must be an integer >= 1, "
                             f"got {self.final_window_steps!r}")


def _settle_step(error: np.ndarray, start: int, threshold: float, window: int) -> int | None:
    """First step ``s >= start`` from which ``error`` stays below ``threshold`` to the end, if
    that lasts at least ``window`` steps."""
    span = error[start:]
    bad = np.flatnonzero(~(span < threshold))
    first_good = start + (int(bad[-1]) + 1 if bad.size else 0)
    return first_good if error.shape[0] - first_good >= window else None


def summarize(position_error_m: np.ndarray, heading_error_rad: np.ndarray,
              kidnaps: list[tuple[int, int]], metrics: MetricsConfig,
              sightings: np.ndarray | None = None) -> dict:
    """The summary figures of one run (see the module docstring). ``kidnaps``: (robot, step)."""
    steps, robots = position_error_m.shape
    window = min(metrics.final_window_steps, steps)
    final = position_error_m[-window:].mean(axis=0)
    last_kidnap = {}
    for robot, step in kidnaps:
        last_kidnap[robot] = max(step, last_kidnap.get(robot, 0))
    settle = [_settle_step(position_error_m[:, r], last_kidnap.get(r, 0), metrics.settle_error_m,
                           window) for r in range(robots)]
    out = {
        "final_error_m": float(final.mean()),
        "final_error_max_m": float(final.max()),
        "final_heading_error_rad": float(heading_error_rad[-window:].mean()),
        "mean_error_m": float(position_error_m.mean()),
        "settle_step": None if any(s is None for s in settle) else int(max(settle)),
        "settled_robots": int(sum(s is not None for s in settle)),
        "localized": bool(np.all(final < metrics.localized_error_m)),
        "kidnap_step": None, "settled_before_kidnap": None, "recovered": None,
        "recover_steps": None, "first_contact_step": None,
    }
    if kidnaps:
        robot, step = min(kidnaps, key=lambda rk: rk[1])
        before = position_error_m[:step, robot]
        pre = _settle_step(before, 0, metrics.settle_error_m, min(window, before.shape[0]))
        out["kidnap_step"] = int(step)
        out["settled_before_kidnap"] = pre is not None
        kidnapped = sorted(last_kidnap)
        out["recovered"] = bool(np.all(final[kidnapped] < metrics.localized_error_m))
        after = [settle[r] for r in kidnapped]
        out["recover_steps"] = (None if any(s is None for s in after)
                                else int(max(s - last_kidnap[r] for s, r in zip(after, kidnapped))))
    if sightings is not None:
        contact = np.flatnonzero(np.asarray(sightings) > 0)
        out["first_contact_step"] = int(contact[0]) if contact.size else None
    return out


def pose_errors(estimates: np.ndarray, true_poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position error ``|xy_est - xy_true|`` and heading error ``|wrap(theta_est - theta_true)|``,
    each ``(T, N)``, of estimates ``(T, N, 3)`` against true poses ``(T, N, 3)``."""
    position = np.hypot(estimates[..., 0] - true_poses[..., 0], estimates[..., 1] - true_poses[..., 1])
    return position, np.abs(wrap_angle(estimates[..., 2] - true_poses[..., 2]))
