"""Constitutive laws: derivatives checked by finite differences of W."""

import numpy as np
import pytest

from osmobulge.modeling import materials as m

LAWS = [
    m.NeoHookean(c1=1.3e5),
    m.MooneyRivlin(c1=1.0e5, c2=0.4e5),
    m.Gent(c1=1.0e5, jm=30.0),
    m.GentGent(c1=0.0316e6, c2=0.0297e6, jm=26.0),
    m.PEO_PDMS,
]
STRETCHES = [(1.0, 1.0), (1.3, 0.9), (2.0, 1.5), (2.7, 2.6), (0.8, 1.7)]


def fd(f, x, h=1e-6):
    return (f(x + h) - f(x - h)) / (2 * h)


@pytest.mark.parametrize("law", LAWS, ids=lambda x: x.law)
@pytest.mark.parametrize(("l1", "l2"), STRETCHES)
def test_tensions_are_derivatives_of_w(law, l1, l2):
    t1, t2 = law.membrane_tensions(l1, l2)
    dw1 = fd(lambda x: law.strain_energy(x, l2), l1)
    dw2 = fd(lambda y: law.strain_energy(l1, y), l2)
    np.testing.assert_allclose(t1, dw1 / l2, rtol=1e-6, atol=1e-6 * law.stress_scale)
    np.testing.assert_allclose(t2, dw2 / l1, rtol=1e-6, atol=1e-6 * law.stress_scale)


@pytest.mark.parametrize("law", LAWS, ids=lambda x: x.law)
@pytest.mark.parametrize(("l1", "l2"), STRETCHES)
def test_tangent_matches_finite_differences(law, l1, l2):
    t1, t2, d11, d12 = law.membrane_tangent(l1, l2)
    s = law.stress_scale
    np.testing.assert_allclose(t1, law.membrane_tensions(l1, l2)[0] / s, rtol=1e-12)
    np.testing.assert_allclose(d11, fd(lambda x: law.membrane_tensions(x, l2)[0] / s, l1), rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(d12, fd(lambda y: law.membrane_tensions(l1, y)[0] / s, l2), rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("law", LAWS, ids=lambda x: x.law)
def test_reference_state_is_stress_free_and_energy_zero(law):
    assert law.strain_energy(1.0, 1.0) == pytest.approx(0.0, abs=1e-9)
    t1, t2 = law.membrane_tensions(1.0, 1.0)
    assert abs(t1) < 1e-9 * law.stress_scale and abs(t2) < 1e-9 * law.stress_scale


@pytest.mark.parametrize("law", LAWS, ids=lambda x: x.law)
def test_uniaxial_stress_is_derivative_of_w(law):
    lam = np.array([1.05, 1.5, 2.2])
    w = lambda x: law.strain_energy(x, x**-0.5)  # noqa: E731
    np.testing.assert_allclose(law.uniaxial_stress(lam), fd(w, lam), rtol=1e-6)


@pytest.mark.parametrize("law", LAWS, ids=lambda x: x.law)
def test_small_strain_moduli(law):
    # uniaxial slope at lambda=1 is Young's modulus 3 mu; equibiaxial membrane tension slope is 6 mu
    eps = 1e-6
    e_uni = (law.uniaxial_stress(1 + eps) - law.uniaxial_stress(1 - eps)) / (2 * eps)
    assert e_uni == pytest.approx(law.youngs_modulus, rel=1e-6, abs=0)
    t_eq = fd(lambda x: law.equibiaxial_tension(x), 1.0)
    assert t_eq == pytest.approx(6 * law.shear_modulus, rel=1e-6, abs=0)


def test_gent_gent_shear_modulus_is_not_the_papers_eqn_60():
    # W2 = C2 / I2 = C2/3 at rest -> mu = 2 C1 + 2 C2/3 (errata E4), not 2 (C1 + C2)
    law = m.PDMS
    assert law.shear_modulus == pytest.approx(2 * 0.0316e6 + 2 * 0.0297e6 / 3)
    assert law.youngs_modulus == pytest.approx(0.249e6, rel=1e-3, abs=0)
    # the preset keeps the paper's E = 0.37 MPa = 6 (C1 + C2) as nondimensionalising modulus
    assert law.E == 0.37e6
    assert 6 * (law.c1 + law.c2) == pytest.approx(law.E, rel=6e-3, abs=0)
    assert m.PEO_PDMS.E == 0.75e6


def test_gent_locks_at_jm():
    law = m.Gent(c1=1e5, jm=10.0)
    lam = law.locking_stretch
    assert 2 * lam**2 + lam**-4 - 3 == pytest.approx(10.0)
    assert np.isfinite(law.strain_energy(lam * 0.999, lam * 0.999))
    assert np.isnan(law.strain_energy(lam * 1.001, lam * 1.001))


@pytest.mark.parametrize(
    ("factory", "kwargs", "match"),
    [
        (m.NeoHookean, {"c1": -1.0}, "'c1' must be > 0"),
        (m.NeoHookean, {"c1": 0.0}, "'c1' must be > 0"),
        (m.NeoHookean, {"c1": float("nan")}, "'c1' must be finite"),
        (m.Gent, {"c1": 1.0, "jm": 0.0}, "'jm'"),
        (m.Gent, {"c1": 1.0, "jm": -3.0}, "'jm'"),
        (m.GentGent, {"c1": 1.0, "c2": float("inf"), "jm": 3.0}, "'c2' must be finite"),
        (m.MooneyRivlin, {"c1": 1.0, "c2": -1.0}, "'c2' must be > 0"),
        (m.LinearElastic, {"E": -1.0}, "'E' must be > 0"),
    ],
)
def test_bad_constants_are_clear_errors(factory, kwargs, match):
    with pytest.raises(ValueError, match=match):
        factory(**kwargs)


def test_constant_type_error():
    with pytest.raises(TypeError, match="c1"):
        m.NeoHookean(c1="soft")


def test_presets_by_name():
    assert m.get_material("pdms") is m.PDMS
    assert m.get_material("PEO-PDMS") is m.PEO_PDMS
    with pytest.raises(ValueError, match="unknown material preset"):
        m.get_material("rubber")
