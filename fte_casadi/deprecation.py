"""Keyword names that changed: the old one keeps working, with a ``DeprecationWarning`` naming the new one.

The public functions keep every keyword they ever had (docs/interface.md): where a name changed (issue #20,
"one name per concept": the observer/controller's sample time is ``sample_time``, ``ts`` is a T-S model), the
old keyword is still accepted through :func:`renamed_keyword`.
"""

from __future__ import annotations

import functools
import warnings

__all__ = ["renamed_keyword"]


def renamed_keyword(old: str, new: str):
    """Decorator: accept keyword ``old`` as ``new`` and warn that it is deprecated.

    Parameters
    ----------
    old, new : str
        The former and the current keyword name of the decorated function's parameter.

    Raises
    ------
    TypeError
        When a call gives both names (as Python does for a keyword given twice).

    Examples
    --------
    >>> import warnings
    >>> @renamed_keyword("ts", "sample_time")
    ... def f(sample_time=None):
    ...     return sample_time
    >>> with warnings.catch_warnings(record=True) as w:
    ...     warnings.simplefilter("always")
    ...     f(ts=0.1), w[0].category.__name__
    (0.1, 'DeprecationWarning')
    """

    def decorate(fn):
        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            if old in kwargs:
                if new in kwargs:
                    raise TypeError(
                        f"{fn.__name__}() got both {new!r} and its former name {old!r}; give only {new!r}"
                    )
                warnings.warn(
                    f"{fn.__name__}(): the keyword {old!r} is deprecated; call it {new!r}",
                    DeprecationWarning,
                    stacklevel=2,
                )
                kwargs[new] = kwargs.pop(old)
            return fn(*args, **kwargs)

        return wrapper

    return decorate
