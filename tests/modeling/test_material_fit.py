"""Tests of osmobulge.modeling.material_fit: Gent constants from uniaxial data and bulge profiles."""

import json
import math

import numpy as np
import pytest

from osmobulge.modeling import bulge_profile
from osmobulge.modeling.material_fit import (
    BulgeProfilePoints,
    MaterialFitError,
    _model_meridians,
    fit_material,
    paper_modulus,
    profile_distances,
)
from osmobulge.modeling.materials import PDMS, PEO_PDMS, Gent, GentGent, MooneyRivlin, NeoHookean

A = 200e-6  # chamber radius, m


def _uniaxial(material, lam, rel_noise, rng):
    stress = material.uniaxial_stress(lam)
    sigma = rel_noise * float(np.max(stress))
    return stress + rng.normal(0.0, sigma, lam.size), sigma


def _picked(material, vtildes, rng, *, k=20, noise=0.003, radius=A):
    """Points picked on the public bulge_profile with Gaussian noise (fraction of a) in r and z."""
    out = []
    for v in vtildes:
        prof = bulge_profile(material, v, n=401)
        idx = np.sort(rng.choice(401, k, replace=False))
        r = prof.r.values[idx] * radius + rng.normal(0.0, noise * radius, k)
        z = prof.z.values[idx] * radius + rng.normal(0.0, noise * radius, k)
        # pick half of the points on the left half of the dome (negative r)
        r[::2] *= -1.0
        out.append(BulgeProfilePoints(r=r, z=z, radius=radius, vtilde=v, label=f"Vtilde={v:g}"))
    return out


# --------------------------------------------------------------------------- geometry helpers


def test_profile_distances_on_a_quarter_circle():
    t = np.linspace(0.0, np.pi / 2, 2001)
    curve = np.column_stack([np.sin(t), np.cos(t)])  # pole (0, 1) -> rim (1, 0)
    pts = np.array([[0.0, 1.2], [0.6, 0.0], [np.sqrt(0.5) * 1.1, np.sqrt(0.5) * 1.1], [1.5, 0.0]])
    d = profile_distances(pts, curve)
    np.testing.assert_allclose(d[:3], [0.2, -0.4, 0.1], atol=1e-6)
    assert d[3] == pytest.approx(0.5, abs=1e-9)  # beyond the rim: distance to the end point, outside


def test_vectorised_meridians_match_bulge_profile():
    vts = np.array([0.7, 2.5, 5.0])
    curves = _model_meridians(PDMS, vts, np.ones(3))
    for v, c in zip(vts, curves, strict=True):
        prof = bulge_profile(PDMS, float(v), n=301)
        d = profile_distances(np.column_stack([prof.r.values, prof.z.values]), c)
        assert np.max(np.abs(d)) < 2e-4  # chords of the RK4 mesh vs the Hermite-interpolated profile
        assert c[0, 1] == pytest.approx(prof.attrs["bulge_height"], rel=1e-9, abs=0)
        np.testing.assert_allclose(c[-1], [1.0, 0.0], atol=1e-12)


def test_paper_modulus_is_six_c1_plus_c2():
    # supplement Table 1: E = 0.37 and 0.75 MPa; the true 3 mu of the Gent 3-parameter law is 6 C1 + 2 C2
    assert paper_modulus(PDMS) == pytest.approx(0.37e6, rel=0.01, abs=0)
    assert paper_modulus(PEO_PDMS) == pytest.approx(0.75e6, rel=0.01, abs=0)
    assert PDMS.youngs_modulus == pytest.approx(6 * PDMS.c1 + 2 * PDMS.c2, rel=1e-12, abs=0)
    assert paper_modulus(MooneyRivlin(1e4, 2e4)) == pytest.approx(MooneyRivlin(1e4, 2e4).youngs_modulus)


# --------------------------------------------------------------------------- uniaxial only


@pytest.mark.parametrize(
    "truth",
    [NeoHookean(5e4), MooneyRivlin(3e4, 1e4), Gent(3e4, 20.0), GentGent(3e4, 2.5e4, 15.0)],
    ids=lambda m: m.law,
)
def test_noise_free_uniaxial_data_to_large_stretch_recover_each_law(truth):
    lam = np.linspace(1.05, 3.5, 30)
    fit = fit_material(truth.law, stretch=lam, stress=truth.uniaxial_stress(lam))
    for k, v in truth.constants.items():
        assert fit.params[k] == pytest.approx(v, rel=1e-5, abs=0), k
    assert fit.youngs_modulus == pytest.approx(truth.youngs_modulus, rel=1e-5, abs=0)
    assert fit.success


