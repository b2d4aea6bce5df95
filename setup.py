"""Native parts of hapticlab, built by setuptools beside the pure-Python packages.

``device/serial/_hostlink``: the host's side of the serial link in a native thread
(firmware/src/hostlink.c; reading and heartbeats that no interpreter lock holds up). A plain
C library loaded with ctypes, not a Python extension; optional: where it cannot be built
(no compiler, not POSIX) the link runs in Python threads, as it says in its statistics.
"""

import os

from setuptools import Extension, setup

NATIVE = [
    Extension("device.serial._hostlink", sources=["firmware/src/hostlink.c"],
              include_dirs=["firmware/include"], extra_compile_args=["-std=c11", "-O2"],
              libraries=["pthread"], optional=True),
] if os.name == "posix" else []

setup(ext_modules=NATIVE)
