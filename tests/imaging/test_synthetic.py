"""Tests of the synthetic micrograph renderer (osmobulge.imaging.synthetic).

Every nuisance is checked by measuring its effect in the rendered image, and
the ground truth against the model (bulge_profile / bulge_mechanics) and an
independent integration of the saved truth profile.
"""

import math

import numpy as np
import pytest
import xarray as xr
from scipy import ndimage
from scipy.interpolate import CubicSpline
from scipy.spatial import cKDTree

from osmobulge.imaging.synthetic import (
    Nuisances,
    SceneGeometry,
    render_frame,
    render_series,
    render_simulation,
)
from osmobulge.modeling import PreStretch, bulge_mechanics, bulge_profile
from osmobulge.modeling.bulge import bulge_profiles as profiles
from osmobulge.modeling.materials import PDMS

# a small chamber keeps the frames small: a = 100 um, h = 50 um, l0 = 10 um at 1 um/px
CH = (100e-6, 50e-6, 10e-6)
SMALL = {"chamber": CH, "shape": (400, 420)}
FULL = 65535.0


def _bg(truth):
    return float(truth.attrs["scene_background_level"]) * (2 ** int(truth.attrs["bit_depth"]) - 1)


# --------------------------------------------------------------------------------------
# profiles and truth
# --------------------------------------------------------------------------------------
def test_batched_profiles_match_bulge_profile():
    lp = PreStretch(0.02, 0.001)
    v = [0.0, 0.4, 2.5, 0.4]
    batch = profiles(PDMS, v, lp, n=201)
    for i in (1, 2):
        ref = bulge_profile(PDMS, v[i], lp, n=201)
        np.testing.assert_allclose(batch.r[i], ref.r.values, atol=1e-9)
        np.testing.assert_allclose(batch.z[i], ref.z.values, atol=1e-9)
        np.testing.assert_allclose(batch.thickness[i], ref.thickness_ratio.values, atol=1e-9)
        assert batch.area_ratio[i] == pytest.approx(ref.attrs["area_ratio"], rel=1e-9, abs=0)
    np.testing.assert_array_equal(batch.r[1], batch.r[3])
    # flat row: the membrane is pre-stretched only
    np.testing.assert_allclose(batch.r[0], batch.rho * 1.0)
    assert np.all(batch.z[0] == 0)


def test_truth_volume_area_height_consistent_with_mechanics():
    v = np.array([0.3, 1.0, 4.0])
    lp = PreStretch(0.01, 0.002)
    s = render_series(v, lambda_pre=lp, **SMALL)
    t = s.truth
    a = CH[0]
    mech = bulge_mechanics(PDMS, v, lp)
    np.testing.assert_allclose(t.volume.values, math.pi * a**3 * v, rtol=1e-12)
    np.testing.assert_allclose(t.volume_ratio.values, 1 + v * a / CH[1], rtol=1e-12)
    np.testing.assert_allclose(t.area_ratio.values, mech.area_ratio.values, rtol=1e-6)
    np.testing.assert_allclose(t.bulge_height.values, mech.bulge_height.values * a, rtol=1e-6)
    np.testing.assert_allclose(t.lambda_pre.values, lp(v), rtol=1e-12)
    np.testing.assert_allclose(t.rim_radius.values, a * lp(v), rtol=1e-12)
    for i in range(v.size):
        r, z = t.profile_r[i].values, t.profile_z[i].values
        # independent integration of the saved half profile (solid of revolution, trapezoids)
        vol = -np.trapezoid(math.pi * r**2, z)
        ds = np.hypot(np.diff(r), np.diff(z))
        area = np.sum(2 * math.pi * 0.5 * (r[1:] + r[:-1]) * ds)
        assert vol == pytest.approx(t.volume.values[i], rel=2e-3, abs=0)
        assert area == pytest.approx(t.area_ratio.values[i] * math.pi * a**2, rel=2e-3, abs=0)
        assert z.max() == pytest.approx(t.bulge_height.values[i], rel=1e-9, abs=0)
        assert r[-1] == pytest.approx(t.rim_radius.values[i], rel=1e-12, abs=0)
        assert t.profile_arclength.values[i] == pytest.approx(np.sum(ds), rel=1e-3, abs=0)
    # Vtilde > 2/3 overhangs: the truth profile reaches beyond the rim
    assert t.profile_r[2].max() > 1.2 * t.rim_radius[2]