def test_jm_stays_above_the_locking_of_the_data():
    lam = np.linspace(1.1, 4.0, 20)
    truth = Gent(3e4, 14.5)  # J1(4) = 13.5: close to locking
    rng = np.random.default_rng(3)
    stress, sigma = _uniaxial(truth, lam, 0.01, rng)
    fit = fit_material("gent", stretch=lam, stress=stress, stress_sigma=sigma)
    j1max = 4.0**2 + 2 / 4.0 - 3.0
    assert fit.params["jm"] > j1max
    assert fit.jm_lower_bound == pytest.approx(j1max, rel=1e-5, abs=0)
    assert fit.params["jm"] == pytest.approx(14.5, abs=3 * fit.stderr["jm"] + 1e-6)


# --------------------------------------------------------------------------- joint fits (slow: solve profiles)


@pytest.fixture(scope="module")
def pdms_data():
    rng = np.random.default_rng(2024)
    lam = np.linspace(1.02, 1.6, 25)  # small-stretch tension test: J1 <= 0.81, Jm = 26
    stress, sigma = _uniaxial(PDMS, lam, 0.01, rng)
    profiles = _picked(PDMS, [1.0, 3.0, 5.0], rng)
    return lam, stress, sigma, profiles


@pytest.fixture(scope="module")
def pdms_fits(pdms_data):
    lam, stress, sigma, profiles = pdms_data
    uni = fit_material("gent-gent", stretch=lam, stress=stress, stress_sigma=sigma, weights="given")
    joint = fit_material("gent-gent", stretch=lam, stress=stress, profiles=profiles, stress_sigma=sigma,
                         profile_sigma=0.003 * A, weights="given")
    return uni, joint


@pytest.mark.slow
def test_joint_fit_recovers_pdms_constants(pdms_fits):
    _, fit = pdms_fits
    truth = PDMS.constants
    for k, tol in (("c1", 0.05), ("c2", 0.15), ("jm", 0.05)):
        assert fit.params[k] == pytest.approx(truth[k], rel=tol, abs=0), k
        assert abs(fit.params[k] - truth[k]) < 3.5 * fit.stderr[k], k
    assert fit.paper_modulus == pytest.approx(paper_modulus(PDMS), rel=0.05, abs=0)
    assert fit.youngs_modulus == pytest.approx(PDMS.youngs_modulus, rel=0.03, abs=0)
    # picked-point noise 0.003 a per coordinate -> rms normal distance ~0.6 um
    rms = math.sqrt(np.mean(np.concatenate(fit.profile_residuals) ** 2))
    assert 0.4e-6 < rms < 0.8e-6
    assert 0.6 < fit.redchi < 1.5


@pytest.mark.slow
def test_joint_fit_constrains_jm_far_better_than_small_stretch_tension(pdms_fits):
    uni, joint = pdms_fits
    # small-stretch uniaxial data barely see the locking: Jm is ill-conditioned (correlated with C1, C2)
    assert uni.stderr["jm"] > 0.5 * uni.params["jm"]
    assert abs(uni.correlations["c1:jm"]) > 0.9
    assert joint.stderr["jm"] < 0.05 * uni.stderr["jm"]
    assert joint.stderr["c2"] < 0.5 * uni.stderr["c2"]


@pytest.mark.slow
def test_material_fit_outputs_are_complete(pdms_fits):
    _, fit = pdms_fits
    s = fit.summary()
    json.dumps(s)  # JSON-safe
    assert s["law"] == "gent-gent" and s["n_profiles"] == 3 and s["n_profile_points"] == 60
    assert s["params"]["jm"] == fit.params["jm"]
    text = fit.report()
    assert "6 (C1 + C2)" in text and "3 mu" in text and "Vtilde = 3" in text
    ds = fit.to_dataset()
    assert list(ds.param.values) == ["c1", "c2", "jm"]
    np.testing.assert_allclose(ds.modelfit_coefficients.values, [fit.params[k] for k in ("c1", "c2", "jm")])
    assert ds.point_distance.attrs["units"] == "m" and ds.sizes["point"] == 60
    assert isinstance(fit.material, GentGent)


