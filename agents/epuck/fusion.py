"""Fusion rules of social odometry that a user brings: the gain of eq. 15-16 and ``p`` after it.

Seed 000 §4 writes every social odometry filter in one form: when two robots that know the same
goal meet, the receiver moves its estimate towards the neighbour's by a scalar gain ``g``,

    x <- (1 - g) x + g x_other                     (eq. 15)
    p <- f(p, p_other, g)                          (eq. 16, with eq. 22 or eq. 26)

and the filters differ only in ``g`` and ``f``: the induced Kalman gain ``g = p / (p + p_other)``,
``f = (1 - g) p`` (SGIKF, eq. 20-22), and the Fermi rule ``g = 1 / (1 + exp(-beta (p - p_other)))``,
``f = (1 - g) p + g p_other`` (SGIFF, eq. 24-26). Those two are built into the compiled brain
(``agents/epuck/kernels.py``); a :class:`FusionRule` is a third of the user's, run by the very same
kernels: its two functions are compiled by numba as C functions (``numba.cfunc``) and the kernel
calls them through their addresses (``swarmloc.numerics.call_f64_3``/``call_f64_4``), so the
batch engine, the agent processes and experiments all run it, and the kernels themselves are
compiled (and cached) once for every rule.

Both functions take plain floats, ``p`` in the unit ``beta`` is expressed in
(``AgentConfig.confidence_unit_m``):

- ``gain(p_own, p_other, beta) -> g``, in [0, 1];
- ``confidence(p_own, p_other, g, beta) -> p_new``, at least 0; it is used where the strategy's
  ``p`` follows the fusion (eq. 22/26: ``p_after_fusion = "fused"``, or a covariance confidence);
  with ``p_after_fusion = "distance"`` ``p`` stays the distance travelled (eq. 23) whatever it says.

A strategy names the rule in its ``gain`` (``Strategy("SSGICI", communicates=True, double=False,
gain="ci")``) once the rule is registered. Registration compiles both functions and holds them to
their Python selves on a grid of inputs (:func:`check_rule`): a function numba cannot compile, a gain
outside [0, 1], a negative or non-finite ``p``, or a compiled result that differs from the Python
one is refused there, naming the rule and the input. docs/extending.md has a worked example.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from swarmloc.registry import Registry

#: C signatures of a rule's functions.
GAIN_SIGNATURE = "float64(float64, float64, float64)"
CONFIDENCE_SIGNATURE = "float64(float64, float64, float64, float64)"

#: The inputs :func:`check_rule` holds a rule to: ``p`` from a perfect estimate to far beyond any
#: arena, ``beta`` from the seeds' range (seed 001 §5: 1e-4 to 1e-1) and the defaults.
_P_PROBE = (0.0, 1e-3, 0.05, 0.3, 1.0, 3.0, 50.0, 1e4)
_BETA_PROBE = (1e-4, 1e-2, 1.0, 10.0)


@dataclass(frozen=True)
class FusionRule:
    """A fusion rule: its name (what a :class:`~swarmloc.agents.epuck.social_odometry.Strategy`'s
    ``gain`` says), ``gain(p_own, p_other, beta)`` and ``confidence(p_own, p_other, g, beta)``,
    plain Python functions numba can compile in nopython mode (``math`` and arithmetic)."""

    name: str
    gain: Callable[[float, float, float], float]
    confidence: Callable[[float, float, float, float], float]
    #: The compiled C functions, set at registration (numba ``CFunc``); kept here so that their
    #: addresses stay valid as long as the rule is registered.
    compiled: tuple = field(default=(), compare=False, repr=False)

    def addresses(self) -> tuple[int, int]:
        """``(gain, confidence)`` addresses of the compiled functions, for ``math_fns``."""
        if not self.compiled:
            raise ValueError(f"fusion rule {self.name!r} is not compiled: register it first")
        return self.compiled[0].address, self.compiled[1].address

    def update(self, x_own: np.ndarray, p_own: np.ndarray, x_other: np.ndarray, p_other: np.ndarray,
               beta: float) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 15-16 with this rule's Python functions, over ``(M, 2)`` locations and ``(M,)``
        values of ``p`` (the reference the compiled kernels are held to)."""
        p_own = np.asarray(p_own, float)
        p_other = np.asarray(p_other, float)
        g = np.array([self.gain(float(a), float(b), beta) for a, b in zip(p_own, p_other, strict=True)])
        p_new = np.array([self.confidence(float(a), float(b), float(k), beta)
                          for a, b, k in zip(p_own, p_other, g, strict=True)])
        x_new = (1.0 - g)[:, None] * np.asarray(x_own, float) + g[:, None] * np.asarray(x_other, float)
        return x_new, p_new


