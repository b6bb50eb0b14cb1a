"""Walls from their silhouettes on the optics looks, against the rendered well radius (issue 16)."""

import numpy as np
import pytest
from scipy import ndimage

from osmobulge.imaging._chamber import ChamberNotFound
from osmobulge.imaging._silhouette import (
    _aligned_misfits,
    _changed_rows,
    _outside_levels,
    _strongest,
    _wall_pair,
    _wall_side,
    find_walls,
)
from osmobulge.imaging.looks import LOOKS, render_look
from osmobulge.imaging.optics import Optics, render_optical

# every preset whose walls show as silhouettes (bright field); dark field must refuse
BRIGHT_FIELD = ["absorbing_band", "edge_dark", "edge_bright", "halo", "no_grey_step", "defocus", "inverted",
                "film_10um", "film_26um", "coarse_2um", "uneven_8bit"]


@pytest.mark.parametrize("name", BRIGHT_FIELD)
def test_rim_radius_within_half_a_pixel(name):
    look = LOOKS[name]
    p = look.pixel_size
    a, h, l0 = look.chamber
    s = render_look(name, [0.0], shape=(700, 900))
    tr = s.truth.isel(time=0)
    w = find_walls(s.frames[0], l0 / p, depth_px=h / p)
    assert abs(w.rim_radius - float(tr.rim_radius) / p) < 0.5
    assert abs(w.axis_col - float(tr.axis_x)) < 0.5
    # the top face: l0/2 above the flat mid-surface
    assert abs(w.top_row - (float(tr.rim_y) - 0.5 * l0 / p)) < 0.5


def test_dark_field_is_refused_not_measured():
    s = render_look("dark_field", [0.0], shape=(700, 900))
    with pytest.raises(ChamberNotFound, match="not straight|top face|silhouette"):
        find_walls(s.frames[0], 20e-6 / 0.8e-6, depth_px=110e-6 / 0.8e-6)


def test_bad_input():
    with pytest.raises(ValueError, match="2-D"):
        find_walls([[[0.0]]], 10)
    with pytest.raises(ValueError, match="l0_px"):
        find_walls([[0.0, 1.0]], -1)
    import numpy as np

    with pytest.raises(ChamberNotFound, match="uniform"):
        find_walls(np.ones((50, 50)), 10)


def _wall_scene(p, lam, a=200e-6, h=110e-6, l0=20e-6):
    """A flat chamber rendered on its own (no noise), the axis at a column centre, the top face on row 60."""
    rows, cols = int(120 + h / p), int(2 * a / p + 100)
    ax = cols / 2

    def to_scene(c, r):
        return (c - ax) * p, (60.0 - r) * p + 0.5 * l0

    rho = np.linspace(0.0, 1.0, 200)
    img = render_optical((rows, cols), to_scene, [(0.0, rho * lam, 0.0 * rho, np.ones_like(rho), lam)], a, h, l0, p,
                         Optics(), blur_sigma=0.5)
    return img.astype(float), ax


@pytest.mark.parametrize("p", [0.8e-6, 2e-6])
def test_a_wall_is_rendered_where_it_is_whatever_its_position(p):
    """The left wall's edge in a base row (half-way between the light outside and the zone's darkest) against
    the wall's radius there, as the wall moves by fractions of a sub-sample (lambda_pre).  Point-sampled
    silhouettes put it 0.24-0.5 px outside, in a staircase (measured); now within 0.04 px."""
    a, h, l0 = 200e-6, 110e-6, 20e-6
    for lam in (1.0, 1.0005, 1.001, 1.002, 1.004):
        img, ax = _wall_scene(p, lam)
        row = int(60 + l0 / p + 0.3 * h / p)
        w = (60 - row) * p + 0.5 * l0
        wall = ax - (a + (a * lam - a) * (w + 0.5 * l0 + h) / h) / p
        prof = img[row]
        level = 0.5 * (prof[0] + prof[int(wall) + 1 : int(wall) + 6].min())
        k = int(np.argmax(prof < level))
        edge = k - 1 + (prof[k - 1] - level) / (prof[k - 1] - prof[k])
        assert abs(edge - wall) < 0.06, (lam, edge - wall)


