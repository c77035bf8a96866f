"""Every sentence of the vision report that states a result, computed from the rows.

Seed 004 (``seeds/004_e71d8ee95e0baa56.txt``, Peula et al.) §IV shows one or two trials per
experiment and gives no numbers; ``docs/vision/README.md`` sets counts over seeded runs next to
its claims. No result is typed into the report: each function here takes rows (one per run, the
columns of :data:`swarmloc.deploy.lab.vision.experiment.COLUMNS`) or their summaries
(:func:`~swarmloc.deploy.lab.vision.experiment.summarize`) and returns the sentence, with the
numbers and the words that depend on them ("opposite sides", "rises", "agrees") chosen from
those numbers. ``tests/test_vision_report.py`` feeds rows whose answer is known and checks the
words and numbers.

Thresholds (the paper gives none): at the end of experiment 1 the robots are "on opposite sides"
of the ball when the angle at the ball between them is at least 120 deg (median over runs),
"side by side" when it is at most 60 deg, "at an angle" between (§IV-A: "they catch the ball from
opposite sides"). A rate or error is "worse" when it changes by more than 10 % of the better
value and by more than one run (counts) or 0.01 m (errors).
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np

OPPOSITE_DEG = 120.0
SIDE_BY_SIDE_DEG = 60.0


def pct(k: int, n: int) -> str:
    """``k/n (p %)``."""
    return f"{k}/{n} ({100.0 * k / n:.0f} %)" if n else "-"


def fmt(value, spec: str = ".2f", unit: str = "") -> str:
    return "-" if value is None else f"{format(value, spec)}{unit}"


def _values(rows, key):
    return [r[key] for r in rows if r.get(key) is not None]


def ends_at_the_ball(rows: list[dict]) -> str:
    """Where the two robots end around the ball (experiment 1): the angle at the ball between
    them, its range and median over runs, and the phrase it implies."""
    angles = _values(rows, "ball_angle_end_deg")
    if not angles:
        return "the angle at the ball between the robots at the end was not measured"
    median = float(np.median(angles))
    if median >= OPPOSITE_DEG:
        where = "on opposite sides of the ball"
    elif median <= SIDE_BY_SIDE_DEG:
        where = "side by side at the ball"
    else:
        where = "at an angle around the ball"
    opposite = sum(a >= OPPOSITE_DEG for a in angles)
    return (
        f"they end {where}: angle at the ball between the robots {min(angles):.0f}-"
        f"{max(angles):.0f}° (median {median:.0f}°; at least {OPPOSITE_DEG:.0f}° in "
        f"{pct(opposite, len(angles))} runs)"
    )


def chosen_goals(rows: list[dict]) -> str:
    """Which goals the robots chose (robot 0 / robot 1 ...), with counts, and how many runs
    had the goals of the rule on the true start positions."""
    counts: dict[str, int] = {}
    for r in rows:
        counts[r["goals"]] = counts.get(r["goals"], 0) + 1
    listed = ", ".join(f"{g} in {k}" for g, k in sorted(counts.items(), key=lambda x: -x[1]))
    right = sum(bool(r["goals_correct"]) for r in rows)
    return f"chosen goals (robot 0/robot 1) {listed}; right in {pct(right, len(rows))}"


def _worse(a, b, count: bool) -> bool:
    """Whether ``b`` is worse than ``a`` for a quantity where more is worse."""
    if a is None or b is None:
        return False
    floor = 1 if count else 0.01
    return b - a > max(floor, 0.1 * abs(a))


def _change(label: str, a, b, spec: str, unit: str = "") -> str:
    if a is None or b is None:
        return f"{label} {fmt(a, spec, unit)} / {fmt(b, spec, unit)}"
    if format(a, spec) == format(b, spec):
        return f"{label} is unchanged at {format(a, spec)}{unit}"
    verb = "rises" if b > a else "falls"
    return f"{label} {verb} from {format(a, spec)}{unit} to {format(b, spec)}{unit}"


def compare_prior(name: str, prior: dict, alone: dict) -> tuple[str, bool]:
    """What changes in experiment ``name`` without the additions (``prior``: summary with the
    parallel-start prior and shared odometry; ``alone``: perception only). Returns the sentence
    and whether the conclusion is weaker without the prior (more collisions, fewer right goals
    or arrivals, or a larger teammate error at the 90th percentile or relayed-ball error)."""
    n = alone["runs"]
    parts = [
        (f"runs with a collision {prior['runs_with_collision']}/{prior['runs']} with the prior, "
         f"{alone['runs_with_collision']}/{n} without"),
        f"goals right {prior['goals_correct']}/{prior['runs']} and {alone['goals_correct']}/{n}",
        f"both reached {prior['all_reached']}/{prior['runs']} and {alone['all_reached']}/{n}",
        _change("teammate error median", prior["teammate_err_median_m"],
                alone["teammate_err_median_m"], ".3f", " m"),
        _change("its 90th percentile", prior["teammate_err_p90_m"], alone["teammate_err_p90_m"],
                ".3f", " m"),
    ]
    if prior.get("blind_relayed_ball_err_median_m") is not None:
        parts.append(_change("the blind robot's relayed-ball error",
                             prior["blind_relayed_ball_err_median_m"],
                             alone["blind_relayed_ball_err_median_m"], ".3f", " m"))
    weaker = (
        _worse(prior["runs_with_collision"], alone["runs_with_collision"], True)
        or _worse(alone["goals_correct"], prior["goals_correct"], True)
        or _worse(alone["all_reached"], prior["all_reached"], True)
        or _worse(prior["teammate_err_p90_m"], alone["teammate_err_p90_m"], False)
        or _worse(prior.get("blind_relayed_ball_err_median_m"),
                  alone.get("blind_relayed_ball_err_median_m"), False)
    )
    verdict = "weaker without the prior" if weaker else "holds without the prior"
    return f"{name}: {verdict}: " + "; ".join(parts) + ".", weaker


def heading_error_sentence(name: str, by_error: dict[float, dict], mode: str) -> str:
    """Collisions, goals and teammate error at each start-heading error (``by_error``: error
    rad -> summary) for one experiment and one mode."""
    parts = []
    for error in sorted(by_error):
        s = by_error[error]
        parts.append(
            f"{error:.1f} rad: collisions in {s['runs_with_collision']}/{s['runs']}, goals right "
            f"{s['goals_correct']}/{s['runs']}, teammate error p90 "
            f"{fmt(s['teammate_err_p90_m'], '.3f')} m"
        )
    return f"{name}, {mode}: " + "; ".join(parts) + "."


def robot_count_sentence(rows: list[dict], key: str = "teammate_err_median_m") -> tuple[str, str]:
    """§II's claim against the rows of the robot-count group: the median over runs of ``key``
    per team size, and whether it falls as robots are added ("agrees") or not ("differs")."""
    sizes = sorted({r["robots"] for r in rows})
    medians = {n: float(np.median(_values([r for r in rows if r["robots"] == n], key)))
               for n in sizes}
    listed = ", ".join(f"{n} robots {medians[n]:.3f} m" for n in sizes)
    falling = all(medians[b] < medians[a] for a, b in pairwise(sizes))
    rising = all(medians[b] > medians[a] for a, b in pairwise(sizes))
    trend = ("falls with every robot added" if falling else "rises with every robot added"
             if rising else "does not fall steadily")
    return f"median teammate error {listed}: it {trend}", "agrees" if falling else "differs"


def body_sentence(name: str, cylinder: dict, box: dict) -> str:
    """Box bodies against cylinders in one experiment (sharing on)."""
    return (
        f"{name}: runs with a collision {cylinder['runs_with_collision']}/{cylinder['runs']} with "
        f"cylinders, {box['runs_with_collision']}/{box['runs']} with boxes; "
        + _change("teammate error median", cylinder["teammate_err_median_m"],
                  box["teammate_err_median_m"], ".3f", " m")
        + f"; goals right {cylinder['goals_correct']}/{cylinder['runs']} and "
        f"{box['goals_correct']}/{box['runs']}."
    )
