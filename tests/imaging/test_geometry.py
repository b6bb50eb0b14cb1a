"""Geometry of traced profiles against analytic shapes (spherical caps, half-spheroids, ellipses)."""

import numpy as np
import pytest

from osmobulge.imaging.geometry import (
    ellipse_distance,
    fit_ellipse,
    revolution_area,
    revolution_measures,
    revolution_volume,
    smooth_profile,
    split_halves,
    to_chamber_frame,
)


# ----------------------------------------------------------------------------- analytic shapes
def cap_curve(a, h, n=2001):
    """Spherical cap of base radius a and height h, rim to rim (x signed), plus exact V and A."""
    R = (a * a + h * h) / (2 * h)
    zc = h - R  # centre height (below the plane for h < a, above for h > a)
    phi_max = np.arccos(-zc / R)  # polar angle of the rim from the apex
    phi = np.linspace(-phi_max, phi_max, n)
    x, z = R * np.sin(phi), zc + R * np.cos(phi)
    volume = np.pi * h * h * (3 * R - h) / 3
    area = 2 * np.pi * R * h
    return x, z, volume, area


def spheroid_curve(a, c, zc=0.0, n=2001):
    """Spheroid (radial semi-axis a, axial c, centre at height zc) cut by z = 0."""
    t_max = np.arccos(-zc / c)  # angle from the pole where z = 0
    t = np.linspace(-t_max, t_max, n)
    x, z = a * np.sin(t), zc + c * np.cos(t)
    volume = np.pi * a * a * ((c + zc) - (c**3 + zc**3) / (3 * c * c))
    return x, z, volume


def half_spheroid_area(a, c):
    """Curved area of half a spheroid (radial a, axial c)."""
    if np.isclose(a, c):
        return 2 * np.pi * a * a
    if c > a:  # prolate
        e = np.sqrt(1 - a * a / (c * c))
        return np.pi * a * a * (1 + c / (a * e) * np.arcsin(e))
    e = np.sqrt(1 - c * c / (a * a))  # oblate
    return np.pi * a * a * (1 + (1 - e * e) / e * np.arctanh(e))


# ----------------------------------------------------------------------------- revolution integrals
@pytest.mark.parametrize("h_over_a", [0.05, 0.4, 1.0, 1.8, 3.0])
def test_spherical_cap_volume_and_area(h_over_a):
    a = 200e-6
    x, z, v, A = cap_curve(a, h_over_a * a)
    m = revolution_measures(x, z)
    assert m.volume_left == pytest.approx(v, rel=2e-6, abs=0)
    assert m.volume_right == pytest.approx(v, rel=2e-6, abs=0)
    assert m.area == pytest.approx(A, rel=2e-6, abs=0)
    assert m.height == pytest.approx(h_over_a * a, rel=1e-9, abs=0)
    assert m.rim_left == pytest.approx(a, rel=1e-9, abs=0) and m.rim_right == pytest.approx(a, rel=1e-9, abs=0)
    assert m.volume_disagreement < 1e-9


def test_beyond_hemisphere_overhangs_and_is_not_a_function():
    x, z, v, _ = cap_curve(1.0, 2.0)
    assert np.abs(x).max() > 1.2  # the curve reaches beyond its rim
    # a z(x) integral over the footprint would count the overhang twice; the curve integral does not
    assert revolution_measures(x, z).volume == pytest.approx(v, rel=2e-6, abs=0)


@pytest.mark.parametrize(("a", "c"), [(1.0, 2.5), (1.0, 1.0), (1.0, 0.3)])  # prolate, sphere, oblate
def test_half_spheroid(a, c):
    x, z, v = spheroid_curve(a, c)
    m = revolution_measures(x, z)
    assert v == pytest.approx(2 / 3 * np.pi * a * a * c, rel=1e-12, abs=0)
    assert m.volume == pytest.approx(v, rel=2e-6, abs=0)
    assert m.area == pytest.approx(half_spheroid_area(a, c), rel=2e-6, abs=0)


def test_truncated_prolate_spheroid_beyond_equator():
    x, z, v = spheroid_curve(1.3, 2.0, zc=0.8)  # rim radius < max radius: overhang
    m = revolution_measures(x, z)
    assert m.volume == pytest.approx(v, rel=2e-6, abs=0)
    assert m.rim_left == pytest.approx(1.3 * np.sqrt(1 - 0.16), rel=1e-9, abs=0)


