"""The simulated device: sampled-data physics of device, hand, samples and rendering.

Import :class:`SimDevice` from :mod:`device.sim.backend` (this package imports nothing heavy).
"""

__all__: list[str] = []
