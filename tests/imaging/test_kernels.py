"""The compiled kernels against the numpy/scipy expressions they replace (the reference code is kept here)."""

import warnings

import numpy as np
import pytest
from scipy import ndimage as ndi

from osmobulge.imaging._chamber import FrameView, _robust_line, band_edges, step_crossing
from osmobulge.imaging._kernels import change_transects, outer_edges, sample_transects
from osmobulge.imaging._normals import viterbi_path
from osmobulge.imaging.synthetic import Nuisances, render_frame


# ------------------------------------------------------------------------ numpy references (the former code)
def _take(a, idx):
    return np.take_along_axis(a, np.clip(idx, 0, a.shape[1] - 1)[:, None], axis=1)[:, 0]


def _ref_crossing(q, offsets, level, start, direction):
    n, k = q.shape
    cols = np.arange(k)[None, :]
    below = q < level[:, None]
    if direction > 0:
        cand = np.where(below & (cols > start[:, None]), cols, k)
        j = cand.min(axis=1)
        ok = j < k
        j0, j1 = np.clip(j - 1, 0, k - 1), np.clip(j, 0, k - 1)
    else:
        cand = np.where(below & (cols < start[:, None]), cols, -1)
        j = cand.max(axis=1)
        ok = j >= 0
        j0, j1 = np.clip(j + 1, 0, k - 1), np.clip(j, 0, k - 1)
    q0, q1 = _take(q, j0), _take(q, j1)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip((q0 - level) / (q0 - q1), 0.0, 1.0)
    out = offsets[j0] + t * (offsets[j1] - offsets[j0])
    out[~ok] = np.nan
    return out


def ref_band_edges(profiles, offsets, polarity, *, centre=None, search=None, side=4):
    q = polarity * -np.asarray(profiles, float)
    n, k = q.shape
    if not np.all(np.isfinite(q)):
        fill = np.nanmedian(q, axis=1, keepdims=True) if n else 0.0
        q = np.where(np.isfinite(q), q, np.nan_to_num(fill, nan=0.0))
    cols = np.arange(k)
    if centre is None:
        ipk = np.argmax(q, axis=1)
    else:
        c = np.asarray(centre, int)
        s = np.full(n, k) if search is None else np.broadcast_to(np.asarray(search), (n,)).astype(int)
        win = np.abs(cols[None, :] - c[:, None]) <= s[:, None]
        ipk = np.argmax(np.where(win, q, -np.inf), axis=1)
    peak = _take(q, ipk)
    left = np.median(q[:, :side], axis=1)
    right = np.median(q[:, -side:], axis=1)
    lo = _ref_crossing(q, offsets, 0.5 * (peak + left), ipk, -1)
    hi = _ref_crossing(q, offsets, 0.5 * (peak + right), ipk, +1)
    return 0.5 * (lo + hi), lo, hi, peak - 0.5 * (left + right), hi - lo


def ref_viterbi_path(score, max_step=1, penalty=0.0):
    sc = np.nan_to_num(np.asarray(score, float), nan=0.0)
    n, k = sc.shape
    m = int(max_step)
    pen = penalty * np.abs(np.arange(-m, m + 1))[::-1]  # window index i <-> move d = m - i
    pad = np.full(k + 2 * m, -np.inf)
    back = np.empty((n, k), np.int16)
    back[0] = 0
    acc = sc[0].copy()
    view = np.lib.stride_tricks.sliding_window_view(pad, 2 * m + 1)  # (k, 2m+1), shares pad's memory
    win = np.empty((k, 2 * m + 1))
    rows = np.arange(k)
    for i in range(1, n):
        pad[m : m + k] = acc
        np.subtract(view, pen, out=win)
        j = win.argmax(axis=1)
        acc = win[rows, j] + sc[i]
        back[i] = m - j  # the move d: came from index (here - d)
    path = np.empty(n, np.int64)
    path[-1] = int(np.argmax(acc))
    for i in range(n - 1, 0, -1):
        path[i - 1] = path[i] - back[i, path[i]]
    return path


def ref_step_crossing(profiles, offsets, *, side=4, fit=0):
    q = np.asarray(profiles, float)
    n, k = q.shape
    a = np.median(q[:, :side], axis=1)
    b = np.median(q[:, -side:], axis=1)
    lev = 0.5 * (a + b)
    s = q > lev[:, None]
    ch = s[:, :-1] != s[:, 1:]
    j = np.arange(k - 1)[None, :]
    dist = np.where(ch, np.abs(j + 0.5 - (k - 1) / 2.0), np.inf)
    jj = np.argmin(dist, axis=1)
    ok = np.isfinite(dist[np.arange(n), jj])
    q0, q1 = _take(q, jj), _take(q, jj + 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip((lev - q0) / (q1 - q0), 0.0, 1.0)
    pos = offsets[jj] + t * (offsets[np.minimum(jj + 1, k - 1)] - offsets[jj])
    pos[~ok] = np.nan
    for i in np.flatnonzero(ok) if fit else ():  # the crossing of a line through 2 fit samples around it
        j0, j1 = max(jj[i] - fit + 1, 0), min(jj[i] + fit, k - 1)
        x, y = offsets[j0:j1 + 1], q[i, j0:j1 + 1]
        f = np.isfinite(y)
        if f.sum() < 3:
            continue
        c1, c0 = np.polyfit(x[f] - pos[i], y[f], 1)
        rise = q[i, jj[i] + 1] - q[i, jj[i]]
        if (c1 != 0 and (c1 > 0) == (rise > 0) and abs(c1) * (x[-1] - x[0]) >= 0.25 * abs(rise)
                and abs((lev[i] - c0) / c1) <= 0.5 * (x[-1] - x[0])):
            pos[i] += (lev[i] - c0) / c1
    return pos, b - a


def ref_robust_line(x, y, *, iters=4, clip=3.0, floor=0.1):
    ok = np.isfinite(x) & np.isfinite(y)
    a = b = np.nan
    rms = np.nan
    for _ in range(iters):
        if ok.sum() < 2:
            break
        xo, yo = x[ok], y[ok]
        xm, ym = xo.mean(), yo.mean()
        sxx = float(np.dot(xo - xm, xo - xm))
        if not sxx > 0:
            break
        b = float(np.dot(xo - xm, yo - ym)) / sxx  # least squares, as np.polyfit(x, y, 1)
        a = ym - b * xm
        res = y - (a + b * x)
        mad = 1.4826 * np.median(np.abs(res[ok] - np.median(res[ok])))
        rms = float(np.sqrt(np.mean(res[ok] ** 2)))
        new = np.isfinite(res) & (np.abs(res) <= max(clip * mad, floor))
        if np.array_equal(new, ok) or new.sum() < 2:
            break
        ok = new
    return a, b, rms, ok


def _outer_edges_numpy(prof, thr, window):
    """The silhouette route's outer edges as numpy did them (``_facetrace._edges`` before it was compiled)."""
    n, m = prof.shape
    rows = np.arange(n)
    above = prof > thr
    i0 = np.argmax(above, axis=1)
    idx = np.minimum(i0[:, None] + np.arange(window)[None, :], m - 1)
    pk = idx[rows, np.argmax(np.take_along_axis(prof, idx, axis=1), axis=1)]
    lo = np.maximum(i0 - 8, 1)
    end = np.minimum(pk + 1, m - 1)
    dp = np.gradient(prof, axis=1)
    k = np.arange(m)[None, :]
    steep = np.argmax(np.where((k >= lo[:, None]) & (k <= pk[:, None]), dp, -np.inf), axis=1)
    right = np.where(steep + 1 == end, prof[rows, end] - prof[rows, end - 1], dp[rows, np.minimum(steep + 1, m - 1)])
    a, b = dp[rows, np.maximum(steep - 1, 0)], dp[rows, steep]
    den = a - 2 * b + right
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(den < 0, np.clip(0.5 * (a - right) / den, -0.5, 0.5), 0.0)
    return np.where(~above.any(axis=1) | (pk <= lo) | (steep >= end), np.nan, steep + off)


# ------------------------------------------------------------------------ tests
@pytest.mark.parametrize("k", range(4))
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32, np.float64])
def test_sample_transects_equals_map_coordinates(k, dtype):
    rng = np.random.default_rng(k)
    frame = (rng.random((37, 53)) * 200).astype(dtype)
    view = FrameView(frame, k)
    h, w = view.shape
    pts = np.c_[rng.uniform(-3, w + 2, 40), rng.uniform(-3, h + 2, 40)]
    ang = rng.uniform(0, 2 * np.pi, 40)
    d = np.c_[np.cos(ang), np.sin(ang)]
    offs = np.linspace(-6.0, 6.0, 25)
    got = sample_transects(frame, k, pts, d, offs)
    x = pts[:, :1] + offs[None, :] * d[:, :1]
    y = pts[:, 1:] + offs[None, :] * d[:, 1:]
    want = view.sample(x, y)  # scipy.ndimage.map_coordinates, order 1
    inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
    assert inside.mean() > 0.5 and (~inside).any()
    np.testing.assert_allclose(got[inside], want[inside], rtol=1e-12, atol=1e-9)
    far = (x < -1) | (x > w) | (y < -1) | (y > h)
    assert np.isnan(got[far]).all() and np.isnan(got[~inside]).all()
    # a non-finite offset is nan at that sample only (never the unchecked path)
    odd = sample_transects(frame, k, np.array([[w / 2, h / 2]]), np.array([[0.6, 0.8]]), np.array([-1.0, np.nan, 1.0]))
    assert np.isnan(odd[0, 1]) and np.isfinite(odd[0, [0, 2]]).all()
    # exactly on the last row/column: the pixel value, not nan
    corner = sample_transects(frame, k, np.array([[w - 1.0, h - 1.0]]), np.array([[1.0, 0.0]]), np.zeros(1))
    assert corner[0, 0] == view.sample(np.array(w - 1.0), np.array(h - 1.0))


