"""Permeability fits through the flux ODE: round trips on synthetic data with known truth."""

import json
import math

import lmfit
import numpy as np
import pytest

from osmobulge.modeling import fitting
from osmobulge.modeling.fitting import FitError, fit_permeability, register_model
from osmobulge.modeling.materials import PDMS, PEO_PDMS
from osmobulge.modeling.permeability import DoubleExponential, Firpo
from osmobulge.modeling.simulate import simulate
from osmobulge.modeling.transport import PAPER_CHAMBERS, mechanics_model, paper_chamber

T = np.arange(0.0, 24 * 3600 + 1, 900.0)  # every 15 min for 24 h
NOISE = 0.01


@pytest.fixture(scope="module")
def pdms_truth():
    """Noiseless V/V0(t) of the paper's four PDMS chambers with the Table 3 law."""
    return [simulate(paper_chamber(n), PDMS, DoubleExponential.PDMS, T) for n in PAPER_CHAMBERS]


@pytest.fixture(scope="module")
def peo_truth():
    return [simulate(paper_chamber(), PEO_PDMS, DoubleExponential.PEO_PDMS, T)]


def noisy(truth, seed):
    rng = np.random.default_rng(seed)
    return [(paper_chamber_of(ds), ds.time.values, ds.volume_ratio.values * (1 + NOISE * rng.standard_normal(T.size)))
            for ds in truth]


def paper_chamber_of(ds):
    from osmobulge.modeling.transport import Chamber

    return Chamber.from_attrs(ds.attrs)


def curve_error(fit, truth):
    """RMS relative deviation of the fitted curves from the noiseless truth."""
    dev = np.concatenate([o.fitted / ds.volume_ratio.values - 1 for o, ds in zip(fit.observations, truth, strict=True)])
    return float(np.sqrt(np.mean(dev**2)))


# -- the round trip of issue 3 ---------------------------------------------------------
@pytest.mark.parametrize(("truth_name", "material", "law"), [
    ("pdms_truth", PDMS, DoubleExponential.PDMS),
    ("peo_truth", PEO_PDMS, DoubleExponential.PEO_PDMS),
])
def test_double_exponential_round_trip(request, truth_name, material, law):
    truth = request.getfixturevalue(truth_name)
    fit = fit_permeability(noisy(truth, seed=0), material, model="double_exponential")
    assert fit.success and fit
    assert fit.p_at_rest == pytest.approx(law(1.0), rel=0.03, abs=0)
    assert abs(fit.p_at_rest - law(1.0)) < 3 * fit.p_at_rest_stderr
    # the fitted curves sit inside the 1 % noise, and the residuals are the noise
    assert curve_error(fit, truth) < 0.3 * NOISE
    assert math.sqrt(fit.redchi) == pytest.approx(NOISE, rel=0.2, abs=0)
    # the whole law, over the stretches the data span
    lam = np.linspace(1.0, 3.0, 9)
    np.testing.assert_allclose(fit.permeability(lam), law(lam), rtol=0.1)
    assert fit.params["c2"] < fit.params["c4"] < 0


@pytest.mark.slow
def test_reported_uncertainty_covers_truth(pdms_truth):
    truth = DoubleExponential.PDMS(1.0)
    inside1 = inside2 = within3 = 0
    for seed in range(20):
        fit = fit_permeability(noisy(pdms_truth, seed=100 + seed), PDMS, model="double_exponential")
        z = abs(fit.p_at_rest - truth) / fit.p_at_rest_stderr
        inside1 += z <= 1
        inside2 += z <= 2
        within3 += abs(fit.p_at_rest / truth - 1) <= 0.03
    # nominal 68 % and 95 %: demand at least 10/20 and 17/20 (measured: 12 and 19)
    assert inside1 >= 10, inside1
    assert inside2 >= 17, inside2
    # the standard error is ~1.1 % of P_w(1), so 3 % is ~2.6 sigma: nearly all seeds
    assert within3 >= 18, within3


def test_constant_fits_on_table3_data_follow_the_paper_pattern(pdms_truth):
    data = noisy(pdms_truth, seed=1)
    linear = fit_permeability(data, PDMS, mechanics="linear", window={"volume_ratio_max": 1.3})
    hyper = fit_permeability(data, PDMS)
    # the small-deflection linear fit sees the unstretched membrane ...
    assert linear.params["p"] == pytest.approx(DoubleExponential.PDMS(1.0), rel=0.1, abs=0)
    assert all(np.all(o.volume_ratio <= 1.3) for o in linear.observations)
    # ... the all-data hyperelastic constant fit a much lower average (paper: 58 % lower)
    assert 0.3 < hyper.params["p"] / linear.params["p"] < 0.6
    # and a constant cannot follow the curves within the noise
    assert math.sqrt(hyper.redchi) > 5 * NOISE


