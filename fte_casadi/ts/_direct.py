"""CasADi functions called from numpy in a loop, through their zero-copy buffer.

A call ``f(x)`` with numpy arrays converts every argument to a DM and every result back: about 60 us on this
machine, where the evaluation of a plant's drift takes about 1 us. The integrator of the fidelity trajectory
and the local searches of the premises' bounds call small functions thousands of times; through
``Function.buffer`` the same evaluation, with the same numbers, costs the evaluation alone.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca
import numpy as np

__all__ = ["direct"]


def direct(f: ca.Function) -> Callable[..., tuple[np.ndarray, ...]]:
    """``(*args) -> outputs``: ``f`` evaluated at dense column vectors ``args`` (one per input), each output a new
    flat array (dense, column-major as CasADi stores it; an output with structural zeros, e.g. a drift with a
    row that is 0, is densified first). Not for concurrent use: one buffer per function."""
    if any(f.nnz_in(i) != f.numel_in(i) for i in range(f.n_in())):
        raise ValueError(f"direct(): {f.name()} has a sparse input; call it as a Function")
    if any(f.nnz_out(i) != f.numel_out(i) for i in range(f.n_out())):
        xin = f.sx_in() if f.is_a("SXFunction") else f.mx_in()
        f = ca.Function(f.name(), xin, [ca.densify(o) for o in f.call(xin)])
    ins = [np.zeros(f.nnz_in(i)) for i in range(f.n_in())]
    outs = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
    buf, run = f.buffer()
    for i, a in enumerate(ins):
        buf.set_arg(i, memoryview(a))
    for i, a in enumerate(outs):
        buf.set_res(i, memoryview(a))

    def call(*args):
        for a, x in zip(ins, args):
            a[:] = np.ravel(x, order="F")
        run()
        return tuple(o.copy() for o in outs)

    call.keep = (buf, f)  # the buffer and the function must outlive the calls
    return call