@pytest.mark.parametrize("k", range(4))
def test_sample_transects_inside_the_frame_equal_map_coordinates(k):
    """Transects wholly inside the frame (the path without bounds checks), up to a hair from the last row/column."""
    rng = np.random.default_rng(10 + k)
    frame = (rng.random((120, 90)) * 60000).astype(np.uint16)
    view = FrameView(frame, k)
    h, w = view.shape
    offs = np.arange(-10.0, 10.01, 0.5)
    pts = np.c_[rng.uniform(11, w - 12, 300), rng.uniform(11, h - 12, 300)]
    ang = rng.uniform(0, 2 * np.pi, 300)
    d = np.c_[np.cos(ang), np.sin(ang)]
    edge = np.array([[w - 1.0 - 1e-5, h / 2], [h / 2 * 0 + 1e-5, 1e-5]])  # ends just inside the last column / corner
    pts, d = np.r_[pts, edge + [[-10.0, 0.0], [10.0, 0.0]]], np.r_[d, [[1.0, 0.0], [-1.0, 0.0]]]
    got = sample_transects(frame, k, pts, d, offs)
    want = view.sample(pts[:, :1] + offs[None, :] * d[:, :1], pts[:, 1:] + offs[None, :] * d[:, 1:])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("k", range(4))
@pytest.mark.parametrize("sigma", [0.35, 1.4, 3.0])
def test_change_transects_equals_its_numpy_composition(k, sigma):
    """The silhouette route's change along transects: three samplings (this frame, the flat frame and its light
    moved by the drift), their ratio (0 where not finite) and scipy's Gaussian along the transects."""
    rng = np.random.default_rng(20 + k)
    frame = (rng.random((80, 70)) * 60000).astype(np.uint16)
    flat = (rng.random((80, 70)) * 60000).astype(np.uint16)
    h, w = FrameView(frame, k).shape
    light = (1000.0 + rng.random((h, w)) * 50000).astype(np.float32)  # (in the view)
    pts = np.c_[rng.uniform(-5, w + 4, 60), rng.uniform(-5, h + 4, 60)]
    ang = rng.uniform(0, 2 * np.pi, 60)
    d = np.c_[np.cos(ang), np.sin(ang)]
    offs = np.arange(12.0, -12.01, -0.5)
    shift = (1.7, -2.3)
    got = change_transects(frame, k, flat, light, pts, d, offs, shift, sigma)
    moved = pts - np.array(shift)
    v = (sample_transects(frame, k, pts, d, offs) - sample_transects(flat, k, moved, d, offs)) / sample_transects(
        light, 0, moved, d, offs)
    v[~np.isfinite(v)] = 0.0
    want = ndi.gaussian_filter1d(v, sigma, axis=1, mode="nearest")
    assert (v == 0).any() and (v != 0).mean() > 0.5  # (transects leave the frame and cross it)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_outer_edges_equals_numpy_reference(seed):
    """Blurred steps and peaks at random places (some rows without a feature, some at the ends, plateaus)."""
    rng = np.random.default_rng(seed)
    n, m = 400, 65 if seed % 2 else 121
    x = np.arange(m, dtype=float)
    at = rng.uniform(-5, m + 5, n)[:, None]
    width = rng.uniform(0.5, 6, n)[:, None]
    prof = rng.uniform(0, 2, n)[:, None] * np.exp(-0.5 * ((x - at) / width) ** 2)
    prof += np.clip(np.tanh((x - at - 3) / width), 0, None) * rng.uniform(0, 1, n)[:, None]
    prof += np.abs(rng.normal(0, 0.02, prof.shape))
    prof[::17] = 0.0  # no feature
    prof[5::23, 10:20] = 1.0  # a plateau (ties)
    prof = np.round(prof, 2 if seed == 3 else 12)  # (more ties)
    for thr, window in ((0.3, int(12 / 0.25)), (0.05, 24), (0.8, 3)):
        got = outer_edges(prof, thr, window)
        want = _outer_edges_numpy(prof, thr, window)
        assert np.isnan(got).sum() > 10 and np.isfinite(got).sum() > 100
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
        np.testing.assert_allclose(got[np.isfinite(got)], want[np.isfinite(want)], rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_band_edges_equals_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    n, k = 300, 61
    offs = np.linspace(-15, 15, k)
    centre = rng.uniform(-8, 8, n)
    width = rng.uniform(2, 20, n)
    band = np.exp(-0.5 * ((offs[None, :] - centre[:, None]) / (0.3 * width[:, None])) ** 2)
    prof = 100 + 30 * np.tanh(offs / 5)[None, :] - 50 * band
    prof = ndi.gaussian_filter1d(prof + rng.normal(0, 3, prof.shape), 1.0, axis=1)
    prof[::17, ::13] = np.nan  # non-finite samples are filled with the row median
    prof[5] = 100.0  # a flat row: no crossing, nan edges
    for pol in (1, -1):
        p = prof if pol == 1 else 200 - prof
        ci = rng.integers(0, k, n)
        for kw in ({}, {"centre": ci, "search": 6}, {"centre": ci, "search": rng.integers(0, 40, n)},
                   {"centre": ci, "search": None}):
            got = band_edges(p, offs, pol, side=4, **kw)
            want = ref_band_edges(p, offs, pol, side=4, **kw)
            for g, w_ in zip(got, want, strict=True):
                np.testing.assert_allclose(g, w_, rtol=1e-12, atol=1e-12, equal_nan=True)
    assert np.isfinite(got[0]).mean() > 0.8


def test_band_edges_on_a_rendered_membrane():
    """Real transects across a rendered frame's flat band: identical to the reference."""
    frame = render_frame(1.0, chamber=(200e-6, 110e-6, 20e-6), seed=1)
    view = FrameView(frame, 0)
    cols = np.arange(20.0, 1000.0, 7.0)
    rows = np.arange(300.0, 950.0, 0.5)  # the dome and the flat band (row ~840) in every column
    prof = view.sample(cols[:, None] + 0 * rows[None, :], rows[None, :] + 0 * cols[:, None])
    for pol, p in ((1, prof), (-1, 65535.0 - prof)):  # a dark band, and the same band bright
        got = band_edges(p, rows, pol)
        want = ref_band_edges(p, rows, pol)
        for g, w_ in zip(got, want, strict=True):
            np.testing.assert_allclose(g, w_, rtol=1e-12, atol=1e-12, equal_nan=True)
        assert np.isfinite(got[0]).mean() > 0.9  # a band found in (almost) every column: compared, not nan


@pytest.mark.parametrize("max_step,penalty", [(1, 0.0), (2, 0.3), (4, 0.1)])
def test_viterbi_equals_numpy_reference(max_step, penalty):
    rng = np.random.default_rng(max_step)
    sc = rng.normal(size=(120, 33))
    sc[rng.random(sc.shape) < 0.05] = np.nan
    sc[:, 10] += 1.5  # a ridge to follow
    np.testing.assert_array_equal(viterbi_path(sc, max_step, penalty), ref_viterbi_path(sc, max_step, penalty))
    # ties (integer scores) break the same way
    ti = rng.integers(0, 3, (60, 9)).astype(float)
    np.testing.assert_array_equal(viterbi_path(ti, max_step, penalty), ref_viterbi_path(ti, max_step, penalty))


def test_band_edges_degenerate_rows_match_reference():
    """Equal neighbours at the crossing (0/0) and a band weaker than its sides give nan exactly as numpy."""
    offs = np.arange(9.0)
    prof = np.array([[5, 5, 5, 1, 5, 5, 5, 5, 5], [0, 0, 0, 0, 9, 0, 0, 0, 0], [3, 3, 2, 2, 1, 2, 2, 3, 3],
                     [1, 1, 1, 1, 1, 1, 1, 1, 1]], float)
    for pol in (1, -1):
        got = band_edges(prof, offs, pol, side=2)
        want = ref_band_edges(prof, offs, pol, side=2)
        for g, w_ in zip(got, want, strict=True):
            np.testing.assert_allclose(g, w_, rtol=1e-12, atol=1e-12, equal_nan=True)


@pytest.mark.parametrize("n_knots", [0, 5, 150])
def test_lsq_spline_equals_scipy(n_knots):
    from scipy.interpolate import make_lsq_spline

    from osmobulge.imaging._kernels import lsq_spline

    rng = np.random.default_rng(n_knots)
    x = np.sort(rng.uniform(0, 1, 900))
    x[[0, -1]] = 0.0, 1.0
    y = np.c_[np.sin(6 * x), np.cos(3 * x)] + rng.normal(0, 0.01, (900, 2))
    w = rng.uniform(0.5, 2, 900)
    w[rng.random(900) < 0.1] = 0.0  # dropped points
    inner = np.quantile(x[w > 0][1:-1], np.linspace(0, 1, n_knots + 2)[1:-1])
    t = np.r_[[0.0] * 4, inner, [1.0] * 4]
    want, got = make_lsq_spline(x, y, t, k=3, w=w), lsq_spline(x, y, t, w)
    np.testing.assert_allclose(got.c, want.c, rtol=0, atol=1e-10)
    np.testing.assert_allclose(got(x), want(x), rtol=0, atol=1e-10)
    got1 = lsq_spline(x, y[:, 0], t)  # 1-D data, no weights
    np.testing.assert_allclose(got1(x), make_lsq_spline(x, y[:, 0], t, k=3)(x), rtol=0, atol=1e-10)


def test_lsq_spline_falls_back_on_an_empty_knot_span():
    """A gap in the data wider than the knot spacing: the normal equations are singular; the knots inside the gap
    are dropped and the fit is a real spline (scipy's QR answer there is nan: B-splines without data)."""
    from scipy.interpolate import make_lsq_spline

    from osmobulge.imaging._kernels import lsq_spline

    x = np.r_[np.linspace(0, 0.3, 20), np.linspace(0.7, 1, 20)]
    y = x**2
    t = np.r_[[0.0] * 4, np.arange(0.35, 0.66, 0.05), [1.0] * 4]  # B-splines with no data in their support
    from osmobulge.imaging._kernels import _band_cholesky_solve, _lsq_normal

    ata, aty = np.zeros((len(t) - 4, 4)), np.zeros((len(t) - 4, 1))
    _lsq_normal(x, y[:, None], t, np.ones(len(x)), ata, aty)
    assert not _band_cholesky_solve(ata, aty)  # singular: the fallback is taken
    assert not np.isfinite(make_lsq_spline(x, y, t, k=3)(x)).all()  # what scipy alone would give
    spl = lsq_spline(x, y, t)
    xx = np.linspace(0, 1, 101)  # across the gap too: x^2 is a cubic spline on any knots, reproduced exactly
    np.testing.assert_allclose(spl(xx), xx**2, rtol=0, atol=1e-12)
    # and with weights: the dropped points (weight 0) leave a gap too; 2-D data
    w = np.ones(len(x))
    w[25:] = 0.0
    spl = lsq_spline(x, np.c_[x, 3 * x**2 - x], np.linspace(0, 1, 12)[np.r_[[0] * 3, 0:12, [11] * 3]], w=w)
    np.testing.assert_allclose(spl(xx[xx <= 0.8]), np.c_[xx, 3 * xx**2 - xx][xx <= 0.8], rtol=0, atol=1e-9)


@pytest.mark.parametrize("sigma", [0.5, 1.0, 2.3])
def test_fill_and_smooth_and_noise_equal_scipy(sigma):
    from osmobulge.imaging._kernels import _fill_and_smooth, ends_noise

    rng = np.random.default_rng(3)
    frame = (rng.random((60, 70)) * 1000).astype(np.uint16)
    pts = np.c_[rng.uniform(-5, 75, 50), rng.uniform(5, 55, 50)]  # some transects leave the frame: nan filled
    d = np.c_[np.zeros(50), np.ones(50)]
    offs = np.linspace(-4, 4, 17)
    raw = sample_transects(frame, 0, pts, d, offs)
    assert np.isnan(raw).any()
    want = ndi.gaussian_filter1d(np.where(np.isfinite(raw), raw, np.nanmedian(raw)), sigma, axis=0, mode="nearest")
    got = _fill_and_smooth(raw.copy(), float(sigma))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)
    ends = np.c_[got[:, :4], got[:, -4:]]
    want = 1.4826 * np.median(np.abs(np.diff(ends, axis=1))) / np.sqrt(2)
    assert ends_noise(got) == pytest.approx(want, rel=1e-12, abs=0)


