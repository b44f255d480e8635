"""A surface-mounted permanent-magnet synchronous motor in the rotor (dq) frame (Krause, Analysis of
Electric Machinery, 2013, ch. 15), written twice as a new user might: states (i_d, i_q, w) and
(w, i_d, i_q). The same plant: only the order of the states differs. w is the electrical speed; the
load torque is an unknown input and the q-axis voltage has an actuator fault."""

from fte_casadi import PlantBuilder

R, L, PSI, POLES, J, B = 0.5, 2e-3, 0.1, 4, 2e-3, 1e-3  # ohm, H, Wb, pole pairs, kg m^2, N m s


def _equations(i_d, i_q, w, v_d, v_q, tl, fa):
    did = (-R * i_d + L * w * i_q + v_d) / L
    diq = (-R * i_q - L * w * i_d - PSI * w + v_q + fa) / L
    dw = POLES * (1.5 * POLES * PSI * i_q - B * w - tl) / J
    return did, diq, dw


def _build(order):
    b = PlantBuilder("pmsm")
    names = {"i_d": "A", "i_q": "A", "w": "rad/s"}
    xs = dict(zip(order, b.states(*order, units=[names[k] for k in order])))
    v_d, v_q = b.inputs("v_d", "v_q")
    (tl,) = b.unknown_inputs("load")
    (fa,) = b.faults("fa", kind="actuator")
    rhs = dict(zip(("i_d", "i_q", "w"), _equations(xs["i_d"], xs["i_q"], xs["w"], v_d, v_q, tl, fa)))
    b.drift([rhs[k] for k in order])
    b.diffusion([0.0 * xs[k] for k in order])
    b.outputs([xs["i_d"], xs["i_q"], xs["w"]])
    b.region(i_d=(-10.0, 10.0), i_q=(-10.0, 10.0), w=(-300.0, 300.0))
    return b.build()


def pmsm_dqw():
    """States (i_d, i_q, w)."""
    return _build(("i_d", "i_q", "w"))


def pmsm_wdq():
    """States (w, i_d, i_q)."""
    return _build(("w", "i_d", "i_q"))
