"""A social odometry fusion rule of one's own: fast covariance intersection (docs/extending.md).

Seed 000's filters fuse two estimates of a goal as if they were independent (the induced Kalman
gain, eq. 20). They are not: two robots that met before share part of their information, and a
Kalman gain then trusts the fused estimate more than it deserves. Covariance intersection
(Julier & Uhlmann 1997) fuses estimates of unknown correlation without overconfidence,

    1 / p_new = w / p_own + (1 - w) / p_other,
    x_new = p_new (w x_own / p_own + (1 - w) x_other / p_other),

and its fast, closed-form weight (Niehsen 2002, "Information fusion based on fast covariance
intersection filtering") is ``w = p_other / (p_own + p_other)``. Written in seed 000's form
``x_new = (1 - g) x_own + g x_other`` (eq. 15) it is

    g = p_own^2 / (p_own^2 + p_other^2),
    p_new = p_own p_other (p_own + p_other) / (p_own^2 + p_other^2).

Run it: ``swarmloc --plugin examples/fusion_rule.py batch ES1 --strategy SFCI``, or in an
experiment beside seed 000's baselines: ``swarmloc --plugin examples/fusion_rule.py experiment
examples/fci-vs-baselines.toml``.
"""

from swarmloc.agents.epuck.fusion import FusionRule
from swarmloc.agents.epuck.fusion import register as register_rule
from swarmloc.agents.epuck.social_odometry import STRATEGIES, Strategy


def fci_gain(p_own, p_other, beta):
    """g of eq. 15 for fast covariance intersection (``beta`` unused)."""
    a = p_own * p_own
    b = p_other * p_other
    if a + b == 0.0:
        return 0.5  # two perfect estimates: their mean
    return a / (a + b)


def fci_confidence(p_own, p_other, g, beta):
    """``p`` after the fusion: the CI bound, never below the better of the two."""
    a = p_own * p_own
    b = p_other * p_other
    if a + b == 0.0:
        return 0.0
    return p_own * p_other * (p_own + p_other) / (a + b)


register_rule(FusionRule("fast-ci", gain=fci_gain, confidence=fci_confidence))
# Single and double strategies (seed 000 §6.1) on the new rule, named like the paper's.
STRATEGIES.register(Strategy("SFCI", communicates=True, double=False, gain="fast-ci"))
STRATEGIES.register(Strategy("DFCI", communicates=True, double=True, gain="fast-ci"))
