"""Second, independent bulge solver (collocation) against the production shooting solver.

The collocation solver (``modeling/_collocation.py``) shares only the constitutive law
with the shooting solver: its right-hand side, pole series, spherical-cap seed and
continuation are written separately.  Agreement to 1e-6 relative (measured: 1e-8 or
better away from locking) therefore checks both.
"""

import math

import numpy as np
import pytest

from osmobulge.modeling import _collocation as col
from osmobulge.modeling import _shooting
from osmobulge.modeling.bulge import bulge_mechanics, bulge_profile, locking_volume
from osmobulge.modeling.materials import PDMS, PEO_PDMS, Gent, LinearElastic, NeoHookean
from osmobulge.modeling.prestretch import PreStretch

LAWS = {
    "neo-hookean": NeoHookean(c1=0.05e6),
    "gent": Gent(c1=0.05e6, jm=20.0),  # locks at vtilde 5.38 (lambda_pre = 1)
    "PDMS": PDMS,
    "PEO_PDMS": PEO_PDMS,
}
PRESTRETCH = {"1": 1.0, "1.05": 1.05, "callable": PreStretch(0.01, 0.002)}
VOLUMES = [0.05, 0.5, 2.0, 5.0]
SCALARS = [
    ("pressure", "pressure"),
    ("area_ratio", "area_ratio"),
    ("inverse_thickness", "inverse_thickness"),
    ("lam0", "pole_stretch"),
    ("bulge_height", "bulge_height"),
    ("mean_stretch", "mean_stretch"),
]


# every law at every pre-stretch, except the constant 1.05 for the two generic laws
# (covered by the presets) to keep the file's run time down
CASES = [(law, ell) for law in LAWS for ell in PRESTRETCH if not (ell == "1.05" and law in ("neo-hookean", "gent"))]


@pytest.mark.parametrize(("law_name", "ell_name"), CASES)
def test_collocation_matches_shooting_mechanics(law_name, ell_name):
    law, ell = LAWS[law_name], PRESTRETCH[ell_name]
    ref = bulge_mechanics(law, VOLUMES, lambda_pre=ell)
    for i, v in enumerate(VOLUMES):
        out = col.solve_collocation(law, v, ell)
        assert out["lambda_pre"] == pytest.approx(float(ref.lambda_pre[i]), rel=1e-15, abs=0)
        for mine, theirs in SCALARS:
            assert out[mine] == pytest.approx(float(ref[theirs][i]), rel=1e-6, abs=0), (law_name, ell_name, v, mine)


@pytest.mark.parametrize(
    ("law_name", "vtilde", "ell"),
    [
        ("neo-hookean", 0.5, 1.0),
        ("neo-hookean", 5.0, 1.05),
        ("gent", 2.0, 1.0),
        ("PDMS", 2.0, PRESTRETCH["callable"]),
        ("PDMS", 5.0, 1.0),
        ("PEO_PDMS", 5.0, 1.05),
    ],
)
def test_collocation_matches_shooting_profile(law_name, vtilde, ell):
    law = LAWS[law_name]
    prof = bulge_profile(law, vtilde, ell, n=9)
    out = col.solve_collocation(law, vtilde, ell, n=9)
    np.testing.assert_allclose(out["rho"], prof.rho.values, rtol=0, atol=1e-15)
    assert out["pressure"] == pytest.approx(prof.attrs["pressure"], rel=1e-6, abs=0)
    scale = {"r": 1.0, "z": out["bulge_height"], "lambda_xi": 1.0, "lambda_phi": 1.0, "alpha": 1.0}
    for name, s in scale.items():
        # 1e-6 relative, with an absolute floor at the nodes where the value is 0 (z at the rim, alpha at the pole)
        np.testing.assert_allclose(out[name], prof[name].values, rtol=1e-6, atol=1e-9 * s, err_msg=name)
    np.testing.assert_allclose(out["thickness_ratio"], prof.thickness_ratio.values, rtol=1e-6)


def test_collocation_solution_satisfies_boundary_conditions():
    ell = 1.05
    out = col.solve_collocation(PDMS, 3.0, ell)
    sol = out["sol"]
    assert sol.y[2, -1] == pytest.approx(ell, abs=1e-9)  # lambda_phi(1) = lambda_pre
    assert sol.y[4, -1] == pytest.approx(3.0, abs=1e-9)  # V(1) = vtilde
    assert abs(sol.y[3, -1]) < 1e-9  # z(1) = 0
    assert out["z"][-1] == pytest.approx(0.0, abs=1e-9)
    assert out["alpha"][0] == 0.0
    assert out["lambda_xi"][0] == out["lambda_phi"][0] == out["lam0"]


