"""Cached mechanics tables (osmobulge.modeling.table): spline error, cache behaviour, range checks.

The spline error is measured against direct ``bulge_mechanics`` solves at the midpoints
between the table's nodes, where an interpolant is least accurate.  Measured with n = 160
(this machine, 2026-11): PDMS f_A 1.1e-7, f_l 2.4e-7, lambda_bar 8.3e-8, pressure 5.8e-6;
PEO_PDMS 4.2e-7, 9.5e-7, 3.2e-7, 2.4e-5; PDMS with PreStretch(0.01, 0.001) 7.4e-8, 1.5e-7,
5.7e-8.  The bounds sit a few times above.

Every midpoint is checked, down to the first one (~3e-4); the table's end below the first
node is checked against the analytic small-deflection limits.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

import osmobulge.modeling._shooting as shooting
import osmobulge.modeling.table as table_mod
from osmobulge.modeling import (
    MechanicsTable,
    NoSolutionError,
    PreStretch,
    bulge_mechanics,
    locking_volume,
    mechanics_table,
)
from osmobulge.modeling.materials import PDMS, PEO_PDMS, GentGent, LinearElastic
from osmobulge.modeling.table import cache_dir

SHAPE_QUANTITIES = ("area_ratio", "inverse_thickness", "lambda_bar")


@pytest.fixture
def cache_tmp(tmp_path, monkeypatch):
    """A fresh, empty cache directory for one test."""
    d = tmp_path / "cache"
    monkeypatch.setenv("OSMOBULGE_CACHE_DIR", str(d))
    return d


@pytest.fixture
def shoot_counter(monkeypatch):
    """Count calls of the shooting integrator (every bulge solve goes through it)."""
    calls = []
    orig = shooting.shoot

    def counted(*args, **kwargs):
        calls.append(1)
        return orig(*args, **kwargs)

    monkeypatch.setattr(shooting, "shoot", counted)
    return calls


# --------------------------------------------------------------------------- spline error

CASES = {
    "PDMS": (PDMS, 1.0, None),
    "PEO_PDMS": (PEO_PDMS, 1.0, None),
    "PDMS-PreStretch": (PDMS, PreStretch(0.01, 0.001), 6.0),
    "PDMS-const-1.05": (PDMS, 1.05, 6.0),
}
#: bounds on the max relative error at the midpoints: (f_A, f_l, lambda_bar), pressure
BOUNDS = {
    "PDMS": (1e-6, 2e-5),
    "PEO_PDMS": (3e-6, 6e-5),
    "PDMS-PreStretch": (1e-6, 2e-5),
    "PDMS-const-1.05": (1e-6, 2e-5),
}


@pytest.fixture(scope="module")
def midpoint_errors():
    """Per case: {quantity: (max relative error, where)} of the n=160 table at its midpoints."""
    cache = {}

    def get(case):
        if case not in cache:
            material, lambda_pre, vmax = CASES[case]
            tab = mechanics_table(material, lambda_pre, vtilde_max=vmax, n=160, cache=False)
            g = tab.vtilde
            mid = 0.5 * (g[1:] + g[:-1])
            direct = bulge_mechanics(material, mid, lambda_pre=lambda_pre)
            errs = {}
            for q in (*SHAPE_QUANTITIES, "pressure"):
                rel = np.abs(getattr(tab, q)(mid) / direct[q].values - 1.0)
                if q == "pressure":
                    # below the smallest positive node the table extrapolates the local power law
                    # (P ~ V^3 slack, ~ V^2 or V pre-stretched); it is checked on its own bound
                    below = mid < g[g > 0][0]
                    errs["pressure_extrapolated"] = (float(rel[below].max()), float(mid[below][rel[below].argmax()]))
                    rel, mid_q = rel[~below], mid[~below]
                else:
                    mid_q = mid
                errs[q] = (float(rel.max()), float(mid_q[rel.argmax()]))
            cache[case] = errs
        return cache[case]

    return get


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_spline_error_of_shape_functions_is_bounded(case, midpoint_errors):
    errs = midpoint_errors(case)
    bound = BOUNDS[case][0]
    for q in SHAPE_QUANTITIES:
        err, where = errs[q]
        assert err < bound, f"{case} {q}: max rel error {err:.2e} at Vtilde={where:.4g} exceeds {bound:.0e}"
    # the measurement is meaningful: a spline is not exact, so the error is not zero
    assert errs["inverse_thickness"][0] > 1e-10


@pytest.mark.slow
@pytest.mark.parametrize("case", ["PDMS", "PEO_PDMS"])
def test_spline_error_of_pressure_is_bounded(case, midpoint_errors):
    err, where = midpoint_errors(case)["pressure"]
    bound = BOUNDS[case][1]
    assert err < bound, f"{case} pressure: max rel error {err:.2e} at Vtilde={where:.4g} exceeds {bound:.0e}"


@pytest.mark.slow
@pytest.mark.parametrize("case", ["PDMS-PreStretch", "PDMS-const-1.05"])
def test_spline_error_of_pressure_with_prestretch_is_bounded(case, midpoint_errors):
    err, where = midpoint_errors(case)["pressure"]
    bound = BOUNDS[case][1]
    assert err < bound, f"{case} pressure: max rel error {err:.2e} at Vtilde={where:.4g} exceeds {bound:.0e}"


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_pressure_below_the_smallest_node_follows_a_power_law(case, midpoint_errors):
    """Below Vtilde ~ 1e-5 the power law of the two smallest nodes is extrapolated.

    With a pre-stretch that grows with Vtilde (PreStretch) the local exponent still drifts
    there by O(Vtilde / c1) ~ 1e-3; P_t/Pi0 is ~1e-9 at such volumes, so this is harmless.
    """
    err, where = midpoint_errors(case)["pressure_extrapolated"]
    assert err < 2e-3, f"{case}: extrapolated pressure off by {err:.2e} at Vtilde={where:.3g}"


def test_small_vtilde_end_follows_the_small_deflection_limits():
    """Between 0 and the first nodes: f_A - 1 -> 4 V^2 and P ~ V^3 (lambda_pre = 1)."""
    tab = mechanics_table(PDMS, vtilde_max=4.0, n=64, cache=False)
    v = np.array([1e-4, 1e-3, 5e-3])
    np.testing.assert_allclose((tab.area_ratio(v) - 1.0) / (4.0 * v**2), 1.0, rtol=5e-3)
    # deeper down f_A - 1 ~ 4e-10 is below the spline's absolute accuracy, f_A itself is not
    assert abs(tab.area_ratio(1e-5) - 1.0) < 1e-9
    p_over_v3 = float(bulge_mechanics(PDMS, [0.01]).pressure[0]) / 0.01**3
    v = np.array([1e-6, 1e-5, 1e-4, 1e-3, 5e-3])  # log-log spline, power law below the smallest node
    np.testing.assert_allclose(tab.pressure(v) / v**3, p_over_v3, rtol=5e-3)
    assert tab.area_ratio(0.0) == 1.0 and tab.pressure(0.0) == 0.0 and tab.inverse_thickness(0.0) == 1.0


# --------------------------------------------------------------------------- cache behaviour


def test_cache_round_trip_loads_without_solving(cache_tmp, shoot_counter, monkeypatch):
    first = mechanics_table(PDMS, vtilde_max=3.0, n=24)
    files = list(cache_tmp.glob("mechanics-*.npz"))
    assert len(files) == 1
    assert len(shoot_counter) > 0
    shoot_counter.clear()

    def no_solve(*args, **kwargs):
        raise AssertionError("a cached table must not solve the bulge problem")

    monkeypatch.setattr(table_mod, "bulge_mechanics", no_solve)
    monkeypatch.setattr(table_mod, "locking_volume", no_solve)
    second = mechanics_table(PDMS, vtilde_max=3.0, n=24)
    assert shoot_counter == []
    assert isinstance(second, MechanicsTable)
    np.testing.assert_array_equal(second.vtilde, first.vtilde)
    for q, values in first.data.items():
        np.testing.assert_array_equal(second.data[q], values, err_msg=q)
    assert second.vtilde_lock == first.vtilde_lock == pytest.approx(locking_volume(PDMS))
    v = np.linspace(0.0, 3.0, 7)
    np.testing.assert_array_equal(second.pressure(v), first.pressure(v))


def test_default_range_is_just_below_locking(cache_tmp):
    tab = mechanics_table(PDMS, n=16, cache=False)
    assert tab.vtilde_lock == pytest.approx(locking_volume(PDMS), rel=1e-12, abs=0)
    assert tab.vtilde_max == pytest.approx(0.99 * tab.vtilde_lock, rel=1e-12, abs=0)


def test_linear_elastic_table():
    lin = mechanics_table(LinearElastic(1e6), n=16, cache=False)
    assert math.isinf(lin.vtilde_lock) and lin.vtilde_max == 12.0
    v = np.array([0.0, 0.5, 3.0])
    np.testing.assert_allclose(lin.area_ratio(v), 1.0 + 4.0 * v**2, rtol=1e-12)
    np.testing.assert_allclose(lin.pressure(v), 256.0 * v**3, rtol=1e-12)


def _n_files(d):
    return len(list(d.glob("mechanics-*.npz"))) if d.exists() else 0


@pytest.fixture
def fast_solver(monkeypatch):
    """Replace the bulge solve inside mechanics_table by the linear-elastic closed forms.

    The cache logic (keys, files, corrupt entries, locations) does not depend on the numbers,
    and each real solve costs ~0.5 s; the real solver is exercised by the round-trip,
    default-range and spline-error tests.  Returns the list of (material, lambda_pre, grid)
    of every solve.
    """
    calls = []

    def solve(material, vtilde, lambda_pre=1.0):
        calls.append((material, lambda_pre, np.asarray(vtilde)))
        return bulge_mechanics(LinearElastic(1e6), vtilde, lambda_pre=lambda_pre)

    monkeypatch.setattr(table_mod, "bulge_mechanics", solve)
    monkeypatch.setattr(table_mod, "locking_volume", lambda material, lambda_pre=1.0: 7.0)
    return calls


def test_cache_key_changes_with_every_input(cache_tmp, fast_solver):
    base = {"material": PDMS, "lambda_pre": 1.0, "vtilde_max": 1.0, "n": 8}
    mechanics_table(**base)
    assert _n_files(cache_tmp) == 1 and len(fast_solver) == 1
    mechanics_table(**base)  # same inputs: same key, no solve
    assert _n_files(cache_tmp) == 1 and len(fast_solver) == 1
    variants = [
        {"material": GentGent(c1=0.02e6, c2=0.0297e6, jm=26.0)},  # constants
        {"material": GentGent(c1=0.0316e6, c2=0.0297e6, jm=26.0)},  # same constants, other E (0.249 MPa)
        {"material": GentGent(c1=0.0316e6, c2=0.0297e6, jm=27.0, reference_modulus=0.37e6)},  # Jm
        {"lambda_pre": 1.02},  # constant pre-stretch
        {"lambda_pre": PreStretch(0.01, 0.0)},  # callable pre-stretch (cache_key)
        {"lambda_pre": PreStretch(0.02, 0.0)},
        {"n": 9},  # grid
        {"vtilde_max": 0.9},  # range
    ]
    for i, change in enumerate(variants, start=2):
        tab = mechanics_table(**(base | change))
        assert _n_files(cache_tmp) == i, change
        assert len(fast_solver) == i, change  # a miss solves once, with the new inputs
        material, lambda_pre, grid = fast_solver[-1]
        assert material is (base | change)["material"] and lambda_pre is (base | change)["lambda_pre"]
        assert grid.max() == pytest.approx((base | change)["vtilde_max"])
        assert tab.area_ratio(0.0) == pytest.approx(float(np.asarray((base | change)["lambda_pre"](0.0)
                                                                      if callable(lambda_pre) else lambda_pre)) ** 2)
    # every variant is a hit the second time round
    for change in variants:
        mechanics_table(**(base | change))
    assert len(fast_solver) == len(variants) + 1


def test_cache_key_of_plain_callables_is_their_values(cache_tmp, fast_solver):
    base = {"vtilde_max": 1.0, "n": 8}
    t1 = mechanics_table(PDMS, lambda v: 1.0 + 0.01 * np.asarray(v), **base)
    t2 = mechanics_table(PDMS, lambda v: 1.0 + 0.01 * np.asarray(v), **base)  # another object, same values
    assert _n_files(cache_tmp) == 1 and len(fast_solver) == 1
    np.testing.assert_array_equal(t1.data["area_ratio"], t2.data["area_ratio"])
    mechanics_table(PDMS, lambda v: 1.0 + 0.02 * np.asarray(v), **base)
    assert _n_files(cache_tmp) == 2 and len(fast_solver) == 2


@pytest.mark.parametrize(
    "corrupt",
    [
        lambda p: p.write_bytes(b"this is not an npz file"),
        lambda p: p.write_bytes(p.read_bytes()[: p.stat().st_size // 2]),  # truncated (killed writer, full disk)
        lambda p: p.write_bytes(b""),  # empty
        lambda p: np.savez(p.open("wb"), vtilde=np.arange(3.0)),  # valid npz, keys missing
    ],
    ids=["garbage", "truncated", "empty", "missing-keys"],
)
def test_corrupt_cache_file_is_recomputed(cache_tmp, fast_solver, corrupt):
    good = mechanics_table(PDMS, vtilde_max=2.0, n=12)
    (path,) = cache_tmp.glob("mechanics-*.npz")
    corrupt(path)
    again = mechanics_table(PDMS, vtilde_max=2.0, n=12)
    assert len(fast_solver) == 2  # it solved again
    for q, values in good.data.items():
        np.testing.assert_array_equal(again.data[q], values, err_msg=q)
    with np.load(path) as f:  # and the entry was rewritten
        np.testing.assert_array_equal(f["vtilde"], good.vtilde)
    mechanics_table(PDMS, vtilde_max=2.0, n=12)
    assert len(fast_solver) == 2  # and is used from then on


def test_osmobulge_cache_dir_is_honoured(tmp_path, monkeypatch, fast_solver):
    target = tmp_path / "nested" / "cache"
    monkeypatch.setenv("OSMOBULGE_CACHE_DIR", str(target))
    assert cache_dir() == target
    mechanics_table(PDMS, vtilde_max=1.0, n=8)
    assert _n_files(target) == 1
    assert [p.name for p in tmp_path.iterdir()] == ["nested"]


def test_cache_dir_defaults_to_the_user_cache(monkeypatch):
    import platformdirs

    monkeypatch.delenv("OSMOBULGE_CACHE_DIR", raising=False)
    assert cache_dir() == type(cache_dir())(platformdirs.user_cache_dir("osmobulge"))


def test_cache_false_writes_nothing(cache_tmp, fast_solver):
    mechanics_table(PDMS, vtilde_max=1.0, n=10, cache=False)
    mechanics_table(PEO_PDMS, PreStretch(0.01, 0.0), vtilde_max=1.0, n=8, cache=False)
    mechanics_table(PDMS, vtilde_max=1.0, n=10, cache=False)  # and reads nothing either
    assert len(fast_solver) == 3
    assert not cache_tmp.exists() or list(cache_tmp.iterdir()) == []


def test_unwritable_cache_does_not_break_the_computation(tmp_path, monkeypatch, fast_solver):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("OSMOBULGE_CACHE_DIR", str(blocker / "cache"))
    tab = mechanics_table(PDMS, vtilde_max=1.0, n=8)
    assert tab.area_ratio(0.5) == pytest.approx(2.0, rel=1e-6, abs=0)  # the stand-in's 1 + 4 V^2
    assert sorted(os.listdir(tmp_path)) == ["a-file"]


# --------------------------------------------------------------------------- range and validation


@pytest.fixture(scope="module")
def small_table():
    return mechanics_table(PDMS, vtilde_max=3.0, n=24, cache=False)


@pytest.mark.parametrize("method", ["area_ratio", "inverse_thickness", "pressure", "lambda_bar"])
@pytest.mark.parametrize("vtilde", [3.01, -1e-9, np.nan, [0.5, 3.5], np.inf])
def test_out_of_range_evaluation_names_the_table_range(small_table, method, vtilde):
    with pytest.raises(ValueError, match=r"outside the mechanics table \[0, 3\] \(the gent-gent law locks at 7\.2"):
        getattr(small_table, method)(vtilde)


def test_out_of_range_turgor_pressure(small_table):
    with pytest.raises(ValueError, match=r"outside the mechanics table \[0, 3\]"):
        small_table.turgor_pressure(4.0, thickness=20e-6, radius=200e-6)


def test_table_edges_are_inside(small_table):
    assert small_table.area_ratio(0.0) == pytest.approx(1.0, abs=1e-12)
    assert small_table.area_ratio(3.0) == pytest.approx(small_table.data["area_ratio"][-1], rel=1e-12, abs=0)
    assert isinstance(small_table.pressure(1.0), float)
    assert small_table.pressure(np.array([1.0, 2.0])).shape == (2,)


@pytest.mark.parametrize(
    ("kwargs", "exc", "match"),
    [
        ({"n": 7}, ValueError, r"n must be >= 8, got 7"),
        ({"vtilde_max": 0.0}, ValueError, r"vtilde_max must be finite and > 0, got 0\.0"),
        ({"vtilde_max": -1.0}, ValueError, r"vtilde_max must be finite and > 0"),
        ({"vtilde_max": float("nan")}, ValueError, r"vtilde_max must be finite and > 0"),
        ({"vtilde_max": 8.0}, NoSolutionError, r"locking limit vtilde_lock=7\.2"),
        ({"lambda_pre": 0.9}, ValueError, r"lambda_pre must be >= 1"),
    ],
)
def test_mechanics_table_validation(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        mechanics_table(PDMS, cache=False, **({"n": 8} | kwargs))


def test_to_dataset_variables_are_annotated(small_table):
    ds = small_table.to_dataset()
    np.testing.assert_array_equal(ds["vtilde"].values, small_table.vtilde)
    for name, var in ds.data_vars.items():
        assert var.attrs.get("units") == "1", name
        assert var.attrs.get("long_name"), name
    np.testing.assert_array_equal(ds["area_ratio"].values, small_table.data["area_ratio"])


def test_to_dataset_coordinate_is_annotated(small_table):
    assert small_table.to_dataset()["vtilde"].attrs.get("long_name")
