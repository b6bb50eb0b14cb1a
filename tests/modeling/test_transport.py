"""Transport model (chamber, conversions, flux ODE right-hand side) and permeability laws."""

import math

import lmfit
import numpy as np
import pytest

from osmobulge.modeling import permeability as perm
from osmobulge.modeling import transport as tr
from osmobulge.modeling.materials import PDMS, LinearElastic

REF = {"radius": 200e-6, "depth": 110e-6, "thickness": 20e-6, "concentration": 3000.0}


# -- constants and conversions ------------------------------------------------
def test_water_constants_are_consistent():
    # C_w V_m = 1 and M_w / rho_w = V_m: Eqn 2 reduces to L = P_w V_m / (R T)
    cw, vm = tr.WATER_CONCENTRATION, tr.WATER_MOLAR_VOLUME
    assert cw * vm == pytest.approx(1.0, rel=1e-15, abs=0)
    assert vm == pytest.approx(18.069e-6, rel=1e-4, abs=0)
    assert cw / 1000.0 == pytest.approx(55.34, rel=1e-3, abs=0)


def test_mobility_matches_printed_eqn2_and_round_trips():
    pw, temp = 2e-12, 298.15
    printed = (pw * tr.WATER_CONCENTRATION / (tr.GAS_CONSTANT * temp)
               * tr.WATER_MOLAR_VOLUME * tr.WATER_MOLAR_MASS / tr.WATER_DENSITY)
    assert tr.mobility(pw, temp) == pytest.approx(printed, rel=1e-14, abs=0)
    assert tr.permeability_from_mobility(tr.mobility(pw, 310.0), 310.0) == pytest.approx(pw, rel=1e-14, abs=0)
    arr = tr.mobility(np.array([1e-12, 2e-12]))
    np.testing.assert_allclose(arr, [tr.mobility(1e-12), tr.mobility(2e-12)])


def test_time_constant_definition_and_temperature_cancels():
    c = tr.Chamber(**REF)
    L = tr.mobility(2e-12, c.temperature)
    expected = -c.thickness * c.volume / (L * c.osmotic_potential * c.area)
    assert tr.time_constant(c, 2e-12) == pytest.approx(expected, rel=1e-14, abs=0)
    # tau = l0 h / (P_w V_m i C0): independent of T
    closed = c.thickness * c.depth / (2e-12 * tr.WATER_MOLAR_VOLUME * 2.0 * 3000.0)
    assert tr.time_constant(c, 2e-12) == pytest.approx(closed, rel=1e-12, abs=0)
    assert tr.time_constant(c.replace(temperature=310.0), 2e-12) == pytest.approx(closed, rel=1e-12, abs=0)
    assert closed / 3600 == pytest.approx(2.818, abs=1e-3)  # hours, reference chamber
    with pytest.raises(ValueError, match="permeability"):
        tr.time_constant(c, -1.0)


def test_vtilde_volume_ratio_round_trip():
    c = tr.Chamber(**REF)
    v = np.array([1.0, 1.3, 8.0])
    vt = tr.vtilde_from_volume_ratio(v, c)
    # Eqn 4: (V - V0)/(A0 a) with the cylinder's V0 and A0
    np.testing.assert_allclose(vt, (v - 1) * c.volume / (c.area * c.radius), rtol=1e-14)
    assert vt[1] == pytest.approx(0.165, rel=1e-6, abs=0)  # the paper's small-deflection limit (Sec. 3.6.1)
    np.testing.assert_allclose(tr.volume_ratio_from_vtilde(vt, c), v, rtol=1e-14)


def test_osmotic_term_with_feed():
    assert tr.osmotic_term(2.0) == 0.5
    assert tr.osmotic_term(2.0, feed_ratio=1.0) == -0.5
    c = tr.Chamber(**REF, feed_concentration=1500.0)
    assert c.feed_ratio == 0.5
    assert c.osmotic_potential == pytest.approx(-2 * 3000 * 8.314462618 * 298.15, rel=1e-6, abs=0)


# -- chamber validation ----------------------------------------------------------
@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("radius", 200.0, r"radius=200.0 m is implausible.*200e-6"),
        ("radius", -1e-4, "radius must be > 0"),
        ("radius", 0.0, "radius must be > 0"),
        ("depth", math.nan, "depth must be finite"),
        ("thickness", 20.0, "thickness=20.0 m is implausible"),
        ("concentration", 200e-6, r"concentration=0.0002 mol/m\^3 is implausible.*3000 for 3 M"),
        ("concentration", math.inf, "concentration must be finite"),
        ("feed_concentration", -1.0, "feed_concentration must be >= 0"),
        ("temperature", 25.0, "temperature=25.0 K is implausible.*kelvin"),
        ("vant_hoff", 0.0, "vant_hoff must be > 0"),
    ],
)
def test_chamber_rejects_bad_values(field, value, match):
    with pytest.raises(ValueError, match=match):
        tr.Chamber(**{**REF, field: value})


