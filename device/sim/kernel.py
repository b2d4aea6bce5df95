"""The compiled servo loop of the simulator.

One call advances the simulation over a range of servo ticks. Per tick, in order:

1. sample the encoder (motor-side position, quantized) and keep it in a ring buffer;
2. contact logic on the encoder: a contact starts when the reading falls below the
   surface while armed; it re-arms once the reading is ``hysteresis`` above it. At a
   contact the incoming speed is the least-squares slope of the buffered readings;
3. rendering (virtual scenes only): spring K·(penetration of the encoder reading),
   plus, in transient scenes, the transient table scaled by the estimated speed;
   output ramp after enable; zero on a latched fault or when the watchdog deadline
   has passed; a command that is not finite (NaN, inf) zeroes output and latches a
   ``nan_command`` fault; current clamp with saturation flag;
4. record the tick's outputs;
5. propagate the continuous plant over the tick with the command held (exact ZOH).
   Real samples switch between free and contact modes; a switch inside a tick is
   located by bisection with precomputed power-of-two propagators, so the physics of
   a real contact does not depend on the servo rate;
6. account the energy through the two ports where something acts on the stylus — the
   actuator (force on the motor side) and a real sample's contact (force on the tip) —
   as work the stylus did on them (in) and they did on the stylus (out), exactly over
   each propagated piece (a quadratic form of the state, :func:`device.sim.plant.work_forms`);
   a contact's pieces are cut where the tip turns, so its in and its out are each exact
   (the actuator's are split per tick, or per piece: their sum is exact);
7. guard: a tip farther than :data:`DIVERGED_M` from the surface, faster than
   :data:`DIVERGED_MPS`, or not finite zeroes output, latches a ``diverged`` fault and
   ends the window, so a blow-up can never pass silently.

Per-tick work depends on the scene: ``render`` 0 (real sample) runs no rendering
code, 1 (spring) no transient code, 2 (spring + transient) both.
"""

from __future__ import annotations

import numpy as np

from ..codes import Blend
from ..events import Flags
from ._jit import lazy_njit
from .plant import FA, FH, V1, V2, VB, Z1, Z2, ZB, Y

__all__ = ["run_ticks", "propagate_linear", "IST", "FST"]

# integer state slots
IST_MODE, IST_ARMED, IST_PLAY, IST_SINCE_ENABLE, IST_FIRST, IST_NEV, IST_RB, IST_FAULT, \
    IST_STOP, IST_FAULT_TICK, IST_ROW1, IST_ROW2, IST_FAULT_CODE, IST_SWITCHES, \
    IST_UNRESOLVED = range(15)
IST = 15
#: contact switches located within one substep; past them a crossing is let pass unlocated
#: (counted in ``IST_UNRESOLVED``: the contact's physics in that piece is approximate)
MAX_SWITCHES = 64
# why the loop latched output off (IST_FAULT_CODE)
FAULT_DEADLINE, FAULT_NAN, FAULT_DIVERGED = 1, 2, 3  # the watchdog/e-stop deadline; a
# non-finite command; a state beyond any physical bound
# float state slots: the two table rows' coefficients of the transient playing; the energy
# the stylus gave to (in) and received from (out) the actuator and the sample [J]; the tip's
# velocity [m/s] where it first met a real sample and where it first left it moving away
# after that (a parting while the tip still moves in is the sample falling away from it, not
# a bounce), at the located switches (NaN until then; the caller sets NaN to start looking)
FST_C1, FST_C2, FST_EIN, FST_EOUT, FST_VIN, FST_VOUT = range(6)
FST = 6
#: the divergence guard's bounds: tip distance from the surface [m] and speed [m/s]
DIVERGED_M = 1.0
DIVERGED_MPS = 10.0
# how a contact speed picks table rows (TransientTable.blend), and the per-tick flags:
# plain ints for the compiled loop, taken from the one definition of each code
BLEND_SCALE, BLEND_NEAREST, BLEND_LINEAR = (int(b) for b in (Blend.SCALE, Blend.NEAREST,
                                                             Blend.LINEAR))
F_CONTACT, F_SAT, F_TRANSIENT, F_ZEROED, F_RAMP = (int(f) for f in (
    Flags.CONTACT, Flags.SATURATED, Flags.TRANSIENT, Flags.ZEROED, Flags.RAMP))

# state indices: the plant's (device/sim/plant.py)