@pytest.mark.parametrize("p", [0.8e-6, 2e-6])
def test_rim_radius_unbiased_as_the_wall_moves(p):
    """find_walls on a lone flat chamber (no noise) as the rim moves by fractions of a pixel: the rim radius
    within 0.12 px of the truth (measured: -0.10 .. +0.04 px; half of the peak of |deviation| gave up to
    0.35 px, as the light outside the wall sits above the local mean)."""
    a, h, l0 = 200e-6, 110e-6, 20e-6
    for lam in (1.0, 1.0005, 1.001, 1.002, 1.004):
        img, _ = _wall_scene(p, lam)
        w = find_walls(img * 6e4, l0 / p, depth_px=h / p)
        assert abs(w.rim_radius - a * lam / p) < 0.12, (lam, w.rim_radius - a * lam / p)


def test_the_top_face_is_a_line_not_a_step():
    """A faint blurred face line above a full-width step of the light (a turbid base): the line is the face."""
    from scipy import ndimage

    from osmobulge.imaging._silhouette import _top_face

    rows = np.arange(400.0)[:, None]
    img = np.ones((400, 600)) * np.where(rows < 225.5, 1.0, 0.7)  # the base 30 % darker from row 225.5
    img = img - 0.15 * np.exp(-0.5 * ((rows - 200.0) / 1.2) ** 2)  # the face: a 15 % line at row 200
    img = ndimage.gaussian_filter(img, 1.0) + np.random.default_rng(0).normal(0, 0.005, img.shape)
    bg = ndimage.gaussian_filter(img, 25.0, mode="nearest")
    d = np.abs(img - bg) / bg
    d /= np.percentile(d, 99.5)
    assert abs(_top_face(d, 25.0) - 200.0) > 3  # the deviation's row score alone takes the step's ramp (7.8 px)
    assert abs(_top_face(d, 25.0, img) - 200.0) < 0.3


def test_the_top_face_of_a_thin_film_on_a_turbid_base_with_the_thickness_guessed():
    """A 10 um film (12.5 px) on a turbid base, searched with the 25 px guess of an unknown thickness: the
    level 14-24 px below the top face lies in the darker base, so the guess alone scores the face 0."""
    from osmobulge.imaging._facetrace import _relative
    from osmobulge.imaging._silhouette import FlatMaps, _top_face
    from osmobulge.imaging.synthetic import render_series

    look = LOOKS["turbid_base"]
    s = render_series([0.0], optics=look.optics, nuisances=look.nuisances, chamber=(200e-6, 110e-6, 10e-6),
                      pixel_size=0.8e-6, shape=(700, 900), seed=2)
    img = np.asarray(s.frames[0], float)
    true = s.truth.attrs["anchor_row"] - 6.25
    d = FlatMaps(img, _relative(img)).size  # |deviation| from the local light, scaled
    assert abs(_top_face(d, 25.0, img) - true) < 0.3  # (measured 0.06 px; was 107 px off)
    w = find_walls(img, 25.0, depth_px=137.5)
    assert abs(w.rim_radius - 250.0) < 0.5


