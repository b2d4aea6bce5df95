"""Lazy numba compilation: no I/O at import time.

``numba.njit(cache=True)`` probes its cache directory as soon as it decorates a
function. :func:`lazy_njit` defers that to the first call: the first call of any
marked function compiles every marked function of its module (replacing the module
globals, so compiled functions call compiled functions) and then runs.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

__all__ = ["lazy_njit"]


class _Lazy:
    def __init__(self, fn: Callable[..., Any]):
        self.py_func = fn
        self.__name__ = fn.__name__
        self.__doc__ = fn.__doc__
        self._compiled: Callable[..., Any] | None = None

    def __call__(self, *args: Any) -> Any:
        if self._compiled is None:
            _compile_module(self.py_func.__module__)
        return self._compiled(*args)


def _compile_module(module_name: str) -> None:
    from numba import njit

    module = sys.modules[module_name]
    for name, obj in list(vars(module).items()):
        if isinstance(obj, _Lazy) and obj._compiled is None:
            obj._compiled = njit(cache=True)(obj.py_func)
            setattr(module, name, obj._compiled)


def lazy_njit(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Mark ``fn`` for ``numba.njit(cache=True)`` on the first call of its module's kernels."""
    return _Lazy(fn)
