"""Round numbers a user reads and types: two significant digits, or the 1-2-5 series.

Used where the toolkit proposes a value (a parameter to try, a sample time, a bound in a message).
"""

from __future__ import annotations

import math

__all__ = ["nice_floor", "nice_ceil", "series_floor", "ratio_text"]

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


def ratio_text(value: float | None, digits: int = 3) -> str:
    """A ratio against 1 (an FTC ratio) with ``digits`` significant digits, or as many more as tell it from 1: a
    ratio above 1 is never printed as 1 ("n/a" for None).

    >>> ratio_text(0.71234), ratio_text(1.0000001164), ratio_text(0.99997), ratio_text(1.0), ratio_text(None)
    ('0.712', '1.00000012', '0.99997', '1', 'n/a')
    """
    if value is None:
        return "n/a"
    d = abs(float(value) - 1.0)
    if 0.0 < d < 10.0 ** (1 - digits):
        digits = min(17, int(math.ceil(-math.log10(d))) + 2)
    return f"{float(value):.{digits}g}"
