"""The nonlinear plant against independent references: scipy's solve_ivp on equations derived
here from the kinematics, energy and power balance, finite differences, scipy's zero-order hold,
and the paper's printed matrices."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

import riprs
from riprs import FurutaParams, Plant

RNG = np.random.default_rng(7)


def kinetic_potential(p: dict[str, float], x: np.ndarray) -> tuple[float, float]:
    """T and V from the link kinematics (independent of the Lagrangian's closed form).

    Arm along e_r = (cos th, sin th, 0); pendulum in the plane of e_t = (-sin th, cos th, 0) and z,
    leaning towards -e_t for alpha > 0, centre of mass at Lp/2.
    """
    th, thd, a, ad = x
    er = np.array([np.cos(th), np.sin(th), 0.0])
    et = np.array([-np.sin(th), np.cos(th), 0.0])
    z = np.array([0.0, 0.0, 1.0])
    lc = p["Lp"] / 2
    # Velocity of the pendulum's centre: d/dt [Lr er + lc (-sin a et + cos a z)].
    v = p["Lr"] * thd * et + lc * (-np.cos(a) * ad * et + np.sin(a) * thd * er - np.sin(a) * ad * z)
    # Angular velocity of the pendulum: thd about z plus ad about the arm axis.
    omega = thd * z - ad * er
    axis = -np.sin(a) * et + np.cos(a) * z  # the rod's own axis (no inertia about it)
    omega_perp = omega - (omega @ axis) * axis
    arm_inertia = p["Jr"] + p["mr"] * p["Lr"] ** 2 / 4
    t = 0.5 * arm_inertia * thd**2 + 0.5 * p["mp"] * v @ v + 0.5 * p["Jp"] * omega_perp @ omega_perp
    v_pot = p["mp"] * p["g"] * lc * np.cos(a)
    return float(t), float(v_pot)


def reference_rhs(p: dict[str, float], u: float, torque: float = 0.0):
    """The equations of motion written out independently in numpy."""
    j0 = p["Jr"] + p["mr"] * p["Lr"] ** 2 / 4 + p["mp"] * p["Lr"] ** 2
    ja = p["Jp"] + p["mp"] * p["Lp"] ** 2 / 4
    m12 = p["mp"] * p["Lr"] * p["Lp"] / 2
    grav = p["mp"] * p["g"] * p["Lp"] / 2

    def rhs(_t: float, x: np.ndarray) -> np.ndarray:
        _, thd, a, ad = x
        s, c = np.sin(a), np.cos(a)
        tau = p["kt"] * (u - p["km"] * thd) / p["Rm"]
        mass = np.array([[j0 + ja * s * s, -m12 * c], [-m12 * c, ja]])
        force = np.array(
            [
                tau + torque - p["Dr"] * thd - 2 * ja * s * c * thd * ad - m12 * s * ad**2,
                -p["Dp"] * ad + ja * s * c * thd**2 + grav * s,
            ]
        )
        acc = np.linalg.solve(mass, force)
        return np.array([thd, acc[0], ad, acc[1]])

    return rhs


@pytest.mark.parametrize("preset", [FurutaParams.qube_servo2, FurutaParams.paper])
def test_energy_matches_kinematics_and_power_balance(preset) -> None:
    params = preset()
    p = params.to_dict()
    plant = Plant(params)
    for _ in range(20):
        x = RNG.normal(size=4) * [1.0, 3.0, 1.5, 5.0]
        u, torque = RNG.normal() * 5, RNG.normal() * 0.01
        t, v = kinetic_potential(p, x)
        assert plant.energy(x) == pytest.approx(t + v, rel=1e-12, abs=1e-15)
        # dE/dt along the flow equals the power of the motor and the disturbance minus friction.
        h = 1e-6
        grad = np.array(
            [(plant.energy(x + h * e) - plant.energy(x - h * e)) / (2 * h) for e in np.eye(4)]
        )
        power = (
            p["kt"] * (u - p["km"] * x[1]) / p["Rm"] * x[1]
            + torque * x[1]
            - p["Dr"] * x[1] ** 2
            - p["Dp"] * x[3] ** 2
        )
        assert grad @ plant.derivative(x, u, torque) == pytest.approx(power, rel=1e-6, abs=1e-9)


def test_derivative_matches_independent_equations() -> None:
    params = FurutaParams.qube_servo2()
    plant = Plant(params)
    for _ in range(20):
        x = RNG.normal(size=4) * [1.0, 3.0, 2.0, 5.0]
        u, torque = RNG.normal() * 6, RNG.normal() * 0.01
        want = reference_rhs(params.to_dict(), u, torque)(0.0, x)
        np.testing.assert_allclose(plant.derivative(x, u, torque), want, rtol=1e-12, atol=1e-12)


def test_rk4_trajectory_agrees_with_solve_ivp() -> None:
    """A 2 s open-loop run with a held, changing voltage: the pendulum falls and swings through
    large angles, so the nonlinear terms all matter."""
    params = FurutaParams.paper()
    plant = Plant(params)
    dt, n = 0.01, 200
    u = 3.0 * np.sin(np.arange(n) * dt * 4.0)
    x = np.array([0.0, 0.0, 0.2, 0.0])
    traj = plant.integrate(x, u, dt, substeps=10)
    ref = [x]
    for k in range(n):
        sol = solve_ivp(
            reference_rhs(params.to_dict(), u[k]),
            (0, dt),
            ref[-1],
            method="DOP853",
            rtol=1e-12,
            atol=1e-12,
        )
        ref.append(sol.y[:, -1])
    ref = np.array(ref)
    assert np.max(np.abs(ref[:, 2])) > 2.0  # it really swung down
    np.testing.assert_allclose(traj, ref, atol=1e-7)
    # The step method is the same integrator.
    np.testing.assert_allclose(plant.step(x, u[0], dt, substeps=10), traj[1], rtol=1e-14)


def test_energy_is_conserved_without_friction_and_input() -> None:
    params = FurutaParams.qube_servo2().replace(km=0.0, Dr=0.0, Dp=0.0)
    plant = Plant(params)
    x0 = np.array([0.0, 4.0, 0.3, -6.0])
    traj = plant.integrate(x0, np.zeros(1000), 0.005, substeps=10)
    energy = np.array([plant.energy(x) for x in traj])
    assert np.ptp(traj[:, 2]) > 1.0
    assert np.max(np.abs(energy - energy[0])) < 1e-8 * abs(energy[0])


@pytest.mark.parametrize(
    "x, u",
    [
        (np.zeros(4), 0.0),
        (np.array([0.7, 0.0, np.pi, 0.0]), 0.0),
        (np.array([0.3, -1.2, 0.8, 2.5]), 4.0),
        (np.array([-2.0, 3.0, -2.2, -4.0]), -9.0),
    ],
)
def test_linearization_equals_finite_differences(x: np.ndarray, u: float) -> None:
    plant = Plant.qube_servo2()
    A, B = plant.linearize(x, u)
    h = 1e-6
    f = plant.derivative
    fd_a = np.column_stack([(f(x + h * e, u) - f(x - h * e, u)) / (2 * h) for e in np.eye(4)])
    fd_b = (plant.derivative(x, u + h) - plant.derivative(x, u - h)) / (2 * h)
    np.testing.assert_allclose(A, fd_a, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(B[:, 0], fd_b, rtol=1e-6, atol=1e-6)


def test_sign_convention_positive_voltage_accelerates_both_angles() -> None:
    for plant in (Plant.qube_servo2(), riprs.paper.plant()):
        xdot = plant.derivative(np.zeros(4), 1.0)
        assert xdot[1] > 0 and xdot[3] > 0
        _, Bd = plant.linearize_discrete(0.01)
        assert np.all(Bd > 0)


def test_paper_preset_reproduces_printed_ad_bd() -> None:
    plant = riprs.paper.plant()
    A, B = plant.linearize()
    # Zero-order hold computed independently with scipy.
    block = np.zeros((5, 5))
    block[:4, :4], block[:4, 4:] = A * 0.01, B * 0.01
    e = expm(block)
    Ad, Bd = e[:4, :4], e[:4, 4:]
    Ad_riprs, Bd_riprs = plant.linearize_discrete(0.01)
    np.testing.assert_allclose(Ad_riprs, Ad, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(Bd_riprs, Bd, rtol=1e-10, atol=1e-14)
    printed = riprs.paper.PRINTED
    half = np.full((4, 4), 0.5e-4)
    half[1, 3] = 0.5e-5
    half[2, :] = 0.5e-3
    half[3, 3] = 0.5e-3
    err = np.abs(Ad - printed["Ad"]) / half
    err[0, 1] = 0.0  # the printed 0.001 is a typo for 0.0099 (riprs.paper docs)
    assert np.max(err) <= 1.0, err
    assert Ad[0, 1] == pytest.approx(0.0099, abs=0.5e-4)
    assert np.max(np.abs(Bd - printed["Bd"]) / 0.5e-4) <= 1.0
    # Against the recovered unrounded model: well inside the printed precision.
    unrounded = riprs.paper.discrete_model()
    assert np.max(np.abs(Ad - unrounded.A) / half) < 0.1
    assert np.max(np.abs(Bd - unrounded.B) / 0.5e-4) < 0.1


def test_fit_recovers_physical_parameters() -> None:
    truth = FurutaParams.qube_servo2().replace(Lr=0.1, Lp=0.2, Jr=1e-4, Jp=8e-5, Dr=9e-4, Dp=1e-4)
    Ad, Bd = Plant(truth).linearize_discrete(0.01)
    fitted, report = FurutaParams.fit(Ad, Bd, 0.01)
    assert report["converged"]
    for name, value in truth.to_dict().items():
        assert getattr(fitted, name) == pytest.approx(value, rel=1e-6), name
    # The unidentifiable parameters come from ``base``; another pendulum mass gives another
    # physical pendulum with the same linear model.
    base = FurutaParams.qube_servo2().replace(mp=0.02)
    fitted, report = FurutaParams.fit(Ad, Bd, 0.01, base=base)
    assert fitted.mp == 0.02 and fitted.Lp == pytest.approx(0.24, rel=1e-6)
    assert report["max_abs_residual"] < 1e-10
    np.testing.assert_allclose(Plant(fitted).linearize_discrete(0.01)[0], Ad, atol=1e-10)
    # With mp = 0.05 the arm inertia would have to be negative: the fit says how far off it is.
    _, report = FurutaParams.fit(Ad, Bd, 0.01, base=base.replace(mp=0.05))
    assert report["max_abs_residual"] > 1e-4


def test_paper_fit_reproduces_the_preset() -> None:
    m = riprs.paper.discrete_model()
    w = np.full((4, 5), 1 / 0.5e-4)
    w[1, 3] = 1 / 0.5e-5
    w[2, :4] = 1 / 0.5e-3
    w[3, 3] = 1 / 0.5e-3
    fitted, report = FurutaParams.fit(m.A, m.B, 0.01, weights=w)
    assert report["max_weighted_residual"] < 0.1
    for name, value in FurutaParams.paper().to_dict().items():
        assert getattr(fitted, name) == pytest.approx(value, rel=1e-6), name


def test_bad_parameters_raise_naming_the_field() -> None:
    with pytest.raises(riprs.InvalidParameterError, match="mp"):
        FurutaParams(mp=-1.0)
    with pytest.raises(riprs.InvalidParameterError, match="Jr"):
        FurutaParams.paper().replace(Jr=0.0)
    with pytest.raises(riprs.InvalidParameterError, match="Dp"):
        FurutaParams(Dp=-1e-3)
    with pytest.raises(riprs.InvalidParameterError, match="g"):
        FurutaParams(g=float("nan"))
    with pytest.raises(TypeError, match="Mp"):
        FurutaParams(Mp=0.1)
    assert FurutaParams(km=0.0).km == 0.0
    p = FurutaParams.paper()
    assert p.replace() == p
    assert p.replace(mp=0.03) != p


def test_bad_inputs_raise_naming_the_argument() -> None:
    plant = Plant.paper()
    with pytest.raises(riprs.ShapeError, match="x"):
        plant.derivative([0.0, 0.0, 0.0])
    with pytest.raises(riprs.NonFiniteError, match="x"):
        plant.derivative([0.0, np.nan, 0.0, 0.0])
    with pytest.raises(riprs.NonFiniteError, match="u"):
        plant.derivative(np.zeros(4), np.inf)
    with pytest.raises(riprs.InvalidParameterError, match="dt"):
        plant.step(np.zeros(4), 0.0, -0.01)
    with pytest.raises(riprs.InvalidParameterError, match="substeps"):
        plant.integrate(np.zeros(4), np.zeros(3), 0.01, substeps=0)
    with pytest.raises(riprs.ShapeError, match="Ad"):
        FurutaParams.fit(np.eye(3), np.ones(4), 0.01)
    with pytest.raises(riprs.InvalidParameterError, match="Ts"):
        FurutaParams.fit(np.eye(4), np.ones(4), 0.0)
    with pytest.raises(TypeError, match="x"):
        plant.energy("upright")


def test_coulomb_friction_and_dead_zone_are_parameters_named_on_error():
    p = riprs.FurutaParams(Cr=0.003, Cp=2e-5, Vd=0.4)
    assert (p.Cr, p.Cp, p.Vd) == (0.003, 2e-5, 0.4)
    assert p.to_dict()["Vd"] == 0.4
    assert riprs.FurutaParams.qube_servo2().Cr == 0.0
    for key in ("Cr", "Cp", "Vd"):
        with pytest.raises(riprs.InvalidParameterError, match=key):
            riprs.FurutaParams(**{key: -1.0})
    # Inside the dead zone the voltage does nothing; beyond it, it is reduced by Vd.
    plant = riprs.Plant(p)
    free = riprs.Plant(p.replace(Vd=0.0))
    x = [0.0, 0.5, 0.2, -0.1]
    np.testing.assert_array_equal(plant.derivative(x, 0.3), free.derivative(x, 0.0))
    np.testing.assert_allclose(plant.derivative(x, -2.0), free.derivative(x, -1.6), rtol=1e-12)
    # The linearisation leaves both out, like the controller designs.
    np.testing.assert_array_equal(plant.linearize()[1], free.linearize()[1])
