"""A synchronous generator on an infinite bus, written as a power engineer writes it from the README (2026-11-29):
the one-axis model in per unit, time in s (Kundur, *Power System Stability and Control*, ch. 12).

    delta' = wb w,   2H w' = Pm - Pe - D w + d,   T'do Eq' = Efd - Eq - (Xd - X'd) Id
    Pe = Eq V sin(delta) / X'd,   Id = (Eq - V cos(delta)) / X'd

wb = 2 pi 50 rad/s, H = 5 s, D = 2, Xd = 2.3, X'd = 0.8 (with the line), V = 1, T'do = 8 s. It rests at Pm = 0.8,
Eq = 1.1, delta = 0.621 rad, Efd = 1.64. The inputs are the turbine's power Pm and the field voltage Efd, ``exciter``
an actuator fault of the field voltage, ``speed_sensor`` a bias of the speed measurement; d a load disturbance; 2 %
multiplicative noise on the speed (the damping fluctuating).

Written in absolute units (:func:`smib`) its sector model telescopes ``Eq sin(delta)`` as ``sin(delta) * Eq``: the
angle's synchronising torque lies in a premise, and every A_i's speed row has no angle entry (the model's delta is
an integrator with no restoring torque). ``fte derive`` warns that the model misses 0.94 of the speed's rate at the
reference; :func:`smib_deviations` writes it in deviations, as the warning advises. ``angle_per_rad`` and
``speed_per_pu`` write the same plant in other units (degrees, mpu): the share the warning measures does not change.

Measured (2026-11-29, ``fte design tests/plant_smib.py:smib_deviations -o s.json``, ``fte simulate s.json --plant
tests/plant_smib.py:smib_deviations --seed 1``, 8 paths; ``smib`` alike): both forms certify. The absolute form's
model thinks the open loop diverges (at 1.55 per s) where the plant's decays (0.118 per s, the deviation form's).
Neither design is of use: step 3's smallest gain (max |K| = 6.3e3) saturates Pm for 92 % of both windows (the
measurement noise alone moves it by 1.26 against its half-range 0.6), and tolerant control is a tie (1) in both;
``fte simulate`` says so. The fault errors: exciter 0.26, speed sensor 0.087, in both forms.
"""

import math

import casadi as ca

WB, H, DAMP, XD, XDP, V, TDO = 2 * math.pi * 50, 5.0, 2.0, 2.3, 0.8, 1.0, 8.0
PM0, EQ0 = 0.8, 1.1
DELTA0 = math.asin(PM0 * XDP / (EQ0 * V))
EFD0 = EQ0 + (XD - XDP) * (EQ0 - V * math.cos(DELTA0)) / XDP


def _rhs(delta, w, eq, pm, efd, d):
    pe = eq * V * ca.sin(delta) / XDP
    idd = (eq - V * ca.cos(delta)) / XDP
    return [WB * w, (pm - pe - DAMP * w + d) / (2 * H), (efd - eq - (XD - XDP) * idd) / TDO]


def _build(name, shift: bool, ka: float = 1.0, kw: float = 1.0):
    """``shift``: states and inputs in deviations from the rest point; ``ka``, ``kw``: units per rad, per pu of
    speed."""
    from fte_casadi import PlantBuilder

    b = PlantBuilder(name)
    names = ("ddelta", "w", "dEq") if shift else ("delta", "w", "Eq")
    a, w, e = b.states(*names, units=["", "", "pu"])
    pm, efd = b.inputs(*(("dPm", "dEfd") if shift else ("Pm", "Efd")))
    (d,) = b.unknown_inputs("dP")
    (fa,) = b.faults("exciter", kind="actuator")
    (fs,) = b.faults("speed_sensor", kind="sensor")
    a0, e0, p0, f0 = (DELTA0, EQ0, PM0, EFD0) if shift else (0.0, 0.0, 0.0, 0.0)
    rates = _rhs(a0 + a / ka, w / kw, e0 + e, p0 + pm, f0 + efd + fa, d)
    b.drift([ka * rates[0], kw * rates[1], rates[2]])
    b.diffusion([0.0, 0.02 * w, 0.0])
    b.outputs([a, w + fs, e], names=["angle", "speed", "Eq_meas"])
    lo, hi = (0.1 - a0) * ka, (1.2 - a0) * ka
    b.region(**{names[0]: (lo, hi), "w": (-0.01 * kw, 0.01 * kw), names[2]: (0.8 - e0, 1.4 - e0)})
    if shift:
        b.operating_point(u=[PM0, EFD0])
        b.input_limits(dPm=(-PM0, 1.2 - PM0), dEfd=(-EFD0, 4.0 - EFD0))
    else:
        b.reference(x=[ka * DELTA0, 0.0, EQ0])
        b.initial_state([ka * DELTA0, 0.0, EQ0])
        b.input_limits(Pm=(0.0, 1.2), Efd=(0.0, 4.0))
    return b.build()


def smib(angle_per_rad: float = 1.0, speed_per_pu: float = 1.0):
    """In absolute units (warned: the model's form, above)."""
    return _build("smib", False, angle_per_rad, speed_per_pu)


def smib_deviations():
    """In deviations from the rest point."""
    return _build("smib_dev", True)


def scenario():
    """20 s at 1 ms: a 30 % loss of the field voltage from 3 to 8 s, a 0.002 pu bias of the speed sensor from 12 to 17
    s, load steps uniform in +/- 0.02 pu each step, noise 0.002 rad, 2e-4 pu, 0.005 pu."""
    from fte_casadi.sim import Bias, LossOfEffectiveness, Scenario, UniformNoise

    return Scenario(
        name="smib",
        T=20.0,
        dt=1e-3,
        faults=(
            LossOfEffectiveness("exciter", loss=0.3, start=3.0, stop=8.0),
            Bias("speed_sensor", value=0.002, start=12.0, stop=17.0),
        ),
        unknown_input=UniformNoise(0.02),
        x0_noise=0.001,
        paths=8,
        measurement_noise=(0.002, 0.0002, 0.005),
    )


def smib_deviations_scenario():
    return scenario()