@pytest.mark.parametrize("seed", range(4))
def test_step_crossing_equals_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    offs = np.arange(-8.0, 8.01, 0.5)
    edge = rng.uniform(-9, 9, 200)
    prof = 50 + 40 * np.tanh((offs[None, :] - edge[:, None]) / rng.uniform(0.5, 3, (200, 1)))
    prof += rng.normal(0, 2, prof.shape)
    prof[::23, 0] = np.nan  # a side level lost: no crossing, nan step
    prof[7] = 5.0  # flat: no crossing
    for side, fit in ((1, 0), (4, 0), (9, 0), (8, 3), (4, 2)):
        got, want = step_crossing(prof, offs, side=side, fit=fit), ref_step_crossing(prof, offs, side=side, fit=fit)
        for g, w_ in zip(got, want, strict=True):
            np.testing.assert_allclose(g, w_, rtol=1e-9, atol=1e-9, equal_nan=True)
    assert np.isfinite(got[0]).mean() > 0.7


@pytest.mark.parametrize("seed", range(4))
def test_robust_line_equals_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    x = np.sort(rng.uniform(-100, 100, 150))
    y = 3.0 + 0.02 * x + rng.normal(0, 0.1, x.size)
    out = rng.random(x.size) < 0.15
    y[out] += rng.uniform(2, 8, out.sum())  # outliers
    y[3] = np.nan
    for kw in ({}, {"clip": 2.5}, {"floor": 1.5, "iters": 2}):
        a, b, rms, ok = _robust_line(x, y, **kw)
        ra, rb, rrms, rok = ref_robust_line(x, y, **kw)
        assert a == pytest.approx(ra, rel=1e-10, abs=1e-12) and b == pytest.approx(rb, rel=1e-10, abs=1e-14)
        assert rms == pytest.approx(rrms, rel=1e-10, abs=0) and np.array_equal(ok, rok)
    assert not ok[out].any()
    # degenerate: fewer than two points, or all x equal
    assert np.isnan(_robust_line(np.array([1.0]), np.array([2.0]))[0])
    assert np.isnan(_robust_line(np.ones(5), np.arange(5.0))[0])


def test_longest_run():
    from osmobulge.imaging._kernels import longest_run

    m = np.array([1, 1, 0, 1, 1, 1, 0, 1], bool)
    w = np.array([1.0, 2.0, 9.0, 1.0, 1.0, 0.5, 4.0, 3.0])
    assert longest_run(m, w) == 3.0 and longest_run(~m, w) == 9.0 and longest_run(m[:0], w[:0]) == 0.0


@pytest.mark.parametrize("size", [1, 3, 41, 151])
def test_running_percentile_equals_scipy(size):
    from osmobulge.imaging._kernels import running_percentile

    rng = np.random.default_rng(size)
    for n in (1, 5, 150, 700):
        x = rng.normal(0, 1, n)
        x[rng.random(n) < 0.2] = 0.0  # ties (stations set to zero)
        for q in (0.0, 50.0, 80.0, 100.0):
            want = ndi.percentile_filter(x, q, size=size, mode="nearest")
            np.testing.assert_array_equal(running_percentile(x, q, size), want)


def test_running_percentile_random_windows_and_ties():
    """Windows longer than the data, many ties, every percentile: as scipy, sample for sample."""
    from osmobulge.imaging._kernels import running_percentile

    rng = np.random.default_rng(3)
    for t in range(400):
        n, size = int(rng.integers(1, 300)), 2 * int(rng.integers(0, 120)) + 1
        x = np.round(rng.normal(size=n), 1) if t % 2 else rng.normal(size=n)
        q = float(rng.choice([0.0, 10.0, 33.3, 50.0, 80.0, 99.9, 100.0]))
        np.testing.assert_array_equal(running_percentile(x, q, size), ndi.percentile_filter(x, q, size,
                                                                                            mode="nearest"))


def test_running_percentile_refuses_an_even_window():
    from osmobulge.imaging._kernels import running_percentile

    with pytest.raises(ValueError, match="odd"):
        running_percentile(np.arange(5.0), 80.0, 4)