@lazy_njit
def _apply(P, x, u, out):
    """out = P @ [x; u] for P of shape (ns, ns+nu)."""
    ns = x.shape[0]
    nu = u.shape[0]
    for i in range(ns):
        s = 0.0
        for j in range(ns):
            s += P[i, j] * x[j]
        for j in range(nu):
            s += P[i, ns + j] * u[j]
        out[i] = s


@lazy_njit
def propagate_linear(P, x0, u, n, out):
    """Step x ← P·[x; u] ``n`` times, storing each state (rows of ``out``)."""
    x = x0.copy()
    tmp = np.empty_like(x)
    for k in range(n):
        _apply(P, x, u, tmp)
        x[:] = tmp
        out[k, :] = x


@lazy_njit
def _sample_force(x, h, ks, bs, has_body):
    """Force of the sample on the tip in contact [N]: k_s·(h + zb − z2) − b_s·(v2 − vb)."""
    zb, vb = (x[ZB], x[VB]) if has_body else (0.0, 0.0)
    return ks * (h + zb - x[Z2]) - bs * (x[V2] - vb)


@lazy_njit
def _crossed(mode, x, h, ks, bs, has_body):
    zb, vb = (x[ZB], x[VB]) if has_body else (0.0, 0.0)
    if mode == 0:  # free → contact when the tip is below the sample's top and moving in
        return x[Z2] < h + zb and x[V2] - vb < 0.0
    # contact → free when the sample would have to pull
    return _sample_force(x, h, ks, bs, has_body) <= 0.0


@lazy_njit
def _account(w, fst):
    """Add work ``w`` [J] the stylus did on a port (negative: the port did work on it)."""
    if w >= 0.0:
        fst[FST_EIN] += w
    else:
        fst[FST_EOUT] -= w


@lazy_njit
def _work(G, x, u, z):
    """zᵀ·G·z for z = [x; u]: the work [J] through a port over a piece (``z`` scratch)."""
    ns = x.shape[0]
    n = ns + u.shape[0]
    for i in range(ns):
        z[i] = x[i]
    for i in range(ns, n):
        z[i] = u[i - ns]
    s = 0.0
    for i in range(n):
        zi = z[i]
        if zi == 0.0:
            continue
        row = 0.0
        for j in range(n):
            row += G[i, j] * z[j]
        s += zi * row
    return s


@lazy_njit
def _advance_switching(pieces, work, x, u, ist, fst, h, ks, bs, has_body, tmp, z):
    """Advance one substep in a two-mode (real contact) plant, locating switches and
    accounting, exactly, the work across the actuator and the contact over each piece."""
    levels = pieces.shape[1] - 1
    remaining = np.int64(1) << levels
    j = levels
    switches = 0
    turns = 0
    while remaining > 0:
        while (np.int64(1) << j) > remaining:
            j -= 1
        mode = ist[IST_MODE]
        _apply(pieces[mode, j], x, u, tmp)
        real = _crossed(mode, tmp, h, ks, bs, has_body)
        crossed = real and switches < MAX_SWITCHES
        # the contact's power −F·v₂ (F > 0) changes sign where v₂ does: that piece is cut
        # finer too, so the work in and the work out are each exact, not only their sum
        # (at most MAX_SWITCHES turns a substep are located: a stylus resting on the sample
        # may jitter about v₂ = 0 at rounding level, where no work goes through anyway)
        turned = mode == 1 and x[V2] * tmp[V2] < 0.0 and turns < MAX_SWITCHES
        if (crossed or turned) and j > 0:  # a switch or a turn inside: try a finer piece
            j -= 1
            continue
        if real and not crossed:
            ist[IST_UNRESOLVED] += 1
        # the piece is accepted: the work across the actuator, and the contact in contact
        _account(_work(work[mode, 0, j], x, u, z), fst)
        if mode == 1:
            _account(_work(work[1, 1, j], x, u, z), fst)
        x[:] = tmp
        remaining -= np.int64(1) << j
        if crossed:  # the finest piece holds the switch: change mode
            switches += 1
            ist[IST_SWITCHES] += 1
            ist[IST_MODE] = 1 - mode
            j = levels
            # the first bounce, at its switches (the finest piece is h·2^-levels long)
            if mode == 0 and np.isnan(fst[FST_VIN]):
                fst[FST_VIN] = x[V2]
            elif (mode == 1 and x[V2] > 0.0 and np.isnan(fst[FST_VOUT])
                  and not np.isnan(fst[FST_VIN])):
                fst[FST_VOUT] = x[V2]
        elif turned:  # past the turn: back to whole pieces
            turns += 1
            j = levels