def _centroid_errors(series, i, win=4.0):
    """Signed offset (px) of the intensity-weighted centre of the band from the true midline.

    For every truth sample away from the rims, pixels near the midline are
    weighted by their darkness and a Gaussian window along the arc; each
    pixel's exact normal distance to the (densified, rim-to-rim) midline is
    averaged, with the curved-band area element (1 - kappa n) divided out.
    """
    t = series.truth
    img = series.frames[i].astype(float)
    bg = _bg(t)
    p = float(t.attrs["pixel_size"])
    l0 = float(t.attrs["membrane_thickness"]) / p
    # full midline, left rim -> pole -> right rim, with its arc length (px)
    c = np.r_[t.midline_col[i, 0].values[::-1], t.midline_col[i, 1].values[1:]]
    r = np.r_[t.midline_row[i, 0].values[::-1], t.midline_row[i, 1].values[1:]]
    th = np.r_[t.profile_thickness[i].values[::-1], t.profile_thickness[i].values[1:]] / p
    zz = np.r_[t.profile_z[i].values[::-1], t.profile_z[i].values[1:]] / p
    s = np.r_[0.0, np.cumsum(np.hypot(np.diff(c), np.diff(r)))]
    sd = np.linspace(0, s[-1], int(s[-1] / 0.05) + 2)
    spc, spr = CubicSpline(s, c), CubicSpline(s, r)
    cd, rd = spc(sd), spr(sd)
    c1, r1, c2, r2 = spc(sd, 1), spr(sd, 1), spc(sd, 2), spr(sd, 2)
    nrm = np.hypot(c1, r1)
    tc, tr = c1 / nrm, r1 / nrm
    kap = (c1 * r2 - r1 * c2) / nrm**3
    nc, nr = -tr, tc
    tree = cKDTree(np.c_[cd, rd])
    errs = []
    for k in range(s.size):
        if min(s[k], s[-1] - s[k]) < l0 + 3 * win + 8 or zz[k] < l0 + 10:  # the rims and flat band
            continue
        j0 = np.searchsorted(sd, s[k])
        half = th[k] / 2 + 6
        rad = int(np.ceil(half + 3 * win)) + 1
        rr, cc = np.mgrid[int(r[k]) - rad : int(r[k]) + rad + 1, int(c[k]) - rad : int(c[k]) + rad + 1]
        _, j = tree.query(np.c_[cc.ravel(), rr.ravel()])
        dn = (cc.ravel() - cd[j]) * nc[j] + (rr.ravel() - rd[j]) * nr[j]
        dt = sd[j] - sd[j0]
        w = np.exp(-(dt**2) / (2 * win**2)) * (np.abs(dn) <= half) * (np.abs(dt) <= 3 * win) / (1 - kap[j] * dn)
        d = (bg - img[rr, cc].ravel()) * w
        errs.append((dn * d).sum() / d.sum())
    return np.array(errs)


@pytest.mark.parametrize("vtilde,tilt", [(0.3, 0.0), (2.0, 3.0), (6.0, -2.0)])
def test_clean_render_band_centre_is_true_midline(vtilde, tilt):
    nu = Nuisances(tilt=tilt, drift=[[0.37, -0.61]])
    s = render_series([vtilde], nuisances=nu, **SMALL)
    err = _centroid_errors(s, 0)
    assert err.size > 100
    assert abs(err.mean()) < 0.002
    assert np.sqrt(np.mean(err**2)) < 0.003
    assert np.abs(err).max() < 0.01  # measured: rms 3e-4..5e-4 px, max <= 2e-3 px


@pytest.mark.parametrize("blur", [1.0, 1.5, 2.5])
def test_flat_band_on_the_base_matches_the_blurred_box_model(blur):
    """Across the band lying on the base (water above, base below) the image is the blurred box model.

    Regression: compositing the membrane "over" a pixel already mixed from base and water
    counted water under the band's lower edge and put that edge 0.24 px too high (1 px blur),
    so every volume read 0.12 px x pi a^2 low.  Model: levels water / band / base with edges
    at z = +-l0/2, mixed by area in each pixel, then the renderer's Gaussian PSF.
    """
    from osmobulge.imaging._chamber import band_edges

    s = render_series([0.0], nuisances=Nuisances(blur_sigma=blur), **SMALL)
    at = s.truth.attrs
    frame = s.frames[0].astype(float) / FULL
    l0 = at["membrane_thickness"] / at["pixel_size"]
    x = np.arange(frame.shape[0]) - at["anchor_row"]  # px below the true flat midline
    bg, lb, lm = at["scene_background_level"], at["scene_base_level"], at["scene_membrane_level"]

    def cover(lo, hi):  # area of each pixel [x - 1/2, x + 1/2] inside [lo, hi]
        return np.clip(np.minimum(x + 0.5, hi) - np.maximum(x - 0.5, lo), 0.0, 1.0)

    sharp = bg + (lm - bg) * cover(-0.5 * l0, 0.5 * l0) + (lb - bg) * cover(0.5 * l0, np.inf)
    model = ndimage.gaussian_filter1d(sharp, blur, mode="nearest", truncate=4.0)  # the renderer's PSF
    near = np.abs(x) < l0 + 5 * blur
    for col in (15, 40, frame.shape[1] - 40, frame.shape[1] - 15):  # the surface, far from the well
        np.testing.assert_allclose(frame[near, col], model[near], atol=1e-4)  # 16-bit steps: 1.5e-5
    if blur <= 1.0:  # the band reaches its level: half-level edges are exact, midline at z = 0
        prof = frame[:, [15, 40]].T
        mid, lo, hi, con, width = band_edges(prof[:, near], x[near].astype(float), +1)
        np.testing.assert_allclose(mid, 0.0, atol=0.01)
        np.testing.assert_allclose(width, l0, atol=0.02)


