"""Qt-free logic of the napari plugin: conversions, point ordering, live fits."""

import numpy as np
import pytest

from osmobulge.plugins import _logic as L


def cap_points_rc(a, h, n, *, axis=(200.0, 300.0), tilt=0.0, phi_span=1.0):
    """Points on a spherical cap (base radius a, height h, px) in image (row, col), bulge up."""
    R = (a * a + h * h) / (2 * h)
    zc = h - R
    phi_max = np.arccos(-zc / R) * phi_span
    phi = np.linspace(-phi_max, phi_max, n)
    x, z = R * np.sin(phi), zc + R * np.cos(phi)
    geom = L.ChamberGeometry(axis_point=axis, angle=tilt)
    volume = np.pi * h * h * (3 * R - h) / 3
    area = 2 * np.pi * R * h
    return geom.to_image(x, z), geom, volume, area


def test_layer_data_round_trip():
    picks = {2: np.array([[1.0, 2.0], [3.0, 4.0]]), 0: np.array([[5.0, 6.0]])}
    data = L.picks_to_layer_data(picks)
    np.testing.assert_array_equal(data[:, 0], [0, 2, 2])
    back = L.layer_data_to_picks(data + [[0.2, 0, 0]] * 3)  # frame coordinate is rounded
    assert sorted(back) == [0, 2]
    np.testing.assert_array_equal(back[2], picks[2])
    assert L.picks_to_layer_data({}).shape == (0, 3)


def test_metres_round_trip():
    p = np.array([[10.0, 20.0], [11.5, 30.25]])
    m = L.points_rc_to_m(p, 1.5e-6)
    np.testing.assert_allclose(m[0], [30e-6, 15e-6])  # (x = col * p, y = row * p)
    np.testing.assert_allclose(L.points_m_to_rc(m, 1.5e-6), p)


@pytest.mark.parametrize("tilt", [0.0, 0.05, -0.1])
def test_geometry_image_chamber_inverse(tilt):
    g = L.ChamberGeometry(axis_point=(120.0, 80.0), angle=tilt)
    rng = np.random.default_rng(1)
    x, z = rng.normal(size=(2, 20)) * 50
    xx, zz = g.to_chamber(g.to_image(x, z))
    np.testing.assert_allclose(xx, x, atol=1e-9)
    np.testing.assert_allclose(zz, z, atol=1e-9)
    # height grows towards row 0 for an untilted, bulge-up chamber
    if tilt == 0:
        np.testing.assert_allclose(g.to_image([0], [10])[0], [70.0, 120.0])


@pytest.mark.parametrize("h_over_a", [0.5, 1.0, 1.8])  # shallow, hemisphere, overhanging
def test_order_along_curve_recovers_shuffled_clicks(h_over_a):
    pts, *_ = cap_points_rc(80.0, 80.0 * h_over_a, 25)
    rng = np.random.default_rng(3)
    perm = rng.permutation(len(pts))
    order = L.order_along_curve(pts[perm])
    recovered = perm[order]
    # the points run rim to rim from the left (smaller column) end
    assert list(recovered) == list(range(len(pts)))


def test_order_inserts_off_path_point():
    pts = np.array([[0, 0], [0, 10], [0, 20], [0, 30], [1.0, 14.0]])
    order = L.order_along_curve(pts)
    cols = pts[order][:, 1]
    assert list(cols) == [0, 10, 14, 20, 30]


@pytest.mark.parametrize(("h_over_a", "tilt"), [(0.4, 0.0), (1.0, 0.03), (1.6, -0.05)])
def test_fit_picked_profile_volume_and_area_of_a_cap(h_over_a, tilt):
    a, p = 100.0, 2e-6
    pts, geom, vol, area = cap_points_rc(a, a * h_over_a, 15, tilt=tilt)
    rng = np.random.default_rng(0)
    fit = L.fit_picked_profile(pts[rng.permutation(len(pts))], pixel_size=p, geometry=geom)
    assert fit, fit.message
    # spline through 15 exact points: volume and area of the cap to 0.3 %
    assert fit.volume == pytest.approx(vol * p**3, rel=3e-3, abs=0)
    assert fit.area == pytest.approx(area * p**2, rel=3e-3, abs=0)
    assert fit.height == pytest.approx(a * h_over_a * p, rel=1e-3, abs=0)
    # a spherical cap is an ellipse: the ellipse arc gives the exact volume too
    assert fit.volume_ellipse == pytest.approx(vol * p**3, rel=1e-3, abs=0)
    x, z = geom.to_chamber(fit.ellipse_rc)
    assert z.min() >= -1e-9
    np.testing.assert_allclose(sorted([x[0], x[-1]]), [-a, a], rtol=1e-3)  # the arc ends on the rim
    assert fit.volume_disagreement < 1e-3


def test_fit_without_geometry_uses_picked_ends():
    a, p = 60.0, 1e-6
    pts, geom, vol, _ = cap_points_rc(a, 45.0, 12, tilt=0.04)
    fit = L.fit_picked_profile(pts, pixel_size=p)
    assert fit.geometry.source == "picked ends"
    np.testing.assert_allclose(fit.geometry.axis_point, geom.axis_point, atol=1e-9)
    assert fit.geometry.angle == pytest.approx(0.04)
    assert fit.volume == pytest.approx(vol * p**3, rel=3e-3, abs=0)