def test_chamber_rejects_membrane_thicker_than_radius_and_non_numbers():
    with pytest.raises(ValueError, match="smaller than radius"):
        tr.Chamber(radius=10e-6, depth=110e-6, thickness=20e-6, concentration=3000.0)
    with pytest.raises(TypeError, match="radius must be a real number"):
        tr.Chamber(**{**REF, "radius": "big"})


def test_chamber_is_frozen_and_attrs_round_trip():
    c = tr.paper_chamber("low_concentration", feed_concentration=10.0)
    with pytest.raises(AttributeError):
        c.radius = 1e-4
    attrs = c.to_attrs()
    assert set(attrs) == {v[0] for v in tr.CHAMBER_ATTRS.values()}
    assert all(isinstance(v, float) for v in attrs.values())
    assert tr.Chamber.from_attrs(attrs) == c
    with pytest.raises(ValueError, match="chamber_depth"):
        tr.Chamber.from_attrs({"chamber_radius": 2e-4, "membrane_thickness": 2e-5, "concentration": 3e3})


def test_paper_chambers():
    ref = tr.paper_chamber()
    assert (ref.radius, ref.depth, ref.thickness, ref.concentration) == (200e-6, 110e-6, 20e-6, 3000.0)
    assert tr.paper_chamber("small_radius").radius == 100e-6
    assert tr.paper_chamber("thick_membrane").thickness == 26e-6
    assert tr.paper_chamber("low_concentration").concentration == 1000.0
    with pytest.raises(ValueError, match="unknown paper chamber"):
        tr.paper_chamber("huge")


# -- mechanics and ODE right-hand side ----------------------------------------------
def test_linear_mechanics_closed_form():
    m = tr.mechanics_model(PDMS, mechanics="linear")
    assert m.E == PDMS.E
    assert m.area_ratio(0.5) == 2.0  # 1 + 4 V^2 (corrected Eqn 12)
    assert m.inverse_thickness(0.5) == 1.0
    assert m.turgor_pressure(0.5, thickness=20e-6, radius=200e-6) == pytest.approx(
        PDMS.E * 128 / 3 * 0.1 * 0.125, rel=1e-6, abs=0)
    # the LinearElastic law selects the same mechanics
    assert isinstance(tr.mechanics_model(LinearElastic(1e6)), tr.LinearMechanics)
    with pytest.raises(ValueError, match="mechanics must be one of"):
        tr.mechanics_model(PDMS, mechanics="nonlinear")
    with pytest.raises(ValueError, match="lambda_pre must be 1"):
        tr.mechanics_model(PDMS, 1.05, mechanics="linear")
    with pytest.raises(ValueError, match="inward deflection"):
        m.area_ratio(-0.1)


def test_volume_rate_is_eqn8_with_feed():
    c = tr.Chamber(**REF, feed_concentration=600.0)
    m = tr.mechanics_model(PDMS)
    v = 3.0
    vt = c.vtilde(v)
    pt = m.turgor_pressure(vt, thickness=c.thickness, radius=c.radius)
    L = tr.mobility(2e-12, c.temperature)
    pi0 = c.osmotic_potential
    expected = (-L * pi0 * c.area / (c.thickness * c.volume) * m.area_ratio(vt) * m.inverse_thickness(vt)
                * (1 / v - 0.2 + pt / pi0))
    assert tr.volume_rate(v, c, m, 2e-12) == pytest.approx(expected, rel=1e-12, abs=0)
    # at rest with pure water the rate is exactly 1/tau
    c0 = tr.Chamber(**REF)
    assert tr.volume_rate(1.0, c0, m, 2e-12) * c0.time_constant(2e-12) == pytest.approx(1.0, rel=1e-12, abs=0)


def test_volume_rate_passes_mean_thickness_to_thickness_laws():
    c = tr.Chamber(**REF)
    m = tr.mechanics_model(PDMS)
    seen = {}

    def law(lambda_bar, thickness):
        seen["l"] = thickness
        return np.full_like(lambda_bar, 2e-12)

    tr.volume_rate(4.0, c, m, law)
    assert seen["l"] == pytest.approx(c.thickness / m.inverse_thickness(c.vtilde(4.0)), rel=1e-6, abs=0)


# -- permeability laws ------------------------------------------------------------
def test_table3_presets_at_rest():
    # main text: P_w(1) = 1.99e-12 m^2/s for both materials (Table 2)
    assert perm.DoubleExponential.PDMS(1.0) == pytest.approx(1.99e-12, rel=0.005, abs=0)
    assert perm.DoubleExponential.PEO_PDMS(1.0) == pytest.approx(2.00e-12, rel=0.005, abs=0)
    expected = 2.07e-8 * math.exp(-9.79) + 1.13e-12 * math.exp(-0.31)
    assert perm.DoubleExponential.PDMS(1.0) == pytest.approx(expected, rel=1e-12, abs=0)
    lam = np.linspace(1, 4, 7)
    assert perm.DoubleExponential.PDMS(lam).shape == (7,)
    assert np.all(np.diff(perm.DoubleExponential.PDMS(lam)) < 0)