# --------------------------------------------------------------------------------------
# nuisances, each measured in the image
# --------------------------------------------------------------------------------------
def test_deterministic_under_seed():
    nu = Nuisances(noise_sigma=0.02, poisson_photons=500, drift_sigma=2.0, dust_count=5, fractured_frames=(1,))
    a = render_series([0.3, 1.0, 4.0], seed=3, nuisances=nu, **SMALL)
    b = render_series([0.3, 1.0, 4.0], seed=3, nuisances=nu, **SMALL)
    c = render_series([0.3, 1.0, 4.0], seed=4, nuisances=nu, **SMALL)
    np.testing.assert_array_equal(a.frames, b.frames)
    xr.testing.assert_identical(a.truth, b.truth)
    assert np.any(a.frames != c.frames)
    assert not np.allclose(a.truth.drift_x.values[1:], c.truth.drift_x.values[1:])
    # one frame alone is the same frame
    one = render_frame(1.0, seed=3, nuisances=Nuisances(noise_sigma=0.02), **SMALL)
    ser = render_series([1.0], seed=3, nuisances=Nuisances(noise_sigma=0.02), **SMALL)
    np.testing.assert_array_equal(one, ser.frames[0])


@pytest.mark.parametrize("bits,dtype", [(8, np.uint8), (12, np.uint16), (16, np.uint16)])
def test_bit_depth_dtype_and_range(bits, dtype):
    s = render_series([1.0], nuisances=Nuisances(bit_depth=bits), **SMALL)
    f = s.frames[0]
    full = 2**bits - 1
    assert f.dtype == dtype
    assert int(f.max()) <= full
    assert f[5, 5] == round(0.80 * full)  # water
    assert f[-3, 5] == round(0.55 * full)  # base
    assert abs(int(f.min()) - round(0.25 * full)) <= 1  # membrane


def test_polarity_flips_contrast():
    pos = render_series([1.0], **SMALL)
    neg = render_series([1.0], nuisances=Nuisances(polarity=-1), **SMALL)
    t = pos.truth
    pole = (int(round(float(t.midline_row[0, 0, 0]))), int(round(float(t.midline_col[0, 0, 0]))))
    rim_band = (int(round(float(t.rim_y[0]))), 5)
    for img, sign in ((pos.frames[0], 1), (neg.frames[0], -1)):
        bg = int(img[5, 5])
        assert sign * (bg - int(img[rim_band])) > 0.5 * FULL * 0.55  # the flat band
        assert sign * (bg - int(img[pole])) > 0.05 * FULL  # the thin dome
    diff = pos.frames[0].astype(int) + neg.frames[0].astype(int) - 65535
    assert np.abs(diff).max() <= 1


def test_tilt_rotates_the_rim_line():
    for tilt in (-3.0, 2.5):
        s = render_series([1.0], nuisances=Nuisances(tilt=tilt, blur_sigma=1.5), **SMALL)
        img = s.frames[0].astype(float)
        dark = np.clip(_bg(s.truth) - img, 0, None)
        dark[img < 0.5 * FULL * 0.55 - 1] *= 1  # keep all
        cols, rows = [], []
        for c in list(range(10, 90, 4)) + list(range(340, 410, 4)):  # flat band, both sides of the dome
            prof = dark[:, c].copy()
            r0 = int(round(float(s.truth.rim_y[0]) - (c - float(s.truth.axis_x[0])) * math.tan(math.radians(tilt))))
            win = slice(r0 - 12, r0 + 6)  # the band, not the base below it
            w = prof[win] * (img[win, c] < 0.5 * 0.80 * FULL)
            rows.append(np.sum(np.arange(win.start, win.stop) * w) / w.sum())
            cols.append(c)
        slope = np.polyfit(cols, rows, 1)[0]
        angle = math.degrees(math.atan(-slope))  # counter-clockwise as displayed
        assert angle == pytest.approx(tilt, abs=0.05)


