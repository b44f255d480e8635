"""A chemostat (a continuous bioreactor), written as a new user writes it from the README (2026-11-29): biomass X,
substrate S and product P in g/L, time in hours, the dilution rate D (per h, the feed pump) the input.

    X' = mu(S) X - D X,   S' = -mu(S) X / Y + D (Sf - S) + d,   P' = (a mu(S) + b) X - D P
    mu(S) = mu_max S / (Ks + S + S^2 / Ki)                         (Haldane: substrate inhibition)

mu_max = 0.5 per h, Ks = 0.2 g/L, Ki = 20 g/L, Y = 0.5, Sf = 10 g/L, a = 2, b = 0.05 per h. At D = 0.3 per h it
rests at S = 0.307, X = 4.85, P = 10.5 g/L. ``pump``: an actuator fault of the dilution rate; ``S_sensor``: a bias
of the substrate probe; d: substrate fed in excess (g/L per h); every state measured.

How it came to be written so (each refusal verbatim, shortened):

1. With the feed's concentration fluctuating, ``D (Sf + d - S)``: "drift row 'S' is nonlinear in 'D': its
   derivative ((10+dSf)-S) depends on ['dSf']": an unknown input may not multiply an input; d is the excess
   substrate fed, ``D dSf`` taken as one unknown input.
2. ``fte design`` refused it, in absolute units, by assumptions (2) and (4): "fault 'S_sensor' cannot be told from
   the states' own motion (every rule); a measurement of 'S' free of fault 'S_sensor' would separate them", with
   S measured. The sector model, written about x = 0, telescoped ``mu(S) X`` as ``mu(S) * X`` and ``D (Sf - S)``
   as ``B(S) D``: the column of S in every A_i is 0, though at the reference the plant moves with S (df/dS =
   [1.81, -3.91, 3.61]). The refusal now says so, and checks its advice: written in deviations from the reference
   (:func:`chemostat_deviations`) assumption (2) holds with the sensor fault alone, and with both faults still
   fails in 4 of 16 rules: the pump and the probe's bias act nearly alike on this plant (growth and dilution move
   X and P against S), which the deviation form's refusal names ("the outputs tell them apart only weakly ...
   without any one of them LMIs (45)-(46) are feasible").
3. The Brownian perturbation of mu_max, ``0.03 mu(S) X`` in each row, does not vanish at rest: in deviations it is
   additive noise; :func:`chemostat_deviations` perturbs the growth's deviation from rest instead.

Measured in deviations with one fault each (``fte design tests/plant_chemostat.py:pump_only -o p.json``, then
``fte simulate p.json --plant tests/plant_chemostat.py:pump_only --seed 1``, 8 paths; ``probe_only`` alike): the
pump alone certifies (by Theorem 1's (29), sigma 0.01 chosen by the tool), its window's FTC true ratio 0.044 (fault
error 0.096); the probe alone certifies (observer 0.25 per h), its window a tie (1: the controller does not act,
max ||B_i K_j|| / max ||A_i|| = 8e-12: the open loop decays at 0.3 per h in every rule, (45) certifies no blend
faster than 0.25, so the smallest gain meets the rate asked), fault error 0.18.
"""

MU, KS, KI, Y, SF, ALPHA, BETA = 0.5, 0.2, 20.0, 0.5, 10.0, 2.0, 0.05
D0 = 0.3  # per h
S0 = (0.2 - (0.2**2 - 4 * 0.015 * 0.06) ** 0.5) / (2 * 0.015)  # mu(S0) = D0: 0.015 S^2 - 0.2 S + 0.06 = 0
X0 = Y * (SF - S0)
P0 = (ALPHA * D0 + BETA) * X0 / D0
SIGMA = 0.03  # the growth's fluctuation, per sqrt(h)


def _mu(s):
    return MU * s / (KS + s + s**2 / KI)


def _declare(b, states, units, pump: bool, sensor: bool):
    """The states, the dilution input, the excess substrate and the faults asked for (0 where not)."""
    xs = b.states(*states, units=units)
    (dil,) = b.inputs(("D", "dD")[states[0].startswith("d")])
    (d,) = b.unknown_inputs("dSf")
    fa = b.faults("pump", kind="actuator")[0] if pump else 0.0
    fs = b.faults("S_sensor", kind="sensor")[0] if sensor else 0.0
    return xs, dil, d, fa, fs