def test_low_contrast_run_equals_the_numpy_figure():
    from osmobulge.imaging._kernels import low_contrast_run

    rng = np.random.default_rng(7)
    for n in (0, 3, 160, 600):
        con = rng.uniform(0.5, 1.0, n)
        con[n // 3: n // 3 + n // 10] *= 0.1  # a gap
        con[rng.random(n) < 0.05] = np.nan
        dome = rng.random(n) < 0.9
        ds = rng.uniform(0.5, 1.5, n)
        cd = np.nan_to_num(con[dome], nan=0.0)
        want = 0.0
        if cd.size:
            win = min(151, 2 * (cd.size // 2) + 1)
            local = np.maximum(ndi.percentile_filter(cd, 80, size=win, mode="nearest"), 0.5 * np.median(cd))
            low = cd < np.maximum(0.3 * local, 3.0 * 0.02)
            run, best = 0.0, 0.0
            for lo_, w in zip(low, ds[dome], strict=True):
                run = run + w if lo_ else 0.0
                best = max(best, run)
            want = best
        assert low_contrast_run(con, dome, ds, 0.02) == pytest.approx(want, rel=1e-12, abs=0)
        if n >= 160:
            assert want > 0.05 * n * 0.9  # the gap is found (not a vacuous comparison)
            assert low_contrast_run(con, dome, ds, np.nan) == 0.0  # np.maximum's nan threshold: nothing is low


def test_nanmedian_equals_numpy():
    from osmobulge.imaging._kernels import nanmedian

    rng = np.random.default_rng(0)
    for n in (1, 2, 7, 100):
        a = rng.normal(size=(n, 3))
        a[rng.random(a.shape) < 0.2] = np.nan
        want = np.nanmedian(a) if np.isfinite(a).any() else np.nan
        assert nanmedian(a) == pytest.approx(want, nan_ok=True, rel=1e-15, abs=0)
    assert np.isnan(nanmedian(np.full(4, np.nan))) and np.isnan(nanmedian(np.zeros(0)))
    assert nanmedian(np.array([3, 1, 2], np.uint16)) == 2.0


def test_median_is_numpys_to_the_bit():
    """One selection instead of numpy's two for an even count: the same value, odd and even counts, ties."""
    from osmobulge.imaging._kernels import median

    rng = np.random.default_rng(1)
    for n in (1, 2, 3, 4, 5, 100, 101, 24552):
        for _ in range(10):
            a = rng.normal(size=n)
            assert median(a) == np.median(a)
            assert median(np.round(a, 1)) == np.median(np.round(a, 1))  # (ties)
    a = rng.normal(size=(12, 2046))
    assert median(a) == np.median(a) and median(np.array([3, 1, 2, 8], np.uint16)) == 2.5


def test_percentile_is_numpys_to_the_bit():
    """numpy's linear percentile by one selection: the same value at both ends, between and at order statistics."""
    from osmobulge.imaging._kernels import percentile

    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 10, 1001, 200_000):
        a = rng.normal(size=n)
        for q in (0.0, 12.3, 50.0, 99.9, 100.0):
            assert percentile(a, q) == np.percentile(a, q), (n, q)
    assert percentile(np.array([[3, 1], [2, 8]], np.uint16), 50.0) == 2.5


def test_upsample_linear_is_the_numpy_interpolation():
    """The compiled block-centre interpolation against its numpy expression (columns, then rows), to the bit,
    for shapes that are and are not multiples of the block."""
    from osmobulge.imaging._kernels import upsample_linear

    def along(coarse, n, block, axis):
        m = coarse.shape[axis]
        x = np.clip((np.arange(n) - 0.5 * (block - 1)) / block, 0.0, m - 1.0)
        i0 = np.minimum(x.astype(int), m - 2)
        t = x - i0
        if axis == 0:
            return coarse[i0] * (1.0 - t)[:, None] + coarse[i0 + 1] * t[:, None]
        return coarse[:, i0] * (1.0 - t) + coarse[:, i0 + 1] * t

    rng = np.random.default_rng(4)
    for shape, block in (((1024, 1024), 4), ((501, 333), 4), ((37, 90), 3), ((8, 8), 4)):
        coarse = rng.normal(size=(-(-shape[0] // block), -(-shape[1] // block)))
        want = along(along(coarse, shape[1], block, 1), shape[0], block, 0)
        assert np.array_equal(upsample_linear(coarse, shape, block), want), shape
    with pytest.raises(ValueError, match="at least 2 blocks"):
        upsample_linear(np.ones((1, 5)), (4, 20), 4)


def test_column_nanmedian_equals_numpy():
    from osmobulge.imaging._kernels import column_nanmedian

    rng = np.random.default_rng(2)
    for n in (1, 2, 7, 8):
        a = rng.normal(size=(n, 300))
        a[rng.random(a.shape) < 0.25] = np.nan  # odd and even counts per column, and empty columns
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            want = np.nanmedian(a, axis=0)
        np.testing.assert_array_equal(column_nanmedian(a), want)
    a = rng.normal(size=(7, 50))
    np.testing.assert_array_equal(column_nanmedian(a), np.median(a, axis=0))


def test_big_endian_frames_are_sampled_like_native_ones():
    """ImageJ writes big-endian TIFFs: the kernels take them (numba needs native byte order)."""
    rng = np.random.default_rng(5)
    frame = (rng.random((30, 40)) * 60000).astype(np.uint16)
    pts, d, offs = np.array([[10.3, 12.7], [20.0, 5.5]]), np.array([[0.6, 0.8], [1.0, 0.0]]), np.linspace(-3, 3, 7)
    np.testing.assert_array_equal(sample_transects(frame.astype(">u2"), 1, pts, d, offs),
                                  sample_transects(frame, 1, pts, d, offs))


@pytest.mark.parametrize("seed", range(6))
def test_robust_profile_spline_equals_numpy_fit(seed):
    """The compiled robust spline: same kept points, curve, length and residuals as the numpy/scipy fit."""
    from osmobulge.imaging.trace import ChamberTracer

    rng = np.random.default_rng(seed)
    R, n = rng.uniform(50, 200), int(rng.integers(30, 500))
    th = np.linspace(np.pi, 0, n)
    U = R * np.cos(th) * rng.uniform(0.8, 1.3)
    Z = R * np.sin(th) * rng.uniform(0.3, 2.5) + rng.normal(0, rng.uniform(0.05, 1.0), n)
    Z[[0, -1]] = 0.0
    Z[rng.integers(5, n - 5, 3)] += rng.uniform(3, 10, 3)  # dust bumps: rejected by both
    ks = rng.uniform(4, 15)
    fast, keep_fast, _ = ChamberTracer._final_fit(U, Z, ks)
    ref, keep_ref = ChamberTracer._robust_fit(U, Z, ks)
    assert not keep_fast.all()
    np.testing.assert_array_equal(keep_fast, keep_ref)
    s = np.linspace(0, ref.length, 57)
    np.testing.assert_allclose(fast(s), ref(s), rtol=0, atol=1e-9)
    assert fast.length == pytest.approx(ref.length, rel=1e-12, abs=0)
    np.testing.assert_allclose(fast.residuals, ref.residuals, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.tangent(s), ref.tangent(s), rtol=0, atol=1e-9)
    _, _, curve = ChamberTracer._final_fit(U, Z, ks, step=1.0)
    np.testing.assert_allclose(curve, ref.sample(step=1.0)[1], rtol=0, atol=1e-9)


def test_final_fit_falls_back_to_scipy_when_the_kernel_cannot_solve(monkeypatch):
    """A status of 1 from the compiled fit (a singular band system) hands over to the numpy/scipy fit."""
    import osmobulge.imaging.trace as T

    th = np.linspace(np.pi, 0, 120)
    U, Z = 80 * np.cos(th), 60 * np.sin(th) + np.random.default_rng(0).normal(0, 0.2, 120)
    want, keep_want = T.ChamberTracer._robust_fit(U, Z, 6.0)
    empty = (np.zeros(8), np.zeros((4, 2)), np.zeros(1), np.zeros(1), np.zeros(1), np.zeros((4, 2)))
    monkeypatch.setattr(T, "robust_profile_spline", lambda *a: (1, np.ones(len(a[0]), bool), *empty))
    spl, keep, curve = T.ChamberTracer._final_fit(U, Z, 6.0)
    np.testing.assert_array_equal(keep, keep_want)
    assert spl.length == pytest.approx(want.length, rel=1e-12, abs=0)
    np.testing.assert_allclose(curve, want.sample(step=1.0)[1], atol=1e-12)


def test_abs_percentile_equals_numpy():
    from osmobulge.imaging._kernels import abs_percentile
    from osmobulge.imaging.geometry import sorted_quantile

    rng = np.random.default_rng(0)
    for n in (1, 2, 7, 400):
        x = rng.normal(0, 3, n)
        m = rng.random(n) < 0.7
        m[0] = True
        for q in (0.0, 50.0, 90.0, 100.0):
            assert abs_percentile(x, m, q) == pytest.approx(np.percentile(np.abs(x[m]), q), rel=1e-12, abs=1e-15)
            # bit for bit the tracer's former band percentile (sorted, then the project's linear quantile)
            assert abs_percentile(x, m, q) == sorted_quantile(np.sort(np.abs(x[m])), q / 100.0)
        x[:5] = x[0]  # ties
        assert abs_percentile(x, m, 90.0) == sorted_quantile(np.sort(np.abs(x[m])), 0.9)
    assert np.isnan(abs_percentile(np.ones(3), np.zeros(3, bool), 90.0))


def test_masked_nanmedian_equals_numpy():
    from osmobulge.imaging._kernels import masked_nanmedian

    rng = np.random.default_rng(1)
    for n in (1, 2, 7, 400):
        x = rng.normal(0, 3, n)
        x[rng.random(n) < 0.2] = np.nan
        ex = rng.random(n) < 0.3
        sel = x[~ex]
        want = np.nanmedian(sel) if np.isfinite(sel).any() else np.nan
        assert masked_nanmedian(x, ex) == pytest.approx(want, rel=0, abs=0, nan_ok=True)
    assert np.isnan(masked_nanmedian(np.ones(3), np.ones(3, bool)))


@pytest.mark.parametrize("reverse", [False, True])
def test_rim_guide_equals_numpy_selection(reverse):
    """The guide from rim to rim: points outside the rim zones, left to right, between the rim points."""
    from osmobulge.imaging._kernels import rim_guide

    R, zc, near = 100.0, 23.0, 14.0
    th = np.linspace(np.pi + 0.3, -0.3, 90)  # reaches beyond both rims, down into the rim zones
    gu = np.c_[1.1 * R * np.cos(th), 80.0 * np.sin(th) + 5.0]
    if reverse:
        gu = gu[::-1].copy()
    u, z = gu[:, 0], gu[:, 1]
    excl = ((np.abs(u) > R - 1.0) & (z < zc)) | (np.hypot(np.abs(u) - R, z) < near)
    assert 0 < excl.sum() < len(gu) - 3
    kept = gu[~excl]
    if kept[0, 0] > kept[-1, 0]:
        kept = kept[::-1]
    want = np.concatenate([[[-R, 0.0]], kept, [[R, 0.0]]])
    ok, got = rim_guide(gu, R, zc, near)
    assert ok
    np.testing.assert_array_equal(got, want)
    ok, got = rim_guide(gu[excl], R, zc, near)  # nothing outside the zones: the caller's straight guide
    assert not ok and got.shape == (0, 2)


def test_cubic_table_fit_equals_the_point_by_point_sums():
    """A fit and its residuals from one table of spans and B-splines: the normal equations of scipy's design
    matrix, and the same bits as the point-by-point evaluation."""
    from scipy.interpolate import BSpline

    from osmobulge.imaging._kernels import _bspl_eval, _cubic_table, _eval_table, _lsq_normal_table

    rng = np.random.default_rng(3)
    x = np.sort(rng.uniform(0, 10, 300))
    x[[0, -1]] = 0.0, 10.0
    y = np.c_[np.sin(x), np.cos(x)] + rng.normal(0, 0.1, (300, 2))
    w = np.where(rng.random(300) < 0.2, 0.0, rng.uniform(0.5, 2, 300))
    t = np.r_[[0.0] * 4, np.sort(rng.uniform(0.5, 9.5, 20)), [10.0] * 4]
    n = len(t) - 4
    spans, B = _cubic_table(t, x)
    ata, aty = np.zeros((n, 4)), np.zeros((n, 2))
    _lsq_normal_table(spans, B, y, w, ata, aty)
    A = BSpline.design_matrix(x, t, 3).toarray() * w[:, None]  # weights multiply the residuals
    full = A.T @ A
    for band in range(4):  # upper bands in columns
        np.testing.assert_allclose(ata[: n - band, band], np.diagonal(full, band), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(aty, A.T @ (y * w[:, None]), rtol=1e-12, atol=1e-12)
    c = rng.normal(size=(n, 2))
    e1, e2 = np.empty((300, 2)), np.empty((300, 2))
    _bspl_eval(t, c, 3, x, e1)
    _eval_table(spans, B, c, e2)
    np.testing.assert_array_equal(e2, e1)


def test_extrapolated_curve_equals_numpy():
    """The tracker's prediction: the last dome moved on as it moved since the one before (equal arc fractions)."""
    from osmobulge.imaging._kernels import extrapolated_curve

    def reference(p, q):
        fp, fq = (np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(c, axis=0).T)))) for c in (p, q))
        if not (fp[-1] > 0 and fq[-1] > 0):
            return p
        x, xq = fp / fp[-1], fq / fq[-1]
        return 2.0 * p - np.column_stack((np.interp(x, xq, q[:, 0]), np.interp(x, xq, q[:, 1])))

    rng = np.random.default_rng(4)
    for n, m in ((300, 280), (50, 51), (5, 400), (2, 2)):
        t, tq = np.sort(rng.uniform(0, np.pi, n)), np.sort(rng.uniform(0, np.pi, m))
        p = np.c_[-100 * np.cos(t), 60 * np.sin(t)]
        q = np.c_[-98 * np.cos(tq), 55 * np.sin(tq)]
        q[m // 2] = q[m // 2 - 1]  # a repeated point (zero-length segment)
        got = extrapolated_curve(p[:, 0].copy(), p[:, 1].copy(), q[:, 0].copy(), q[:, 1].copy())
        np.testing.assert_allclose(got, reference(p, q), rtol=0, atol=1e-9)
    flat = np.zeros((4, 2))
    assert (extrapolated_curve(*flat.T.copy(), *flat.T.copy()) == 0).all()
    assert extrapolated_curve(np.zeros(0), np.zeros(0), *flat.T.copy()).shape == (0, 2)


@pytest.mark.parametrize(("k", "sign"), [(0, 1.0), (1, -1.0), (3, 1.0)])
def test_strongest_edge_equals_numpy_reference(k, sign):
    """The coarse wall search: argmax of the signed gradient of the smoothed row-median (some samples outside)."""
    from osmobulge.imaging._kernels import strongest_edge

    rng = np.random.default_rng(k)
    frame = ndi.gaussian_filter(rng.random((90, 120)), 2.0) * 1000
    view = FrameView(frame, k)
    zs = np.linspace(5.0, 40.0, 9)
    px, py = np.full(9, 30.0) + 0.1 * zs, zs
    d = np.array([np.cos(0.05), np.sin(0.05)])
    for x0 in (30.0, 2.0):  # the second reaches outside the frame on some rows
        offs = np.arange(-12.0, 12.0 + 1e-9, 1.0)
        prof = view.transects(np.c_[px - 30.0 + x0, py], np.broadcast_to(d, (9, 2)), offs)
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            med = np.nanmedian(prof, axis=0)
        grad = sign * np.gradient(ndi.gaussian_filter1d(med, 1.0))
        want = int(np.argmax(grad)) if np.all(np.isfinite(med)) else -1
        got = strongest_edge(frame, k, px - 30.0 + x0, py, np.full(9, d[0]), np.full(9, d[1]), offs, sign)
        assert got == want


@pytest.mark.parametrize(("k", "step"), [(0, 2.0), (2, 4.0), (1, 0.7)])
def test_guide_transects_equal_resample_normals_and_smoothed_samples(k, step):
    """The fused station pass: resample_polyline, polyline_normals, samples nan-filled and smoothed along (scipy)."""
    from osmobulge.imaging._kernels import guide_transects
    from osmobulge.imaging._normals import polyline_normals, resample_polyline

    rng = np.random.default_rng(k)
    frame = ndi.gaussian_filter(rng.random((150, 160)), 1.5) * 4000
    th = np.linspace(np.pi, 0, 40)
    guide = np.c_[80 + 60 * np.cos(th), 120 - 125 * np.sin(th)]  # reaches outside the frame: nan samples filled
    guide = np.insert(guide, 10, guide[10], axis=0)  # a repeated point
    offs = np.arange(-9.0, 9.0 + 1e-9, 0.5)
    pts_r, s_r = resample_polyline(guide, step)
    nrm_r = polyline_normals(pts_r, smooth=2.0 / step)
    raw = sample_transects(frame, k, pts_r, nrm_r, offs)
    assert np.isnan(raw).any()
    prof_r = ndi.gaussian_filter1d(np.where(np.isfinite(raw), raw, np.nanmedian(raw)), 1.0 / step, axis=0,
                                   mode="nearest")
    pts, s, nrm, prof = guide_transects(frame, k, guide, step, offs, 1.0 / step)
    np.testing.assert_allclose(pts, pts_r, rtol=0, atol=1e-9)
    np.testing.assert_allclose(s, s_r, rtol=0, atol=1e-9)
    np.testing.assert_allclose(nrm, nrm_r, rtol=0, atol=1e-9)
    np.testing.assert_allclose(prof, prof_r, rtol=1e-9, atol=1e-6)


@pytest.mark.parametrize("seed", range(8))
def test_revolution_halves_equal_split_halves_and_measures(seed):
    """Compiled revolution_measures against split_halves + revolution_volume/area (overhangs, axis points)."""
    from osmobulge.imaging.geometry import revolution_area, revolution_measures, revolution_volume, split_halves

    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 400))
    th = np.linspace(np.pi, 0, n)
    x = rng.uniform(0.5, 2.0) * np.cos(th) * (1 + rng.uniform(0, 0.6) * np.sin(th) ** 2)  # overhangs its rim
    z = rng.uniform(0.2, 3.0) * np.sin(th) + rng.normal(0, 0.01, n)
    if seed % 3 == 0:
        x[n // 2] = 0.0  # a point on the axis
    if seed % 2:
        x, z = x[::-1], z[::-1]
    for close in (True, False):
        m = revolution_measures(x, z, close=close)
        (rl, zl), (rr, zr) = split_halves(x, z)
        want = (revolution_volume(rl, zl, close=close), revolution_volume(rr, zr, close=close),
                revolution_area(rl, zl), revolution_area(rr, zr), zl[0], rl[-1], rr[-1])
        got = (m.volume_left, m.volume_right, m.area_left, m.area_right, m.height, m.rim_left, m.rim_right)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-14)
    with pytest.raises(ValueError, match="does not cross"):
        revolution_measures(np.abs(x) + 0.1, z)


def _ref_exclusion(tracer, g, u, z):
    """The tracer's former numpy ``_exclusion``."""
    R = g.rim_radius
    zc, near = g.thickness + 3.0, 0.5 * g.thickness + 2.0 + 2.0 * tracer.blur
    return ((np.abs(u) > R - 1.0) & (z < zc)) | (np.hypot(np.abs(u) - R, z) < near)


def _ref_clean(tracer, g, r, ref_con):
    """The tracer's former numpy ``_clean``."""
    from osmobulge.imaging._chamber import _nanmedian

    st = tracer.settings
    mid = r["mid"]
    pts = r["station_pts"] + np.nan_to_num(mid)[:, None] * r["normals"]
    pu, pz = g.line.coords(pts)
    good = np.isfinite(mid) & (r["contrast"] > max(st.min_contrast * ref_con, 4.0 * r.get("noise", 0.0)))
    excl = _ref_exclusion(tracer, g, pu, pz) | _ref_exclusion(tracer, g, *g.line.coords(r["station_pts"]))
    use = good & ~excl
    if use.sum() > 10:
        filled = np.interp(np.arange(len(mid)), np.flatnonzero(use), mid[use])
        med = ndi.median_filter(filled, 15, mode="nearest")
        dev = np.abs(mid - med)
        mad = 1.4826 * _nanmedian(dev[use])
        use &= dev <= max(4.0 * mad, 1.0)
    d2 = np.diff(np.where(use, mid, np.nan), 2)
    d2 = d2[np.isfinite(d2)]
    sigma = 1.4826 * _nanmedian(np.abs(d2)) / np.sqrt(6.0) if d2.size > 10 else st.smoothing
    return pu, pz, good, excl, use, float(np.clip(sigma, 0.01, 3.0))


def _ref_bridge(R, pu, pz, side, reach=40.0):
    """The tracer's former numpy ``_bridge``."""
    du, dz = pu - side * R, pz
    rho = np.hypot(du, dz)
    if rho.size == 0:
        return np.zeros((0, 2))
    rmin = float(rho.min())
    if rmin < 2.0:
        return np.zeros((0, 2))
    near = rho < rmin + reach
    th = np.arctan2(dz[near], side * du[near])
    if near.sum() >= 4:
        x, y = rho[near], np.unwrap(th)
        dx = x - x.mean()
        c1 = float(np.dot(dx, y - y.mean()) / max(float(np.dot(dx, dx)), 1e-300))
        c0 = float(y.mean()) - c1 * float(x.mean())
    else:
        c0, c1 = float(np.median(th)), 0.0
    rr = np.arange(1.0, rmin, 1.0)
    tt = c0 + c1 * rr
    return np.column_stack((side * R + side * rr * np.cos(tt), rr * np.sin(tt)))


@pytest.mark.parametrize("seed", range(6))
def test_clean_and_bridge_equal_numpy_reference(seed):
    """Station cleaning (outliers, rim zones, nan bands) and the rim bridges on a traced dome, against numpy."""
    from dataclasses import replace

    rng = np.random.default_rng(seed)
    from osmobulge.imaging._kernels import rim_bridge, rim_zone
    from osmobulge.imaging.synthetic import render_series
    from osmobulge.imaging.trace import trace_series

    s = render_series([0.0, 0.8 + 0.3 * seed], chamber=(100e-6, 50e-6, 10e-6), shape=(400, 420), seed=seed)
    tr, traces = trace_series(s.frames)
    g = traces[1].geometry
    res = tr.trace_dome(FrameView(s.frames[1], tr.k), g, None)
    r = {k: np.array(res[k]) for k in ("mid", "contrast", "station_pts", "normals")}
    r["noise"] = res["noise"]
    n = len(r["mid"])
    r["mid"] = r["mid"] + rng.normal(0, 0.2, n)
    r["mid"][rng.integers(0, n, 8)] += rng.uniform(-6, 6, 8)  # outliers
    r["mid"][rng.integers(0, n, 4)] = np.nan
    r["contrast"][rng.integers(0, n, 5)] = np.nan
    g = replace(g, line=replace(g.line, angle=rng.uniform(-0.05, 0.05)))
    ref_con = float(np.nanmedian(r["contrast"]))
    want = _ref_clean(tr, g, r, ref_con)
    got = tr._clean(g, dict(r), ref_con)
    for key, w in zip(("pu", "pz", "good", "excluded", "use", "sigma"), want, strict=True):
        np.testing.assert_allclose(got[key], w, rtol=0, atol=1e-9, err_msg=key)
    np.testing.assert_array_equal(rim_zone(got["pu"], got["pz"], g.rim_radius, *tr._exclusion_zone(g)),
                                  _ref_exclusion(tr, g, got["pu"], got["pz"]))
    assert 0 < got["use"].sum() < n
    pu, pz = got["pu"][got["use"]], got["pz"][got["use"]]
    for side in (-1.0, 1.0):
        for sub in (slice(None), slice(0, 3)):  # the line fit, and fewer than 4 points (the median angle)
            b_ref = _ref_bridge(g.rim_radius, pu[sub], pz[sub], side)
            b = rim_bridge(pu[sub], pz[sub], float(g.rim_radius), float(side), 40.0)
            np.testing.assert_allclose(b, b_ref, rtol=0, atol=1e-9)
    assert rim_bridge(pu[:0], pz[:0], float(g.rim_radius), 1.0, 40.0).shape == (0, 2)


def _ref_ellipse_volume(ell, n=721):
    """The ellipse arc above z = 0 as the napari plugin closes it (``plugins._logic._ellipse_arc``), revolved."""
    from types import SimpleNamespace

    from osmobulge.imaging.geometry import revolution_measures
    from osmobulge.plugins._logic import _ellipse_arc

    # the ellipse's own (x, z) frame as the plugin's geometry: axis at the origin, level, z = +y
    arc = _ellipse_arc(ell, SimpleNamespace(axis_point=(0.0, 0.0), angle=0.0, up=(0.0, 1.0)), n)[:, ::-1]
    if len(arc) < 3:
        return np.nan
    try:
        return revolution_measures(arc[:, 0], arc[:, 1]).volume
    except ValueError:
        return np.nan


@pytest.mark.parametrize("seed", range(6))
def test_ellipse_arc_volume_equals_numpy_reference(seed):
    """Domes above, below and across z = 0, tilted and off the axis; every one that reaches the axis has a volume."""
    from osmobulge.imaging.extract import _ellipse_volume
    from osmobulge.imaging.geometry import EllipseFit

    rng = np.random.default_rng(seed)
    finite = 0
    for _ in range(20):
        ell = EllipseFit(center=(rng.normal(0, 5), rng.uniform(-80, 40)), semi_axes=tuple(rng.uniform(20, 150, 2)),
                         angle=rng.uniform(-0.3, 0.3))
        want, got = _ref_ellipse_volume(ell), _ellipse_volume(ell)
        # nan only where the arc above z = 0 does not reach the axis (then no solid of revolution is defined)
        assert (np.isnan(want) and np.isnan(got)) or got == pytest.approx(want, rel=1e-12, abs=0)
        finite += np.isfinite(got)
    assert finite >= 12


@pytest.mark.parametrize("yc_over_b", [-0.95, -0.6, -0.2, 0.0, 0.3, 0.8])
def test_ellipse_volume_is_the_spheroid_cap(yc_over_b):
    """Analytic: the cap above z = 0 of a spheroid (semi-axes a, a, b) centred at height yc on the axis.

    V = pi a^2 (2 b / 3 + yc - yc^3 / (3 b^2)); a dome lower than the hemisphere (centre below the rim line,
    Vtilde < 2/3) included -- the former polygon rule returned nan there.
    """
    from osmobulge.imaging.extract import _ellipse_volume
    from osmobulge.imaging.geometry import EllipseFit

    a, b = 150.0, 90.0
    yc = yc_over_b * b
    want = np.pi * a**2 * (2 * b / 3 + yc - yc**3 / (3 * b**2))
    for angle in (0.0, np.pi):  # the fit may report either orientation of the same ellipse
        got = _ellipse_volume(EllipseFit(center=(0.0, yc), semi_axes=(a, b), angle=angle))
        assert got == pytest.approx(want, rel=5e-5 if yc_over_b > -0.9 else 5e-4, abs=0)  # the polygon: 2e-5, 3e-4


def _ref_ridge_rows(img, w_max=8):
    """The former numpy ``_chamber._ridge_rows``."""
    best = np.zeros(img.shape, np.float32)
    for w in range(1, w_max + 1):
        up = np.roll(img, w, axis=0)
        dn = np.roll(img, -w, axis=0)
        r = 0.5 * (up + dn) - img
        r[:w] = 0
        r[-w:] = 0
        both = np.sign(up - img) == np.sign(dn - img)
        r = np.where(both, r, 0)
        best = np.where(np.abs(r) > np.abs(best), r, best)
    rows = np.argmax(np.abs(best), axis=0)
    return rows, best[rows, np.arange(img.shape[1])]


@pytest.mark.parametrize("shape", [(256, 256), (100, 37), (10, 5), (3, 4)])
def test_ridge_rows_equals_numpy_reference(shape):
    from osmobulge.imaging._chamber import _ridge_rows

    rng = np.random.default_rng(shape[0])
    img = ndi.gaussian_filter(rng.random(shape).astype(np.float32) * 1000, 1.0)
    img[shape[0] // 2: shape[0] // 2 + 3] -= 300  # a dark band
    img[:, 0] = 5.0  # a flat column: no ridge anywhere (row 0, value 0)
    want, got = _ref_ridge_rows(img), _ridge_rows(img)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])


