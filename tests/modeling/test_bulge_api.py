"""Public API contract of osmobulge.modeling.bulge: validation, Dataset layout, closed forms.

The solver's physics (analytic limits, second method, paper values) is tested elsewhere;
here every validation branch gets one ``pytest.raises(..., match=...)`` and the returned
Datasets are checked against independent truths: the flat membrane, the linear-elastic
closed forms (main text Eqns 11-13, Eqn 12 corrected), hand unit conversions with the
supplement Table 1 constants, and integrals of the profile's own fields.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr
from scipy.integrate import simpson

from osmobulge.modeling import (
    NoSolutionError,
    PreStretch,
    bulge_mechanics,
    bulge_profile,
    locking_volume,
    mechanics_table,
    turgor_ratio,
)
from osmobulge.modeling.materials import PDMS, PEO_PDMS, LinearElastic, NeoHookean

MECHANICS_VARS = (
    "area_ratio",
    "inverse_thickness",
    "pressure",
    "lambda_bar",
    "mean_stretch",
    "pole_thickness_ratio",
    "pole_stretch",
    "bulge_height",
    "lambda_pre",
)
PROFILE_VARS = ("r", "z", "lambda_xi", "lambda_phi", "thickness_ratio", "alpha")
NETCDF_ATTR_TYPES = (str, int, float, np.integer, np.floating, np.ndarray, list, tuple, bytes)


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("vtilde", "match"),
    [
        ([-0.1, 1.0], r"vtilde must be >= 0"),
        ([0.5, np.nan], r"vtilde must be finite"),
        ([0.5, np.inf], r"vtilde must be finite"),
        ([[0.5, 1.0], [1.5, 2.0]], r"vtilde must be a scalar or 1-D array, got shape \(2, 2\)"),
        ([1.0, 0.5], r"vtilde must be strictly increasing"),
        ([0.5, 0.5], r"vtilde must be strictly increasing"),
    ],
)
def test_bulge_mechanics_rejects_bad_vtilde(vtilde, match):
    with pytest.raises(ValueError, match=match):
        bulge_mechanics(PDMS, vtilde)


@pytest.mark.parametrize(("material", "limit"), [(PDMS, r"7\.2\d*"), (PEO_PDMS, r"13\.8\d*")])
def test_vtilde_beyond_locking_names_the_limit(material, limit):
    vlock = locking_volume(material)
    with pytest.raises(NoSolutionError, match=rf"locking limit vtilde_lock={limit}"):
        bulge_mechanics(material, [0.5, vlock * 1.01])
    # exactly at the limit there is no solution either (the pressure diverges)
    with pytest.raises(NoSolutionError, match=limit):
        bulge_mechanics(material, [vlock])
    assert issubclass(NoSolutionError, ValueError)


def test_bulge_profile_beyond_locking_names_the_limit():
    with pytest.raises(NoSolutionError, match=r"7\.2"):
        bulge_profile(PDMS, 7.5)


@pytest.mark.parametrize(
    ("lambda_pre", "exc", "match"),
    [
        (0.99, ValueError, r"lambda_pre must be >= 1 \(rim pre-stretch\), got min 0\.99"),
        (np.nan, ValueError, r"lambda_pre must be finite"),
        (np.inf, ValueError, r"lambda_pre must be finite"),
        ("stretchy", TypeError, r"lambda_pre must be a number >= 1 or a callable of vtilde, got 'stretchy'"),
        (None, TypeError, r"lambda_pre must be a number >= 1 or a callable"),
        (lambda v: 1.0 - 0.1 * np.asarray(v), ValueError, r"lambda_pre\(vtilde\) must be >= 1"),
        (lambda v: np.full(np.shape(v), np.nan), ValueError, r"lambda_pre\(vtilde\) must be finite"),
    ],
)
def test_bulge_mechanics_rejects_bad_lambda_pre(lambda_pre, exc, match):
    with pytest.raises(exc, match=match):
        bulge_mechanics(PDMS, [0.5, 1.0], lambda_pre=lambda_pre)


def test_bulge_profile_rejects_bad_lambda_pre():
    with pytest.raises(ValueError, match=r"lambda_pre must be >= 1"):
        bulge_profile(PDMS, 1.0, lambda_pre=0.9)


def test_bulge_profile_rejects_linear_elastic():
    with pytest.raises(TypeError, match=r"bulge_profile needs a hyperelastic law"):
        bulge_profile(LinearElastic(1e6), 1.0)


@pytest.mark.parametrize("n", [2, 0, -5])
def test_bulge_profile_rejects_small_n(n):
    with pytest.raises(ValueError, match=rf"n must be >= 3, got {n}"):
        bulge_profile(PDMS, 1.0, n=n)


@pytest.mark.parametrize("vtilde", [0.0, -1.0, [0.5, 1.0]])
def test_bulge_profile_needs_one_positive_volume(vtilde):
    with pytest.raises(ValueError, match=r"vtilde must be (a single positive number|>= 0)"):
        bulge_profile(PDMS, vtilde)


@pytest.mark.parametrize("bad", ["PDMS", 0.37e6, None, {"c1": 1.0}])
@pytest.mark.parametrize(
    "call",
    [
        lambda m: bulge_mechanics(m, [1.0]),
        lambda m: bulge_profile(m, 1.0),
        lambda m: locking_volume(m),
        lambda m: mechanics_table(m, cache=False),
    ],
    ids=["bulge_mechanics", "bulge_profile", "locking_volume", "mechanics_table"],
)
def test_wrong_material_type(call, bad):
    with pytest.raises(TypeError, match=r"material must be an osmobulge\.modeling\.materials law"):
        call(bad)


@pytest.mark.parametrize("ratio", [0.0, -0.1, np.nan, np.inf])
def test_turgor_ratio_rejects_bad_thickness_over_radius(ratio):
    with pytest.raises(ValueError, match=r"thickness_over_radius \(l0/a\) must be finite and > 0"):
        turgor_ratio([1.0], PDMS, ratio)


# --------------------------------------------------------------------------- Dataset layout


def _assert_annotated(ds: xr.Dataset):
    for name, var in ds.variables.items():
        assert isinstance(var.attrs.get("units"), str), f"{name} has no units"
        assert isinstance(var.attrs.get("long_name"), str) and var.attrs["long_name"], f"{name} has no long_name"
    for obj in [ds, *ds.variables.values()]:
        for key, value in obj.attrs.items():
            assert isinstance(value, NETCDF_ATTR_TYPES), f"attr {key!r}={value!r} is not netCDF-safe"


def test_bulge_mechanics_dataset_layout():
    v = np.array([0.0, 0.25, 1.0, 3.0])
    ds = bulge_mechanics(PDMS, v, lambda_pre=1.02)
    assert set(ds.data_vars) == set(MECHANICS_VARS)
    assert dict(ds.sizes) == {"vtilde": v.size}
    assert all(ds[k].dims == ("vtilde",) for k in MECHANICS_VARS)
    np.testing.assert_array_equal(ds["vtilde"].values, v)
    _assert_annotated(ds)
    assert ds["vtilde"].attrs["units"] == "1"
    assert ds.attrs["material_law"] == "gent-gent"
    # supplement Table 1 constants travel with the result
    assert ds.attrs["material_c1"] == pytest.approx(0.0316e6)
    assert ds.attrs["material_c2"] == pytest.approx(0.0297e6)
    assert ds.attrs["material_jm"] == pytest.approx(26.0)
    assert ds.attrs["stress_scale_Pa"] == pytest.approx(0.0316e6)
    assert ds.attrs["nondimensionalising_modulus_Pa"] == pytest.approx(0.37e6)
    assert float(ds.attrs["lambda_pre"]) == pytest.approx(1.02)
    np.testing.assert_allclose(ds["lambda_pre"].values, 1.02)
    # lambda_bar is sqrt(f_A) and l_pole/l0 is the pole stretch to the power -2 (incompressible, equibiaxial)
    np.testing.assert_allclose(ds["lambda_bar"] ** 2, ds["area_ratio"], rtol=1e-14)
    np.testing.assert_allclose(ds["pole_thickness_ratio"] * ds["pole_stretch"] ** 2, 1.0, rtol=1e-14)
    # every quantity grows with the volume (pole thins)
    for k in ("area_ratio", "inverse_thickness", "pressure", "bulge_height", "pole_stretch"):
        assert np.all(np.diff(ds[k].values) > 0), k
    assert np.all(np.diff(ds["pole_thickness_ratio"].values) < 0)


def test_bulge_mechanics_dataset_is_netcdf_serialisable():
    ds = bulge_mechanics(PDMS, [0.5, 1.0])
    back = xr.open_dataset(ds.to_netcdf(engine="scipy"), engine="scipy").load()
    xr.testing.assert_identical(back, ds)


def test_scalar_vtilde_gives_one_row():
    ds = bulge_mechanics(PDMS, 1.0)
    assert dict(ds.sizes) == {"vtilde": 1}
    assert float(ds["vtilde"][0]) == 1.0


def test_bulge_profile_dataset_layout_and_consistency():
    """Profile fields satisfy their own definitions and reproduce the requested volume."""
    v, lp = 3.0, 1.03
    p = bulge_profile(PDMS, v, lambda_pre=lp, n=801)
    assert set(p.data_vars) == set(PROFILE_VARS)
    assert dict(p.sizes) == {"rho": 801}
    _assert_annotated(p)
    assert p["alpha"].attrs["units"] == "rad"
    rho = p["rho"].values
    np.testing.assert_allclose(rho, np.linspace(0.0, 1.0, 801), atol=0)
    r, z, lxi, lphi, alpha = (p[k].values for k in ("r", "z", "lambda_xi", "lambda_phi", "alpha"))
    # boundary conditions: clamped rim at z = 0, rim stretch lambda_pre, symmetric pole
    assert z[-1] == pytest.approx(0.0, abs=1e-12)
    assert r[-1] == pytest.approx(lp, rel=1e-12, abs=0)
    assert r[0] == 0.0 and alpha[0] == 0.0
    assert lxi[0] == pytest.approx(lphi[0], rel=1e-9, abs=0)
    # Eqn 17 (r = lambda_phi rho) and Eqn 18 (l/l0 = 1/(lambda_xi lambda_phi))
    np.testing.assert_allclose(r, lphi * rho, rtol=1e-14)
    np.testing.assert_allclose(p["thickness_ratio"], 1.0 / (lxi * lphi), rtol=1e-14)
    # Eqn 22-23 (corrected) integrated with Simpson: height, volume and area from the fields
    dz = lxi * np.sin(alpha)  # = -dz/drho with z measured up from the rim
    assert simpson(dz, x=rho) == pytest.approx(z[0], rel=1e-7, abs=0)
    assert simpson(r**2 * dz, x=rho) == pytest.approx(v, rel=1e-7, abs=0)
    assert 2.0 * simpson(lxi * lphi * rho, x=rho) == pytest.approx(p.attrs["area_ratio"], rel=1e-7, abs=0)
    # attrs agree with bulge_mechanics at the same volume
    ds = bulge_mechanics(PDMS, [v], lambda_pre=lp)
    for key in ("pressure", "area_ratio", "inverse_thickness", "bulge_height", "pole_stretch"):
        assert p.attrs[key] == pytest.approx(float(ds[key][0]), rel=1e-9, abs=0), key
    assert p.attrs["vtilde"] == v and p.attrs["lambda_pre"] == pytest.approx(lp)
    assert p.attrs["bulge_height"] == pytest.approx(z[0], rel=1e-9, abs=0)


# --------------------------------------------------------------------------- independent truths


@pytest.mark.parametrize("lambda_pre", [1.0, 1.05])
@pytest.mark.parametrize("material", [PDMS, NeoHookean(0.1e6)], ids=["PDMS", "neo-Hookean"])
def test_zero_volume_is_the_flat_stretched_membrane(material, lambda_pre):
    flat = bulge_mechanics(material, [0.0, 0.5], lambda_pre=lambda_pre).isel(vtilde=0)
    assert float(flat.area_ratio) == pytest.approx(lambda_pre**2, rel=1e-15, abs=0)
    assert float(flat.inverse_thickness) == pytest.approx(lambda_pre**2, rel=1e-15, abs=0)
    assert float(flat.pressure) == 0.0
    assert float(flat.bulge_height) == 0.0
    assert float(flat.pole_stretch) == pytest.approx(lambda_pre)
    assert float(flat.pole_thickness_ratio) == pytest.approx(lambda_pre**-2)


def test_small_volume_area_follows_the_spherical_cap():
    """f_A - 1 -> 4 V^2 for an unstretched rim (errata E3: not 4 pi V^2); continuous with V = 0."""
    v = np.array([0.0, 1e-3, 3e-3])
    ds = bulge_mechanics(PDMS, v)
    np.testing.assert_allclose((ds.area_ratio.values[1:] - 1.0) / (4.0 * v[1:] ** 2), 1.0, rtol=2e-2)
    assert 0.0 < float(ds.pressure[1]) < 1e-3


@pytest.mark.parametrize(("material", "lambda_pre"), [(PDMS, 1.05), (NeoHookean(0.1e6), 1.2)],
                         ids=["PDMS-1.05", "neo-Hookean-1.2"])
def test_small_volume_with_prestretch_is_a_tensioned_paraboloid(material, lambda_pre):
    """Pre-tensioned rim of radius b = lambda_pre a: uniform tension gives a paraboloid of height
    delta = 2 V a / lambda_pre^2 and area pi (b^2 + delta^2), so f_A - lambda_pre^2 -> 4 V^2 / lambda_pre^4."""
    v = np.array([0.0, 3e-3, 1e-2])
    ds = bulge_mechanics(material, v, lambda_pre=lambda_pre).isel(vtilde=slice(1, None))
    lp, vv = lambda_pre, v[1:]
    np.testing.assert_allclose((ds.area_ratio - lp**2) / (4.0 * vv**2 / lp**4), 1.0, rtol=1e-3)
    np.testing.assert_allclose(ds.bulge_height / (2.0 * vv / lp**2), 1.0, rtol=1e-3)


@pytest.mark.parametrize(("material", "lambda_pre", "vtilde"),
                         [(PDMS, 1.05, 1e-3), (NeoHookean(0.1e6), 1.05, 1e-3), (PEO_PDMS, 1.0, 0.001096985797892384)],
                         ids=["PDMS-1.05-1e-3", "neo-Hookean-1.05-1e-3", "PEO_PDMS-1.0-1.097e-3"])
def test_tiny_volume_solves(material, lambda_pre, vtilde):
    """Issue 2: Vtilde from 1e-3 for any lambda_pre >= 1 (these values were once rejected by a
    convergence test finer than the round-off of the pole stretch)."""
    ds = bulge_mechanics(material, [vtilde], lambda_pre=lambda_pre)
    lp = lambda_pre
    # pre-tensioned: paraboloid; unstretched rim: the Hencky shape is within 0.3 % of the cap
    rel = 1e-3 if lp > 1 else 1e-2
    assert float(ds.area_ratio[0]) - lp**2 == pytest.approx(4.0 * vtilde**2 / lp**4, rel=rel, abs=0)


def test_linear_elastic_rows_are_the_closed_forms():
    v = np.array([0.0, 0.01, 0.05, 0.5, 2.0, 7.0])
    lin = LinearElastic(0.37e6)
    ds = bulge_mechanics(lin, v)
    np.testing.assert_allclose(ds.area_ratio, 1.0 + 4.0 * v**2, rtol=1e-15)
    np.testing.assert_allclose(ds.inverse_thickness, 1.0, rtol=0)
    # P a / (C1 l0) with C1 = E/6 and P a/(E l0) = 128 V^3 / 3 (Eqn 11)
    np.testing.assert_allclose(ds.pressure, 6.0 * 128.0 / 3.0 * v**3, rtol=1e-14)
    np.testing.assert_allclose(ds.lambda_bar, np.sqrt(1.0 + 4.0 * v**2), rtol=1e-15)
    np.testing.assert_allclose(ds.bulge_height, 2.0 * v, rtol=1e-15)  # Nix: V = pi a^2 delta / 2
    np.testing.assert_allclose(turgor_ratio(ds.pressure, lin, 0.1), 128.0 / 3.0 * 0.1 * v**3, rtol=1e-14)
    assert math.isinf(locking_volume(lin))
    _assert_annotated(ds)


def test_turgor_ratio_matches_hand_conversion_of_table_pressure():
    """f_p = P_t / E with P_t in Pa from the table and E = 0.37 MPa (supplement Sec. 5.6)."""
    table = mechanics_table(PDMS, vtilde_max=4.0, n=48, cache=False)
    v = np.array([0.1, 0.7, 2.0, 3.9])
    l0, a = 20e-6, 200e-6  # reference chamber
    p_pa = table.turgor_pressure(v, thickness=l0, radius=a)
    # by hand: P_t = Ptilde C1 l0 / a with C1 = 0.0316 MPa
    np.testing.assert_allclose(p_pa, table.pressure(v) * 0.0316e6 * l0 / a, rtol=1e-14)
    np.testing.assert_allclose(turgor_ratio(table.pressure(v), PDMS, l0 / a), p_pa / 0.37e6, rtol=1e-13)


def test_constant_callable_lambda_pre_equals_the_constant():
    v = [0.2, 1.0, 4.0]
    const = bulge_mechanics(PDMS, v, lambda_pre=1.04)
    func = bulge_mechanics(PDMS, v, lambda_pre=lambda x: np.full(np.shape(x), 1.04))
    for k in MECHANICS_VARS:
        np.testing.assert_allclose(func[k], const[k], rtol=1e-12, err_msg=k)
    unit = bulge_mechanics(PDMS, v, lambda_pre=PreStretch(0.0, 0.0))
    plain = bulge_mechanics(PDMS, v)
    for k in MECHANICS_VARS:
        np.testing.assert_allclose(unit[k], plain[k], rtol=1e-12, err_msg=k)


def test_varying_lambda_pre_is_applied_row_by_row():
    """A callable pre-stretch gives, at each volume, the constant-pre-stretch solution at its value."""
    pre = PreStretch(0.02, -0.001)
    v = np.array([0.3, 1.0, 3.0])
    ds = bulge_mechanics(PDMS, v, lambda_pre=pre)
    np.testing.assert_allclose(ds.lambda_pre, 1.0 + 0.02 * v - 0.001 * v**2, rtol=1e-15)
    for i, vi in enumerate(v):
        one = bulge_mechanics(PDMS, [vi], lambda_pre=float(pre(vi)))
        for k in ("area_ratio", "inverse_thickness", "pressure", "pole_stretch"):
            assert float(ds[k][i]) == pytest.approx(float(one[k][0]), rel=1e-9, abs=0), (k, vi)
    assert ds.attrs["lambda_pre"] == pre.cache_key


def test_results_do_not_depend_on_the_other_requested_volumes():
    alone = bulge_mechanics(PDMS, [1.0])
    among = bulge_mechanics(PDMS, [0.3, 1.0, 5.0]).sel(vtilde=1.0)
    dense = bulge_mechanics(PDMS, np.linspace(0.0, 6.5, 27)).sel(vtilde=1.0)
    for other in (among, dense):
        for k in ("area_ratio", "inverse_thickness", "pressure", "pole_stretch", "bulge_height"):
            assert float(other[k]) == pytest.approx(float(alone[k][0]), rel=1e-9, abs=0), k