@lazy_njit
def _pick_rows(speed, tbl_v, blend, atten, ist, fst):
    """Rows and coefficients of the table to play for a contact at ``speed`` [m/s].

    ``scale``: row 0 × speed / v0. ``nearest``: the row of the nearest speed, scaled by
    speed / v_i. ``linear``: the two rows bracketing the speed, weighted linearly; below
    the slowest or above the fastest row, that end row scaled by speed / v_end (impact
    transients grow about linearly with the momentum brought in).
    """
    n = tbl_v.shape[0]
    i1, i2, c1, c2 = 0, 0, 0.0, 0.0
    if blend == BLEND_SCALE or n == 1:
        c1 = speed / tbl_v[0]
    elif blend == BLEND_NEAREST:
        best = 0
        for i in range(1, n):
            if abs(tbl_v[i] - speed) < abs(tbl_v[best] - speed):
                best = i
        i1 = best
        c1 = speed / tbl_v[best]
    else:
        if speed <= tbl_v[0]:
            c1 = speed / tbl_v[0]
        elif speed >= tbl_v[n - 1]:
            i1 = n - 1
            c1 = speed / tbl_v[n - 1]
        else:
            j = 0
            while tbl_v[j + 1] < speed:
                j += 1
            w = (speed - tbl_v[j]) / (tbl_v[j + 1] - tbl_v[j])
            i1, i2, c1, c2 = j, j + 1, 1.0 - w, w
    ist[IST_ROW1] = i1
    ist[IST_ROW2] = i2
    fst[FST_C1] = c1 * atten
    fst[FST_C2] = c2 * atten


#: rows of the output array ``out`` of :func:`run_ticks`
OUT_POS, OUT_FCMD, OUT_FOUT, OUT_CUR, OUT_ACC, OUT_Z2, OUT_V2, OUT_A2 = range(8)
N_OUT = 8