def test_sag_gives_negative_volume_and_open_end_is_closed():
    x, z, v, _ = cap_curve(1.0, 0.3)
    assert revolution_measures(x, -z).volume == pytest.approx(-v, rel=2e-6, abs=0)
    # lift the whole curve by 0.1: closing to z=0 adds the cylinder pi a^2 0.1
    m = revolution_measures(x, z + 0.1)
    assert m.volume == pytest.approx(v + np.pi * 0.1, rel=2e-6, abs=0)


def test_flat_and_disk_area():
    r = np.linspace(0, 2.0, 11)
    assert revolution_volume(r, np.zeros_like(r)) == 0.0
    assert revolution_area(r, np.zeros_like(r)) == pytest.approx(np.pi * 4.0)


def test_left_right_disagreement_detects_asymmetry():
    x, z, _, _ = cap_curve(1.0, 1.0)
    z2 = np.where(x > 0, 1.1 * z, z)
    m = revolution_measures(x, z2)
    assert m.volume_right / m.volume_left == pytest.approx(1.1, rel=1e-6, abs=0)
    assert m.volume_disagreement == pytest.approx(0.1 / 1.05, rel=1e-4, abs=0)


def test_split_halves_orders_and_validates():
    x = np.array([1.0, 0.5, -0.5, -1.0])  # right to left: reversed internally
    z = np.array([0.0, 1.0, 1.0, 0.0])
    (rl, zl), (rr, zr) = split_halves(x, z)
    np.testing.assert_allclose(rl, [0, 0.5, 1.0])
    np.testing.assert_allclose(zr, [1, 1, 0])
    with pytest.raises(ValueError, match="does not cross"):
        split_halves(np.array([0.1, 0.2]), np.array([0.0, 1.0]))
    with pytest.raises(ValueError, match="equal length"):
        split_halves(np.zeros(3), np.zeros(4))


# ----------------------------------------------------------------------------- smoothing spline
@pytest.mark.parametrize("h_over_a", [0.3, 1.0, 2.2])
def test_spline_of_noisy_points_recovers_volume_and_area(h_over_a):
    """Noise of 0.5 px on a 150 px radius dome: volume and area within 1 %."""
    rng = np.random.default_rng(1)
    a = 150.0
    x, z, v, A = cap_curve(a, h_over_a * a, n=int(8 * a * (1 + h_over_a)))
    xn, zn = x + rng.normal(0, 0.5, x.size), z + rng.normal(0, 0.5, z.size)
    spl = smooth_profile(np.c_[xn, zn], sigma=0.5 * np.sqrt(2))
    s, p = spl.sample(step=0.5)
    m = revolution_measures(p[:, 0], p[:, 1])
    assert m.volume == pytest.approx(v, rel=0.01, abs=0)
    assert m.area == pytest.approx(A, rel=0.01, abs=0)
    assert spl.rms == pytest.approx(0.5 * np.sqrt(2), rel=0.2, abs=0)
    # arc length of the cap: 2 R phi_max
    R = (a * a + (h_over_a * a) ** 2) / (2 * h_over_a * a)
    assert spl.length == pytest.approx(2 * R * np.arccos((R - h_over_a * a) / R), rel=0.01, abs=0)


def test_spline_arc_length_parameterisation_and_tangent():
    t = np.linspace(0, np.pi, 60)
    spl = smooth_profile(np.c_[np.cos(t), np.sin(t)])
    p = spl(np.array([0.0, np.pi / 2, np.pi]))
    np.testing.assert_allclose(p, [[1, 0], [0, 1], [-1, 0]], atol=1e-5)
    np.testing.assert_allclose(spl.tangent(np.pi / 2), [-1, 0], atol=1e-5)
    s, pts = spl.sample(n=101)
    np.testing.assert_allclose(np.hypot(*np.diff(pts, axis=0).T), np.pi / 100, rtol=1e-4)


