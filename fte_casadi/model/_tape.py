"""Scalar CasADi expressions as plain data: an instruction tape written from an SX Function, and read
back by replaying a fixed list of arithmetic operations.

A design document carries the scheduling map ``(y, xhat) -> h`` in this form (``scheduling_ops``) so that
reading a document never deserialises an executable object: CasADi's own ``Function.deserialize`` can
load a shared library named in its input, this reader can only add, multiply, take a sine and the like.
The same tape, hashed, fingerprints a plant's equations (:mod:`._fingerprint`).
"""

from __future__ import annotations

import math

import casadi as ca

from ..errors import DesignFileError

__all__ = []  # public: docs/api.md

TAPE_FORMAT = "casadi-sx-tape/1"
#: the largest tape a document may hold (the built-in plants' maps have tens of instructions)
MAX_INSTRUCTIONS = 200_000

_UNARY = {getattr(ca, f"OP_{k}") for k in (
    "ASSIGN", "NEG", "EXP", "LOG", "SQRT", "SQ", "TWICE", "SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN",
    "NOT", "FLOOR", "CEIL", "FABS", "SIGN", "INV", "SINH", "COSH", "TANH", "ASINH", "ACOSH", "ATANH",
    "ERF", "LOG1P", "EXPM1",
)}  # fmt: skip
_BINARY = {getattr(ca, f"OP_{k}") for k in (
    "ADD", "SUB", "MUL", "DIV", "POW", "CONSTPOW", "LT", "LE", "EQ", "NE", "AND", "OR", "IF_ELSE_ZERO",
    "FMOD", "COPYSIGN", "FMIN", "FMAX", "ATAN2", "HYPOT", "REMAINDER",
)}  # fmt: skip
_CONST, _INPUT, _OUTPUT = ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT


def _const(v: float):
    """A constant as JSON can hold it (CasADi folds some expressions into inf or NaN constants)."""
    return v if math.isfinite(v) else ("inf" if v > 0 else "-inf" if v < 0 else "nan")


def write_tape(fn: ca.Function) -> dict:
    """The instructions of the SX Function ``fn`` (dense vector inputs and outputs) as JSON-ready data."""
    if not fn.is_a("SXFunction"):
        fn = fn.expand()
    ops = []
    for k in range(fn.n_instructions()):
        op = int(fn.instruction_id(k))
        out, inp = [int(v) for v in fn.instruction_output(k)], [int(v) for v in fn.instruction_input(k)]
        if op == _CONST:
            ops.append([op, out[0], _const(float(fn.instruction_constant(k)))])
        else:
            ops.append([op, out, inp])
    return {
        "format": TAPE_FORMAT,
        "inputs": [int(fn.nnz_in(i)) for i in range(fn.n_in())],
        "outputs": [int(fn.nnz_out(i)) for i in range(fn.n_out())],
        "input_names": list(fn.name_in()),
        "output_names": list(fn.name_out()),
        "ops": ops,
    }


def _int(v, what: str, below: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < below:
        raise ValueError(f"{what} must be an integer in [0, {below}); got {v!r}")
    return v


def read_tape(data, name: str, key: str = "scheduling_ops") -> ca.Function:
    """The SX Function of a tape written by :func:`write_tape`, replayed with the arithmetic operations
    listed in this module only; anything else (another operation, a call, an index out of range) is a
    :class:`DesignFileError` naming ``key``."""
    try:
        if not isinstance(data, dict) or data.get("format") != TAPE_FORMAT:
            raise ValueError(f"it is not a tape of format {TAPE_FORMAT!r}")
        sizes_in, sizes_out, ops = data["inputs"], data["outputs"], data["ops"]
        if not (isinstance(sizes_in, list) and isinstance(sizes_out, list) and isinstance(ops, list)):
            raise ValueError("'inputs', 'outputs' and 'ops' must be lists")
        if len(ops) > MAX_INSTRUCTIONS:
            raise ValueError(f"it holds {len(ops)} instructions, more than {MAX_INSTRUCTIONS}")
        sizes_in = [_int(v, "an input size", 10_000) for v in sizes_in]
        sizes_out = [_int(v, "an output size", 10_000) for v in sizes_out]
        names_in = data.get("input_names") or [f"i{k}" for k in range(len(sizes_in))]
        names_out = data.get("output_names") or [f"o{k}" for k in range(len(sizes_out))]
        if len(names_in) != len(sizes_in) or len(names_out) != len(sizes_out):
            raise ValueError("the names do not match the inputs and outputs")
        if not all(isinstance(s, str) and s.isidentifier() for s in list(names_in) + list(names_out)):
            raise ValueError("input and output names must be identifiers")
        args = [ca.SX.sym(str(nm), s) for nm, s in zip(names_in, sizes_in)]
        outs = [[None] * s for s in sizes_out]
        work: dict[int, ca.SX] = {}

        def w(i):
            if isinstance(i, bool) or not isinstance(i, int) or i not in work:
                raise ValueError(f"instruction reads work slot {i!r} before it is written")
            return work[i]

        for ins in ops:
            if not isinstance(ins, list) or len(ins) != 3:
                raise ValueError(f"instruction {ins!r} is not [op, outputs, inputs]")
            op = ins[0]
            if op == _CONST:
                c = ins[2]
                if isinstance(c, str) and c in ("inf", "-inf", "nan"):
                    c = float(c)
                if isinstance(c, bool) or not isinstance(c, (int, float)):
                    raise ValueError(f"constant {c!r} is not a number")
                work[_int(ins[1], "a work slot", 10**9)] = ca.SX(float(c))
                continue
            out, inp = ins[1], ins[2]
            if not (isinstance(out, list) and isinstance(inp, list)):
                raise ValueError(f"instruction {ins!r} is not [op, outputs, inputs]")
            if op == _INPUT and len(inp) == 2 and len(out) == 1:
                i = _int(inp[0], "an input index", len(args))
                work[_int(out[0], "a work slot", 10**9)] = args[i][
                    _int(inp[1], "an input entry", sizes_in[i])
                ]
            elif op == _OUTPUT and len(inp) == 1 and len(out) == 2:
                i = _int(out[0], "an output index", len(outs))
                outs[i][_int(out[1], "an output entry", sizes_out[i])] = w(inp[0])
            elif op in _UNARY and len(inp) == 1 and len(out) == 1:
                work[_int(out[0], "a work slot", 10**9)] = ca.SX.unary(op, w(inp[0]))
            elif op in _BINARY and len(inp) == 2 and len(out) == 1:
                work[_int(out[0], "a work slot", 10**9)] = ca.SX.binary(op, w(inp[0]), w(inp[1]))
            else:
                raise ValueError(f"operation {op!r} is not one of the arithmetic operations a tape may hold")
        res = [ca.vertcat(*[ca.SX(0.0) if e is None else e for e in o]) if o else ca.SX(0, 1) for o in outs]
        return ca.Function(name, args, res, list(names_in), list(names_out))
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise DesignFileError(
            f"{key!r} is corrupt ({exc}); it must be the data `fte design` writes: make the document again"
        ) from None