def test_drift_moves_the_scene_by_the_requested_offset():
    from skimage.registration import phase_cross_correlation

    drift = np.array([[0.0, 0.0], [3.4, -2.7], [-6.25, 1.5]])
    s = render_series([1.0, 1.0, 1.0], nuisances=Nuisances(drift=drift), **SMALL)
    f0 = s.frames[0].astype(float)
    for i in (1, 2):
        shift, _, _ = phase_cross_correlation(f0, s.frames[i].astype(float), upsample_factor=50)
        # shift (row, col) registers frame i onto frame 0: minus the drift
        np.testing.assert_allclose(-shift[::-1], drift[i], atol=0.05)
        assert float(s.truth.axis_x[i] - s.truth.axis_x[0]) == pytest.approx(drift[i, 0])
        assert float(s.truth.rim_y[i] - s.truth.rim_y[0]) == pytest.approx(drift[i, 1])
    np.testing.assert_allclose(s.truth.midline_col[2] - s.truth.midline_col[0], drift[2, 0])


def test_random_walk_drift_statistics():
    with pytest.warns(UserWarning, match="leaves the field"):  # 16 x 16 px cannot hold the chamber
        s = render_series(np.zeros(400), nuisances=Nuisances(drift_sigma=2.0, blur_sigma=0), shape=(16, 16), chamber=CH)
    steps = np.diff(np.stack([s.truth.drift_x.values, s.truth.drift_y.values]), axis=1)
    assert s.truth.drift_x.values[0] == 0 and s.truth.drift_y.values[0] == 0
    assert steps.std() == pytest.approx(2.0, rel=0.08, abs=0)
    assert abs(steps.mean()) < 0.25


def test_gaussian_and_poisson_noise_levels():
    g = render_series([1.0], nuisances=Nuisances(noise_sigma=0.01), **SMALL).frames[0].astype(float)
    water = g[5:60, 5:100]
    assert water.std() == pytest.approx(0.01 * FULL, rel=0.05, abs=0)
    assert water.mean() == pytest.approx(0.8 * FULL, rel=1e-3, abs=0)
    p = render_series([1.0], nuisances=Nuisances(poisson_photons=400), **SMALL).frames[0].astype(float) / FULL
    base = p[-8:, 5:400]
    # variance = mean / photons in both grey regions
    assert p[5:60, 5:100].var() == pytest.approx(0.80 / 400, rel=0.06, abs=0)
    assert base.var() == pytest.approx(0.55 / 400, rel=0.06, abs=0)
    # exact Poisson below the normal-approximation threshold gives the same law
    q = render_series([1.0], nuisances=Nuisances(poisson_photons=20000), **SMALL).frames[0].astype(float) / FULL
    assert q[5:60, 5:100].var() == pytest.approx(0.80 / 20000, rel=0.08, abs=0)


@pytest.mark.parametrize("sigma", [0.8, 2.5])
def test_blur_sets_the_edge_width(sigma):
    s = render_series([1.0], nuisances=Nuisances(blur_sigma=sigma, drift=[[0.3, 0.0]]), **SMALL)
    img = s.frames[0].astype(float)
    row = int(round(float(s.truth.rim_y[0]))) + 30  # in the well, below the membrane
    edge = float(s.truth.axis_x[0]) + 100  # right wall of the well (lambda_pre = 1), x = 310.3
    col = int(round(edge))
    seg = np.diff(img[row, col - 15 : col + 16])  # derivative of the edge: the PSF
    x = np.arange(seg.size) + 0.5 - 15 + col
    w = np.abs(seg)
    mu = (x * w).sum() / w.sum()
    var = ((x - mu) ** 2 * w).sum() / w.sum()
    # the area-sampled edge differenced has variance f(1-f), f = fractional edge position
    f = (edge + 0.5) % 1.0
    assert var == pytest.approx(sigma**2 + f * (1 - f), rel=0.02, abs=0)
    assert mu == pytest.approx(edge, abs=0.01)