@pytest.mark.slow
def test_joint_fit_peo_pdms_with_automatic_weights():
    rng = np.random.default_rng(7)
    lam = np.linspace(1.02, 1.8, 20)
    stress, _ = _uniaxial(PEO_PDMS, lam, 0.01, rng)
    # bulge volumes given as measured volumes (m^3) rather than Vtilde
    profiles = [
        BulgeProfilePoints(r=p.r, z=p.z, radius=p.radius, volume=p.vtilde * math.pi * A**3)
        for p in _picked(PEO_PDMS, [2.0, 6.0, 10.0], rng, noise=0.002)
    ]
    fit = fit_material(PEO_PDMS, stretch=lam, stress=stress, profiles=profiles)  # starts from Table 1 values
    truth = PEO_PDMS.constants
    for k, tol in (("c1", 0.05), ("c2", 0.15), ("jm", 0.05)):
        assert fit.params[k] == pytest.approx(truth[k], rel=tol, abs=0), k
    # the automatic weights recover the noise levels: 1 % of the largest stress, 0.002 a * (normal component)
    assert fit.stress_sigma == pytest.approx(0.01 * PEO_PDMS.uniaxial_stress(1.8), rel=0.4, abs=0)
    assert fit.profile_sigma == pytest.approx(0.002 * A, rel=0.3, abs=0)
    assert fit.redchi == pytest.approx(1.0, rel=0.05, abs=0)


# --------------------------------------------------------------------------- bad input


def test_bad_uniaxial_input_is_rejected():
    lam = np.linspace(1.1, 2.0, 5)
    s = PDMS.uniaxial_stress(lam)
    with pytest.raises(ValueError, match="same length"):
        fit_material("gent-gent", stretch=lam, stress=s[:-1])
    with pytest.raises(ValueError, match="stretch must be > 0"):
        fit_material("gent-gent", stretch=np.r_[0.0, lam[1:]], stress=s)
    with pytest.raises(ValueError, match="stress must be finite"):
        fit_material("gent-gent", stretch=lam, stress=np.r_[s[:-1], np.nan])
    with pytest.raises(ValueError, match="stretch must be finite"):
        fit_material("gent-gent", stretch=np.r_[lam[:-1], np.inf], stress=s)
    with pytest.raises(ValueError, match="uniaxial data"):
        fit_material("gent-gent", profiles=[])
    with pytest.raises(ValueError, match="law must be one of"):
        fit_material("ogden", stretch=lam, stress=s)
    with pytest.raises(ValueError, match="weights must be one of"):
        fit_material("gent", stretch=lam, stress=s, weights="robust")
    with pytest.raises(ValueError, match="cannot determine"):
        fit_material("gent-gent", stretch=lam[:3], stress=s[:3])
    with pytest.raises(ValueError, match="not in gent"):
        fit_material("gent", stretch=lam, stress=s, initial={"c2": 1.0})
    with pytest.raises(ValueError, match="stress_sigma"):
        fit_material("gent", stretch=lam, stress=s, stress_sigma=-1.0)
    with pytest.raises(TypeError, match="BulgeProfilePoints"):
        fit_material("gent", stretch=lam, stress=s, profiles=[(1, 2)])


def test_bad_profile_points_are_rejected():
    r = np.array([0.0, 50e-6, 100e-6])
    z = np.array([150e-6, 130e-6, 90e-6])
    with pytest.raises(ValueError, match="same length"):
        BulgeProfilePoints(r=r, z=z[:2], radius=A, vtilde=1.0)
    with pytest.raises(ValueError, match="in metres"):
        BulgeProfilePoints(r=r * 1e6, z=z * 1e6, radius=200.0, vtilde=1.0)
    with pytest.raises(ValueError, match="must be in metres"):
        BulgeProfilePoints(r=r * 1e6, z=z * 1e6, radius=A, vtilde=1.0)
    with pytest.raises(ValueError, match="exactly one"):
        BulgeProfilePoints(r=r, z=z, radius=A)
    with pytest.raises(ValueError, match="exactly one"):
        BulgeProfilePoints(r=r, z=z, radius=A, vtilde=1.0, volume=1e-11)
    with pytest.raises(ValueError, match="z must be finite"):
        BulgeProfilePoints(r=r, z=np.r_[z[:2], np.nan], radius=A, vtilde=1.0)
    with pytest.raises(ValueError, match="vtilde must be finite and > 0"):
        BulgeProfilePoints(r=r, z=z, radius=A, vtilde=-1.0)
    p = BulgeProfilePoints(r=r, z=z, radius=A, volume=math.pi * A**3)
    assert p.vtilde == pytest.approx(1.0)


def test_a_fit_that_does_not_converge_raises():
    lam = np.linspace(1.05, 2.5, 15)
    stress = PDMS.uniaxial_stress(lam)
    with pytest.raises(MaterialFitError, match="did not converge"):
        fit_material("gent-gent", stretch=lam, stress=stress, max_nfev=2)