def _compile(rule: FusionRule) -> tuple:
    from numba import cfunc

    out = []
    for what, fn, signature in (("gain", rule.gain, GAIN_SIGNATURE),
                                ("confidence", rule.confidence, CONFIDENCE_SIGNATURE)):
        if not callable(fn):
            raise ValueError(  # noqa: TRY004 -- the registry's contract is ValueError
                f"{what}: expected a function, got {type(fn).__name__}")
        try:
            out.append(cfunc(signature)(fn))
        except Exception as exc:  # noqa: BLE001 -- numba's errors are many classes; name the function
            where = f"{fn.__code__.co_filename}:{fn.__code__.co_firstlineno}" if hasattr(fn, "__code__") else "?"
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ValueError(f"{what} ({where}) does not compile with numba as {signature}: {first}") from None
    return tuple(out)


def check_rule(name: str, rule: FusionRule) -> None:
    """Refuse, at registration, a rule the kernels could not run or that they would run
    differently from its Python functions (ValueError naming the input). Compiles it (stored in
    ``rule.compiled``)."""
    if not isinstance(rule, FusionRule):
        raise ValueError(  # noqa: TRY004 -- the registry's contract is ValueError
            f"expected a FusionRule, got {type(rule).__name__}")
    if rule.name != name:
        raise ValueError(f"registered as {name!r} but named {rule.name!r}")
    from swarmloc.agents.epuck.social_odometry import GAINS

    if name in GAINS:
        raise ValueError(f"{name!r} is a built-in gain (built in: {', '.join(GAINS)})")
    compiled = _compile(rule)
    for p_own in _P_PROBE:
        for p_other in _P_PROBE:
            for beta in _BETA_PROBE:
                where = f"p_own={p_own}, p_other={p_other}, beta={beta}"
                try:
                    g = float(rule.gain(p_own, p_other, beta))
                    p_new = float(rule.confidence(p_own, p_other, g, beta))
                except Exception as exc:  # noqa: BLE001 -- the user's code may raise anything
                    raise ValueError(f"raised {type(exc).__name__} ({exc}) at {where}") from None
                if not (0.0 <= g <= 1.0):
                    raise ValueError(f"gain {g!r} outside [0, 1] at {where}")
                if not (math.isfinite(p_new) and p_new >= 0.0):
                    raise ValueError(f"confidence {p_new!r} is not a finite p >= 0 at {where}")
                g_c = compiled[0](p_own, p_other, beta)
                p_c = compiled[1](p_own, p_other, g, beta)
                if g_c != g or p_c != p_new:
                    raise ValueError(f"the compiled rule gives g={g_c!r}, p={p_c!r} against Python's "
                                     f"g={g!r}, p={p_new!r} at {where} (fastmath or object mode?)")
    object.__setattr__(rule, "compiled", compiled)


#: Fusion rules of the user's, by the name a strategy's ``gain`` gives. The built-in gains
#: (``social_odometry.GAINS``) are not in it: the kernels run them inline.
FUSION_RULES: Registry[FusionRule] = Registry("fusion rule", check_rule)


#: Register a rule (compiled and checked), then name it in a strategy's ``gain``. The registry's
#: own method, so that the origin it records is the caller's file and line.
register = FUSION_RULES.register