def test_illumination_gradient_and_vignetting():
    s = render_series([1.0], nuisances=Nuisances(illumination_gradient=0.2, blur_sigma=0), **SMALL)
    img = s.frames[0].astype(float)
    w = img.shape[1]
    left, right = img[20, 0], img[20, w - 1]
    # field = 1 + g * x with x = -1 .. 1 from the centre to the edges (pixel centres)
    xl, xr = (0 - (w - 1) / 2) / (w / 2), ((w - 1) - (w - 1) / 2) / (w / 2)
    assert left / right == pytest.approx((1 + 0.2 * xl) / (1 + 0.2 * xr), rel=1e-3, abs=0)
    v = render_series([1.0], nuisances=Nuisances(vignetting=0.3, blur_sigma=0), **SMALL).frames[0].astype(float)
    h = v.shape[0]
    centre_val = v[h // 2 - 150, w // 2]  # water above the centre
    xc, yc = (w // 2 - (w - 1) / 2) / (w / 2), ((h - 1) / 2 - (h // 2 - 150)) / (h / 2)
    expect_c = 0.8 * FULL * (1 - 0.3 * (xc**2 + yc**2) / 2)
    assert centre_val == pytest.approx(expect_c, abs=1.0)
    corner = v[0, 0]
    xk, yk = (0 - (w - 1) / 2) / (w / 2), ((h - 1) / 2) / (h / 2)
    assert corner == pytest.approx(0.8 * FULL * (1 - 0.3 * (xk**2 + yk**2) / 2), abs=1.0)


def test_dust_darkens_the_specks():
    s = render_series([1.0], nuisances=Nuisances(dust_count=12, dust_opacity=0.6, blur_sigma=0), seed=5, **SMALL)
    img = s.frames[0].astype(float)
    clean = render_series([1.0], nuisances=Nuisances(blur_sigma=0), **SMALL).frames[0].astype(float)
    specks = np.asarray(s.truth.attrs["dust_specks"]).reshape(-1, 4)
    assert specks.shape == (12, 4)
    for xc, yc, _rad, op in specks:
        r, c = int(round(yc)), int(round(xc))
        if 0 <= r < img.shape[0] and 0 <= c < img.shape[1]:
            assert img[r, c] / clean[r, c] == pytest.approx(1 - op, abs=0.05)
    ratio = img / clean
    assert ratio.min() < 0.75 and ratio.max() <= 1.0 + 1e-4


# --------------------------------------------------------------------------------------
# scene layout, neighbours and flagged frames
# --------------------------------------------------------------------------------------
def test_bulge_direction_rotates_the_scene():
    h, w = 400, 420
    ap = (207.0, 300.0)
    up = render_series([1.0], scene=SceneGeometry(axis_position=ap), **SMALL).frames[0].astype(int)
    down = render_series(
        [1.0], scene=SceneGeometry(bulge_direction="down", axis_position=(w - 1 - ap[0], h - 1 - ap[1])), **SMALL
    ).frames[0]
    assert np.abs(np.rot90(up, 2) - down).max() <= 1
    sq = {"chamber": CH, "shape": (420, 420)}
    up = render_series([1.0], scene=SceneGeometry(axis_position=(207.0, 300.0)), **sq).frames[0].astype(int)
    left = render_series(
        [1.0], scene=SceneGeometry(bulge_direction="left", axis_position=(300.0, 419 - 207.0)), **sq
    ).frames[0]
    assert np.abs(np.rot90(up, 1) - left).max() <= 1


def test_prestretch_widens_the_well_top():
    lp = PreStretch(0.05, 0.0)
    s = render_series([2.0], lambda_pre=lp, nuisances=Nuisances(blur_sigma=0), **SMALL)
    img = s.frames[0].astype(float)
    t = s.truth
    ax, rim = float(t.axis_x[0]), float(t.rim_y[0])
    base = 0.55 * FULL

    def half_width(row):  # liquid run around the axis in a base row, from the coverage of edge pixels
        line = img[row]
        inside = (line - base) / (0.8 * FULL - base)
        c0 = int(ax)
        return 0.5 * inside[c0 - 160 : c0 + 160].sum()

    top = half_width(int(rim + 5 + 2))  # just below the base top surface (l0/2 = 5 px)
    bottom = half_width(int(rim + 5 + 48))  # near the well bottom (h = 50 px)
    assert top == pytest.approx(100 * (1 + 0.1 * (1 - 2.5 / 50)), abs=0.2)
    assert bottom == pytest.approx(100 * (1 + 0.1 * (2.5 / 50 + 0.5 / 50 * 0)), abs=0.6)
    assert float(t.rim_radius[0]) == pytest.approx(110e-6)


def test_neighbours_have_their_own_wells_and_bulges():
    nu = Nuisances(neighbours=((-260e-6, 0.5),), blur_sigma=0)
    s = render_series(
        [0.3, 0.6], nuisances=nu, chamber=CH, shape=(400, 640), scene=SceneGeometry(axis_position=(420.0, 300.0))
    )
    t = s.truth
    np.testing.assert_allclose(t.neighbour_vtilde.values[:, 0], [0.15, 0.3])
    img = s.frames[1].astype(float)
    row = 300 + 5 + 20
    assert img[row, 420] == pytest.approx(0.8 * FULL, abs=1)  # reference well
    assert img[row, 420 - 260] == pytest.approx(0.8 * FULL, abs=1)  # neighbour well
    assert img[row, 420 - 130] == pytest.approx(0.55 * FULL, abs=1)  # base between them
    # the neighbour's dome: membrane above its axis at its own (smaller) height
    mech = bulge_mechanics(PDMS, [0.3])
    nb_top = 300 - mech.bulge_height.values[0] * 100 - 0.5 * mech.pole_thickness_ratio.values[0] * 10
    col = img[:, 420 - 260]
    cover = (0.8 * FULL - col) / ((0.8 - 0.25) * FULL)  # membrane area coverage of each pixel
    band = slice(int(nb_top) - 5, int(nb_top) + 3)
    first = int(nb_top) - 5 + np.nonzero(cover[band] > 0.999)[0][0]
    assert first - 0.5 - cover[first - 1] == pytest.approx(nb_top, abs=0.05)  # its top edge, sub-pixel
    assert list(t.flag.values) == ["ok", "ok"]


def test_touching_frames_merge_the_bulges():
    nu = Nuisances(neighbours=((260e-6, 0.3),), touching_frames=(1,), blur_sigma=0)
    kw = {"chamber": CH, "shape": (400, 640), "scene": SceneGeometry(axis_position=(250.0, 330.0))}
    s = render_series([1.0, 1.0], nuisances=nu, **kw)
    t = s.truth
    assert list(t.flag.values) == ["ok", "touching"]
    assert t.neighbour_vtilde.values[1, 0] > t.neighbour_vtilde.values[0, 0]
    for i, joined in ((0, False), (1, True)):
        img = s.frames[i].astype(float)
        above = img[: 330 - 12] < 0.8 * FULL - 0.15 * (0.8 - 0.25) * FULL  # membrane above the flat band
        lab, _ = ndimage.label(above, structure=np.ones((3, 3)))
        ref_pole = lab[int(round(float(t.midline_row[i, 0, 0]))), int(round(float(t.midline_col[i, 0, 0])))]
        nb_col = lab[:, 250 + 260]
        nb_pole = nb_col[np.nonzero(nb_col)[0].min()]  # the neighbour's top, above its axis
        assert ref_pole > 0 and nb_pole > 0
        assert (ref_pole == nb_pole) == joined


def test_delaminated_frame_lifts_the_membrane_off_the_rim():
    nu = Nuisances(delaminated_frames=(1,), blur_sigma=0)
    s = render_series([1.0, 1.0], nuisances=nu, **SMALL)
    t = s.truth
    assert list(t.flag.values) == ["ok", "delaminated"]
    ax, rim = float(t.axis_x[0]), float(t.rim_y[0])
    col = int(ax + 100 + 0.3 * 100 / 2)  # halfway along the lifted length
    row = int(rim + 4)  # just above the base top surface (rim line + l0/2 = +5)
    ok, dl = s.frames[0].astype(float), s.frames[1].astype(float)
    assert ok[row, col] == pytest.approx(0.25 * FULL, abs=1)  # membrane on the surface
    assert dl[row, col] == pytest.approx(0.80 * FULL, abs=1)  # water under the lifted membrane
    # the drawn dome is lifted by delamination_gap * l0 = 15 px, the truth profile is not
    np.testing.assert_allclose(t.midline_row[1] - t.midline_row[0], -15.0)
    np.testing.assert_allclose(t.profile_z[1], t.profile_z[0])
    far = (slice(0, int(rim) - 30), slice(None))
    np.testing.assert_array_equal(ok[int(rim) + 20 :], dl[int(rim) + 20 :])  # base and well unchanged
    assert np.any(ok[far] != dl[far])


@pytest.mark.parametrize("mode", ["gap", "collapsed"])
def test_fractured_frame_tears_the_dome(mode):
    nu = Nuisances(fractured_frames=(1,), fracture_mode=mode, fracture_gap=0.2, blur_sigma=0)
    s = render_series([1.0, 1.0], nuisances=nu, seed=2, **SMALL)
    t = s.truth
    assert list(t.flag.values) == ["ok", "fractured"]

    def dark_along_midline(img):
        vals = []
        for side in range(2):
            r = np.round(t.midline_row[0, side].values).astype(int)
            c = np.round(t.midline_col[0, side].values).astype(int)
            vals.append(img[r, c] < 0.6 * FULL)
        return np.concatenate(vals)

    ok = dark_along_midline(s.frames[0].astype(float))
    torn = dark_along_midline(s.frames[1].astype(float))
    assert ok.all()
    missing = 1 - torn.mean()
    if mode == "gap":
        assert missing == pytest.approx(0.2, abs=0.05)
    else:
        assert missing > 0.9
        # the flaps hang into the well
        ax, rim = float(t.axis_x[0]), float(t.rim_y[0])
        well = s.frames[1][int(rim) + 10 : int(rim) + 50, int(ax) - 95 : int(ax) + 95].astype(float)
        assert (well < 0.6 * FULL).sum() > 50


# --------------------------------------------------------------------------------------
# inputs
# --------------------------------------------------------------------------------------
def test_render_simulation_from_volume_ratio():
    ds = xr.Dataset(
        {"volume_ratio": ("time", np.array([1.0, 1.5, 2.0]))},
        coords={"time": ("time", np.array([0.0, 900.0, 1800.0]))},
        attrs={"chamber_radius": CH[0], "chamber_depth": CH[1], "membrane_thickness": CH[2]},
    )
    s = render_simulation(ds, shape=(400, 420))
    np.testing.assert_allclose(s.truth.vtilde.values, [0.0, 0.25, 0.5])
    np.testing.assert_allclose(s.truth.volume_ratio.values, ds.volume_ratio.values)
    np.testing.assert_allclose(s.truth.time.values, [0.0, 900.0, 1800.0])
    assert s.truth.attrs["frame_interval"] == 900.0


def test_render_simulation_of_the_transport_model():
    from osmobulge.modeling import Chamber, simulate

    ch = Chamber(radius=100e-6, depth=50e-6, thickness=10e-6, concentration=3000.0)
    sim = simulate(ch, PDMS, 2e-12, [0.0, 1800.0, 3600.0])
    s = render_simulation(sim, material=PDMS, shape=(400, 420))
    np.testing.assert_allclose(s.truth.vtilde.values, sim.vtilde.values, rtol=1e-12)
    np.testing.assert_allclose(s.truth.volume_ratio.values, sim.volume_ratio.values, rtol=1e-9)
    np.testing.assert_allclose(s.truth.area_ratio.values[1:], sim.area_ratio.values[1:], rtol=1e-3)
    assert Chamber.from_attrs(s.truth.attrs) == ch
    assert s.frames.shape == (3, 400, 420)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"nuisances": Nuisances.__new__(Nuisances)}, "nuisances"),
        ({"chamber": (200, 110e-6, 20e-6)}, "radius"),
        ({"chamber": (1e-4, 1e-4)}, "chamber"),
        ({"pixel_size": 1.0}, "pixel_size"),
        ({"shape": (8, 8)}, "shape"),
        ({"times": [0.0, 1.0]}, "times"),
    ],
)
def test_render_series_validation(kwargs, match):
    kw = dict(SMALL) | kwargs
    if "nuisances" in kwargs:
        kw["nuisances"] = "clean"
    with pytest.raises((ValueError, TypeError), match=match):
        render_series([0.5], **kw)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"polarity": 0}, "polarity"),
        ({"bit_depth": 9}, "bit_depth"),
        ({"fracture_mode": "shattered"}, "fracture_mode"),
        ({"tilt": 60.0}, "tilt"),
        ({"noise_sigma": -0.1}, "noise_sigma"),
        ({"delaminated_frames": (1,), "fractured_frames": (1,)}, "share"),
        ({"touching_frames": (0,)}, "neighbour"),
        ({"neighbours": ((0.0, 1.0),)}, "offset"),
        ({"drift": np.zeros((3, 3))}, "drift"),
        ({"dust_radius": (5.0, 1.0)}, "dust_radius"),
    ],
)
def test_nuisance_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Nuisances(**kwargs)