def test_the_shared_maps_give_each_turn_what_find_walls_finds_on_it_alone():
    """FlatMaps (the light, deviation and row scores computed once, turned per view) against find_walls on each
    turned frame by itself: the same walls in all four views; the half-turned views' row scores are the
    unturned ones reversed (exactly: the columns a multiple of four, odd median windows)."""
    from osmobulge.imaging._facetrace import _relative
    from osmobulge.imaging._silhouette import FlatMaps, _line_score

    look = LOOKS["edge_dark"]
    p = look.pixel_size
    _, h, l0 = look.chamber
    s = render_look("edge_dark", [0.0], shape=(700, 900))
    img = np.asarray(s.frames[0], float)
    maps = FlatMaps(img, _relative(img))
    for k in range(4):
        view = np.rot90(img, k)
        rows, line = maps.scores(k, l0 / p)
        np.testing.assert_allclose(line, _line_score(view, l0 / p), rtol=0, atol=1e-12)
        np.testing.assert_allclose(rows, np.percentile(np.rot90(maps.size, k), 15, axis=1), rtol=0, atol=0)
        try:
            alone = find_walls(view, l0 / p, depth_px=h / p, light=_relative(view))
        except ChamberNotFound as err:
            with pytest.raises(ChamberNotFound, match=str(err)[:30]):
                find_walls(None, l0 / p, depth_px=h / p, maps=(maps, k))
            continue
        shared = find_walls(None, l0 / p, depth_px=h / p, maps=(maps, k))
        assert shared == alone, k
    upright = find_walls(None, l0 / p, depth_px=h / p, maps=(maps, 0))
    assert abs(upright.rim_radius - float(s.truth.isel(time=0).rim_radius) / p) < 0.5  # (the well, not a stray)


# ---------------------------------------------------------------------- the compiled loops against numpy/scipy
# The straightforward numpy/scipy expressions the module's kernels replace (as they were written before), and
# the kernels checked against them: on a rendered frame in its four turns and on random data (ties, nan).


def _line_score_reference(img, l0_px):
    from scipy import ndimage

    h, w = img.shape
    s = img[:, : w - w % 4].reshape(h, -1, 4).mean(axis=2)
    best = np.zeros(h)
    for thick in (l0_px, 0.5 * l0_px, 0.25 * l0_px):
        gap, win = max(int(round(0.55 * thick)), 2), max(int(round(0.4 * thick)), 3) | 1
        off = gap + win // 2
        if off >= h:
            continue
        med = ndimage.median_filter(s, size=(win, 1), mode="nearest")
        up = np.r_[np.repeat(med[:1], off, axis=0), med[:-off]]
        dn = np.r_[med[off:], np.repeat(med[-1:], off, axis=0)]
        a = s / np.maximum(up, 1e-12) - 1.0
        b = s / np.maximum(dn, 1e-12) - 1.0
        r = np.where(a * b > 0, np.minimum(np.abs(a), np.abs(b)), 0.0)
        best = np.maximum(best, np.percentile(r, 15, axis=1))
    return best


def _scaled_deviation_reference(img, bg):
    sd = (img - bg) / np.maximum(bg, 1e-6 * max(float(bg.max()), 1e-30))
    return sd / np.percentile(np.abs(sd), 99.5)