@pytest.mark.parametrize(("dtype", "f"), [(np.uint16, 4), (np.uint16, 2), (np.uint8, 3), (np.float64, 1), (bool, 2),
                                         (np.float32, 4), (np.float32, 2), (np.int32, 5)])
def test_block_mean_equals_numpy(dtype, f):
    from osmobulge.imaging._chamber import _coarse

    rng = np.random.default_rng(f)
    frame = (rng.random((103, 77)) * 60000).astype(dtype) if dtype is not bool else rng.random((103, 77)) < 0.5

    def want(a):
        h2, w2 = a.shape[0] // f * f, a.shape[1] // f * f
        return np.asarray(a[:h2, :w2], np.float32).reshape(h2 // f, f, w2 // f, f).mean(axis=(1, 3))

    for a in (frame, np.rot90(frame)):  # a rotated view is not contiguous
        got = _coarse(a, f)
        assert got.dtype == np.float32 and got.shape == want(a).shape
        np.testing.assert_allclose(got, want(a), rtol=1e-6)
        # the sums in float64 (exact here), times 1 / f^2, rounded once to float32: the unrolled f = 2 and 4
        # loops give the same bits as the general one
        h2, w2 = a.shape[0] // f * f, a.shape[1] // f * f
        sums = np.asarray(a[:h2, :w2], np.float64).reshape(h2 // f, f, w2 // f, f).sum(axis=(1, 3))
        np.testing.assert_array_equal(got, (sums * (1.0 / (f * f))).astype(np.float32))


@pytest.mark.parametrize("k", range(4))
@pytest.mark.parametrize("dtype", [np.uint16, np.uint8, np.float64, np.int32])
def test_view_block_mean_equals_block_mean_of_the_float32_patch(k, dtype):
    """The global guide's block means straight from the frame: the same bits as through the float32 patch."""
    from osmobulge.imaging._kernels import block_mean

    rng = np.random.default_rng(k)
    frame = (rng.random((90, 70)) * (250 if dtype == np.uint8 else 60000)).astype(dtype)
    if dtype == np.float64:
        frame += rng.random(frame.shape) / 3  # not exact in float32: the patch's rounding must stay
    if dtype == np.int32:
        frame *= 1000  # beyond float32's 24 bits
    view = FrameView(frame, k)
    for box in ((5, 61, 3, 50), (-4, 200, -9, 33), (0, view.shape[0], 0, view.shape[1])):
        patch, origin = view.patch(*box)
        got, got_origin = view.block_mean(*box, 4)
        assert got_origin == origin
        np.testing.assert_array_equal(got, block_mean(patch, 4))
    if np.dtype(dtype).kind in "ui" and np.dtype(dtype).itemsize <= 2:
        frame.flags.writeable = False  # a memory-mapped file's frame: the copy is writable, no new kernel type
        np.testing.assert_array_equal(FrameView(frame, k).block_mean(0, 40, 0, 40, 2)[0],
                                      block_mean(view.patch(0, 40, 0, 40)[0], 2))


def test_sobel_rows_equal_the_whole_image_gradient():
    """The orientation's wall score takes the gradient of the strips' rows only: the same bits."""
    from osmobulge.imaging._chamber import _sobel_rows

    img = np.random.default_rng(4).random((40, 33)).astype(np.float32)
    for view in (img, np.rot90(img)):
        full = ndi.sobel(view, axis=1)
        for r0, r1 in ((0, 5), (3, 17), (10, view.shape[0]), (0, view.shape[0]), (view.shape[0] - 1, view.shape[0])):
            np.testing.assert_array_equal(_sobel_rows(view, r0, r1), full[r0:r1])


def test_compiled_on_disk_sees_a_missing_cache(monkeypatch, tmp_path):
    """The first-run progress note: True once the kernels are cached, False when an index file is missing."""
    from osmobulge.imaging import _kernels as K

    index = tmp_path / "index.nbi"
    index.write_bytes(b"")
    for f in (K.robust_profile_spline, K.clean_stations, K._guide_stations, K.dusty_rows, K.revolution_halves):
        monkeypatch.setattr(f._cache._cache_file, "_index_path", str(index))
    assert K.compiled_on_disk() is True
    monkeypatch.setattr(K.dusty_rows._cache._cache_file, "_index_path", str(tmp_path / "missing.nbi"))
    assert K.compiled_on_disk() is False


def _ref_rim_contact(view, line, R, zw, far_left, far_right):
    """The former rim contact figure of ``ChamberTracer._figures`` (numpy)."""
    from osmobulge.imaging._chamber import _nanmedian

    uu = R + np.linspace(0.02, 0.1, 9) * R
    uz = [(u_, np.full(len(u_), z_)) for sgn, far in zip((-1.0, 1.0), (far_left, far_right), strict=True)
          for u_, z_ in ((sgn * uu, 0.0), (far, 0.0), (far, zw))]
    pts = line.point(np.concatenate([q[0] for q in uz]), np.concatenate([q[1] for q in uz]))
    v = np.split(sample_transects(view.frame, view.k, pts, np.zeros_like(pts), np.zeros(1))[:, 0],
                 np.cumsum([len(q[0]) for q in uz])[:-1])
    vals = []
    for k in (0, 3):
        band, band_far, water = (_nanmedian(x) for x in v[k:k + 3])
        den = water - band_far
        vals.append(float((water - band) / den) if np.isfinite(den) and abs(den) > 0 else np.nan)
    return float(min(vals))


@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_rim_contact_equals_numpy_reference(k):
    from osmobulge.imaging._chamber import Line
    from osmobulge.imaging._kernels import rim_contact
    from osmobulge.imaging.trace import _RIM_FRACTIONS

    rng = np.random.default_rng(k)
    frame = (rng.random((90, 120)) * 4000).astype(np.uint16)
    view = FrameView(frame, k)
    h, w = view.shape
    for trial in range(40):
        line = Line(w / 2 + rng.normal(0, 5), h / 2 + rng.normal(0, 5), rng.normal(0, 0.05))
        R = rng.uniform(5, 30)
        # far columns: inside the view, or some (the last trials all) outside it -- nan medians, nan figures
        spread = 0.45 * w if trial < 30 else 3.0 * w
        far_l, far_r = -rng.uniform(R, spread, 15), rng.uniform(R, spread, 11)
        if trial >= 35:  # the left side wholly outside: nan on the left, Python's min keeps it
            far_l = -rng.uniform(3.0 * w, 4.0 * w, 15)
        zw = rng.uniform(3, 12)
        d, nv = line.direction, line.normal
        got = rim_contact(view.frame, view.k, line.x0, line.y0, d[0], d[1], nv[0], nv[1], R, zw, _RIM_FRACTIONS,
                          far_l, far_r)
        want = _ref_rim_contact(view, line, R, zw, far_l, far_r)
        assert (np.isnan(got) and np.isnan(want)) or got == pytest.approx(want, rel=1e-12, abs=1e-15)
    # a flat field: the water and the band far out agree, the figure is nan (no contrast to refer to)
    flat = FrameView(np.full((60, 60), 7, np.uint16), k)
    line = Line(30.0, 30.0, 0.0)
    args = (line.x0, line.y0, *line.direction, *line.normal, 10.0, 5.0, _RIM_FRACTIONS, -np.arange(12.0, 20.0),
            np.arange(12.0, 20.0))
    assert np.isnan(rim_contact(flat.frame, flat.k, *args))


def test_curve_extent_equals_numpy():
    from osmobulge.imaging._chamber import Line
    from osmobulge.imaging._kernels import curve_extent

    rng = np.random.default_rng(3)
    for n in (1, 2, 50):
        u, z = rng.normal(0, 40, n), rng.uniform(-2, 60, n)
        line = Line(*rng.uniform(100, 200, 2), rng.normal(0, 0.1))
        pts = line.point(u, z)
        got = curve_extent(u, z, line.x0, line.y0, *line.direction, *line.normal)
        assert got == (np.max(np.abs(u)), pts[:, 0].min(), pts[:, 0].max(), pts[:, 1].min())
    assert all(np.isnan(curve_extent(np.zeros(0), np.zeros(0), 0.0, 0.0, 1.0, 0.0, 0.0, -1.0)))


@pytest.mark.parametrize("seed", range(4))
def test_profile_ellipse_equals_fit_ellipse_and_its_volume(seed):
    from osmobulge.imaging._kernels import profile_ellipse
    from osmobulge.imaging.extract import _ellipse_volume
    from osmobulge.imaging.geometry import fit_ellipse

    rng = np.random.default_rng(seed)
    for trial in range(30):
        a, b = rng.uniform(20, 200), rng.uniform(20, 200)
        t = np.linspace(rng.uniform(-0.5, 0.3), np.pi - rng.uniform(-0.5, 0.3), int(rng.integers(6, 300)))
        th = rng.normal(0, 0.2)
        x = a * np.cos(t) * np.cos(th) - b * np.sin(t) * np.sin(th) + rng.normal(0, 3)
        y = a * np.cos(t) * np.sin(th) + b * np.sin(t) * np.cos(th) - rng.uniform(0, 0.6) * b
        x, y = x + rng.normal(0, 0.4, x.size), y + rng.normal(0, 0.4, x.size)
        if trial % 5 == 0:
            x[::7] = np.nan  # non-finite points are dropped, as fit_ellipse drops them
        ell = fit_ellipse(np.c_[x, y])
        status, ga, gb, grms, gvol = profile_ellipse(x, y, 721)
        assert status == 0 and ell
        np.testing.assert_allclose([ga, gb, grms], [*ell.semi_axes, ell.rms], rtol=1e-12)
        want = _ellipse_volume(ell)
        assert (np.isnan(gvol) and np.isnan(want)) or gvol == pytest.approx(want, rel=1e-12, abs=0)
    # what the compiled route does not decide goes back to fit_ellipse: too few points, collinear points
    assert profile_ellipse(np.arange(4.0), np.arange(4.0), 721)[0] != 0
    assert profile_ellipse(np.arange(10.0), 2.0 * np.arange(10.0), 721)[0] != 0
    assert not fit_ellipse(np.c_[np.arange(10.0), 2.0 * np.arange(10.0)])


def test_arc_resample_equals_numpy_interp():
    from osmobulge.imaging._kernels import arc_resample

    rng = np.random.default_rng(0)
    for m, n in ((2, 2), (2, 401), (57, 401), (900, 401), (300, 7)):
        u, z = np.cumsum(rng.uniform(0.2, 1.5, m)), np.cumsum(rng.normal(0, 1, m))
        sc = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(u), np.diff(z)))))
        si = np.linspace(0.0, sc[-1], n)
        length, uu, zz = arc_resample(u, z, n)
        assert length == sc[-1]
        np.testing.assert_array_equal(uu, np.interp(si, sc, u))
        np.testing.assert_array_equal(zz, np.interp(si, sc, z))