def test_scene_validation_and_event_range():
    with pytest.raises(ValueError, match="bulge_direction"):
        SceneGeometry(bulge_direction="sideways")
    with pytest.raises(ValueError, match="membrane_level"):
        SceneGeometry(membrane_level=1.5)
    with pytest.raises(ValueError, match="frame indices"):
        render_series([0.5], nuisances=Nuisances(fractured_frames=(3,)), **SMALL)
    with pytest.raises(ValueError, match="well"):
        render_series([0.5], nuisances=Nuisances(neighbours=((150e-6, 1.0),)), **SMALL)


def test_the_truth_gap_to_a_neighbour_is_the_bands_distance():
    """The truth's least gap between the dome's band and a neighbour's: flat, the two films' ends face each
    other across the base, offset - 2 a lambda_pre - l0 / lambda_pre**2 apart (each band's end is half its
    thickness beyond its midline's; the film stretched equibiaxially by lambda_pre is that much thinner); growing,
    the gap shrinks, and it is below 0 exactly on the frames flagged touching."""
    lam = 1.02
    nu = Nuisances(neighbours=((260e-6, 0.3), (-300e-6, 1.0)))
    ser = render_series([0.0, 2.0, 5.0], chamber=(100e-6, 50e-6, 10e-6), nuisances=nu, shape=(512, 900),
                        pixel_size=1e-6, lambda_pre=lam)
    gap = ser.truth.neighbour_gap.values
    assert gap[0] == pytest.approx(260e-6 - 2 * 100e-6 * lam - 10e-6 / lam**2, abs=1e-9)
    assert gap[1] < gap[0]
    assert list(ser.truth.flag.values) == ["ok", "ok", "touching"] and gap[2] < 0 < gap[1]
    assert ser.truth.neighbour_gap.attrs["units"] == "m"


