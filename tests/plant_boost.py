"""An averaged DC-DC boost converter in continuous conduction (Erickson & Maksimovic, Fundamentals of
Power Electronics, 3rd ed. 2020, ch. 2 and 7), written as a new user writes it: SI units, textbook
parameters, no design defaults.

States: the inductor current i_L (A) and the output capacitor voltage v_C (V). Input: the duty cycle
D of the switch (dimensionless). Averaged over one switching period:

    L di_L/dt = Vin - (1 - D) v_C
    C dv_C/dt = (1 - D) i_L - v_C / R - i_o

The duty cycle multiplies the states (D v_C, D i_L): it enters affinely with state-dependent
coefficients, which the builder accepts, so the equations are written in the physical (absolute)
variables. For a fixed D the averaged model is a linear RLC circuit, so the open loop is stable.

Parameters: Vin = 12 V, L = 1 mH, C = 470 uF, R = 20 ohm (a 29 W load at 24 V), nominal duty
D* = 0.5. Operating point (open-loop equilibrium at D* = 0.5, checked numerically with CasADi in
``_equilibrium``): v_C* = Vin / (1 - D*) = 24 V, i_L* = v_C* / (R (1 - D*)) = 2.4 A; the drift is
zero there to round-off (4.7e-13). Linearised there the poles are -53.2 +/- 727j rad/s ((1 - D*) /
sqrt(L C) = 729 rad/s, damping 0.073, 1/(2 R C) = 53.2 1/s): ms time constants, so the scenario runs
at dt = 1e-5 s.

Unknown input: i_o, an extra load current drawn from the output (A). Brownian perturbation: the
load resistance fluctuates by 3 %: the diffusion is 0.03 x the load current term v_C / (R C) of
the capacitor equation. Faults: fa, an actuator fault of the duty command (the switch delivers
D + fa; the scenario injects a loss of effectiveness), and fs, a bias of the output-voltage sensor.

Outputs: i_L (current sensor), v_C (the voltage sensor with the fault fs) and a second, independent
voltage sensor v_C2 on the output. The third output is there because assumption (2) of the design
(faults and unknown inputs told apart, [[A_i, Bf_i, Bd_i], [C, Df, 0]] of full column rank) needs
at least as many outputs as faults plus unknown inputs: here 2 + 1 = 3.
"""

import casadi as ca

from fte_casadi import PlantBuilder

VIN, L, C, R = 12.0, 1e-3, 470e-6, 20.0  # V, H, F, ohm
D_STAR = 0.5  # nominal duty cycle
NOISE = 0.03  # relative fluctuation of the load resistance (per sqrt(s))


def _rhs(i_l, v_c, duty, i_o):
    return [(VIN - (1.0 - duty) * v_c) / L, ((1.0 - duty) * i_l - v_c / R - i_o) / C]


def _equilibrium(duty=D_STAR):
    """The open-loop equilibrium at a duty cycle, solved numerically with CasADi's rootfinder."""
    x = ca.SX.sym("x", 2)
    g = ca.Function("g", [x], [ca.vertcat(*_rhs(x[0], x[1], duty, 0.0))])
    root = ca.rootfinder("root", "newton", g)
    xe = root([1.0, 10.0]).full().ravel()
    return xe, float(ca.norm_inf(g(xe)))


def boost():
    b = PlantBuilder("boost")
    i_l, v_c = b.states("i_L", "v_C", units=["A", "V"])
    (duty,) = b.inputs("duty")
    (i_o,) = b.unknown_inputs("i_o")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift(_rhs(i_l, v_c, duty + fa, i_o))
    b.diffusion([0.0, -NOISE * v_c / (R * C)])
    b.outputs([i_l, v_c + fs, v_c], names=["i_L", "v_C", "v_C2"], units=["A", "V", "V"])
    b.region(i_L=(0.0, 6.0), v_C=(12.0, 36.0))
    b.reference(x=[VIN / ((1 - D_STAR) ** 2 * R), VIN / (1 - D_STAR)])
    b.initial_state([VIN / ((1 - D_STAR) ** 2 * R), VIN / (1 - D_STAR)])
    b.input_limits(duty=(0.05, 0.9))
    b.parameters(Vin=VIN, L=L, C=C, R=R, D_star=D_STAR, noise=NOISE)
    return b.build()


def scenario():
    """T = 0.15 s at dt = 1e-5 s: a 20 % loss of the duty command for 20 <= t < 50 ms, a 0.5 V bias of
    the voltage sensor for 80 <= t < 110 ms, the load current uniform in +/- 0.1 A, sensor noise of
    20 mA on i_L and 50 mV on each voltage."""
    from fte_casadi.sim import Bias, LossOfEffectiveness, Scenario, UniformNoise

    return Scenario(
        name="boost",
        T=0.15,
        dt=1e-5,
        faults=(
            LossOfEffectiveness("fa", loss=0.2, start=0.02, stop=0.05),
            Bias("fs", value=0.5, start=0.08, stop=0.11),
        ),
        unknown_input=UniformNoise(0.1),
        x0_noise=0.01,
        paths=8,
        measurement_noise=(0.02, 0.05, 0.05),
    )


def boost_deviations():
    """The same converter in deviations from its operating point (i_L* = 2.4 A, v_C* = 24 V at D* = 0.5), the
    duty cycle's deviation the input (docs/your-plant.md, "A reference far from 0")."""
    i0, v0 = VIN / ((1 - D_STAR) ** 2 * R), VIN / (1 - D_STAR)
    b = PlantBuilder("boost_dev")
    di, dv = b.states("di_L", "dv_C", units=["A", "V"])
    (dd,) = b.inputs("dduty")
    (i_o,) = b.unknown_inputs("i_o")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift(_rhs(i0 + di, v0 + dv, D_STAR + dd + fa, i_o))
    b.diffusion([0.0, -NOISE * dv / (R * C)])
    b.outputs([di, dv + fs, dv], names=["i_L", "v_C", "v_C2"], units=["A", "V", "V"])
    b.region(di_L=(-i0, 6.0 - i0), dv_C=(12.0 - v0, 36.0 - v0))
    b.operating_point(u=[D_STAR])
    b.input_limits(dduty=(0.05 - D_STAR, 0.9 - D_STAR))
    return b.build()


def boost_deviations_scenario():
    """:func:`scenario`, for :func:`boost_deviations`."""
    return scenario()