def test_clear_of_curve_equals_numpy_reference():
    from osmobulge.imaging._kernels import clear_of_curve

    rng = np.random.default_rng(5)
    us = np.arange(-300.0, 300.0, 3.0)
    for trial in range(20):
        u = np.sort(rng.uniform(-250, 250, int(rng.integers(1, 400))))
        z = rng.uniform(-5, 80 if trial % 4 else 5, u.size)
        zmax = 30.0
        low = z < zmax
        want = np.ones(us.size, bool)
        if low.any():  # the former code of ChamberTracer._geometry_at
            lu = np.sort(u[low])
            j = np.searchsorted(lu, us)
            nl = len(lu) - 1
            du = np.minimum(np.abs(us - lu[np.clip(j - 1, 0, nl)]), np.abs(us - lu[np.clip(j, 0, nl)]))
            want = du > 6.0
        np.testing.assert_array_equal(clear_of_curve(us, u, z, zmax, 6.0), want)
    assert clear_of_curve(us, np.zeros(3), np.full(3, 99.0), zmax, 6.0).all()  # no point that low


@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_measure_line_equals_numpy_reference(k):
    """The compiled line fit (line_band) against the former numpy measure_line, on a rendered frame seen rotated."""
    from osmobulge.imaging._chamber import Line, _measure_line_numpy, find_chambers, measure_line

    # the first frame of a series (a flat membrane, what find_chambers takes) with a little noise
    frame = render_frame(0.0, chamber=(150e-6, 110e-6, 20e-6), seed=k, nuisances=Nuisances(noise_sigma=0.02))
    stored = np.rot90(frame, -k).copy()  # stored so that view k shows the bulge up again
    view = FrameView(stored, k)
    g = find_chambers(view)
    rng = np.random.default_rng(k)
    hit = 0
    for trial in range(12):
        # a line near the flat band (a few px and a degree off) or (the last ones) far off it
        dy = rng.uniform(-400, 400) if trial >= 9 else rng.normal(0, 3)
        line = Line(g.line.x0 + rng.normal(0, 3), g.line.y0 + dy, g.line.angle + rng.normal(0, 0.02))
        u = np.r_[np.arange(-500.0, -1.6 * g.rim_radius, 3.0), np.arange(1.6 * g.rim_radius, 500.0, 3.0)]
        for pol in (1, -1):
            kw = {"polarity": pol, "thickness": g.thickness, "window": 0.5 * g.thickness + 8.0}
            got, want = measure_line(view, line, u, **kw), _measure_line_numpy(view, line, u, **kw)
            assert (got[0].x0, got[0].y0, got[0].angle) == pytest.approx((want[0].x0, want[0].y0, want[0].angle),
                                                                       rel=1e-12, abs=1e-12)
            np.testing.assert_allclose(got[1:4], want[1:4], rtol=1e-12, equal_nan=True)
            np.testing.assert_array_equal(got[4], want[4])
            hit += got[4].sum() > 100
    assert hit >= 3  # some lines did find the band