def test_touching_truth_flag_sees_crossing_domes():
    """Small chambers with close neighbours: the domes cross between subsampled midline points.

    Regression: the gap was computed between subsampled points only, so crossing bands
    could pass between samples and the truth said "ok" (found by the extraction tests).
    """
    nu = Nuisances(neighbours=((260e-6, 0.3), (-260e-6, 0.3)))
    ser = render_series([0.5, 5.0], chamber=(100e-6, 50e-6, 10e-6), nuisances=nu, shape=(512, 768), pixel_size=1e-6)
    assert list(ser.truth.flag.values) == ["ok", "touching"]


def test_exposure_changes_scale_each_frames_light_and_nothing_else():
    """exposure_sigma: frames after the first in another light (the truth's light_gain), drawn from a stream of
    their own: the same scene, noise and drift as without it, each frame's grey levels times its gain."""
    kw = {"shape": (300, 400), "chamber": (60e-6, 40e-6, 10e-6), "seed": 3}
    plain = render_series([0.0, 0.5, 1.0, 1.5], nuisances=Nuisances(noise_sigma=0.0, drift_sigma=1.0), **kw)
    lit = render_series([0.0, 0.5, 1.0, 1.5], nuisances=Nuisances(noise_sigma=0.0, drift_sigma=1.0,
                                                                   exposure_sigma=0.1), **kw)
    g = lit.truth.light_gain.values
    assert g[0] == 1.0 and np.all(g[1:] != 1.0) and np.all(np.abs(g - 1.0) < 0.25)
    assert "light_gain" not in plain.truth and lit.truth.attrs["nuisance_exposure_sigma"] == 0.1
    np.testing.assert_array_equal(lit.frames[0], plain.frames[0])
    np.testing.assert_array_equal(lit.truth.drift_x.values, plain.truth.drift_x.values)
    full = 2**16 - 1
    for i in range(1, 4):  # (grey levels rounded to whole counts, the bright ones clipped at full scale)
        a, b = plain.frames[i].astype(float), lit.frames[i].astype(float)
        ok = a * g[i] < full - 1
        np.testing.assert_allclose(b[ok], a[ok] * g[i], atol=0.5 * (1.0 + g[i]) + 1e-3)  # (two roundings)
    with pytest.raises(ValueError, match="exposure_sigma"):
        Nuisances(exposure_sigma=0.8)


