"""simulate(): quadrature solution of the flux ODE against closed forms and solve_ivp."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from osmobulge.modeling.materials import PDMS, PEO_PDMS, LinearElastic
from osmobulge.modeling.permeability import DoubleExponential, Firpo
from osmobulge.modeling.simulate import MechanicsRangeError, VolumePath, simulate
from osmobulge.modeling.transport import mechanics_model, paper_chamber, volume_rate

DAY = np.arange(0.0, 24 * 3600 + 1, 900.0)  # every 15 min for 24 h


def reference_solution(chamber, material, permeability, t, *, mechanics="hyperelastic", v0=1.0):
    """Independent solution: adaptive Runge-Kutta on the right-hand side."""
    mech = mechanics_model(material, 1.0, mechanics)
    sol = solve_ivp(lambda _t, y: [volume_rate(y[0], chamber, mech, permeability)], (0.0, t[-1]), [v0],
                    t_eval=t, method="DOP853", rtol=1e-10, atol=1e-12)
    assert sol.success
    return sol.y[0]


def test_linear_membrane_without_turgor_matches_closed_form():
    # P_t ~ 0 (E = 1 uPa): dv/dt = f_A / (tau v) with f_A = 1 + 4 Vt^2 = 1 + k^2 u^2, k = 2 h/a,
    # u = v - 1, separable:  t / tau = ln(1 + k^2 u^2) / (2 k^2) + arctan(k u) / k
    c = paper_chamber()
    tau = c.time_constant(2e-12)
    t = DAY[DAY <= 4 * 3600]  # later, f_A ~ v^2 drives v into the 1e3 where even 1 uPa turgor counts
    v = simulate(c, LinearElastic(1e-6), 2e-12, t, mechanics="linear").volume_ratio.values
    k = 2 * c.depth / c.radius
    u = v - 1
    t_closed = tau * (np.log1p(k**2 * u**2) / (2 * k**2) + np.arctan(k * u) / k)
    np.testing.assert_allclose(t_closed, t, rtol=1e-8, atol=1e-6)
    # and the tiny-deflection start follows v = sqrt(1 + 2 t / tau) (f_A = f_l = 1; here f_A - 1 < 1.1e-5)
    early = simulate(c, LinearElastic(1e-6), 2e-12, [0.0, 1.0, 10.0, 30.0], mechanics="linear").volume_ratio
    np.testing.assert_allclose(early, np.sqrt(1 + 2 * np.array([0.0, 1.0, 10.0, 30.0]) / tau), rtol=3e-8)


@pytest.mark.parametrize(
    ("name", "material", "law", "mechanics", "v0", "feed"),
    [
        ("reference", PDMS, DoubleExponential.PDMS, "hyperelastic", 1.0, 0.0),
        ("small_radius", PDMS, 8.35e-13, "hyperelastic", 1.0, 0.0),
        ("reference", PEO_PDMS, DoubleExponential.PEO_PDMS, "hyperelastic", 1.0, 0.0),
        ("reference", PDMS, 2.02e-12, "linear", 1.0, 0.0),
        ("reference", PDMS, DoubleExponential.PDMS, "hyperelastic", 8.0, 3000.0),  # reverse actuation
        ("low_concentration", PDMS, Firpo(4e-12, 20e-6), "hyperelastic", 1.0, 0.0),
    ],
)
def test_quadrature_agrees_with_solve_ivp(name, material, law, mechanics, v0, feed):
    c = paper_chamber(name, feed_concentration=feed)
    ds = simulate(c, material, law, DAY, mechanics=mechanics, v0=v0)
    ref = reference_solution(c, material, law, DAY, mechanics=mechanics, v0=v0)
    np.testing.assert_allclose(ds.volume_ratio.values, ref, rtol=1e-6)


def test_linear_equilibrium_where_osmotic_equals_turgor():
    c = paper_chamber()
    ds = simulate(c, PDMS, 2e-12, [0.0, 10 * 86400.0], mechanics="linear")
    h_a, l_a, pi0 = c.depth / c.radius, c.thickness / c.radius, -c.osmotic_potential

    def balance(v):  # osmotic pull 1/v against turgor P_t/|Pi0| with Eqn 11
        return 1 / v - PDMS.E * 128 / 3 * l_a * ((v - 1) * h_a) ** 3 / pi0

    v_eq = brentq(balance, 1.0, 10.0, xtol=1e-14)
    assert ds.attrs["end"] == "equilibrium"
    assert ds.attrs["end_volume_ratio"] == pytest.approx(v_eq, rel=1e-12, abs=0)
    assert ds.volume_ratio.values[-1] == pytest.approx(v_eq, rel=1e-9, abs=0)
    assert abs(ds.driving_force.values[-1]) < 1e-9


def test_gent_equilibrium_below_locking():
    c = paper_chamber()
    ds = simulate(c, PDMS, 8.35e-13, [0.0, 3 * 86400.0])
    mech = mechanics_model(PDMS)
    v_eq = ds.attrs["end_volume_ratio"]
    assert c.vtilde(v_eq) < mech.vtilde_lock
    # the turgor near locking balances the diluted osmotic pull
    pt = mech.turgor_pressure(c.vtilde(v_eq), thickness=c.thickness, radius=c.radius)
    assert 1 / v_eq == pytest.approx(pt / -c.osmotic_potential, rel=1e-9, abs=0)
    assert ds.volume_ratio.values[-1] == pytest.approx(v_eq, rel=1e-6, abs=0)


def test_reverse_actuation_returns_to_rest():
    c = paper_chamber(feed_concentration=3000.0)  # isotonic feed (Fig. 2b)
    ds = simulate(c, PDMS, DoubleExponential.PDMS, DAY, v0=8.0)
    v = ds.volume_ratio.values
    assert v[0] == 8.0
    assert np.all(np.diff(v) < 0)
    assert 1.0 < v[-1] < 1.01
    assert ds.attrs["end_volume_ratio"] == 1.0


def test_gent_lock_stops_with_clear_error_or_truncates():
    thin = paper_chamber(thickness=2e-6)  # weak turgor: no equilibrium before the table end
    with pytest.raises(MechanicsRangeError, match=r"Gent locking.*t = \d.* s .*Vtilde = 7\.1") as err:
        simulate(thin, PDMS, DoubleExponential.PDMS, DAY)
    assert isinstance(err.value, ValueError)
    ds = simulate(thin, PDMS, DoubleExponential.PDMS, DAY, on_limit="truncate")
    assert ds.attrs["limit_reached"] == 1
    assert ds.time.values[-1] <= ds.attrs["limit_time"] == pytest.approx(err.value.time, rel=1e-6, abs=0)
    assert ds.sizes["time"] < DAY.size
    assert np.all(np.isfinite(ds.volume_ratio)) and ds.vtilde.values[-1] <= mechanics_model(PDMS).vtilde_max
    full = simulate(paper_chamber(), PDMS, DoubleExponential.PDMS, DAY, on_limit="truncate")
    assert full.attrs["limit_reached"] == 0 and full.sizes["time"] == DAY.size


def test_hypertonic_feed_stops_at_inward_deflection():
    c = paper_chamber(feed_concentration=3500.0)
    with pytest.raises(MechanicsRangeError, match="deflect inward"):
        simulate(c, PDMS, 2e-12, DAY, v0=4.0)


def test_dataset_layout_units_and_attrs():
    c = paper_chamber("thick_membrane")
    law = Firpo.through(1.99e-12, thickness=20e-6, critical_thickness=40e-6)
    ds = simulate(c, PDMS, law, DAY)
    for name in ("volume_ratio", "vtilde", "lambda_bar", "area_ratio", "thickness", "turgor_pressure",
                 "permeability"):
        assert ds[name].dims == ("time",)
        assert "units" in ds[name].attrs and "long_name" in ds[name].attrs
    assert ds.thickness.attrs["units"] == "m" and ds.turgor_pressure.attrs["units"] == "Pa"
    assert ds.time.attrs["units"] == "s"
    # thickness-law callables get the mean thickness l0 / f_l
    np.testing.assert_allclose(ds.thickness, c.thickness / ds.inverse_thickness)
    np.testing.assert_allclose(ds.permeability, law(thickness=ds.thickness.values), rtol=1e-14)
    np.testing.assert_allclose(ds.vtilde, (ds.volume_ratio - 1) * c.depth / c.radius, rtol=1e-12)
    np.testing.assert_allclose(ds.lambda_bar**2, ds.area_ratio, rtol=1e-6)  # two splines of the table
    # netCDF-safe attrs, chamber recoverable
    assert all(isinstance(v, str | int | float) for v in ds.attrs.values())
    assert ds.attrs["permeability_p_henry"] == law.p_henry
    from osmobulge.modeling.transport import Chamber

    assert Chamber.from_attrs(ds.attrs) == c
    assert isinstance(ds.to_netcdf(engine="scipy"), bytes | memoryview)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"t": [0.0, 10.0, 5.0]}, "non-decreasing"),
        ({"t": [0.0, math.nan]}, "finite"),
        ({"t": [-1.0, 1.0]}, ">= 0"),
        ({"t": [[0.0, 1.0]]}, "1-D"),
        ({"on_limit": "ignore"}, "on_limit must be one of"),
        ({"mechanics": "fem"}, "mechanics must be one of"),
        ({"permeability": -2e-12}, "permeability must be finite and > 0"),
        ({"v0": 0.5}, "v0 must be"),
        ({"permeability": lambda lam: 0.0 * lam}, "permeability must be finite and > 0"),
    ],
)
def test_simulate_validation(kwargs, match):
    args = {"t": DAY, "permeability": 2e-12, **kwargs}
    t, p = args.pop("t"), args.pop("permeability")
    with pytest.raises(ValueError, match=match):
        simulate(paper_chamber(), PDMS, p, t, **args)


def test_path_reuses_grid_across_permeabilities():
    c = paper_chamber()
    path = VolumePath(c, mechanics_model(PDMS), 1.0, n=401)
    for p in (1e-12, 3e-12):
        direct = simulate(c, PDMS, p, DAY).volume_ratio.values
        np.testing.assert_allclose(path.volume_ratio(DAY, p), direct, rtol=2e-6)
    # a constant permeability only rescales time: v(t; 2P) = v(2t; P)
    np.testing.assert_allclose(path.volume_ratio(DAY, 2e-12), path.volume_ratio(2 * DAY, 1e-12), rtol=1e-12)


def test_errata_eqn25_eqn63_instantaneous_mobility():
    # Eqn 8 solved for L at each instant must give back the permeability that generated the rate:
    # L = -(dv/dt) l0 V0 / (A0 Pi0) / (f_A f_l) / (1/(V/V0) - C_feed/C0 + E f_p / Pi0)   (dividing)
    from osmobulge.modeling.transport import mobility

    c = paper_chamber()
    ds = simulate(c, PDMS, DoubleExponential.PDMS, [0.0, 6 * 3600.0, 12 * 3600.0, 86400.0])
    geometric = -c.thickness * c.volume / (c.area * c.osmotic_potential) / (ds.area_ratio * ds.inverse_thickness)
    bracket = 1 / ds.volume_ratio + ds.turgor_pressure / c.osmotic_potential
    np.testing.assert_allclose(bracket, ds.driving_force, rtol=1e-12)
    right = ds.volume_rate * geometric / bracket
    np.testing.assert_allclose(right, mobility(ds.permeability), rtol=1e-9)
    # supp. Eqn 63 multiplies by the bracket: off by bracket**2 (0.166 at 6 h, 0.0052 at 24 h)
    printed_63 = ds.volume_rate * geometric * bracket
    np.testing.assert_allclose(printed_63 / right, bracket**2, rtol=1e-12)
    assert float(bracket[-1] ** 2) == pytest.approx(0.00523, rel=1e-2, abs=0)
    # main Eqn 25 as printed, 1/V0 with V0 in m^3 (1.4e-11): 1/V0 dwarfs E f_p / Pi0 and L comes out ~1e-11 x
    printed_25 = ds.volume_rate * geometric / (1 / c.volume + ds.turgor_pressure / c.osmotic_potential)
    assert np.all(printed_25[1:] / right[1:] < 1e-9)