def test_constant_round_trip_exact_on_noiseless_data():
    c = paper_chamber("small_radius")
    t = np.linspace(0, 6 * 3600, 25)
    for mech in ("linear", "hyperelastic"):
        ds = simulate(c, PDMS, 1.3e-12, t, mechanics=mech)
        fit = fit_permeability([ds], PDMS, mechanics=mech, n_grid=1201)
        assert fit.params["p"] == pytest.approx(1.3e-12, rel=1e-6, abs=0)


def test_firpo_round_trip():
    law = Firpo.through(1.99e-12, thickness=20e-6, critical_thickness=10e-6)
    truth = [simulate(paper_chamber(n), PDMS, law, T) for n in ("reference", "small_radius", "low_concentration")]
    fit = fit_permeability(noisy(truth, seed=2), PDMS, model="firpo")
    assert fit.p_at_rest == pytest.approx(1.99e-12, rel=0.03, abs=0)
    assert fit.params["critical_thickness"] == pytest.approx(10e-6, rel=0.2, abs=0)
    assert curve_error(fit, truth) < 0.3 * NOISE
    with pytest.raises(ValueError, match="thickness"):
        fit.permeability(1.0)
    assert fit.permeability(1.0, thickness=20e-6) == pytest.approx(fit.p_at_rest, rel=1e-6, abs=0)


# -- results -------------------------------------------------------------------------
def test_result_report_summary_dataset(pdms_truth):
    fit = fit_permeability(noisy(pdms_truth, seed=3), PDMS, model="double_exponential")
    text = fit.report()
    for part in ("[[Fit Statistics]]", "[[Variables]]", "p_at_rest", "P_w(lambda_bar=1)", "a=100 um"):
        assert part in text
    summ = fit.summary()
    json.dumps(summ, allow_nan=False)
    assert summ["params"]["p_at_rest"]["value"] == pytest.approx(fit.p_at_rest, rel=1e-6, abs=0)
    assert len(summ["chambers"]) == 4 and summ["chambers"][1]["chamber_radius"] == 100e-6
    ds = fit.to_dataset()
    assert ds.sizes["point"] == 4 * T.size and ds.sizes["chamber"] == 4
    np.testing.assert_allclose(ds.residual, ds.fitted - ds.volume_ratio)
    assert float(ds.modelfit_coefficients.sel(param="c4")) == fit.params["c4"]
    assert isinstance(ds.to_netcdf(engine="scipy"), bytes | memoryview)
    # covariance-based intervals: best +- 1.96... sigma, ordered
    lo2, lo1, best, hi1, hi2 = (v for _, v in fit.ci["p_at_rest"])
    assert lo2 < lo1 < best < hi1 < hi2
    assert hi1 - best == pytest.approx(fit.stderr["p_at_rest"], rel=1e-9, abs=0)
    # the stretch-law uncertainty by the delta method agrees with lmfit's propagation at rest
    assert fit.permeability_stderr(1.0) == pytest.approx(fit.stderr["p_at_rest"], rel=1e-3, abs=0)
    # fitted curve at arbitrary times matches the stored one
    np.testing.assert_allclose(fit.curve(0, T), fit.observations[0].fitted, rtol=1e-12)


def test_profile_confidence_intervals_bracket_covariance_ones():
    c = paper_chamber()
    rng = np.random.default_rng(5)
    ds = simulate(c, PDMS, 1.5e-12, T[:40])
    v = ds.volume_ratio.values * (1 + NOISE * rng.standard_normal(40))
    cov = fit_permeability([(c, T[:40], v)], PDMS)
    prof = fit_permeability([(c, T[:40], v)], PDMS, ci_method="profile")
    lo_c, hi_c = cov.ci["ln_p"][1][1], cov.ci["ln_p"][3][1]
    lo_p, hi_p = prof.ci["ln_p"][1][1], prof.ci["ln_p"][3][1]
    assert lo_p == pytest.approx(lo_c, abs=0.1 * (hi_c - lo_c))
    assert hi_p == pytest.approx(hi_c, abs=0.1 * (hi_c - lo_c))


# -- failures are loud -------------------------------------------------------------------
def test_non_convergence_raises_or_flags(pdms_truth):
    data = noisy(pdms_truth, seed=4)
    with pytest.raises(FitError, match="did not converge"):
        fit_permeability(data, PDMS, model="double_exponential", max_nfev=3)
    flagged = fit_permeability(data, PDMS, model="double_exponential", max_nfev=3, errors="flag")
    assert not flagged and flagged.success is False
    assert all(math.isnan(v) for v in flagged.params.values())
    assert math.isnan(flagged.permeability(1.0)) and math.isnan(flagged.p_at_rest)
    assert np.all(np.isnan(flagged.observations[0].fitted))
    json.dumps(flagged.summary(), allow_nan=False)


def test_unidentifiable_parameter_raises():
    def law(lambda_bar, p, useless):
        return p + 0.0 * useless * lambda_bar

    model = lmfit.Model(law, independent_vars=["lambda_bar"])
    model.set_param_hint("p", value=1e-12, min=0)
    model.set_param_hint("useless", value=1.0)
    c = paper_chamber()
    ds = simulate(c, PDMS, 1e-12, T[:30])
    with pytest.raises(FitError, match="covariance could not be estimated"):
        fit_permeability([ds], PDMS, model=model)