def test_a_time_stamp_is_burned_into_its_corner_and_nowhere_else():
    """Nuisances(time_stamp=corner): white text (the time since the first frame) in that corner, different in
    every frame, a static scale bar 100 um long in the other bottom corner; every other pixel as rendered
    without them."""
    times = [0.0, 3600.0 + 23 * 60 + 5]  # (00:00:00, 01:23:05)
    plain = render_series([0.0, 0.5], times=times, nuisances=Nuisances(noise_sigma=0.01), **SMALL)
    s = render_series([0.0, 0.5], times=times, nuisances=Nuisances(noise_sigma=0.01, time_stamp="tr"), **SMALL)
    f, g = np.asarray(s.frames), np.asarray(plain.frames)
    full = np.iinfo(f.dtype).max
    changed = f != g
    rows, cols = f.shape[1:]
    r, c = np.nonzero(changed[1])
    # the stamp's text within a band at the top right, and the bar with its label at the bottom left
    top = (r < rows // 4) & (c > cols // 2)
    bottom = (r > rows * 3 // 4) & (c < cols // 2)
    assert np.all(top | bottom) and top.sum() > 50 and bottom.sum() > 50
    assert np.all(f[changed] > 0.5 * full) and np.any(f[changed] == full)
    # the digits differ between the frames; the bar does not
    assert np.any(changed[0][: rows // 4] != changed[1][: rows // 4])
    np.testing.assert_array_equal(changed[0][rows * 3 // 4 :], changed[1][rows * 3 // 4 :])
    bar_rows = np.flatnonzero(np.all(f[0][:, 10 : 10 + round(100e-6 / s.truth.attrs["pixel_size"])] == full, axis=1))
    assert bar_rows.size >= 2 and bar_rows.min() > rows * 3 // 4
    assert s.truth.attrs["nuisance_time_stamp"] == "tr"
    # white is the bit depth's full scale (a 12-bit camera's frames in 16-bit words)
    s12 = render_series([0.0], nuisances=Nuisances(bit_depth=12, time_stamp="bl"), **SMALL)
    assert s12.frames.dtype == np.uint16 and s12.frames.max() == 4095
    with pytest.raises(ValueError, match="time_stamp must be one of"):
        Nuisances(time_stamp="top")