def test_firpo_law_and_paper_henry_values():
    law = perm.Firpo(p_henry=4e-12, critical_thickness=20e-6)
    assert law(1.0, thickness=20e-6) == pytest.approx(2e-12, rel=1e-6, abs=0)
    assert law(1.0, thickness=1e-3) == pytest.approx(4e-12 * 50 / 51, rel=1e-6, abs=0)
    with pytest.raises(ValueError, match="thickness"):
        law(1.0)
    # Fig. 6a caption: L_c = 10, 20, 40, 80, 200 um -> P_Henry = 3, 4, 6, 10, 22 x 1e-12
    henry = [perm.Firpo.through(1.99e-12, thickness=20e-6, critical_thickness=lc * 1e-6).p_henry * 1e12
             for lc in (10, 20, 40, 80, 200)]
    np.testing.assert_allclose(henry, [3, 4, 6, 10, 22], rtol=0.01)  # printed to 1-2 digits
    assert perm.accepts_thickness(law) and not perm.accepts_thickness(perm.DoubleExponential.PDMS)


def test_law_validation_and_evaluation():
    with pytest.raises(ValueError, match="p must be finite and > 0"):
        perm.Constant(-1e-12)
    with pytest.raises(ValueError, match="c2 must be finite"):
        perm.DoubleExponential(1e-12, math.nan, 1e-12, 0.0)
    np.testing.assert_array_equal(perm.evaluate_permeability(2e-12, np.ones(3)), np.full(3, 2e-12))
    with pytest.raises(ValueError, match="permeability must be finite and > 0"):
        perm.evaluate_permeability(lambda lam: -lam, np.ones(3))
    with pytest.raises(ValueError, match="vectorised"):
        perm.evaluate_permeability(lambda lam: np.ones(2), np.ones(3))


def test_lmfit_models_recover_table3_and_firpo():
    lam = np.linspace(1.0, 3.5, 40)
    truth = perm.DoubleExponential.PDMS
    model = perm.DoubleExponentialModel()
    pars = model.guess(truth(lam), lambda_bar=lam)
    assert pars["c1"].min == 0 and pars["c3"].min == 0
    rng = np.random.default_rng(3)
    data = truth(lam) * (1 + 0.01 * rng.standard_normal(lam.size))
    res = model.fit(data, pars, lambda_bar=lam, weights=1.0 / (0.01 * data))
    assert res.success and res.errorbars
    assert res.params["p_at_rest"].value == pytest.approx(truth(1.0), rel=0.02, abs=0)
    assert res.params["c2"].value == pytest.approx(-9.79, rel=0.1, abs=0)
    assert res.params["c4"].value == pytest.approx(-0.31, abs=0.05)
    assert np.sqrt(np.mean((res.best_fit / truth(lam) - 1) ** 2)) < 0.01  # the curve within the 1 % noise
    exact = model.make_params_from(2.07e-8, -9.79, 1.13e-12, -0.31)
    np.testing.assert_allclose(model.eval(exact, lambda_bar=lam), truth(lam), rtol=1e-12)
    thick = np.linspace(2e-6, 20e-6, 20)
    fl = perm.Firpo(4e-12, 20e-6)
    fm = perm.FirpoModel()
    res = fm.fit(fl(thickness=thick), fm.guess(fl(thickness=thick), thickness=thick), thickness=thick)
    assert res.params["p_henry"].value == pytest.approx(4e-12, rel=1e-6, abs=0)
    assert res.params["critical_thickness"].value == pytest.approx(20e-6, rel=1e-6, abs=0)
    cm = perm.ConstantPermeabilityModel()
    assert isinstance(cm, lmfit.Model)
    assert cm.guess(np.array([1e-12, 2e-12, 3e-12]))["p"].value == pytest.approx(2e-12, rel=1e-14, abs=0)


def test_errata_small_deflection_window_stretch():
    # Sec. 3.6.1 / supp. Sec. 7.1: "Vtilde < 0.165; V/V0 < 1.3 ... an approximate biaxial stretch of 1.4".
    # Both mechanics give lambda_bar = sqrt(A/A0) ~ 1.05 there; 1.4 is reached only at V/V0 ~ 1.9-2.2.
    c = tr.paper_chamber()
    hyper, lin = tr.mechanics_model(PDMS), tr.mechanics_model(PDMS, mechanics="linear")
    vt = c.vtilde(1.3)
    assert hyper.lambda_bar(vt) == pytest.approx(1.0498, rel=1e-3, abs=0)
    assert lin.lambda_bar(vt) == pytest.approx(math.sqrt(1 + 4 * 0.165**2), rel=1e-12, abs=0)
    from scipy.optimize import brentq

    vt14 = brentq(lambda x: hyper.lambda_bar(x) - 1.4, 0.01, 5.0)
    assert c.volume_ratio(vt14) == pytest.approx(2.174, rel=2e-3, abs=0)
    # Sec. 3.3: "Vtilde < 0.05 ... lambda_bar ~ 1.2": it is 1.005
    assert hyper.lambda_bar(0.05) == pytest.approx(1.005, rel=1e-3, abs=0)