# -- data handling -------------------------------------------------------------------------
def test_nan_and_non_monotone_times():
    c = paper_chamber()
    t = T[:30].copy()
    v = simulate(c, PDMS, 2e-12, t).volume_ratio.values.copy()
    v_nan = v.copy()
    v_nan[5] = np.nan
    with pytest.raises(ValueError, match="NaN.*nan_policy='omit'"):
        fit_permeability([(c, t, v_nan)], PDMS)
    fit = fit_permeability([(c, t, v_nan)], PDMS, nan_policy="omit", n_grid=1201)
    assert fit.observations[0].n_dropped == 1 and fit.ndata == 29
    assert fit.params["p"] == pytest.approx(2e-12, rel=1e-6, abs=0)
    t_bad = t.copy()
    t_bad[10] = t_bad[8]
    with pytest.raises(ValueError, match=r"strictly increasing; t\[10\]"):
        fit_permeability([(c, t_bad, v)], PDMS)
    assert fit_permeability([(c, t_bad, v)], PDMS, nan_policy="omit").observations[0].n_dropped == 1
    with pytest.raises(ValueError, match=">= 0 s"):
        fit_permeability([(c, t - 100.0, v)], PDMS)


def test_dataset_observations_and_attrs():
    ds = simulate(paper_chamber(), PDMS, 2e-12, T[:20])
    bare = ds.copy()
    bare.attrs = {k: v for k, v in ds.attrs.items() if k != "chamber_depth"}
    with pytest.raises(ValueError, match="chamber_depth"):
        fit_permeability([bare], PDMS)
    hours = ds.assign_coords(time=("time", ds.time.values / 3600, {"units": "h"}))
    with pytest.raises(ValueError, match="time must be in s"):
        fit_permeability([hours], PDMS)
    with pytest.raises(TypeError, match="first item must be a Chamber"):
        fit_permeability([("ref", T, T)], PDMS)


def test_windows_select_points():
    c = paper_chamber()
    ds = simulate(c, PDMS, DoubleExponential.PDMS, T)
    mech = mechanics_model(PDMS)
    fit = fit_permeability([ds], PDMS, window={"lambda_bar_max": 1.4})
    used = fit.observations[0].volume_ratio
    lam_all = np.asarray(mech.lambda_bar(c.vtilde(ds.volume_ratio.values)))
    assert used.size == int(np.sum(lam_all <= 1.4)) > 3
    fit_t = fit_permeability([ds], PDMS, window={"time_max": 7200.0})
    assert fit_t.observations[0].time.max() == 7200.0
    with pytest.raises(ValueError, match="no data left"):
        fit_permeability([ds], PDMS, window={"volume_ratio_max": 0.5})


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"mechanics": "fem"}, "mechanics must be one of"),
    ({"nan_policy": "drop"}, "nan_policy must be one of"),
    ({"error_model": "poisson"}, "error_model must be one of"),
    ({"ci_method": "bootstrap"}, "ci_method must be one of"),
    ({"errors": "ignore"}, "errors must be one of"),
    ({"window": {"volume_max": 2}}, "window keys must be among"),
    ({"window": {"volume_ratio_max": -1}}, "must be finite and > 0"),
    ({"model": "triple_exponential"}, "model must be one of"),
    ({"weights": [np.ones(3)]}, "weights"),
])
def test_option_validation(kwargs, match):
    ds = simulate(paper_chamber(), PDMS, 2e-12, T[:20])
    with pytest.raises(ValueError, match=match):
        fit_permeability([ds], PDMS, **kwargs)


def test_registered_family_round_trip():
    def single_exponential(lambda_bar, p0, k):
        return p0 * np.exp(k * (lambda_bar - 1.0))

    model = lmfit.Model(single_exponential, independent_vars=["lambda_bar"])
    model.set_param_hint("ln_p0", value=math.log(1e-12))
    model.set_param_hint("p0", expr="exp(ln_p0)", min=0)
    model.set_param_hint("k", value=0.0)
    register_model("single_exponential_test", model, overwrite=True)
    assert "single_exponential_test" in fitting.registered_models()
    with pytest.raises(ValueError, match="already registered"):
        register_model("single_exponential_test", model)
    with pytest.raises(ValueError, match="built-in"):
        register_model("constant", model)
    with pytest.raises(ValueError, match="independent variables"):
        register_model("bad", lmfit.Model(lambda x, a: a * x))

    def law(lam):
        return single_exponential(lam, 2e-12, -0.8)

    truth = [simulate(paper_chamber(n), PDMS, law, T) for n in ("reference", "small_radius")]
    fit = fit_permeability(noisy(truth, seed=6), PDMS, model="single_exponential_test")
    assert fit.params["p0"] == pytest.approx(2e-12, rel=0.03, abs=0)
    assert fit.params["k"] == pytest.approx(-0.8, abs=0.05)
