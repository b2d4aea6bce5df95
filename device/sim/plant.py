"""Continuous-time linear dynamics of device + hand (+ sample) and their exact ZOH discretization.

States (SI units)::

    0 z1   motor-side position [m]         (the encoder reads this one)
    1 v1   motor-side velocity [m/s]
    2 z2   tip/hand position [m]            (the accelerometer sits here)
    3 v2   tip/hand velocity [m/s]
    4 fa   force delivered by the amplifier/actuator [N]
    5 y    accelerometer output before noise/ADC [m/s²]
    6 yd   its derivative [m/s³]
    7 fh   the hand's pull k_h·z_ref + b_h·v_ref towards its intended motion [N]
    8 zb   the block's displacement from rest [m]   (only for a real sample that is a block)
    9 vb   its velocity [m/s]

Inputs, held constant over each servo tick::

    0 f_cmd   commanded force after the current clamp [N] (zero-order hold: what a
              sampled-data device does)
    1 fh_rate slope of the hand's pull over the tick [N/s] (the hand is a continuous
              input: its pull is interpolated linearly between ticks, not held)
    2 one     constant 1 (carries k_s·h of the contact spring)

A real sample adds a second *mode* (in contact), in which the tip feels
k_s·(h + zb − z2) − b_s·(v2 − vb) from the sample. A sample that is a block (a second
body of mass m_b on its support k_b, b_b) feels the opposite force; its vibration is
excited by the contact itself and reaches the tip only through it, so the sample is
passive: it returns at most the energy the tip brought. Everything is linear within a
mode, so the exact discrete propagator over a tick is the matrix exponential of the
augmented matrix [[A, B], [0, 0]]·T (Van Loan); mode switches are located inside a tick
by the kernel (see :mod:`device.sim.kernel`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.linalg import expm

from ..errors import SceneError
from ..scene import BLOCK_HINT, MAX_STIFFNESS, Material, Support
from .params import DeviceParams, HandParams

__all__ = ["Plant", "build_plant", "zoh", "piece_propagators", "N_INPUTS", "block_model",
           "BlockModel", "contact_modes", "SUPPORT_ZETA", "MAX_CONTACT_ZETA", "MAX_CONTACT_HZ",
           "tip_share", "port_forms", "work_forms"]

Z1, V1, Z2, V2, FA, Y, YD, FH, ZB, VB = range(10)
U_CMD, U_HAND_RATE, U_ONE = range(3)
N_INPUTS = 3
N_LEVELS = 30  # bisection depth for locating a contact switch inside a substep
#: fastest a real sample's contact may ring on the masses it joins [Hz]: a 1-g block on a
#: 10⁷-N/m contact rings at ~16 kHz; a servo tick is cut into 8 pieces per period of it, so
#: at 100 kHz a 1-kHz servo takes 800 pieces a tick (10¹⁵ N/m on the stylus, ~15 MHz, took
#: 33 s per 3-s window; 10²⁰ N/m would take days)
MAX_CONTACT_HZ = 100_000.0


@dataclass
class Plant:
    """Continuous-time matrices per mode and what the kernel needs to switch modes.

    Attributes
    ----------
    A : ndarray, shape (n_modes, ns, ns)
    B : ndarray, shape (n_modes, ns, N_INPUTS)
    accel_row : ndarray, shape (n_modes, ns + N_INPUTS)
        True tip acceleration as a row over [x; u].
    contact_stiffness, contact_damping : float
        k_s [N/m], b_s [N·s/m] of the real sample (0 for virtual samples).
    support : Support or None
        What the block rests on (given, or derived from the measured ringing).
    block_mass : float [kg]
        The block's mass (0 when the sample does not move).
    n_sub : int
        Substeps per tick for contact-switch detection (1 without a real sample).
    """

    A: np.ndarray
    B: np.ndarray
    accel_row: np.ndarray
    contact_stiffness: float
    contact_damping: float
    surface_height: float
    n_sub: int
    support: Support | None = None
    block_mass: float = 0.0

    @property
    def n_states(self) -> int:
        return self.A.shape[1]

    @property
    def n_modes(self) -> int:
        return self.A.shape[0]


def _mode_matrices(dev: DeviceParams, hand: HandParams, contact: Material | None,
                   block: tuple[float, Support] | None, h: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """A and B of one mode; ``contact`` is the sample touching the tip (None: free),
    ``block`` its mass [kg] and support when the sample is a block."""
    ns = 10 if block is not None else 8
    m1 = dev.motor_mass
    m2 = dev.tip_mass + hand.mass
    A = np.zeros((ns, ns))
    B = np.zeros((ns, N_INPUTS))
    kl, bl = dev.link_stiffness, dev.link_damping
    A[Z1, V1] = 1.0
    A[V1, Z1], A[V1, Z2] = -kl / m1, kl / m1
    A[V1, V1], A[V1, V2] = -(bl + dev.motor_damping) / m1, bl / m1
    A[V1, FA] = 1.0 / m1
    A[Z2, V2] = 1.0
    A[V2, Z1], A[V2, Z2] = kl / m2, -(kl + hand.stiffness) / m2
    A[V2, V1], A[V2, V2] = bl / m2, -(bl + hand.damping) / m2
    A[V2, FH] = 1.0 / m2
    B[FH, U_HAND_RATE] = 1.0
    if block is not None:  # the block on its support, in both modes
        mb, sup = block
        A[ZB, VB] = 1.0
        A[VB, ZB] = -sup.stiffness / mb
        A[VB, VB] = -sup.damping / mb
    if contact is not None:  # F = k_s·(h + zb − z2) − b_s·(v2 − vb) on the tip, −F on the block
        ks, bs = contact.stiffness, contact.damping
        A[V2, Z2] -= ks / m2
        A[V2, V2] -= bs / m2
        B[V2, U_ONE] = ks * h / m2
        if block is not None:
            mb = block[0]
            A[V2, ZB] += ks / m2
            A[V2, VB] += bs / m2
            A[VB, Z2] += ks / mb
            A[VB, V2] += bs / mb
            A[VB, ZB] -= ks / mb
            A[VB, VB] -= bs / mb
            B[VB, U_ONE] = -ks * h / mb
    wa = 2 * math.pi * dev.amplifier_bandwidth_hz
    A[FA, FA] = -wa
    B[FA, U_CMD] = wa
    wy = 2 * math.pi * dev.accel_bandwidth_hz  # 2nd-order Butterworth on the tip acceleration
    A[Y, YD] = 1.0
    A[YD, :] += wy * wy * A[V2, :]
    B[YD, :] += wy * wy * B[V2, :]
    A[YD, Y] -= wy * wy
    A[YD, YD] -= math.sqrt(2.0) * wy
    return A, B


def contact_modes(contact: tuple[float, float], block: tuple[float, Support] | None = None,
                  dev: DeviceParams | None = None, hand: HandParams | None = None
                  ) -> np.ndarray:
    """Eigenvalues [1/s] of device + hand + sample while in contact (the hand's pull held),
    sorted by frequency; a ringing shows as −B ± i·2πf.

    Parameters
    ----------
    contact : (float, float)
        The contact's stiffness [N/m] and damping [N·s/m].
    block : (float, Support), optional
        The block's mass [kg] and what it rests on; None: the sample does not move.
    """
    dev, hand = dev or DeviceParams(), hand or HandParams()
    A, _ = _mode_matrices(dev, hand, _Spring(*contact), block, 0.0)
    keep = [Z1, V1, Z2, V2] + ([ZB, VB] if block is not None else [])
    lam = np.linalg.eigvals(A[np.ix_(keep, keep)])
    return lam[np.argsort(np.abs(lam.imag))]


class _Spring(NamedTuple):
    """A contact or support while a block is solved for: unchecked, as the solver's trials
    may pass the limits a scene states (:data:`device.scene.MAX_STIFFNESS`); only the block
    it settles on is checked."""

    stiffness: float
    damping: float


#: damping ratio of a derived support (a block alone on it rings down in ~3 periods / 0.05)
SUPPORT_ZETA = 0.05
#: the largest damping ratio of an elastic contact (stylus against block)
MAX_CONTACT_ZETA = 0.5


@dataclass(frozen=True)
class BlockModel:
    """A ringing block as the simulator models it (see :func:`block_model`).

    Attributes
    ----------
    contact_stiffness, contact_damping : float
        [N/m], [N·s/m] between the stylus tip and the block.
    mass : float [kg]
    support : Support
        What the block rests on.
    """

    contact_stiffness: float
    contact_damping: float
    mass: float
    support: Support

    @property
    def static_stiffness(self) -> float:
        """What pressing the block feels [N/m]: contact and support in series."""
        return 1.0 / (1.0 / self.contact_stiffness + 1.0 / self.support.stiffness)


@functools.lru_cache(maxsize=64)
def block_model(material: Material) -> BlockModel:
    """The passive block that rings as ``material``'s measured ringing.

    ``material.stiffness`` is what pressing the block feels (Table 1's K: the contact and
    the support in series); the ringing is the mode in which the tip and the block bounce
    against each other on the contact, touched by the reference stylus and hand (the
    defaults of :class:`DeviceParams` and :class:`HandParams`: Table 1 was measured with one
    stylus). Solved for: the contact's stiffness and damping, with the support's stiffness
    following from the series and its damping ratio :data:`SUPPORT_ZETA`. The contact must
    be elastic — underdamped, its damping ratio with the stylus against the block at most
    :data:`MAX_CONTACT_ZETA` (a dashpot-like contact would push the tip with b·v the instant
    it touches); where several such blocks ring as measured, the one whose ringing moves
    the tip most is taken. It is a property of the block, the same whoever holds the
    stylus later.

    Raises
    ------
    SceneError
        No passive block reproduces the ringing (naming why).
    """
    from scipy.optimize import fsolve

    if material.ringing is None or not material.is_block or material.support is not None:
        raise ValueError("block_model derives a ringing block (mass and ringing, no support)")
    r, mb, K = material.ringing, float(material.mass), float(material.stiffness)
    m2 = DeviceParams().tip_mass + HandParams().mass
    mu = m2 * mb / (m2 + mb)  # the stylus and the block against each other
    w0 = 2 * math.pi * r.frequency
    target = complex(-r.decay, w0)

    def unpack(p) -> BlockModel:
        ks = K * (1.0 + abs(p[0]))  # stiffer than the series, so the support is finite
        kb = 1.0 / (1.0 / K - 1.0 / ks)
        sup = _Spring(kb, 2.0 * SUPPORT_ZETA * math.sqrt(kb * mb))
        return BlockModel(ks, abs(p[1]) * mb * r.decay, mb, sup)

    def nearest(b: BlockModel) -> complex:
        lam = contact_modes((b.contact_stiffness, b.contact_damping), (b.mass, b.support))
        return lam[np.argmin(np.abs(lam - target))]

    def residual(p):
        lam = nearest(unpack(p))
        return [(lam.imag - target.imag) / w0, (lam.real - target.real) / w0]

    found: list[tuple[float, BlockModel]] = []
    for r0 in (0.05, 0.2, 0.5, 1.0, 2.0, 4.0, 9.0, 29.0):
        for b0 in (0.1, 1.0, 5.0):
            p, _, ok, _ = fsolve(residual, [r0, b0], full_output=True, xtol=1e-12)
            if ok != 1:
                continue
            b = unpack(p)
            if abs(nearest(b) - target) <= 1e-6 * w0 and \
                    b.contact_damping <= 2 * MAX_CONTACT_ZETA * math.sqrt(
                        b.contact_stiffness * mu):
                found.append((tip_share(b, target), b))
    if not found:
        raise SceneError(f"no passive block of {mb:g} kg pressed at {K:g} N/m rings at "
                         f"{r.frequency:g} Hz with decay {r.decay:g} 1/s through an elastic "
                         "contact on this stylus; a heavier block or another stiffness may",
                         "ringing",
                         part=("material",), where="material")
    b = max(found, key=lambda t: t[0])[1]
    if not max(b.contact_stiffness, b.support.stiffness) <= MAX_STIFFNESS:
        raise SceneError(f"the block of {mb:g} kg that rings so needs a contact of "
                         f"{b.contact_stiffness:.3g} N/m on a support of "
                         f"{b.support.stiffness:.3g} N/m, stiffer than any a stylus meets "
                         f"(<= {MAX_STIFFNESS:g} N/m); a heavier block or a lower frequency",
                         "ringing", part=("material",), where="material")
    return BlockModel(b.contact_stiffness, b.contact_damping, b.mass,
                      Support(b.support.stiffness, b.support.damping))


def tip_share(b: BlockModel, target: complex) -> float:
    """How much the mode nearest ``target`` moves the tip after an impact (modal
    amplitude of the tip's velocity per unit incoming velocity)."""
    dev, hand = DeviceParams(), HandParams()
    A, _ = _mode_matrices(dev, hand, _Spring(b.contact_stiffness, b.contact_damping),
                          (b.mass, b.support), 0.0)
    keep = [Z1, V1, Z2, V2, ZB, VB]
    lam, V = np.linalg.eig(A[np.ix_(keep, keep)])
    x0 = np.zeros(len(keep))
    x0[3] = -1.0  # the tip arrives at 1 m/s, everything else at rest
    c = np.linalg.solve(V, x0)
    i = int(np.argmin(np.abs(lam - target)))
    return float(2 * abs(c[i] * V[3, i]))


def build_plant(dev: DeviceParams, hand: HandParams, material: Material | None = None,
                surface_height: float = 0.0) -> Plant:
    """Assemble the continuous-time model for one scene.

    Only what the scene requires is modelled: a virtual scene has one mode and
    eight states; a real sample adds the contact mode, and a block adds two states.
    """
    block = None
    if material is not None and material.ringing is not None and not material.is_block:
        raise SceneError(f"the simulator models a ringing sample as a block: {BLOCK_HINT}",
                         "mass", part=("material",), where="material")
    if material is not None and material.is_block:
        if material.support is None:  # a measured ringing: the block that rings so
            b = block_model(material)
            material = Material(b.contact_stiffness, b.contact_damping)
            block = (b.mass, b.support)
        else:
            block = (float(material.mass), material.support)
    modes = [_mode_matrices(dev, hand, None, block, surface_height)]
    n_sub = 1
    if material is not None:
        modes.append(_mode_matrices(dev, hand, material, block, surface_height))
        m2 = dev.tip_mass + hand.mass
        mu = m2 * block[0] / (m2 + block[0]) if block is not None else m2
        fastest = math.sqrt(material.stiffness / mu)  # the contact's own oscillation
        lam = np.linalg.eigvals(modes[1][0])
        fastest = max(fastest, float(np.max(np.abs(lam[np.abs(lam.imag) > 0].imag),
                                            initial=0.0)))
        f_max = fastest / (2 * math.pi)
        if not f_max <= MAX_CONTACT_HZ:
            what = (f"a {block[0]:g}-kg block and the stylus" if block is not None
                    else "the stylus")
            raise SceneError(f"{what} would ring on this contact at {f_max:.3g} Hz, above "
                             f"the {MAX_CONTACT_HZ:g} Hz the simulator resolves (each servo "
                             "tick is cut into 8 pieces per period, so the cost grows with "
                             "it): give a softer contact or a heavier block", "stiffness",
                             part=("material",), where="material")
        # substep <= 1/8 of the fastest contact period: a contact cannot begin and end unseen
        n_sub = max(1, math.ceil(dev.dt / (2 * math.pi / fastest / 8)))
    A = np.stack([m[0] for m in modes])
    B = np.stack([m[1] for m in modes])
    accel_row = np.concatenate([A[:, V2, :], B[:, V2, :]], axis=1)
    return Plant(A=A, B=B, accel_row=accel_row,
                 contact_stiffness=material.stiffness if material else 0.0,
                 contact_damping=material.damping if material else 0.0,
                 surface_height=surface_height, n_sub=n_sub,
                 support=block[1] if block else None, block_mass=block[0] if block else 0.0)


def zoh(A: np.ndarray, B: np.ndarray, dt: float) -> np.ndarray:
    """Exact zero-order-hold propagator [Φ | Γ] over ``dt`` [s].

    x(t+dt) = Φ·x(t) + Γ·u with u held constant: Φ = e^(A·dt), Γ = ∫₀^dt e^(A·s) ds·B,
    both read off the exponential of the augmented matrix [[A, B], [0, 0]]·dt.

    Returns
    -------
    ndarray, shape (ns, ns + nu)
    """
    ns, nu = B.shape
    M = np.zeros((ns + nu, ns + nu))
    M[:ns, :ns] = A
    M[:ns, ns:] = B
    E = expm(M * dt)
    return np.ascontiguousarray(E[:ns, :])


#: levels between direct matrix exponentials in :func:`piece_propagators`
SQUARINGS = 5


def piece_propagators(A: np.ndarray, B: np.ndarray, h: float, levels: int = N_LEVELS) -> np.ndarray:
    """Propagators over h·2^(j−levels), j = 0..levels (the last one spans ``h``).

    Every (:data:`SQUARINGS` + 1)-th level is an exact matrix exponential; the levels in
    between are squares of the one below (e^(M·2t) = (e^(M·t))², exact in exact arithmetic),
    at most :data:`SQUARINGS` squarings from an exponential, so rounding grows by at most
    2^5 = 32 machine epsilons — and a stiff contact's scene compiles ~6× faster than with
    an exponential per level (the emulator prepares scenes while the host waits).

    Returns
    -------
    ndarray, shape (levels + 1, ns, ns + nu)
    """
    ns, nu = B.shape
    out = np.empty((levels + 1, ns, ns + nu))
    E = np.zeros((ns + nu, ns + nu))
    E[ns:, ns:] = np.eye(nu)
    for j in range(levels + 1):
        if j % (SQUARINGS + 1) == 0:
            P = zoh(A, B, h * 2.0 ** (j - levels))
        else:
            E[:ns, :] = out[j - 1]
            P = (E @ E)[:ns, :]
        out[j] = P
    return out


def port_forms(n_states: int, contact: tuple[float, float] | None, surface_height: float
               ) -> np.ndarray:
    """Quadratic forms of the power through the stylus's two ports, on z = [x; u].

    Row 0, the actuator: the stylus does work −f_a·v₁ on it. Row 1, a real sample's
    contact (``contact`` = (k_s [N/m], b_s [N·s/m]); zero without one): −F·v₂ with
    F = k_s·(h + z_b − z₂) − b_s·(v₂ − v_b) the sample's force on the tip (z_b, v_b when the
    plant has a block's states). Each P = zᵀ·Q·z with Q symmetric.

    Returns
    -------
    ndarray, shape (2, n, n), n = n_states + :data:`N_INPUTS`
    """
    n = n_states + N_INPUTS
    Q = np.zeros((2, n, n))
    e = np.eye(n)

    def power(a: np.ndarray, b: np.ndarray) -> np.ndarray:  # P = −(aᵀz)(bᵀz)
        return -0.5 * (np.outer(a, b) + np.outer(b, a))

    Q[0] = power(e[FA], e[V1])
    if contact is not None:
        ks, bs = contact
        c = ks * surface_height * e[n_states + U_ONE] - ks * e[Z2] - bs * e[V2]
        if n_states > ZB:
            c = c + ks * e[ZB] + bs * e[VB]
        Q[1] = power(c, e[V2])
    return Q


def work_forms(A: np.ndarray, B: np.ndarray, Q: np.ndarray, h: float,
               levels: int = N_LEVELS, pieces: np.ndarray | None = None) -> np.ndarray:
    """Exact work through each port over pieces of h·2^(j−levels), j = 0..levels.

    With z = [x; u] moving as e^(M·t)·z₀ (M = [[A, B], [0, 0]]: the input held), the work
    over a piece of length τ is z₀ᵀ·G(τ)·z₀ with G(τ) = ∫₀^τ e^(Mᵀs)·Q·e^(Ms) ds. G is read
    off one matrix exponential (Van Loan 1978: e^([[−Mᵀ, Q], [0, M]]·τ) = [[·, F₁₂], [0, F₂₂]]
    and G = F₂₂ᵀ·F₁₂) at every (:data:`SQUARINGS` + 1)-th level whose span is short enough
    that e^(−Mᵀτ) stays small (τ·ρ(M) <= 1/2: over a whole 1-kHz tick it grows as e^31 and
    the subtraction loses every digit); the levels between, and those above, double the
    one below, G(2τ) = G(τ) + e^(Mᵀτ)·G(τ)·e^(Mτ), with e^(Mτ) the level's propagator
    (``pieces``, from :func:`piece_propagators` over the same ``h``, when given: it keeps
    their rounding bounded; otherwise an exponential of its own). A trapezoid over a piece
    1/8 of a damped stiff contact's period read 4–6 % off at 1 kHz; this is exact up to
    rounding in the terms it sums (which grow with k_s·h: ~1e-14 of a piece's work with the
    surface at 0, ~1e-6 at 0.5 m on 1e8 N/m).

    Returns
    -------
    ndarray, shape (n_ports, levels + 1, n, n)
    """
    ns, nu = B.shape
    n = ns + nu
    M = np.zeros((n, n))
    M[:ns, :ns] = A
    M[:ns, ns:] = B
    rho = float(np.max(np.abs(np.linalg.eigvals(M))))
    tau0 = h * 2.0 ** (-levels)
    finer = max(0, math.ceil(math.log2(tau0 * rho / 0.5))) if tau0 * rho > 0.5 else 0

    def propagator(j: int) -> np.ndarray:  # e^(M·τ_j), τ_j = τ₀·2^j
        if pieces is not None and j >= 0:
            E = np.zeros((n, n))
            E[:ns, :] = pieces[j]
            E[ns:, ns:] = np.eye(nu)
            return E
        return expm(M * (tau0 * 2.0**j))

    ports = Q.shape[0]
    out = np.zeros((ports, levels + 1, n, n))
    live = [p for p in range(ports) if np.any(Q[p])]
    G = {p: np.zeros((n, n)) for p in live}
    for j in range(-finer, levels + 1):
        tau = tau0 * 2.0**j
        fresh = j == -finer or (j % (SQUARINGS + 1) == 0 and tau * rho <= 0.5)
        E = None if fresh else propagator(j - 1)
        for p in live:
            if fresh:  # Van Loan, where e^(−Mᵀτ) stays small
                C = np.zeros((2 * n, 2 * n))
                C[:n, :n] = -M.T
                C[:n, n:] = Q[p]
                C[n:, n:] = M
                F = expm(C * tau)
                G[p] = F[n:, n:].T @ F[:n, n:]
            else:  # double the piece before: G(2τ) = G(τ) + E(τ)ᵀ·G(τ)·E(τ)
                G[p] = G[p] + E.T @ G[p] @ E
            if j >= 0:
                out[p, j] = 0.5 * (G[p] + G[p].T)
    return out