def test_spline_normal_residuals_are_the_points_distances_from_the_curve():
    """Points every 1.5 px along a half circle of 300 px, scattered across it (as the tracer's stations along
    their normals), fit by a smoothing spline: ``normal_residuals`` equals each point's shortest distance from
    the fitted curve (sampled every 0.01 px, brute force) within 5e-3 px, while ``residuals`` (from the point's
    own spline point) also carry a tangential part of up to a px."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(2)
    at = np.linspace(0.0, np.pi, 630)
    for scatter in (0.3, 0.5):
        pts = (300.0 + rng.normal(0.0, scatter, at.size))[:, None] * np.c_[np.cos(at), np.sin(at)]
        spl = smooth_profile(pts, sigma=0.5)
        _, dense = spl.sample(step=0.01)
        dist = cKDTree(dense).query(pts)[0]
        inner = slice(1, -1)  # (the ends' nearest curve point may be the curve's end, not a foot of a normal)
        np.testing.assert_allclose(spl.normal_residuals[inner], dist[inner], atol=5e-3)
        assert np.max(spl.residuals - spl.normal_residuals) > 0.3


def test_spline_derivative_is_scipys_to_the_bit():
    """The profile spline's derivative (built without scipy's ``BSpline.derivative`` checks) has scipy's knots,
    coefficients and values to the bit, on smoothing and regression splines of noisy domes and a 1-D spline."""
    from scipy import interpolate

    from osmobulge.imaging.geometry import _derivative

    rng = np.random.default_rng(4)
    at = np.linspace(0.0, np.pi, 400)
    for sigma, knots in ((0.5, None), (1.0, None), (None, 12.0)):
        pts = (300.0 + rng.normal(0.0, 0.4, at.size))[:, None] * np.c_[np.cos(at), 0.7 * np.sin(at)]
        spl = smooth_profile(pts, sigma=sigma, knot_spacing=knots).spline
        mine, theirs = _derivative(spl), spl.derivative()
        np.testing.assert_array_equal(mine.t, theirs.t)
        np.testing.assert_array_equal(mine.c, theirs.c)
        u = np.linspace(0.0, 1.0, 777)
        np.testing.assert_array_equal(mine(u), theirs(u))
        assert (mine.k, mine.axis, mine.extrapolate) == (theirs.k, theirs.axis, theirs.extrapolate)
    one = interpolate.make_interp_spline(np.linspace(0, 1, 20), np.sin(np.linspace(0, 3, 20)), k=3)
    np.testing.assert_array_equal(_derivative(one)(u), one.derivative()(u))


def test_compiled_spline_evaluation_is_scipys():
    """The profile spline's points, tangents and arc-length table come from compiled loops: scipy's values within
    1e-12 of the curve's size, in any order of the parameters, and nan for a nan arc length; the arc length is
    the curve's (scipy's quadrature of the speed within 1e-5, and within 1e-3 px along the way)."""
    from scipy import integrate

    from osmobulge.imaging._kernels import cubic_arc_table, spline_points

    rng = np.random.default_rng(5)
    at = np.linspace(0.0, np.pi, 300)
    for sigma, knots in ((0.5, None), (0.25, None), (None, 10.0)):
        pts = (200.0 + rng.normal(0.0, 0.3, at.size))[:, None] * np.c_[np.cos(at), np.sin(at)]
        spl = smooth_profile(pts, sigma=sigma, knot_spacing=knots)
        b, der = spl.spline, spl.spline.derivative()
        u = rng.permutation(np.r_[0.0, rng.uniform(0.0, 1.0, 200), 1.0])
        np.testing.assert_allclose(spline_points(b.t, b.c, 3, u), b(u).T, rtol=0, atol=1e-12 * 200)
        np.testing.assert_allclose(spline_points(der.t, der.c, 2, u), der(u).T, rtol=0, atol=1e-12 * 200)
        s = np.r_[0.0, rng.uniform(0.0, spl.length, 40), spl.length]
        np.testing.assert_allclose(spl(s), b(spl._u_of_s(s)).T, rtol=0, atol=1e-12 * 200)
        d = der(spl._u_of_s(s)).T
        np.testing.assert_allclose(spl.tangent(s), d / np.hypot(*d.T)[:, None], rtol=0, atol=1e-12)
        assert spl(np.array([[0.0, 1.0]])).shape == (1, 2, 2) and np.isnan(spl(np.array([np.nan]))).all()
        uu, ss = cubic_arc_table(b.t, np.ascontiguousarray(b.c[: len(b.t) - 4]))
        exact = integrate.quad(lambda x, der=der: np.hypot(*der(x)), 0.0, 1.0, points=b.t[4:-4], limit=200)[0]
        # (the trapezoid rule at 8-12 steps per knot span: 1e-6 on the regression spline's wiggles of the noise)
        assert ss[-1] == pytest.approx(exact, rel=1e-5) and spl.length == pytest.approx(exact, rel=1e-5)
        np.testing.assert_allclose(ss[::64], [integrate.quad(lambda x, der=der: np.hypot(*der(x)), 0.0, v)[0]
                                              for v in uu[::64]], rtol=1e-5, atol=1e-3)  # (px along the way)
    with pytest.raises(ValueError, match="coefficients"):
        spline_points(b.t, b.c[:5], 3, u)


def test_spline_validation():
    with pytest.raises(ValueError, match="shape"):
        smooth_profile(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="at least 4"):
        smooth_profile(np.zeros((6, 2)))
    with pytest.raises(ValueError, match="smoothing"):
        smooth_profile(np.random.default_rng(0).random((6, 2)), smoothing=-1)


# ----------------------------------------------------------------------------- ellipse
@pytest.mark.parametrize(("center", "axes", "angle", "arc"), [
    ((3.0, -2.0), (5.0, 2.0), 0.3, 2 * np.pi),
    ((0.0, 40.0), (120.0, 80.0), 0.0, np.pi),  # upper half, as a dome above its rim
    ((0.0, -30.0), (100.0, 150.0), 0.0, 0.8 * 2 * np.pi),
])
def test_ellipse_fit_recovers_known_ellipse(center, axes, angle, arc):
    rng = np.random.default_rng(2)
    t = np.linspace(0, arc, 300) + (np.pi - arc) / 2 if arc < 2 * np.pi else np.linspace(0, arc, 300)
    (xc, yc), (a, b) = center, axes
    x = xc + a * np.cos(t) * np.cos(angle) - b * np.sin(t) * np.sin(angle)
    y = yc + a * np.cos(t) * np.sin(angle) + b * np.sin(t) * np.cos(angle)
    sig = 0.002 * max(axes)
    fit = fit_ellipse(np.c_[x, y] + rng.normal(0, sig, (t.size, 2)))
    assert fit
    np.testing.assert_allclose(fit.center, center, atol=0.02 * max(axes))
    np.testing.assert_allclose(sorted(fit.semi_axes), sorted(axes), rtol=0.02)
    assert fit.rms == pytest.approx(sig * np.sqrt(2) * 0.7, rel=0.5, abs=0)  # normal part of isotropic noise
    on = fit.points(np.linspace(0, 2 * np.pi, 7))
    assert on.shape == (7, 2)


@pytest.mark.parametrize("seed", range(8))
def test_direct_ellipse_is_skimages_estimate(seed):
    """The fast direct fit gives skimage's EllipseModel parameters (noisy arcs, whole ellipses, domes)."""
    from skimage.measure import EllipseModel

    from osmobulge.imaging.geometry import _direct_ellipse

    rng = np.random.default_rng(seed)
    a, b = rng.uniform(5.0, 300.0, 2)
    th, c = rng.uniform(-3.0, 3.0), rng.uniform(-200.0, 200.0, 2)
    t0 = rng.uniform(0, 2 * np.pi)
    t = t0 + np.linspace(0.0, rng.uniform(0.8, 2 * np.pi), 150)
    pts = np.c_[c[0] + a * np.cos(t) * np.cos(th) - b * np.sin(t) * np.sin(th),
                c[1] + a * np.cos(t) * np.sin(th) + b * np.sin(t) * np.cos(th)]
    pts += rng.normal(0, 0.01 * min(a, b), pts.shape)
    ref = EllipseModel.from_estimate(pts)
    assert ref
    fast = _direct_ellipse(pts)
    assert fast is not None
    np.testing.assert_allclose(fast.center, ref.center, rtol=1e-9, atol=1e-9 * max(a, b))
    np.testing.assert_allclose(fast.axis_lengths, ref.axis_lengths, rtol=1e-9)
    assert fast.theta == pytest.approx(float(ref.theta), abs=1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_compiled_direct_ellipse_equals_the_numpy_algebra(seed):
    """The compiled eigenproblem (characteristic cubic, null vectors) gives LAPACK's ellipse, and the same failures."""
    from osmobulge.imaging._kernels import direct_ellipse
    from osmobulge.imaging.geometry import _direct_ellipse_numpy

    rng = np.random.default_rng(100 + seed)
    n_ok = 0
    for _ in range(50):
        a, b = rng.uniform(5.0, 300.0, 2)
        th, c = rng.uniform(-3.0, 3.0), rng.uniform(-200.0, 200.0, 2)
        t = rng.uniform(0, 2 * np.pi) + np.linspace(0.0, rng.uniform(0.8, 2 * np.pi), int(rng.integers(6, 300)))
        pts = np.c_[c[0] + a * np.cos(t) * np.cos(th) - b * np.sin(t) * np.sin(th),
                    c[1] + a * np.cos(t) * np.sin(th) + b * np.sin(t) * np.cos(th)]
        pts += rng.normal(0, rng.choice([0.0, 1e-3, 1e-2, 0.1]) * min(a, b), pts.shape)
        status, xc, yc, w, h, phi = direct_ellipse(pts[:, 0].copy(), pts[:, 1].copy())
        ref = _direct_ellipse_numpy(pts)
        if status == 2:  # an ill-conditioned root: the numpy algebra decides
            continue
        assert (status == 1) == (ref is None)
        if status == 0:
            n_ok += 1
            np.testing.assert_allclose([xc, yc], ref.center, rtol=0, atol=1e-7 * max(a, b))
            np.testing.assert_allclose([w, h], ref.axis_lengths, rtol=1e-7)
            if abs(w - h) > 1e-3 * w:  # a circle's angle is arbitrary
                assert abs((phi - ref.theta + np.pi / 2) % np.pi - np.pi / 2) < 1e-6
    assert n_ok >= 35  # most fits take the compiled route
    # very eccentric, rotated ellipses: the cubic's roots are ill-conditioned there and LAPACK decides (status 2)
    for ratio in (1e2, 1e3, 1e4):
        for th in (0.3, 2.35):
            t = np.linspace(0.0, 2 * np.pi, 60, endpoint=False)
            a, b = 1000.0, 1000.0 / ratio
            pts = np.c_[a * np.cos(t) * np.cos(th) - b * np.sin(t) * np.sin(th),
                        a * np.cos(t) * np.sin(th) + b * np.sin(t) * np.cos(th)]
            status, xc, yc, w, h, _ = direct_ellipse(pts[:, 0].copy(), pts[:, 1].copy())
            ref = _direct_ellipse_numpy(pts)
            if status == 0:
                np.testing.assert_allclose([w, h], ref.axis_lengths, rtol=1e-7)
            fit = fit_ellipse(pts)  # LAPACK's ellipse whichever route gave it
            np.testing.assert_allclose(fit.semi_axes, ref.axis_lengths, rtol=1e-7)
            if ratio <= 1e3:  # (at 1e4 the direct fit itself is off by a percent)
                np.testing.assert_allclose(fit.semi_axes, (a, b), rtol=1e-5)
                np.testing.assert_allclose(fit.center, (0.0, 0.0), atol=1e-6 * a)
    # collinear points: no ellipse either way
    line = np.c_[np.arange(10.0), 2 * np.arange(10.0)]
    assert direct_ellipse(line[:, 0].copy(), line[:, 1].copy())[0] != 0 and _direct_ellipse_numpy(line) is None


def test_direct_ellipse_leaves_undecided_cases_to_numpy(monkeypatch):
    """Status 2 of the compiled fit (repeated roots, a singular scatter) hands the points to the numpy algebra."""
    from osmobulge.imaging import geometry as G

    t = np.linspace(0.3, 2.8, 60)
    pts = np.c_[90 * np.cos(t), 10 + 60 * np.sin(t)]
    monkeypatch.setattr(G, "direct_ellipse", lambda x, y: (2, *([np.nan] * 5)))
    fit = G._direct_ellipse(pts)
    np.testing.assert_allclose(fit.center, [0.0, 10.0], atol=1e-6)
    np.testing.assert_allclose(fit.axis_lengths, [90.0, 60.0], rtol=1e-9)


def test_degenerate_points_give_a_failed_fit_not_an_error():
    """Collinear points, two parallel lines (the constraint at rounding level), an ellipse 1e9 times flatter than
    long (a zero denominator in the axes) and a zero axis in the distance."""
    line = np.c_[np.arange(10.0), 2 * np.arange(10.0)]
    two_lines = np.array([[-3, 1], [-5, 1], [-5, 0], [5, 1], [5, 1], [4, 0], [1, 0], [-4, 1], [-3, 1.0]])
    t = np.linspace(0.1, 6.2, 27)
    flat = np.c_[-1e-9 * np.sin(t), np.cos(t)]
    for pts in (line, two_lines, flat):
        fit = fit_ellipse(pts)
        assert not fit and fit.message
    assert np.isnan(ellipse_distance([[1.0, 2.0]], (0, 0), (5.0, 0.0), 0.0)).all()


def test_robust_ellipse_fit_rejects_outliers():
    rng = np.random.default_rng(3)
    t = np.linspace(0, np.pi, 200)
    pts = np.c_[100 * np.cos(t), 60 * np.sin(t)] + rng.normal(0, 0.3, (200, 2))
    pts[::10] += rng.normal(0, 25, (20, 2))  # 10 % gross outliers (dust)
    plain = fit_ellipse(pts)
    robust = fit_ellipse(pts, robust=True)
    assert robust and robust.inliers.sum() >= 170
    np.testing.assert_allclose(sorted(robust.semi_axes), [60, 100], rtol=0.01)
    err_plain = abs(max(plain.semi_axes) - 100) + abs(min(plain.semi_axes) - 60)
    err_robust = abs(max(robust.semi_axes) - 100) + abs(min(robust.semi_axes) - 60)
    assert err_robust < err_plain


@pytest.mark.parametrize("seed", range(6))
def test_ellipse_distance_is_the_true_shortest_distance(seed):
    """Against brute force over 400k points of the ellipse: inside, outside, near the centre, on the axes."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    a, b = rng.uniform(1.0, 300.0, 2)
    th, c = rng.uniform(-3.0, 3.0), rng.uniform(-100.0, 100.0, 2)
    t = np.linspace(0.0, 2 * np.pi, 400_001)
    ct, st = np.cos(th), np.sin(th)
    curve = np.c_[c[0] + a * np.cos(t) * ct - b * np.sin(t) * st, c[1] + a * np.cos(t) * st + b * np.sin(t) * ct]
    axes = np.r_[np.outer(np.linspace(-2, 2, 9), [a * ct, a * st]), np.outer(np.linspace(-2, 2, 9), [-b * st, b * ct])]
    pts = np.r_[rng.normal(c, 2 * max(a, b), (60, 2)), c + rng.normal(0, 0.01 * min(a, b), (10, 2)), c + axes,
                curve[::20_000] + rng.normal(0, 0.3, (21, 2))]
    _, j = cKDTree(curve).query(pts)
    # refine each brute-force nearest point on a 4001-point grid around it (resolution ~2e-8 of the perimeter)
    tt = t[j][:, None] + np.linspace(-1, 1, 4001)[None, :] * (t[1] - t[0])
    ex = c[0] + a * np.cos(tt) * ct - b * np.sin(tt) * st - pts[:, :1]
    ey = c[1] + a * np.cos(tt) * st + b * np.sin(tt) * ct - pts[:, 1:]
    brute = np.hypot(ex, ey).min(axis=1)
    np.testing.assert_allclose(ellipse_distance(pts, c, (a, b), th), brute, rtol=0, atol=1e-6 * max(a, b))


def test_ellipse_fit_failure_is_falsy_and_validation():
    assert not fit_ellipse(np.zeros((3, 2)))
    assert "at least 5" in fit_ellipse(np.zeros((3, 2))).message
    with pytest.raises(ValueError, match="shape"):
        fit_ellipse(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="residual_threshold"):
        fit_ellipse(np.random.default_rng(0).random((10, 2)), robust=True, residual_threshold=-1)


# ----------------------------------------------------------------------------- chamber frame
@pytest.mark.parametrize("tilt_deg", [-4.0, 0.0, 3.0])
def test_chamber_frame_undoes_tilt(tilt_deg):
    x, z, v, _ = cap_curve(100.0, 130.0)
    th = np.deg2rad(tilt_deg)
    # image: col = x0 + x cos - (-z) sin ... build by rotating (x, -z) (rows grow downwards)
    col = 500 + x * np.cos(th) - (-z) * np.sin(th)
    row = 400 + x * np.sin(th) + (-z) * np.cos(th)
    xx, zz = to_chamber_frame(np.c_[col, row], axis_point=(500, 400), angle=th)
    np.testing.assert_allclose(xx, x, atol=1e-9)
    np.testing.assert_allclose(zz, z, atol=1e-9)
    assert revolution_measures(xx, zz).volume == pytest.approx(v, rel=1e-5, abs=0)