def _ref_walls(tracer, view, line, well):
    """The former ChamberTracer._coarse_walls (numpy) followed by measure_walls: the reference of _walls."""
    from dataclasses import replace

    from osmobulge.imaging._chamber import WALL_WINDOW, measure_walls
    from osmobulge.imaging._kernels import strongest_edge

    g0 = tracer.ref
    top = -0.5 * g0.thickness
    depth = g0.well.depth if np.isfinite(g0.well.depth) else 4 * g0.thickness
    zs = top - np.linspace(0.2, 0.7, 9) * depth
    span = tracer.settings.max_drift
    out = {}
    offs = np.arange(-span, span + 1e-9, 1.0)
    d = line.direction
    dx, dy = np.full(len(zs), d[0]), np.full(len(zs), d[1])
    coarse = well
    for name, u0, slope, sign in (("u_left", well.u_left, well.slope_left, tracer._wall_sign),
                                  ("u_right", well.u_right, well.slope_right, -tracer._wall_sign)):
        p = line.point(u0 + slope * (zs - top), zs)
        j = strongest_edge(view.frame, view.k, p[:, 0], p[:, 1], dx, dy, offs, float(sign))
        if j < 0:
            break
        out[name] = u0 + float(offs[j])
    else:
        coarse = replace(well, **out)
    return measure_walls(view, line, coarse, thickness=g0.thickness, window=WALL_WINDOW)


@pytest.mark.parametrize("seed", range(3))
def test_walls_equal_coarse_search_and_measure_walls(seed, monkeypatch):
    """locate_walls (one call) against the former coarse search + measure_walls.

    Walls predicted off by up to ~30 px, with wrong slopes (a poor first fit:
    measure_walls' second attempt decides) and on lines far off the surface
    (walls lost).
    """
    from dataclasses import replace

    from osmobulge.imaging import trace as T
    from osmobulge.imaging.synthetic import render_series

    status = []
    real = T.locate_walls
    monkeypatch.setattr(T, "locate_walls", lambda *a: status.append(int(real(*a)[0])) or real(*a))
    nu = Nuisances(noise_sigma=0.02, dust_count=40 * (seed > 0), blur_sigma=1.0 + seed, tilt=2.0 * seed)
    s = render_series([0.0, 2.0], chamber=(150e-6, 110e-6, 20e-6), seed=seed, nuisances=nu)
    tr = T.ChamberTracer(s.frames[0])
    rng = np.random.default_rng(seed)
    g = tr.ref
    cases = [(rng.normal(0, 4 if t < 15 else 15, 2), rng.normal(0, 0.05, 2), rng.normal(0, 1)) for t in range(25)]
    cases += [(np.zeros(2), np.array([-sl, sl]), dz) for sl in (0.1, 0.2, 0.3)
              for dz in (0.0, -60.0, 150.0, -400.0, 3000.0)]
    for frame in s.frames:
        view = FrameView(frame, tr.k)
        for du, sl, dz in cases:
            line = g.line.shifted(rng.normal(0, 2), dz)
            well = replace(g.well, u_left=g.well.u_left + du[0], u_right=g.well.u_right + du[1],
                           slope_left=sl[0], slope_right=sl[1])
            got, want = tr._walls(view, line, well), _ref_walls(tr, view, line, well)
            if want[0] is None:
                assert got[0] is None and np.isnan(got[1])
                continue
            w0, w1 = got[0], want[0]
            np.testing.assert_allclose([w0.u_left, w0.u_right, w0.slope_left, w0.slope_right, got[1]],
                                       [w1.u_left, w1.u_right, w1.slope_left, w1.slope_right, want[1]],
                                       rtol=1e-12, atol=1e-12)
    assert set(status) == {0, 1, 2}  # done in one call, walls lost, measure_walls' second attempt


