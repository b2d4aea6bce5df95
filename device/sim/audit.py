"""Energy audit of the simulated samples: does anything give the stylus more than it took?

For one scene at one servo rate, a long window of taps sweeping 0.02–0.4 m/s (the range
people tap at, and beyond) measures:

- the work across the stylus's ports (:attr:`~device.events.WindowResult.energy`): what
  the stylus did on the actuator and on a real sample (``energy_in_j``) and what they did
  on the stylus (``energy_out_j``). A passive sample stores or dissipates: out ≤ in;
- the coefficient of restitution of single taps at 0.02, 0.11 and 0.4 m/s
  (:func:`~device.sim.metrics.restitution`): a passive contact returns a slower stylus,
  e < 1;
- the fastest the stylus left the sample after a contact (``max_rebound_speed``, true tip
  speed, until the next contact or 60 ms) against the fastest it arrived
  (``max_contact_speed``), and the fastest arrival against the fastest
  tap the hand intended: a sample that throws the stylus back faster than it came makes
  later approaches faster. The device's own estimate at each contact is reported too; it
  reads a few per cent high on hard samples (the encoder is on the motor side, which runs
  on through the link at impact) and is not the physics;
- that every state stayed finite (the divergence guard did not trip).

A real sample must pass all of these. A virtual scene gets the same numbers and a verdict:
a spring rendered from held samples returns a little more than it took (the half-sample
lag of the zero-order hold); a transient is an open-loop force pushed at the stylus, active
by design. The physical damping of the device and the hand keeps those stable: see the
restitution, and :func:`~device.sim.metrics.passivity_margin`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..scene import Scene
from .backend import SimDevice
from .metrics import restitution
from .tapper import Tapper

__all__ = ["EnergyRow", "energy_audit", "AUDIT_TAPPER", "RESTITUTION_SPEEDS"]

#: taps sweeping 0.02–0.4 m/s in 20 steps, slow to fast, again and again
AUDIT_TAPPER = Tapper(sweep=tuple(float(v) for v in np.linspace(0.02, 0.40, 20)))
#: how long after a contact its rebound is looked for [s] (rubber's bounce lasts ~30 ms)
REBOUND_HORIZON_S = 0.06
#: single-tap speeds of the restitution measurement [m/s]
RESTITUTION_SPEEDS = (0.02, 0.11, 0.40)


@dataclass(frozen=True)
class EnergyRow:
    """One scene at one rate (see the module docstring). Energies [J], speeds [m/s]."""

    scene: str
    kind: str
    rate_hz: float
    window_s: float
    energy_in_j: float
    energy_out_j: float
    max_restitution: float
    max_contact_speed: float
    max_rebound_speed: float
    max_measured_contact_speed: float
    max_tap_speed: float
    finite: bool
    passive: bool
    verdict: str

    def as_dict(self) -> dict:
        return asdict(self)


def energy_audit(scene: Scene, rate_hz: float = 10_000.0, window_s: float = 30.0,
                 seed: int = 1) -> EnergyRow:
    """Audit ``scene`` at ``rate_hz`` [Hz] over a ``window_s`` [s] window of taps."""
    dev = SimDevice(rate_hz=rate_hz, seed=seed, noise=False, tapper=AUDIT_TAPPER)
    dev.load_scene(scene)
    dev.home()
    res = dev.run_window(window_s, from_first_contact=False)
    strokes = dev.last_plan.strokes
    tapped = strokes[strokes[:, 0] < window_s]
    max_tap = float(tapped[:, 1].max()) if len(tapped) else 0.0
    e_in, e_out = res.energy["in"], res.energy["out"]
    finite = not res.faults and all(math.isfinite(x) for x in (e_in, e_out))
    e = [restitution(scene, rate_hz, speed=v).e for v in RESTITUTION_SPEEDS]
    e_max = max((x for x in e if math.isfinite(x)), default=math.nan)
    v_meas = float(res.velocities.max()) if res.contacts else 0.0
    v2 = res.traces["true_velocity"]
    v_max = float(-v2.min()) if v2.size and np.all(np.isfinite(v2)) else math.inf
    v_back = _rebound(res.traces["t"], v2, [c.t for c in res.contacts])
    # the port integrals are exact quadratic forms: allow their rounding, scaled to what
    # went through
    gives_back_less = e_out <= e_in * (1 + 1e-6) + 1e-12
    bounces_slower = not e_max >= 1.0  # nan (never left the surface) counts as no bounce
    # the stylus follows the intention through the hand's impedance: a little overshoot
    no_faster = v_max <= max_tap * 1.02
    passive = (finite and gives_back_less and bounces_slower and no_faster
               and v_back <= v_max)
    if scene.is_real:
        verdict = "passive" if passive else "ACTIVE: a real sample must not create energy"
    elif passive:
        verdict = "passive at this rate"
    elif scene.transient is not None:
        verdict = "active by design: an open-loop force transient at each contact"
    else:
        verdict = ("active: the held spring force lags the penetration (zero-order hold); "
                   "the device's and the hand's damping absorb it")
    return EnergyRow(scene.name, scene.kind, float(rate_hz), float(window_s), e_in, e_out,
                     e_max, v_max, v_back, v_meas, max_tap, finite, passive, verdict)


def _rebound(t: np.ndarray, v: np.ndarray, contacts: list[float],
             horizon_s: float = REBOUND_HORIZON_S) -> float:
    """Fastest the stylus left the surface [m/s]: the largest outward true tip speed from
    each contact until the next one or ``horizon_s`` later."""
    if not contacts or not v.size:
        return 0.0
    if not np.all(np.isfinite(v)):
        return math.inf
    ends = [*contacts[1:], math.inf]
    out = 0.0
    for c, nxt in zip(contacts, ends, strict=True):
        i, j = np.searchsorted(t, [c, min(nxt, c + horizon_s)])
        if j > i:
            out = max(out, float(v[i:j].max()))
    return out
