"""The simulated participant as a forced-choice observer with a known answer (issue 57).

In an adaptive phase the participant feels a standard and a comparison rendering and says
which has more of one transient parameter. The simulated participant answers from the two
parameter values the device was asked to render (not from the trace: its answer does not
depend on the simulated physics, so its psychometric function is known exactly), with its
own just-noticeable difference for that parameter and its own lapse rate:

    P(right | x) = γ + (1 − γ − λ)·(1 − exp(−(x / α)^β)),   x = |log10(comparison / standard)|

a Weibull function of the log ratio with guess rate γ = 1/2 (two intervals), lapse rate
λ and shape β. Its JND for a parameter is the Weber fraction W at which it is right 75 % of
the time, so α follows from W, β and λ. Because the Weibull's shape does not change when
the intensity is scaled, the function is a Weibull of the same shape in dB (x·20) too; a
procedure in linear units sees the same observer through a monotone change of axis. Its
threshold at any criterion, in any unit (:meth:`Observer.threshold`), is the truth a
measured threshold is compared with (``hapticlab bench thresholds``).

The JNDs are assumptions until someone measures them: :data:`DISCRIMINATION` holds the
population values used (vibrotactile frequency and amplitude about 20 %, as the factorial
protocol's levels assume; decay rate 25 %, a guess), each person's drawn around them
(log-normal, SD :data:`JND_SPREAD`). A lab that has measured them gives its group Weber
fractions instead (``discrimination``), and every simulated session then answers with
those.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Observer", "DISCRIMINATION", "JND_SPREAD", "SHAPE", "LAPSE_MAX",
           "draw_observer", "discrimination_from_report"]

#: the Weber fraction at 75 % correct (two-interval forced choice) a simulated person is
#: assumed to have, by transient parameter, before any is measured
DISCRIMINATION: dict[str, float] = {"frequency": 0.20, "decay": 0.25, "slope": 0.20,
                                    "gain": 0.20, "decay_time": 0.25}
#: a person's JND is the population's times exp(N(0, JND_SPREAD²))
JND_SPREAD = 0.25
#: the Weibull shape β of every simulated observer's psychometric function
SHAPE = 3.5
#: a person's lapse rate is drawn uniformly in [0, LAPSE_MAX]
LAPSE_MAX = 0.04


@dataclass(frozen=True)
class Observer:
    """A forced-choice observer (module docstring).

    Attributes
    ----------
    jnd : mapping of str to float
        Weber fraction at 75 % correct, by transient parameter.
    lapse : float
        λ: the upper asymptote is 1 − λ (wrong answers however large the difference).
    shape : float
        β.
    guess : float
        γ (1/2: two intervals).
    """

    jnd: Mapping[str, float] = field(default_factory=lambda: dict(DISCRIMINATION))
    lapse: float = 0.02
    shape: float = SHAPE
    guess: float = 0.5

    def __post_init__(self) -> None:
        if not 0 <= self.lapse < 0.25:
            raise ValueError(f"a lapse rate of {self.lapse!r}: must lie in [0, 0.25)")
        for k, w in self.jnd.items():
            if not (isinstance(w, int | float) and math.isfinite(w) and w > 0):
                raise ValueError(f"the JND of {k} must be a positive Weber fraction, got {w!r}")

    def _f(self, p: float) -> float:
        f = (p - self.guess) / (1.0 - self.guess - self.lapse)
        if not 0.0 < f < 1.0:
            raise ValueError(f"proportion correct {p:g} is out of this observer's reach "
                             f"({self.guess:g} to {1 - self.lapse:g})")
        return f

    def alpha(self, parameter: str) -> float:
        """The Weibull's scale α on |log10 ratio| for ``parameter``."""
        if parameter not in self.jnd:
            raise KeyError(f"the observer has no JND for {parameter!r}; it has "
                           f"{', '.join(self.jnd)}")
        x75 = math.log10(1.0 + self.jnd[parameter])
        return x75 / (-math.log1p(-self._f(0.75))) ** (1.0 / self.shape)

    def p_right(self, parameter: str, x: float) -> float:
        """P(right) at |log10 ratio| ``x``."""
        a = self.alpha(parameter)
        return self.guess + (1.0 - self.guess - self.lapse) * (
            1.0 - math.exp(-(max(x, 0.0) / a) ** self.shape))

    def threshold(self, parameter: str, criterion: float, units: str = "log",
                  standard: float | None = None, direction: str = "up") -> float:
        """The intensity at which this observer is right ``criterion`` of the time, in a
        procedure's ``units`` (``linear`` needs the standard's value)."""
        x = self.alpha(parameter) * (-math.log1p(-self._f(criterion))) ** (1.0 / self.shape)
        if units == "log":
            return x
        if units == "dB":
            return 20.0 * x
        if standard is None:
            raise ValueError("a linear threshold needs the standard's value")
        ratio = 10.0 ** x if direction == "up" else 10.0 ** -x
        return abs(abs(standard) * ratio - abs(standard))

    def judge(self, parameter: str, values, rng: np.random.Generator) -> int:
        """Which of ``values`` (two parameter values, as rendered) it says is larger."""
        a, b = (abs(float(v)) for v in values)
        larger = 0 if a > b else 1
        x = abs(math.log10(a / b)) if a > 0 and b > 0 else math.inf
        right = rng.random() < self.p_right(parameter, x)
        return larger if right else 1 - larger


def draw_observer(rng: np.random.Generator,
                  discrimination: Mapping[str, float] | None = None) -> Observer:
    """One person's observer: each JND the population's (:data:`DISCRIMINATION`, or the
    measured ``discrimination``, which replaces it parameter by parameter) times
    exp(N(0, JND_SPREAD²)), and a lapse rate uniform in [0, LAPSE_MAX]."""
    pop = {**DISCRIMINATION, **(discrimination or {})}
    jnd = {k: float(w * math.exp(rng.normal(0.0, JND_SPREAD))) for k, w in sorted(pop.items())}
    return Observer(jnd=jnd, lapse=float(rng.uniform(0.0, LAPSE_MAX)))


def discrimination_from_report(report: Mapping) -> dict[str, float]:
    """The group Weber fractions at 75 % correct a report of thresholds measured (its
    ``thresholds`` analyses' group summary), by parameter: what :func:`draw_observer` takes
    to make simulated participants with the JNDs a lab measured.

    Raises
    ------
    ValueError
        When the report has no threshold measured at 75 % correct.
    """
    out: dict[str, list[float]] = {}
    for a in report.get("analyses", []):
        if a.get("type") != "threshold":
            continue
        for row in a.get("group", []):
            if abs(float(row.get("criterion", 0)) - 0.75) < 1e-9 and \
                    row.get("weber_geomean") is not None:
                out.setdefault(row["parameter"], []).append(float(row["weber_geomean"]))
    if not out:
        raise ValueError("the report has no group Weber fraction measured at 75 % correct "
                         "(a threshold analysis with criterion = 0.75)")
    return {k: float(np.exp(np.mean(np.log(v)))) for k, v in out.items()}