def test_fit_with_few_points_is_falsy_with_message():
    pts, geom, *_ = cap_points_rc(50.0, 20.0, 3)
    fit = L.fit_picked_profile(pts, pixel_size=1e-6, geometry=geom)
    assert not fit and "4 points" in fit.message and "5 points" in fit.message
    assert not L.fit_picked_profile(np.empty((0, 2)), pixel_size=1e-6)
    with pytest.raises(ValueError, match="pixel_size"):
        L.fit_picked_profile(pts, pixel_size=0)


def test_fit_not_crossing_axis_is_falsy():
    pts, geom, *_ = cap_points_rc(50.0, 20.0, 12, axis=(200.0, 300.0))
    far = L.ChamberGeometry(axis_point=(500.0, 300.0))
    fit = L.fit_picked_profile(pts, pixel_size=1e-6, geometry=far)
    assert not fit and "axis" in fit.message


# ----------------------------------------------------------------------------- snapping on synthetic frames
def _segment_distance(points, curve):
    """Distance of each point to the polyline ``curve`` (both (N, 2))."""
    a, b = curve[:-1][None], curve[1:][None]
    p = np.asarray(points)[:, None, :]
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=-1) / np.sum(ab * ab, axis=-1), 0, 1)
    return np.min(np.linalg.norm(a + t[..., None] * ab - p, axis=-1), axis=1)


@pytest.fixture(scope="module", params=[1, -1], ids=["dark", "bright"])
def synthetic_frame(request):
    from osmobulge.imaging.synthetic import Nuisances, render_series

    s = render_series([1.2], chamber=(100e-6, 60e-6, 10e-6), pixel_size=2e-6, shape=(200, 240), seed=1,
                      nuisances=Nuisances(noise_sigma=0.01, polarity=request.param))
    t = s.truth.isel(time=0)
    col = np.concatenate([t.midline_col.sel(side="left").values[::-1], t.midline_col.sel(side="right").values[1:]])
    row = np.concatenate([t.midline_row.sel(side="left").values[::-1], t.midline_row.sel(side="right").values[1:]])
    return s.frames[0], np.c_[row, col], request.param


def test_snap_points_lands_on_the_true_midline(synthetic_frame):
    frame, truth, polarity = synthetic_frame
    # away from the rim corners, where the dome's band meets the flat band
    idx = np.linspace(24, len(truth) - 25, 11).astype(int)
    rng = np.random.default_rng(5)
    clicked = truth[idx] + rng.uniform(-3, 3, size=(len(idx), 2))
    clicked = clicked[rng.permutation(len(idx))]  # click order does not matter
    before = _segment_distance(clicked, truth)
    res = L.snap_points(frame, clicked, ends="normal")
    after = _segment_distance(res.points_rc, truth)
    assert res.polarity == polarity
    assert res.snapped.all()
    assert before.max() > 1.5
    assert after.max() < 0.25, after  # sub-pixel
    np.testing.assert_allclose(res.moved, np.linalg.norm(res.points_rc - clicked, axis=1), atol=1e-12)


def test_snap_rim_to_rim_clicks(synthetic_frame):
    """Clicks from rim to rim: the ends snap along the flat membrane's normal onto the rim line."""
    frame, truth, _ = synthetic_frame
    idx = np.linspace(0, len(truth) - 1, 13).astype(int)
    rng = np.random.default_rng(6)
    clicked = truth[idx] + rng.uniform(-2, 2, size=(len(idx), 2))
    res = L.snap_points(frame, clicked)
    assert res.snapped.all()
    assert _segment_distance(res.points_rc[1:-1], truth).max() < 0.25
    # the rows of the rim ends: on the rim line within 0.75 px (the dome's band starts there)
    np.testing.assert_allclose(res.points_rc[[0, -1], 0], truth[[0, -1], 0], atol=0.75)
    # columns are not moved by a vertical snap
    np.testing.assert_allclose(res.points_rc[[0, -1], 1], clicked[[0, -1], 1])


def test_snap_points_far_from_any_band_stay(synthetic_frame):
    frame, truth, _ = synthetic_frame
    pts = np.array([[20.0, 20.0], [20.0, 40.0], [20.0, 60.0]])  # water only, far above the dome
    res = L.snap_points(frame, pts, search=3.0)
    assert not res.snapped.any()
    np.testing.assert_array_equal(res.points_rc, pts)


def test_snap_points_validation():
    img = np.zeros((10, 10))
    with pytest.raises(ValueError, match="polarity"):
        L.snap_points(img, [[1, 1]], polarity=2)
    with pytest.raises(ValueError, match="search and step"):
        L.snap_points(img, [[1, 1]], search=1.0, step=2.0)
    with pytest.raises(ValueError, match="ends must be one of"):
        L.snap_points(img, [[1, 1]], ends="rim")
    with pytest.raises(ValueError, match="2-D"):
        L.snap_points(np.zeros((2, 10, 10)), [[1, 1]])
    assert L.snap_points(img, np.empty((0, 2))).points_rc.shape == (0, 2)
