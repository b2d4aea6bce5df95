"""Balanced (Williams) Latin squares for counterbalancing condition order."""

from __future__ import annotations

__all__ = ["williams_square"]


def williams_square(n: int) -> list[list[int]]:
    """Rows of a Williams design for ``n`` conditions (0..n−1).

    Every condition appears once per row and once per column position across the square,
    and every ordered pair of adjacent conditions (a immediately before b) appears equally
    often: once in the n rows for even n; twice in the 2n rows (the square and its
    mirror) for odd n.

    Parameters
    ----------
    n : int
        Number of conditions, >= 1.

    Returns
    -------
    list of list of int
        ``n`` rows (even n) or ``2n`` rows (odd n), each a permutation of range(n).
    """
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"a Williams square needs n >= 1 conditions, got {n!r}")
    first = [0]
    lo, hi = 1, n - 1
    for k in range(1, n):  # 0, 1, n−1, 2, n−2, …
        if k % 2:
            first.append(lo)
            lo += 1
        else:
            first.append(hi)
            hi -= 1
    rows = [[(c + r) % n for c in first] for r in range(n)]
    if n % 2:
        rows += [list(reversed(row)) for row in rows]
    return rows
