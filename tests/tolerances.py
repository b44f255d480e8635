"""Tolerances shared by the tests, in one place."""

ROUNDOFF = 1e-9  # exact derivations (sector models): error is round-off
PAPER_A = 0.01  # the paper prints A to two decimals
PAPER_B = 1e-3
PAPER_W = 1e-4
PAPER_BOUND = 1e-3  # premise bounds printed to 4 digits
PAPER_A_TANK = 1.5e-4  # three-tank A_i printed to 4 decimals
PAPER_H = 1e-6  # H follows from (17) exactly; printed to 7 digits
C_DOUBLE = 1e-12  # generated C vs CasADi, double precision (per step, absolute on O(1) values)
C_FLOAT_REL = 1e-4  # generated C in float vs double reference, relative