def _half_crossings_reference(prof, pk, base=None):
    n, m = prof.shape
    rows = np.arange(n)
    top = prof[rows, pk]
    half = 0.5 * (top + (0.0 if base is None else base))
    k = np.arange(m)[None, :]
    below = (k > pk[:, None]) & ~(prof > half[:, None])
    j = np.argmax(below, axis=1)
    ok = (top > half) & below[rows, j]
    jm = np.maximum(j - 1, 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = jm + (prof[rows, jm] - half) / (prof[rows, jm] - prof[rows, j])
    return np.where(ok, e, np.nan)


def _wall_edges_reference(sd, c):
    import warnings

    n, m = sd.shape
    rows = np.arange(n)
    lo = max(c - 3, 0)
    pk = lo + np.argmax(np.abs(sd[:, lo : c + 4]), axis=1)
    prof = np.sign(sd[rows, pk])[:, None] * sd
    e = _half_crossings_reference(prof, pk)
    idx = np.round(np.nan_to_num(e, nan=-100.0)).astype(int)[:, None] + np.arange(4, 13)[None, :]
    valid = (idx >= 0) & (idx < m) & np.isfinite(e)[:, None]
    outside = np.where(valid, prof[rows[:, None], np.clip(idx, 0, m - 1)], np.nan)
    enough = valid.sum(axis=1) >= 4
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        base = np.nanmedian(outside, axis=1)
    e2 = _half_crossings_reference(prof, pk, np.where(enough, base, 0.0))
    return np.where(enough & np.isfinite(e2), e2, e)


@pytest.fixture(scope="module")
def flat_frame():
    """A rendered flat frame (edge_dark) and its local light."""
    from osmobulge.imaging._facetrace import _relative

    img = np.asarray(render_look("edge_dark", [0.0], shape=(700, 900)).frames[0], float)
    return img, _relative(img)


def test_line_score_is_the_numpy_expression(flat_frame):
    from osmobulge.imaging._silhouette import _line_score

    img, _ = flat_frame
    for k in range(4):
        for l0 in (25.0, 12.5, 60.0):
            np.testing.assert_allclose(_line_score(np.rot90(img, k), l0), _line_score_reference(np.rot90(img, k), l0),
                                       rtol=0, atol=1e-12)
    rng = np.random.default_rng(3)
    for trial in range(20):
        img = rng.random((rng.integers(5, 200), rng.integers(4, 150))) * 100
        if trial % 2:  # ties
            img = np.round(img / 10)
        if trial % 5 == 4:  # not finite: scipy's median filter
            img[rng.integers(img.shape[0]), rng.integers(img.shape[1])] = np.nan
        for l0 in (3.0, 10.0, 25.0, 40.0):
            np.testing.assert_allclose(_line_score(img, l0), _line_score_reference(img, l0), rtol=0, atol=1e-12)


def test_scaled_deviation_is_the_numpy_expression(flat_frame):
    from osmobulge.imaging._silhouette import _scaled_deviation

    img, light = flat_frame
    crop = (slice(300, 401), slice(150, 729))  # (a tracked frame's: float32 light, as SilhouetteTracer keeps it)
    cases = [(img, light), (img[crop], np.asarray(light[crop].astype(np.float32), float))]
    rng = np.random.default_rng(4)
    for trial in range(12):
        a = rng.random((rng.integers(2, 300), rng.integers(2, 300))) * 100
        bg = a * rng.uniform(0.5, 1.5, a.shape)
        if trial % 4 == 1:
            bg[0, 0] = 0.0  # light below the floor
        if trial % 4 == 2:
            a[1, 1] = np.nan
        cases.append((a, bg))
    for a, bg in cases:
        with np.errstate(invalid="ignore"):
            sd, size = _scaled_deviation(a, bg)
            ref = _scaled_deviation_reference(a, bg)
        np.testing.assert_array_equal(sd, ref)
        np.testing.assert_array_equal(size, np.abs(ref))


def test_wall_edges_are_the_numpy_expression(flat_frame):
    from osmobulge.imaging._silhouette import FlatMaps, _wall_edges

    maps = FlatMaps(*flat_frame)
    rng = np.random.default_rng(5)
    strips = [np.rot90(maps.deviation, k)[r0 : r0 + 80] for k in range(4) for r0 in (100, 400)]
    for _ in range(6):
        sd = rng.normal(0, 1, (rng.integers(1, 60), rng.integers(2, 80)))
        sd[rng.random(sd.shape) < 0.03] = np.nan
        strips.append(sd)
    for sd in strips:
        m = sd.shape[1]
        for c in sorted({0, 2, m // 3, m // 2, m - 5, m - 1} & set(range(m))):
            for v in (sd, sd[:, ::-1]):
                np.testing.assert_array_equal(_wall_edges(v, c), _wall_edges_reference(v, c))


def test_percentiles_and_medians_are_numpys():
    from scipy import ndimage

    from osmobulge.imaging._silhouette import (
        _column_medians,
        _percentile_rows,
        _rank,
        _running_median,
        _size_percentile,
    )

    rng = np.random.default_rng(6)
    for trial in range(30):
        h, w = rng.integers(1, 120), rng.integers(1, 120)
        a = rng.random((h, w))
        if trial % 3 == 1:
            a = np.round(a * 4)  # ties
        if trial % 3 == 2:
            a = np.cumsum(a, axis=0)  # sorted columns
        if trial % 5 == 4:
            a[rng.integers(h), rng.integers(w)] = np.nan
        for v in (a, a.T, np.rot90(a), a[:, ::-1]):  # (rows and columns of the stored array)
            for q in (0, 15, 50, 99.5, 100):
                np.testing.assert_array_equal(_percentile_rows(v, q), np.percentile(v, q, axis=1))
            np.testing.assert_array_equal(_column_medians(v), np.median(v, axis=0))
        if not np.isnan(a).any():
            for win in (3, 5, 7, 11, 21):
                out = np.empty_like(a)
                _running_median(a, win, out)
                np.testing.assert_array_equal(out, ndimage.median_filter(a, size=(win, 1), mode="nearest"))
    for trial in range(8):  # large enough to be sampled
        a = rng.random((200, 150 + trial)) * 100
        bg = a * rng.uniform(0.9, 1.1, a.shape)
        if trial == 1:
            bg[5, 5] = -1.0
        if trial in (2, 3):
            (a if trial == 2 else bg)[7, 7] = np.nan
        if trial == 4:
            a[:100], bg[:100] = 5.0, 5.0  # ties at 0
        floor = 1e-6 * max(float(bg.max()), 1e-30)
        for q in (0, 15, 50, 99.5, 100):
            got = _size_percentile(a, bg, *_rank(a.size, q))
            np.testing.assert_array_equal(got, (floor, np.percentile(np.abs((a - bg) / np.maximum(bg, floor)), q)))


def test_clipped_wall_line_is_the_numpy_rule():
    """_clipped_line (compiled) gives what the rule says in numpy: the line through the finite points, again
    without those more than max(3 std, 0.3) px off it, read at the base row, with the kept points' rms; an
    outlier row (a speck on the wall) is dropped and does not move the wall."""
    from osmobulge.imaging._silhouette import _clipped_line

    rng = np.random.default_rng(7)
    for trial in range(60):
        x = np.arange(300.0, 300.0 + rng.integers(6, 120))
        y = rng.uniform(100, 900) + rng.normal(0.0, 0.02) * x + rng.normal(0.0, rng.uniform(0.02, 0.5), x.size)
        y[rng.random(x.size) < 0.1] = np.nan
        if trial % 3 == 0:
            y[int(rng.integers(0, x.size))] += 6.0  # (a speck)
        ok = np.isfinite(y)
        xo, yo = x[ok], y[ok]
        r = yo - np.polyval(np.polyfit(xo, yo, 1), xo)
        keep = np.abs(r) <= max(3.0 * np.std(r), 0.3)
        line = np.polyfit(xo[keep], yo[keep], 1)
        want_rms = np.sqrt(np.mean((yo[keep] - np.polyval(line, xo[keep])) ** 2))
        at, rms, n = _clipped_line(x, y, 290.0)
        assert n == ok.sum()
        np.testing.assert_allclose([at, rms], [np.polyval(line, 290.0), want_rms], rtol=0, atol=1e-9)
    # a clean wall with one speck: the wall is where the clean rows put it
    x = np.arange(300.0, 360.0)
    y = 500.0 + 0.01 * (x - 300.0) + rng.normal(0.0, 0.1, x.size)
    clean = _clipped_line(x, y, 290.0)[0]
    y[20] += 8.0
    assert abs(_clipped_line(x, y, 290.0)[0] - clean) < 0.02
    assert _clipped_line(x, np.full(x.size, np.nan), 290.0)[2] == 0


def _zone(x, wall, side, width=15.0):
    """A wall's silhouette zone as the column score shows it: sharp at the wall, fading into the well (on the side
    ``-side``: a left wall's (side -1) zone lies right of it), blurred by 1.5 px."""
    inside = -side * (x - wall)
    return ndimage.gaussian_filter1d(np.where(inside >= 0, np.exp(-inside / width), 0.0), 1.5)


def test_a_walls_zone_falls_sharply_on_the_walls_side():
    x = np.arange(400.0)
    for wall, side in ((100.0, -1), (300.0, 1)):
        z = _zone(x, wall, side)
        assert _wall_side(z, int(np.argmax(z))) == side
    # a symmetric, flat-topped zone (saturated): no side, wherever its peak column falls in the top
    top = np.clip(2.0 * np.exp(-0.5 * ((x - 200.0) / 8.0) ** 2), 0.0, 1.0)
    assert {_wall_side(top, c) for c in np.flatnonzero(top >= 1.0)} == {0}


def test_the_wall_pair_is_one_wells_not_the_base_between_two_wells():
    """Three zones of about one strength (this well's two walls and a neighbouring well's left one, as on
    ho_blind_1206c): the two strongest, this well's right wall and the neighbour's left one, face away from each
    other (the base between two wells), so the pair is the left and right wall next to each other."""
    x = np.arange(1024.0)
    score = 2.0 * (0.95 * _zone(x, 362.0, -1) + _zone(x, 662.0, 1) + _zone(x, 792.0, -1))
    strongest = sorted(_strongest(score, x.size, 40))  # (the wrong pair: this well's left wall is the weakest)
    assert abs(strongest[0] - 662) <= 4 and abs(strongest[1] - 792) <= 4
    left, right = _wall_pair(score, x.size, 40)
    assert abs(left - 362) <= 4 and abs(right - 662) <= 4
    # one well's zones whose sides are unknown (symmetric): the two strongest, as always
    sym = np.exp(-0.5 * ((x - 300.0) / 6.0) ** 2) + np.exp(-0.5 * ((x - 700.0) / 6.0) ** 2)
    assert _wall_pair(sym, x.size, 40) == [300, 700]
    # two zones facing away from each other and nothing else: refused, not paired
    with pytest.raises(ChamberNotFound, match="side by side"):
        _wall_pair(2.0 * (_zone(x, 300.0, 1) + _zone(x, 700.0, -1)), x.size, 40)


def test_wells_side_by_side_closer_than_min_width_are_not_read_as_one():
    """Three wells whose walls between them are 30 px thick (wells 40 um apart at 1.6 um/px), each wall's zone of
    one strength: find_walls' min_width (40 px) merges each pair of inner zones, and the two strongest were the
    first well's left wall and the third's right one (measured blind: one well of 3.3x the radius, the flat frame
    ok with that rim).  A right wall's zone followed by a left one between them is the base between two wells:
    the pair is the well nearest the field's centre; with the radius known, the pair of that radius."""
    x = np.arange(1024.0)
    walls = [(208.0, -1), (391.0, 1), (421.0, -1), (603.0, 1), (633.0, -1), (816.0, 1)]
    score = 2.0 * sum((1.0 if k in (0, 5) else 0.98) * _zone(x, c, side) for k, (c, side) in enumerate(walls))
    assert sorted(_strongest(score, x.size, 40)) == [pytest.approx(208, abs=4), pytest.approx(816, abs=4)]
    left, right = _wall_pair(score, x.size, 40)
    assert abs(left - 421) <= 4 and abs(right - 603) <= 4
    # two left walls' zones, then two right ones (no base between two wells between the strongest): the zones
    # alone take the outer two; the radius (91 px) the pair of it
    odd = 2.0 * (_zone(x, 100.0, -1) + 0.95 * _zone(x, 300.0, -1) + 0.95 * _zone(x, 482.0, 1) + _zone(x, 900.0, 1))
    left, right = _wall_pair(odd, x.size, 40)
    assert abs(left - 100) <= 4 and abs(right - 900) <= 4
    left, right = _wall_pair(odd, x.size, 40, radius_px=91.0)
    assert abs(left - 300) <= 4 and abs(right - 482) <= 4
    # one well alone (no zones between its walls): as before, with or without its radius
    one = 2.0 * (_zone(x, 300.0, -1) + _zone(x, 700.0, 1))
    pair = _wall_pair(one, x.size, 40)
    assert pair == _wall_pair(one, x.size, 40, radius_px=200.0) and abs(pair[0] - 300) <= 4 and abs(pair[1] - 700) <= 4


def test_rows_where_a_wall_changed_beyond_its_shift_are_left_out_of_its_line():
    """_changed_rows on 60 rows of two walls' zones (dark lines 0.5 deep, 2 px wide, 3 px inside edges at columns
    30 and 90), leaned 1.3 px outwards since the first frame, with noise of 0.02: nothing left out.  A particle
    (0.3 darker, 8 px across) 7 px outside the right wall takes out its rows there (and 2 either side) and no
    others, as does one over the right wall's edge from the well's side (which a shift of the row does not
    explain); a change both walls' outsides share (their halos moved, 5x the noise) takes out none; a particle
    over most of a wall's rows leaves its rows all in (too few would be left to fit a line)."""
    rng = np.random.default_rng(3)
    n, m = 60, 120
    yy, xx = np.mgrid[:n, :m].astype(float)

    def zones(shift):
        return -0.5 * (np.exp(-0.5 * ((xx - 33 + shift) / 2) ** 2) + np.exp(-0.5 * ((xx - 87 - shift) / 2) ** 2))

    then = zones(0.0)
    now = zones(1.3) + 0.02 * rng.standard_normal((n, m))
    left, right = np.full(n, 30.0 - 1.3), np.full(n, 90.0 + 1.3)
    assert not np.concatenate(_changed_rows(now, then, left, right)).any()
    for row, col in ((20, 98.3), (35, 88.0)):  # (outside the right wall; over its edge from inside)
        particle = -0.3 * (np.hypot(yy - row, xx - col) <= 4)
        g_left, g_right = _changed_rows(now + particle, then, left, right)
        assert not g_left.any()
        assert set(np.flatnonzero(g_right)) <= set(range(row - 6, row + 7)) and np.count_nonzero(g_right) >= 5
    shared = now + 5 * 0.02 * (np.abs(xx - 60) > 34)  # (both walls' outsides alike)
    assert not np.concatenate(_changed_rows(shared, then, left, right)).any()
    big = now - 0.3 * ((yy < 45) & (xx > 93))  # (45 of the right wall's 60 rows)
    g_left, g_right = _changed_rows(big, then, left, right)
    assert not g_left.any() and not g_right.any()


def test_the_aligned_misfits_are_numpys():
    """_aligned_misfits (compiled) against the numpy expression: per row, the least mean square of ``now - then``
    shifted over the window of ``half`` px either side of the rounded edge, whole shifts within ``reach`` (skipped
    where the shifted window leaves the row), then tenths within 1 px of the best whole one (np.interp; skipped
    where they reach past the row); nan without an edge or with the window off the row."""
    rng = np.random.default_rng(7)
    now, then = rng.standard_normal((30, 60)), rng.standard_normal((30, 60))
    then[5] = np.roll(now[5], 3)  # (a row that is a shift of the other: its misfit ~0 at -3)
    edges = rng.uniform(-2.0, 62.0, 30)
    edges[5], edges[::9] = 30.0, np.nan
    got = _aligned_misfits(now, then, edges, 6, 5)
    x = np.arange(60.0)
    for i in range(30):
        if not np.isfinite(edges[i]) or not 5 <= int(np.rint(edges[i])) <= 54:
            assert np.isnan(got[i])
            continue
        j = np.arange(int(np.rint(edges[i])) - 5, int(np.rint(edges[i])) + 6)
        whole = {s: np.mean((now[i, j] - then[i, j - s]) ** 2) for s in range(-6, 7)
                 if j[0] - s >= 0 and j[-1] - s < 60}
        best = min(whole, key=lambda s: (whole[s], s))  # (the first least: whole shifts are tried from -6 up)
        fine = [np.mean((now[i, j] - np.interp(j - (best + 0.1 * t), x, then[i])) ** 2) for t in range(-10, 11)
                if j[0] - (best + 0.1 * t) >= 0 and np.floor(j[-1] - (best + 0.1 * t)) + 1 < 60]
        assert got[i] == pytest.approx(min([whole[best], *fine]), rel=1e-9), i
    assert got[5] < 1e-20


def test_the_levels_outside_a_wall_are_numpys():
    """_outside_levels (compiled) against the numpy expression: the samples 4-12 px outside each row's rounded edge,
    nan off the row; per row ``np.nanmedian`` where at least 4 are finite, the absolute differences of neighbouring
    finite samples summed and counted.  Edges near either end of the row, nan edges and nan samples included."""
    rng = np.random.default_rng(5)
    change = rng.standard_normal((40, 50))
    change[rng.random(change.shape) < 0.05] = np.nan
    edges = rng.uniform(-3.0, 53.0, 40)
    edges[::7] = np.nan
    for outward in (-1, 1):
        level, diffs, count = _outside_levels(change, edges, outward)
        k = np.rint(np.nan_to_num(edges, nan=-1000.0)).astype(int)[:, None] + outward * np.arange(4, 13)
        band = np.where((k >= 0) & (k < 50), np.take_along_axis(change, np.clip(k, 0, 49), axis=1), np.nan)
        band[np.isnan(edges)] = np.nan
        enough = np.count_nonzero(np.isfinite(band), axis=1) >= 4
        want = np.full(40, np.nan)
        want[enough] = np.nanmedian(band[enough], axis=1)
        np.testing.assert_array_equal(level, want)
        steps = np.diff(band, axis=1)
        steps = steps[np.isfinite(steps)]
        assert count == steps.size and diffs == pytest.approx(np.abs(steps).sum(), rel=1e-12)


def test_a_walls_second_line_is_its_own_when_the_radius_pairs_the_walls():
    """drawn_20261207_72 (inverted, an absorbing film and base, a neighbouring well 41 um away each side, 0.85
    um/px): every wall's silhouette shows a second line 9-15 px inside it, a zone of its own between the chamber's
    walls, so the pair of the strongest zones, of the chamber's radius, was refused and no other fitted: the look
    was refused (ChamberNotFound, measured blind).  Zones within a tenth of the radius of a wall (at most 16 px)
    are its own now.  Here the column score of four walls (the chamber's at 356 and 668, radius 156 px; the
    neighbours' at 307 and 717, the right one's the strongest, as there) each with a narrow second line 13 px
    inside it."""
    x = np.arange(1024.0)
    walls = [(307.0, 1), (356.0, -1), (668.0, 1), (717.0, -1)]
    score = sum((1.2 if c == 717.0 else 1.0) * _zone(x, c, side) for c, side in walls)
    score = score + sum(0.3 * np.exp(-0.5 * ((x - c + 13.0 * side) / 2.0) ** 2) for c, side in walls)
    left, right = _wall_pair(2.0 * score, x.size, 40, radius_px=156.0)
    assert abs(left - 356) <= 2 and abs(right - 668) <= 2
    # a zone between the walls farther than that from both is not the wall's own: the view is refused as before
    far = score + 0.5 * np.exp(-0.5 * ((x - 390.0) / 2.0) ** 2)
    with pytest.raises(ChamberNotFound, match="other wall would lie"):
        _wall_pair(2.0 * far, x.size, 40, radius_px=156.0)


def test_drawn_72s_walls_are_found_through_their_second_lines():
    """drawn_20261207_72's flat frame (rendered from its optics: the walls' second lines, the neighbours' wells 41
    um away each side): with the chamber's radius, the chamber's walls within 0.5 px of the rendered well's (the
    view was refused before, ChamberNotFound)."""
    s = render_look("drawn_20261207_72", [0.0])
    t, p = s.truth, s.truth.attrs["pixel_size"]
    a, l0, h = (t.attrs[k] for k in ("chamber_radius", "membrane_thickness", "chamber_depth"))
    w = find_walls(s.frames[0], l0 / p, depth_px=h / p, radius_px=a / p)
    axis = t.attrs["anchor_col"]
    assert abs(w.left - (axis - a / p)) < 0.5 and abs(w.right - (axis + a / p)) < 0.5