@pytest.mark.parametrize("seed", range(3))
def test_track_pass_equals_refine_clean_and_motion(seed):
    """track_pass (one call) against ChamberTracer._refine (narrow), _clean and the motion percentile."""
    from osmobulge.imaging._kernels import abs_percentile
    from osmobulge.imaging.synthetic import render_series
    from osmobulge.imaging.trace import ChamberTracer

    nu = Nuisances(noise_sigma=0.02, dust_count=30 * seed, blur_sigma=1.0 + 0.5 * seed, tilt=1.5 * seed)
    s = render_series([0.0, 1.0, 1.3, 4.0], chamber=(150e-6, 110e-6, 20e-6), seed=seed, nuisances=nu)
    tr = ChamberTracer(s.frames[0])
    prev = tr.process(s.frames[1], 1)
    rng = np.random.default_rng(seed)
    used = []
    for frame in s.frames[2:]:  # Vtilde 1.3: near the last dome; 4: far from it (the band mostly lost)
        view = FrameView(frame, tr.k)
        g, _ = tr.measure_geometry(view)
        for half in (5.0, 7.5, 10.0):
            # the last dome as the guide, moved off by up to a few px (the band near or beyond the window's end)
            guide = np.c_[prev.u, prev.z + rng.normal(0, 1.5)]
            ref_con = abs(g.contrast)
            got = tr._track_pass(view, g, guide, half, ref_con)
            band = tr._track_band(g)  # the last dome's band (narrower than the flat band's thickness)
            assert band < g.thickness - 1.0
            want = tr._clean(g, tr._refine(view, g, guide, half, dp=False, band=band), ref_con)
            want["motion"] = float(abs_percentile(want["mid"], want["use"], 90.0))
            assert set(got) == set(want)
            for key, v in want.items():
                if isinstance(v, np.ndarray) and v.dtype == bool:
                    np.testing.assert_array_equal(got[key], v, err_msg=key)
                else:
                    np.testing.assert_allclose(got[key], v, rtol=1e-12, atol=1e-12, equal_nan=True, err_msg=key)
            used.append(int(got["use"].sum()))
    assert max(used) > 50  # the band was found along the dome (not in every case)


@pytest.mark.parametrize("seed", range(3))
def test_pass_tail_equals_bridges_final_fit_and_figures(seed):
    """pass_tail (one call) against the former end of _passes: bridges, _final_fit, residual RMS, edge fraction."""
    from osmobulge.imaging._kernels import pass_tail, rim_bridge
    from osmobulge.imaging.synthetic import render_series
    from osmobulge.imaging.trace import ChamberTracer

    nu = Nuisances(noise_sigma=0.02, dust_count=30 * seed, blur_sigma=1.0 + 0.5 * seed)
    s = render_series([0.0, 1.0, 1.2, 3.0], chamber=(150e-6, 110e-6, 20e-6), seed=seed, nuisances=nu)
    tr = ChamberTracer(s.frames[0])
    prev = tr.process(s.frames[1], 1)
    rng = np.random.default_rng(seed)
    checked = 0
    for frame in s.frames[2:]:
        view = FrameView(frame, tr.k)
        g, _ = tr.measure_geometry(view)
        for half in (5.0, 9.0):
            r = tr._track_pass(view, g, np.c_[prev.u, prev.z + rng.normal(0, 1.0)], half, abs(g.contrast))
            use, R = r["use"], g.rim_radius
            if use.sum() < 6:
                continue
            pu, pz = r["pu"][use], r["pz"][use]
            bl, br = (rim_bridge(pu, pz, float(R), side, 40.0) for side in (-1.0, 1.0))
            U = np.concatenate(([-R], bl[:, 0], pu, br[::-1, 0], [R]))
            Z = np.concatenate(([0.0], bl[:, 1], pz, br[::-1, 1], [0.0]))
            ks = float(np.clip(4.0 + 10.0 * r["sigma"], 4.0, 15.0))
            spl, keep, puz = ChamberTracer._final_fit(U, Z, ks)
            inner = keep.copy()
            inner[[0, -1]] = False
            edge = (np.abs(r["lo"]) > r["half"] - 1.0) | (np.abs(r["hi"]) > r["half"] - 1.0)
            status, gU, gZ, gkeep, _, _, gres, _, _, gcurve, rms, ef = pass_tail(
                r["pu"], r["pz"], use, float(R), 40.0, ks, 1.0, r["lo"], r["hi"], float(r["half"]))
            assert status == 0
            np.testing.assert_array_equal(gU, U)
            np.testing.assert_array_equal(gZ, Z)
            np.testing.assert_array_equal(gkeep, keep)
            np.testing.assert_allclose(gcurve, puz, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(gres, spl.residuals, rtol=1e-12, atol=1e-12, equal_nan=True)
            assert rms == pytest.approx(float(np.sqrt(np.mean(spl.residuals[inner] ** 2))), rel=1e-12, abs=0)
            assert ef == float(np.mean(edge[use]))
            checked += 1
    assert checked >= 2


def test_stored_profile_ellipse_subsamples_as_linspace():
    """At most 200 points, np.linspace(0, n - 1, m).astype(int) of them; nothing for a flat or nan profile."""
    from osmobulge.imaging._kernels import profile_ellipse, stored_profile_ellipse

    rng = np.random.default_rng(1)
    for n in (5, 37, 200, 201, 777, 1999):
        t = np.linspace(0.1, np.pi - 0.1, n)
        u, z = 80 * np.cos(t) + rng.normal(0, 0.3, n), 60 * np.sin(t) - 20 + rng.normal(0, 0.3, n)
        sel = np.linspace(0, n - 1, min(n, 200)).astype(int)
        np.testing.assert_equal(stored_profile_ellipse(u, z, 200, 721), profile_ellipse(u[sel], z[sel], 721))
    flat = np.linspace(-50, 50, 300)
    assert stored_profile_ellipse(flat, 0.4 * np.sin(flat), 200, 721)[0] == 3  # spans <= 1 px in z
    z = 60 * np.sin(np.linspace(0.1, 3.0, 300))
    z[7] = np.nan
    assert stored_profile_ellipse(flat, z, 200, 721)[0] == 3  # np.ptp is nan: no ellipse
    assert stored_profile_ellipse(np.zeros(0), np.zeros(0), 200, 721)[0] == 3


@pytest.mark.parametrize("n", [11, 14, 15, 16, 40, 333])
def test_clean_stations_running_median_short_and_tied(n):
    """The sliding-window median of clean_stations is ndi.median_filter(win 15, nearest): short runs, ties."""
    from osmobulge.imaging._chamber import _nanmedian
    from osmobulge.imaging._kernels import clean_stations

    rng = np.random.default_rng(n)
    for ties in (False, True):
        mid = rng.normal(0, 1.0, n)
        if ties:
            mid = np.round(mid)  # many equal values in every window
        mid[rng.integers(0, n, max(1, n // 10))] += rng.choice([-6.0, 6.0])  # outliers to reject
        con = np.full(n, 10.0)
        x = np.linspace(-500.0, 500.0, n)  # stations on a line far from the rims (R = 10 px at the origin)
        y = np.full(n, -300.0)
        zero, one = np.zeros(n), np.ones(n)
        pu, pz, good, excl, use, _ = clean_stations(mid, con, x, y, zero, -one, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0,
                                                    10.0, 3.0, 4.0, 1.0, 15)
        assert good.all() and not excl.any()
        dev = np.abs(mid - ndi.median_filter(mid, 15, mode="nearest"))
        want = dev <= max(4.0 * 1.4826 * _nanmedian(dev), 1.0)
        np.testing.assert_array_equal(use, want)
        assert not want.all()  # some outliers were rejected


def test_lsq_spline_with_as_few_distinct_points_as_coefficients():
    """Four distinct weighted points and interior knots: one cubic through them (it once looped forever)."""
    from osmobulge.imaging._kernels import lsq_spline

    x = np.linspace(0, 1, 20)
    w = np.r_[1, 1, [0] * 16, 1, 1]
    t = np.r_[[0.0] * 4, 0.25, 0.5, 0.75, [1.0] * 4]
    spl = lsq_spline(x, x**2, t, w)
    np.testing.assert_allclose(spl(x), x**2, rtol=0, atol=1e-9)  # x^2 is a cubic: reproduced exactly
    for n_w in (5, 6, 9):  # a few more points: some interior knots stay
        w = np.zeros(20)
        w[np.r_[0:2, 20 - (n_w - 2):20]] = 1.0
        np.testing.assert_allclose(lsq_spline(x, x**2, t, w)(x), x**2, rtol=0, atol=1e-9)


def test_line_points_scalar_and_array_agree():
    """Line.point's one-point path, its array path, coords and shifted are one geometry (bit for bit)."""
    from osmobulge.imaging._chamber import Line

    rng = np.random.default_rng(7)
    for _ in range(200):
        line = Line(*rng.uniform(-500, 1500, 2), rng.uniform(-np.pi, np.pi))
        u, z = rng.normal(0, 300, 2)
        one = line.point(float(u), float(z))
        arr = line.point(np.array([u]), np.array([z]))[0]
        np.testing.assert_array_equal(one, arr)
        np.testing.assert_array_equal(line.direction, [np.cos(line.angle), np.sin(line.angle)])
        np.testing.assert_array_equal(line.normal, [np.sin(line.angle), -np.cos(line.angle)])
        sh = line.shifted(u, z)
        np.testing.assert_array_equal([sh.x0, sh.y0], one)
        # back to line coordinates, and a point of the shifted line is the same view point
        cu, cz = line.coords(one[None, :])
        assert cu[0] == pytest.approx(u, abs=1e-9) and cz[0] == pytest.approx(z, abs=1e-9)
        np.testing.assert_allclose(sh.point(1.5, -2.0), line.point(u + 1.5, z - 2.0), rtol=0, atol=1e-9)
    # float32 fields (a caller's): both paths compute in float64
    line = Line(np.float32(100.1), np.float32(50.3), 0.3)
    np.testing.assert_array_equal(line.point(1.0, 2.0), line.point(np.array([1.0]), np.array([2.0]))[0])
    assert line.point(1.0, 2.0).dtype == np.float64 and isinstance(line.shifted(1.0, 2.0).x0, float)
