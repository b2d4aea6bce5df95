"""Values kept in a DataFrame's ``attrs`` that are shared, not copied.

pandas deep-copies ``attrs`` into the result of nearly every operation (a filter, a column,
a copy). With the session table of 21,700 sessions, the SHA-256 of 43,400 files and the
list of a design's participants in ``attrs``, each column access cost milliseconds and
each filter most of a second at 10⁶ rows. These are read, never changed in place, once
made: deep-copying one returns the same object, so every frame derived from the loaded
data shares them (and pandas' comparison of attrs when it concatenates sees the same
object, not two DataFrames it cannot compare).
"""

from __future__ import annotations

from typing import Any

import pandas as pd

__all__ = ["KeptDict", "KeptList", "KeptFrame", "kept"]


class KeptDict(dict):
    """A dict shared by every copy of the attrs holding it."""

    def __deepcopy__(self, memo=None) -> KeptDict:
        return self


class KeptList(list):
    """A list shared by every copy of the attrs holding it."""

    def __deepcopy__(self, memo=None) -> KeptList:
        return self


class KeptFrame(pd.DataFrame):
    """A DataFrame shared by every copy of the attrs holding it (its own operations give
    plain DataFrames)."""

    def __deepcopy__(self, memo=None) -> KeptFrame:
        return self


def kept(value: Any) -> Any:
    """``value`` as its shared kind (dicts, lists and DataFrames; others as they are)."""
    if isinstance(value, pd.DataFrame):
        return value if isinstance(value, KeptFrame) else KeptFrame(value)
    if isinstance(value, dict):
        return value if isinstance(value, KeptDict) else KeptDict(value)
    if isinstance(value, list):
        return value if isinstance(value, KeptList) else KeptList(value)
    return value
