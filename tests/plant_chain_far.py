"""A user's chain of 6 stages, each coupling through sin (64 rules); the input at the last stage,
the unknown input at the first (the far end); no design defaults."""

import casadi as ca

from fte_casadi import PlantBuilder


def chainfar(n=6):
    b = PlantBuilder("chainfar")
    x = b.states(*[f"x{k + 1}" for k in range(n)])
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    f = []
    for k in range(n):
        prev = x[k - 1]
        c = 0.8 * ca.sin(prev) if k > 0 else 0.2 * ca.sin(prev)
        r = -(1.0 + 0.1 * k) * x[k] + c
        if k == 0:
            r += 0.5 * d
        if k == n - 1:
            r += u + fa
        f.append(r)
    b.drift(f)
    b.diffusion([0.01 * xk for xk in x])
    b.outputs([x[0] + fs] + list(x))
    b.region(**{f"x{k + 1}": (-1.0, 1.0) for k in range(n)})
    return b.build()
