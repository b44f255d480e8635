"""Which faults and unknown inputs the outputs cannot tell apart, and what measurement would.

When assumption (1) or (2) of Section 3 fails, the rank test says only that some combination is
lost. This module finds the *smallest* sets of faults and unknown inputs behind it (rank tests on
column subsets, rule by rule) and, for each set, the states whose additional measurement (a sensor
free of the faults) restores the rank in every rule, and names them by their declared names.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from ._augment import Augmented
from ._uio import rank

__all__ = []  # public: docs/api.md

#: the largest set size searched (sets of faults and unknown inputs)
MAX_SET = 3


@dataclass(frozen=True)
class Confounded:
    """A smallest set of faults/unknown inputs the outputs cannot separate (in ``rules``), and the
    states whose extra measurement, free of the faults, separates them in every rule."""

    faults: tuple[str, ...]
    unknown_inputs: tuple[str, ...]
    rules: tuple[int, ...]
    separating_states: tuple[str, ...]


def _blocks(aug: Augmented, i: int):
    n, lf = aug.n, aug.lf
    Ab = aug.Abar[i]
    A, Bf, Bd = Ab[:n, :n], Ab[:n, n + lf :], aug.Bdbar[i][:n]
    C, Df = aug.Cbar[:, :n], aug.Cbar[:, n + lf :]
    return A, Bf, Bd, C, Df


def _matrix(aug: Augmented, i: int, fsel, dsel, extra_rows=None) -> np.ndarray:
    """``[[A_i, Bf_S, Bd_S], [C, Df_S, 0]]`` (plus rows ``[e_k, 0, 0]`` of extra state measurements)."""
    A, Bf, Bd, C, Df = _blocks(aug, i)
    top = np.hstack([A, Bf[:, list(fsel)], Bd[:, list(dsel)]])
    bot = np.hstack([C, Df[:, list(fsel)], np.zeros((C.shape[0], len(dsel)))])
    rows = [top, bot]
    if extra_rows is not None:
        rows.append(np.hstack([extra_rows, np.zeros((extra_rows.shape[0], len(fsel) + len(dsel)))]))
    return np.vstack(rows)


def _deficient(aug: Augmented, i: int, fsel, dsel, extra=None) -> bool:
    M = _matrix(aug, i, fsel, dsel, extra)
    return rank(M) < M.shape[1]


def confounded_sets(aug: Augmented, fault_names, input_names, state_names) -> list[Confounded]:
    """The smallest sets (up to :data:`MAX_SET` members) of faults and unknown inputs for which
    ``[[A_i, Bf_S, Bd_S], [C, Df_S, 0]]`` loses column rank in some rule (assumption (2) restricted
    to the set), each with the states whose measurement restores the rank in every such rule."""
    items = [("f", j) for j in range(aug.lf)] + [("d", j) for j in range(aug.ld)]
    found: list[tuple[frozenset, tuple[int, ...]]] = []
    for size in range(1, min(MAX_SET, len(items)) + 1):
        for combo in combinations(items, size):
            s = frozenset(combo)
            if any(prev <= s for prev, _ in found):
                continue  # not minimal
            fsel = [j for k, j in combo if k == "f"]
            dsel = [j for k, j in combo if k == "d"]
            rules = tuple(i for i in range(aug.r) if _deficient(aug, i, fsel, dsel))
            if rules:
                found.append((s, rules))
    out = []
    for s, rules in found:
        fsel = sorted(j for k, j in s if k == "f")
        dsel = sorted(j for k, j in s if k == "d")
        sep = tuple(
            state_names[k]
            for k in range(aug.n)
            if not any(_deficient(aug, i, fsel, dsel, np.eye(aug.n)[[k]]) for i in rules)
        )
        out.append(Confounded(tuple(fault_names[j] for j in fsel), tuple(input_names[j] for j in dsel),
                              tuple(i + 1 for i in rules), sep))  # fmt: skip
    return out


def undecoupled_inputs(
    aug: Augmented, input_names, state_names
) -> list[tuple[tuple[str, ...], tuple[str, ...]]]:
    """Assumption (1) by parts: the smallest sets of unknown inputs whose directions (over all rules)
    the outputs do not see in full (``rank(Cbar Bd_S) < rank(Bd_S)``), each with the states whose
    measurement would make them seen."""
    Bd_all = [np.hstack([aug.Bdbar[i][:, [j]] for i in range(aug.r)]) for j in range(aug.ld)]
    C = aug.Cbar
    found: list[frozenset] = []
    out = []
    for size in range(1, min(MAX_SET, aug.ld) + 1):
        for combo in combinations(range(aug.ld), size):
            s = frozenset(combo)
            if any(prev <= s for prev in found):
                continue
            B = np.hstack([Bd_all[j] for j in combo])
            if rank(C @ B) < rank(B):
                found.append(s)
                sep = []
                for k in range(aug.n):
                    row = np.zeros((1, C.shape[1]))
                    row[0, k] = 1.0
                    if rank(np.vstack([C, row]) @ B) == rank(B):
                        sep.append(state_names[k])
                out.append((tuple(input_names[j] for j in combo), tuple(sep)))
    return out


def _names(kind: str, names) -> str:
    return " and ".join(f'{kind} "{n}"' for n in names)


def describe(aug: Augmented, plant, failed: set[str]) -> str:
    """Sentences naming what cannot be separated, for the failed assumptions among (1) and (2)."""
    parts = []
    if "(2)" in failed:
        for c in confounded_sets(aug, plant.fault_names, plant.unknown_input_names, plant.state_names):
            who = " and ".join(
                x for x in (_names("fault", c.faults), _names("unknown input", c.unknown_inputs)) if x
            )
            verb = "enter the outputs identically" if len(c.faults) + len(c.unknown_inputs) > 1 else (
                "cannot be told from the states' own motion")  # fmt: skip
            rules = "every rule" if len(c.rules) == aug.r else f"rule(s) {list(c.rules)}"
            if c.separating_states:
                fix = ("; a measurement of " + " or ".join(f'"{s}"' for s in c.separating_states)
                       + (f' free of {_names("fault", c.faults)}' if c.faults else "")
                       + " would separate them")  # fmt: skip
            else:
                fix = "; no single additional state measurement separates them (model fewer of them)"
            parts.append(f"{who} {verb} ({rules}){fix}")
    if "(1)" in failed:
        for ins, sep in undecoupled_inputs(aug, plant.unknown_input_names, plant.state_names):
            fix = (" a measurement of " + " or ".join(f'"{s}"' for s in sep) + " would let H decouple it"
                   if sep else " no single additional state measurement lets H decouple it")  # fmt: skip
            parts.append(f"{_names('unknown input', ins)} moves states the outputs do not see;{fix}")
    return "; ".join(parts)
