"""Round numbers a user reads and types: two significant digits, or the 1-2-5 series.

Used where the toolkit proposes a value (a parameter to try, a sample time, a bound in a message).
"""

from __future__ import annotations

import math

__all__ = ["nice_floor", "nice_ceil", "series_floor"]

#: relative slack that keeps a value computed as 0.19999999999999998 at 0.2
_SLACK = 1e-12


def nice_floor(v: float) -> float:
    """``v`` rounded down to two significant digits (0 for ``v <= 0``).

    >>> nice_floor(0.0821), nice_floor(4431.0)
    (0.082, 4400.0)
    """
    if not v > 0:
        return 0.0
    e = math.floor(math.log10(v)) - 1
    return float(f"{math.floor(v / 10.0**e * (1 + _SLACK))}e{e}")  # an exact decimal literal


def nice_ceil(v: float) -> float:
    """``v`` rounded up to two significant digits (``v > 0``).

    >>> nice_ceil(0.4431)
    0.45
    """
    e = math.floor(math.log10(v)) - 1
    return float(f"{math.ceil(v / 10.0**e * (1 - _SLACK))}e{e}")  # 2.4, not 2.4000000000000004


def series_floor(v: float) -> float:
    """The largest of 1, 2 or 5 times a power of ten not above ``v`` (``v > 0``), as its decimal literal.

    >>> [series_floor(v) for v in (0.0999, 0.1, 0.35, 7.0, 1.99e-3)]
    [0.05, 0.1, 0.2, 5.0, 0.001]
    """
    e = math.floor(math.log10(v))
    for mant in (5, 2, 1):
        c = float(f"{mant}e{e}")
        if c <= v * (1 + _SLACK):
            return c
    return float(f"5e{e - 1}")
