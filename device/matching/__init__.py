"""Acceleration matching (SPEC §1), fitted vibration models (§2) and the grasp-force model (§3).

Signal code in the manner of scipy.signal: pure functions over arrays, units in the
docstrings. Only :mod:`device.matching.library` drives a device.
"""

__all__: list[str] = []
