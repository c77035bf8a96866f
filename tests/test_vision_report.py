"""The vision report states only what its rows say (issue #49): each result sentence is
computed (``deploy/lab/vision/claims.py``), so rows with a known answer must give that answer,
and changing the rows must change the sentence."""

from __future__ import annotations

import re

import pytest

from swarmloc.deploy.lab.vision import claims
from swarmloc.deploy.lab.vision import experiment as vx
from swarmloc.deploy.lab.vision import report as vr


def _row(**values) -> dict:
    base = dict.fromkeys(vx.COLUMNS) | {
        "experiment": 1, "scenario": "vision-exp1", "sharing": True, "seed": 1, "variant": "",
        "collisions": 0, "contact_s": 0.0, "obstacle_collisions": 0, "goals_correct": True,
        "goals": "ball/ball", "true_goals": "ball/ball", "all_reached": True,
        "all_reached_s": 6.0, "reach_s_0": 5.0, "reach_s_1": 6.0, "teammate_err_median_m": 0.05,
        "teammate_err_p90_m": 0.1, "teammate_known_fraction": 0.9, "ball_err_median_m": 0.01,
        "bad_images": 0, "bad_payloads": 0, "cpu_s": 0.5, "robots": 2,
    }
    return base | values


@pytest.mark.parametrize(
    ("angles", "phrase"),
    [((170.0, 164.0, 150.0), "on opposite sides of the ball"),
     ((66.0, 71.0, 40.0), "at an angle around the ball"),
     ((5.0, 20.0, 61.0), "side by side at the ball")],
)
def test_where_the_robots_end_follows_the_angle_at_the_ball(angles, phrase):
    rows = [_row(seed=i, ball_angle_end_deg=a) for i, a in enumerate(angles)]
    text = claims.ends_at_the_ball(rows)
    assert phrase in text
    lo, hi, median = (float(x) for x in re.search(r"(\d+)-(\d+)° \(median (\d+)°", text).groups())
    assert (lo, hi, median) == (round(min(angles)), round(max(angles)), round(sorted(angles)[1]))


def test_the_report_claims_what_its_rows_say_about_experiment_one():
    """The sentence the old report typed in ("They arrive side by side, not from opposite
    sides") was wrong for rows at 164-171°; the claim table now says what the rows say, both
    ways."""
    for angles, word, not_word in (((171.0, 164.0), "opposite sides", "side by side"),
                                   ((10.0, 20.0), "side by side", "opposite sides")):
        rows = [_row(seed=i, ball_angle_end_deg=a) for i, a in enumerate(angles)]
        rows += [_row(seed=i, sharing=False, collisions=3, ball_angle_end_deg=5.0)
                 for i in range(2)]
        text, verdict = vr._ours(vx.summarize(rows), "vision-exp1", "collisions with sharing",
                                 rows)
        assert word in text and not_word not in text
        assert verdict == ("agrees" if word == "opposite sides" else "agrees (collisions)")
        off, _ = vr._ours(vx.summarize(rows), "vision-exp1", "collisions without sharing", rows)
        assert "collided in 2/2 (100 %) runs without sharing" in off


def test_no_sharing_goals_are_counted_from_the_rows():
    rows = [_row(scenario="vision-exp2", sharing=s, goals=g, true_goals="obstacle/ball",
                 goals_correct=g == "obstacle/ball", variant="b")
            for s, g in ((True, "obstacle/ball"), (False, "obstacle/obstacle"),
                         (False, "obstacle/obstacle"), (False, "obstacle/ball"))]
    text, _ = vr._ours(vx.summarize(rows), "vision-exp2", "goals and collisions with sharing",
                       rows)
    assert "obstacle/obstacle in 2, obstacle/ball in 1; right in 1/3 (33 %)" in text


def test_weaker_without_the_prior_only_when_the_numbers_say_so():
    rows = [_row(seed=i) for i in range(4)]
    same = vx.summarize(rows)[0]
    sentence, weaker = claims.compare_prior("vision-exp1", same, same)
    assert not weaker and "holds without the prior" in sentence
    worse = vx.summarize([_row(seed=i, collisions=int(i < 3), teammate_err_p90_m=0.4)
                          for i in range(4)])[0]
    sentence, weaker = claims.compare_prior("vision-exp1", same, worse)
    assert weaker and "weaker without the prior" in sentence
    assert "runs with a collision 0/4 with the prior, 3/4 without" in sentence
    assert "its 90th percentile rises from 0.100 m to 0.400 m" in sentence


def test_robot_count_verdict_follows_the_medians():
    falling = [_row(seed=i, robots=n, teammate_err_median_m=0.1 / n)
               for n in (2, 3, 4, 6) for i in range(3)]
    text, verdict = claims.robot_count_sentence(falling)
    assert verdict == "agrees" and "falls with every robot added" in text
    rising = [r | {"teammate_err_median_m": 0.01 * r["robots"]} for r in falling]
    text, verdict = claims.robot_count_sentence(rising)
    assert verdict == "differs" and "2 robots 0.020 m" in text and "6 robots 0.060 m" in text
