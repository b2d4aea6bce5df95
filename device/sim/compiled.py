"""A scene compiled for the simulated device's servo kernel at one servo rate:
:class:`CompiledScene` (the plant's propagators and work forms, the rendering, the transient
table), and the encoder's velocity weights."""

from __future__ import annotations

import numpy as np

from ..scene import Scene, TransientTable
from .params import DeviceParams, HandParams
from .plant import N_INPUTS, Plant, build_plant, piece_propagators, port_forms, work_forms, zoh

__all__ = ["CompiledScene", "compile_scene", "velocity_weights"]


class CompiledScene:
    """A scene turned into what the servo kernel needs at one servo rate.

    Only what the scene requires is built: virtual scenes get one mode and no
    contact-switch propagators; spring-only scenes no transient table.
    """

    def __init__(self, scene: Scene, dev: DeviceParams, hand: HandParams,
                 table: TransientTable | None = None):
        self.scene = scene
        self.plant: Plant = build_plant(dev, hand, scene.material, scene.surface_height)
        p = self.plant
        dt = dev.dt
        ns = p.n_states
        self.tick_prop = np.stack([zoh(p.A[m], p.B[m], dt) for m in range(p.n_modes)])
        n = ns + N_INPUTS
        free = port_forms(ns, None, p.surface_height)  # the actuator's port alone
        if p.n_modes > 1:
            h = dt / p.n_sub
            self.pieces = np.stack([piece_propagators(p.A[m], p.B[m], h)
                                    for m in range(p.n_modes)])
            touching = port_forms(ns, (p.contact_stiffness, p.contact_damping),
                                  p.surface_height)
            self.work = np.stack([work_forms(p.A[m], p.B[m], q, h, pieces=self.pieces[m])
                                  for m, q in enumerate((free, touching))])
            self.tick_work = np.zeros((n, n))
        else:
            self.pieces = np.zeros((1, 1, ns, n))
            self.work = np.zeros((1, 2, 1, n, n))
            self.tick_work = np.ascontiguousarray(
                work_forms(p.A[0], p.B[0], free, dt, levels=0)[0, 0])
        if scene.is_real:
            self.render = 0
        elif scene.transient is None:
            self.render = 1
        else:
            self.render = 2
        self.spring = float(scene.spring or 0.0)
        if self.render == 2:
            if table is None:  # a transient played on this device's own parameters
                table = scene.transient.table(dev.servo_rate_hz, dev.effective_mass)
            self.transient_table = table
        else:
            self.transient_table = TransientTable([1.0], np.zeros((1, 1)))
        tt = self.transient_table
        self.table = tt.forces
        self.table_v = tt.velocities
        self.blend = int(tt.blend)
        self.attenuation = float(tt.attenuation)
        p = self.plant
        #: what the servo loop needs of this scene (:func:`device.sim.kernel.run_ticks`)
        self.kernel_args = (self.tick_prop, self.pieces, self.work, self.tick_work,
                            int(p.n_sub), p.accel_row,
                            float(p.surface_height), float(p.contact_stiffness),
                            float(p.contact_damping), int(self.render), self.spring,
                            self.table, self.table_v, self.blend, self.attenuation)


def compile_scene(scene: Scene, dev: DeviceParams, hand: HandParams,
                  table: TransientTable | None = None) -> CompiledScene:
    """Build the kernel inputs of ``scene`` (see :class:`CompiledScene`); ``table`` is its
    transient as the device plays it (built from the scene's own parameters when None)."""
    return CompiledScene(scene, dev, hand, table)


def velocity_weights(dev: DeviceParams) -> np.ndarray:
    """Least-squares slope weights over the encoder buffer, oldest sample first [1/s]."""
    n = max(2, int(round(dev.velocity_window_s * dev.servo_rate_hz)) + 1)
    k = np.arange(n) - (n - 1) / 2.0
    return k / np.sum(k * k) * dev.servo_rate_hz