def _rates(x, s, p, D, d) -> list:
    """Growth, consumption and production, diluted at D; d the excess substrate fed."""
    mu = _mu(s)
    return [mu * x - D * x, -mu * x / Y + D * (SF - s) + d, (ALPHA * mu + BETA) * x - D * p]


def chemostat(pump: bool = True, sensor: bool = True):
    """In absolute units, with a reference state (refused: the model's form, above)."""
    from fte_casadi import PlantBuilder

    b = PlantBuilder("chemostat")
    (x, s, p), dil, d, fa, fs = _declare(b, ("X", "S", "P"), ["g/L"] * 3, pump, sensor)
    b.drift(_rates(x, s, p, dil + fa, d))
    mu = _mu(s)
    b.diffusion([SIGMA * mu * x, -SIGMA * mu * x / Y, SIGMA * ALPHA * mu * x])
    b.outputs([x, s + fs, p], names=["OD", "S_meas", "P_meas"], units=["g/L", "g/L", "g/L"])
    b.region(X=(3.0, 6.0), S=(0.05, 1.0), P=(6.0, 14.0))
    b.reference(x=[X0, S0, P0])
    b.initial_state([X0, S0, P0])
    b.input_limits(D=(0.0, 0.45))
    b.time_unit("h")
    return b.build()


def chemostat_probe():
    """In absolute units, the probe's bias the only fault."""
    return chemostat(pump=False)


def chemostat_deviations(pump: bool = True, sensor: bool = True):
    """The same plant in deviations from its rest point, the input the dilution rate less 0.3 per h."""
    from fte_casadi import PlantBuilder

    b = PlantBuilder("chemostat_dev")
    (dx, ds, dp), v, d, fa, fs = _declare(b, ("dX", "dS", "dP"), ["g/L"] * 3, pump, sensor)
    x, s, p = X0 + dx, S0 + ds, P0 + dp
    b.drift(_rates(x, s, p, D0 + v + fa, d))
    g = SIGMA * (_mu(s) * x - D0 * X0)  # the growth's deviation from rest fluctuating
    b.diffusion([g, -g / Y, ALPHA * g])
    b.outputs([dx, ds + fs, dp], names=["OD", "S_meas", "P_meas"], units=["g/L", "g/L", "g/L"])
    b.region(dX=(3.0 - X0, 6.0 - X0), dS=(0.05 - S0, 1.0 - S0), dP=(6.0 - P0, 14.0 - P0))
    b.operating_point(u=[D0])
    b.input_limits(dD=(-D0, 0.45 - D0))
    b.time_unit("h")
    return b.build()


def scenario():
    """100 h sampled every 36 s: a 30 % loss of the pump from 20 to 40 h, a 0.1 g/L bias of the probe from 60 to 80 h,
    the excess substrate uniform in +/- 0.06 g/L per h, probe noise 0.05, 0.01, 0.1 g/L."""
    from fte_casadi.sim import Bias, LossOfEffectiveness, Scenario, UniformNoise

    return Scenario(
        name="chemostat",
        T=100.0,
        dt=0.01,
        faults=(
            LossOfEffectiveness("pump", loss=0.3, start=20.0, stop=40.0),
            Bias("S_sensor", value=0.1, start=60.0, stop=80.0),
        ),
        unknown_input=UniformNoise(0.06),
        x0_noise=0.05,
        paths=8,
        measurement_noise=(0.05, 0.01, 0.1),
    )


def pump_only():
    """In deviations, the pump's fault alone."""
    return chemostat_deviations(sensor=False)


def pump_only_scenario():
    return _only(0)


def probe_only():
    """In deviations, the probe's bias alone."""
    return chemostat_deviations(pump=False)


def probe_only_scenario():
    return _only(1)


def _only(k: int):
    import dataclasses

    sc = scenario()
    return dataclasses.replace(sc, faults=sc.faults[k : k + 1])