def _series_derivative(series, rho, scale):
    """d/drho of a polynomial-in-rho series, exactly, from a degree-4 fit on O(scale) radii."""
    nodes = scale * np.linspace(0.2, 1.0, 9)
    values = series(nodes)  # (8, 9)
    out = np.empty((values.shape[0], rho.size))
    for i, row in enumerate(values):
        coef = np.polynomial.polynomial.polyfit(nodes / scale, row, 4)
        out[i] = np.polynomial.polynomial.polyval(rho / scale, np.polynomial.polynomial.polyder(coef)) / scale
    return out


def _loglog_slopes(rho, residual):
    return np.array([np.polyfit(np.log(rho), np.log(np.abs(r)), 1)[0] for r in residual])


# order of the ODE residual of each component (lam_xi, alpha, lam_phi, z, V, A, L, B) when the
# truncated pole series is plugged in: alpha stops at k rho, so its equation is off by
# 3 k3 rho^2; the stretches stop at rho^2, so their equations are off by O(rho^3)
EXPECTED_ORDERS = np.array([3, 2, 3, 3, 5, 3, 3, 3])


@pytest.mark.parametrize("law_name", ["neo-hookean", "PDMS", "PEO_PDMS"])
@pytest.mark.parametrize("implementation", ["collocation", "shooting"])
def test_pole_series_residual_orders(law_name, implementation):
    law = LAWS[law_name]
    lam0, pressure = 1.9, 4.0
    if implementation == "collocation":
        series = lambda r: col.pole_series(law, lam0, pressure, r)  # noqa: E731
    else:
        series = lambda r: _shooting.pole_series(law, np.full(r.shape, lam0), np.full(r.shape, pressure), r)  # noqa: E731
    rho = np.geomspace(2e-3, 2e-2, 8)
    y = series(rho)
    residual = _series_derivative(series, rho, 0.05) - col.bulge_rhs(law, rho, y, pressure)
    slopes = _loglog_slopes(rho, residual)
    np.testing.assert_allclose(slopes, EXPECTED_ORDERS, atol=0.1)


def test_pole_series_residual_detects_a_wrong_coefficient():
    # a 1 % error in b2 (a2 = 3 b2 + lam0 k^2/2 kept consistent) leaves an O(rho) residual in Eqn 19
    law = PDMS
    lam0, pressure = 1.9, 4.0
    b2 = col.pole_series(law, lam0, pressure, 1.0)[2] - lam0

    def wrong(r):
        y = col.pole_series(law, lam0, pressure, r)
        y[2] += 0.01 * b2 * r * r
        y[0] += 0.03 * b2 * r * r
        return y

    rho = np.geomspace(2e-3, 2e-2, 8)
    residual = _series_derivative(wrong, rho, 0.05) - col.bulge_rhs(law, rho, wrong(rho), pressure)
    slopes = _loglog_slopes(rho, residual)
    assert slopes[0] == pytest.approx(1.0, abs=0.1)
    # and a wrong pole curvature k leaves an O(1) residual in Eqn 20
    residual_k = (
        1.01 * col.pole_series(law, lam0, pressure, rho)[1] / rho
        - col.bulge_rhs(law, rho, col.pole_series(law, lam0, pressure, rho), pressure)[1]
    )
    assert np.all(np.abs(residual_k) > 1e-3)


def test_continuation_stalls_at_the_locking_volume():
    # independent confirmation of locking_volume: collocation reaches it but not beyond
    with pytest.raises(col.CollocationError, match="locking volume") as info:
        col.solve_collocation(PDMS, 8.0)
    assert info.value.vtilde_reached == pytest.approx(locking_volume(PDMS), rel=2e-4, abs=0)
    assert info.value.vtilde_reached < locking_volume(PDMS)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"material": LinearElastic(1e6), "vtilde": 1.0}, TypeError, "material"),
        ({"material": PDMS, "vtilde": 0.0}, ValueError, "vtilde"),
        ({"material": PDMS, "vtilde": math.nan}, ValueError, "vtilde"),
        ({"material": PDMS, "vtilde": "big"}, TypeError, "vtilde"),
        ({"material": PDMS, "vtilde": 1.0, "lambda_pre": 0.9}, ValueError, "lambda_pre"),
        ({"material": PDMS, "vtilde": 1.0, "lambda_pre": lambda v: 0.5}, ValueError, "lambda_pre"),
        ({"material": PDMS, "vtilde": 1.0, "tol": 0.0}, ValueError, "tol"),
        ({"material": PDMS, "vtilde": 1.0, "n": 2}, ValueError, "n must"),
    ],
)
def test_bad_input(kwargs, error, match):
    with pytest.raises(error, match=match):
        col.solve_collocation(**kwargs)