@lazy_njit
def run_ticks(n0, n1, state, scene, device, u_hand, f_ext, zero_from, stop_after,
              out, o_flags, ev_tick, ev_vel):
    """Advance ticks n0..n1-1 (indices into the input and output arrays).

    Parameters
    ----------
    state : tuple
        ``(x, ist, fst, rb)``: plant state, integer and float loop state, encoder ring
        buffer (all updated in place).
    scene : tuple
        ``(tick_prop, pieces, work, tick_work, n_sub, accel_row, h, ks, bs, render, K,
        table, tbl_v, blend, atten)`` from :class:`~device.sim.compiled.CompiledScene`.
    device : tuple
        ``(enc_res, vel_w, hyst, kt, i_max, ramp_ticks, rate)`` from the device parameters.
    u_hand : ndarray
        The hand's pull at every tick and one beyond ``n1`` [N].
    f_ext : ndarray
        Open-loop force per tick [N] (empty for none).
    zero_from, stop_after : int
        Tick from which output is zeroed (watchdog, e-stop); ticks of a window after its
        first contact (−1: not measured from a contact).
    out : ndarray (N_OUT, n)
        Per-tick outputs (rows ``OUT_*``); ``o_flags`` the flags; ``ev_tick``, ``ev_vel``
        the contact events.

    Returns the first tick not simulated (n1, or earlier when ``ist[IST_STOP]`` is reached).
    """
    x, ist, fst, rb = state
    (tick_prop, pieces, work, tick_work, n_sub, accel_row, h, ks, bs, render, K, table,
     tbl_v, blend, atten) = scene
    enc_res, vel_w, hyst, kt, i_max, ramp_ticks, rate = device
    ns = x.shape[0]
    u = np.zeros(3)
    tmp = np.empty(ns)
    z = np.empty(ns + 3)
    n_rb = rb.shape[0]
    has_body = ns > ZB
    n_modes = tick_prop.shape[0]
    inv_res = 1.0 / enc_res
    n_tab = table.shape[1]
    has_ext = f_ext.shape[0] > 0
    for n in range(n0, n1):
        if ist[IST_STOP] >= 0 and n >= ist[IST_STOP]:
            return n
        # 1. encoder
        enc = np.floor(x[Z1] * inv_res + 0.5) * enc_res
        head = ist[IST_RB]
        rb[head] = enc
        head = (head + 1) % n_rb
        ist[IST_RB] = head
        flags = 0
        # 2. contact logic
        if enc < h:
            flags |= F_CONTACT
            if ist[IST_ARMED] == 1:
                ist[IST_ARMED] = 0
                slope = 0.0
                for k in range(n_rb):  # oldest sample is at `head`
                    slope += vel_w[k] * rb[(head + k) % n_rb]
                speed = -slope
                e = ist[IST_NEV]
                if e < ev_tick.shape[0]:
                    ev_tick[e] = n
                    ev_vel[e] = speed
                ist[IST_NEV] = e + 1
                if ist[IST_FIRST] < 0:
                    ist[IST_FIRST] = n
                    if stop_after >= 0:  # a window measured from the first contact
                        ist[IST_STOP] = n + stop_after
                if render == 2:
                    ist[IST_PLAY] = 0
                    _pick_rows(speed, tbl_v, blend, atten, ist, fst)
        elif enc > h + hyst:
            ist[IST_ARMED] = 1
        # 3. rendering
        fc = 0.0
        if render >= 1:
            if enc < h:
                fc = K * (h - enc)
            if render == 2 and ist[IST_PLAY] >= 0:
                k = ist[IST_PLAY]
                fc += fst[FST_C1] * table[ist[IST_ROW1], k] + fst[FST_C2] * table[ist[IST_ROW2], k]
                flags |= F_TRANSIENT
                ist[IST_PLAY] += 1
                if ist[IST_PLAY] >= n_tab:
                    ist[IST_PLAY] = -1
        if has_ext:
            fc += f_ext[n]
        since = ist[IST_SINCE_ENABLE]
        if since < ramp_ticks:
            fc *= (since + 1.0) / ramp_ticks
            flags |= F_RAMP
        ist[IST_SINCE_ENABLE] = since + 1
        if ist[IST_FAULT] == 0 and n >= zero_from:
            ist[IST_FAULT] = 1
            ist[IST_FAULT_TICK] = n
            ist[IST_FAULT_CODE] = FAULT_DEADLINE
        cur = fc / kt
        if ist[IST_FAULT] == 0 and not (abs(cur) < np.inf):  # NaN or ±inf never reaches the
            ist[IST_FAULT] = 1                                 # amplifier: zero and latch
            ist[IST_FAULT_TICK] = n
            ist[IST_FAULT_CODE] = FAULT_NAN
        if ist[IST_FAULT] != 0:
            cur = 0.0
            flags |= F_ZEROED
        elif cur > i_max:
            cur = i_max
            flags |= F_SAT
        elif cur < -i_max:
            cur = -i_max
            flags |= F_SAT
        u[0] = cur * kt
        x[FH] = u_hand[n]  # the hand's pull, exact at each tick ...
        u[1] = (u_hand[n + 1] - u_hand[n]) * rate  # ... and linear in between
        u[2] = 1.0
        # 4. record
        out[OUT_POS, n] = enc
        out[OUT_FCMD, n] = fc if ist[IST_FAULT] == 0 else 0.0  # ramped, zeroed (docs §6)
        out[OUT_FOUT, n] = x[FA]
        out[OUT_CUR, n] = cur
        out[OUT_ACC, n] = x[Y]
        o_flags[n] = flags
        out[OUT_Z2, n] = x[Z2]
        out[OUT_V2, n] = x[V2]
        mode = ist[IST_MODE]
        a2 = 0.0
        for j in range(ns):
            a2 += accel_row[mode, j] * x[j]
        for j in range(3):
            a2 += accel_row[mode, ns + j] * u[j]
        out[OUT_A2, n] = a2
        # 5. propagate, and 6. the work through the ports over the tick (or each piece)
        if n_modes == 1:
            _account(_work(tick_work, x, u, z), fst)
            _apply(tick_prop[0], x, u, tmp)
            x[:] = tmp
        else:
            for _ in range(n_sub):
                _advance_switching(pieces, work, x, u, ist, fst, h, ks, bs, has_body, tmp, z)
        # 7. guard
        if not (abs(x[Z2] - h) < DIVERGED_M and abs(x[V2]) < DIVERGED_MPS
                and abs(x[V1]) < DIVERGED_MPS):
            if ist[IST_FAULT] == 0:
                ist[IST_FAULT] = 1
                ist[IST_FAULT_TICK] = n
                ist[IST_FAULT_CODE] = FAULT_DIVERGED
            ist[IST_STOP] = n + 1
            return n + 1
    return n1
