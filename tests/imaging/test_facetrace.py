"""The silhouette route of the tracer (issue 16): optics-rendered looks against their truth, its gates.

Every series is rendered by the optics model (:mod:`osmobulge.imaging.optics`)
and measured by :func:`extract` as a user would (``tracer="auto"``, the
``Chamber`` given); the tolerances are the issue's: volume within max(3 %, a
0.5 px layer over the rim disc), rim radius within 0.5 px, lambda_pre within
0.3 %, and no frame outside them flagged ``ok``.
"""

from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from osmobulge.imaging._chamber import ChamberNotFound
from osmobulge.imaging._facetrace import SilhouetteTracer, _light_plane, _profiles, dark_background
from osmobulge.imaging.extract import extract
from osmobulge.imaging.looks import LOOKS, get_look, render_look, score
from osmobulge.imaging.synthetic import SceneGeometry
from osmobulge.imaging.trace import TraceSettings
from osmobulge.modeling import PreStretch
from osmobulge.modeling.transport import Chamber

PRE = PreStretch(0.01, 0.0)
VT = [0.0, 0.05, 0.6, 2.0]
SHAPE = (860, 1000)  # the reference chamber up to Vtilde 2 at 0.8 um/px (its pole ~ 300 px above the rim)


def _chamber(truth):
    a, h, l0 = (truth.attrs[k] for k in ("chamber_radius", "chamber_depth", "membrane_thickness"))
    return Chamber(a, h, l0, 3000.0)


def _volume_tolerance(s):
    """The issue's volume tolerance per frame (px**3): max(3 %, a 0.5 px layer over the rim disc)."""
    p = s.truth.attrs["pixel_size"]
    rim = s.truth.rim_radius.values[0] / p
    return np.maximum(0.03 * s.truth.volume.values / p**3, 0.5 * np.pi * rim**2)


def _known(s):
    """The chamber's membrane thickness and well depth in px: the tracer's ``l0_px`` and ``depth_px``."""
    p, ch = s.truth.attrs["pixel_size"], _chamber(s.truth)
    return {"l0_px": ch.thickness / p, "depth_px": ch.depth / p}


def _extract(s, **kw):
    return extract(s.frames, pixel_size=s.truth.attrs["pixel_size"], chamber=_chamber(s.truth), progress=False,
                   frame_interval=600.0, **kw)


@pytest.fixture(scope="module")
def edge_dark():
    return render_look("edge_dark", VT, shape=SHAPE, lambda_pre=PRE)


@pytest.mark.parametrize("name", ["edge_dark", "edge_bright", "halo", "no_grey_step", "defocus", "inverted",
                                  "absorbing_band", "film_10um", "film_26um", "uneven_8bit", "coarse_2um",
                                  "turbid_base"])
def test_optics_looks_are_measured_within_the_issues_tolerances(name, edge_dark):
    s = edge_dark if name == "edge_dark" else render_look(name, VT, shape=SHAPE, lambda_pre=PRE)
    # far from the dark-background refusal (0.05): the background is the illumination, either polarity
    assert dark_background(s.frames[0])[0] > 0.2
    ds = _extract(s)
    assert ds.attrs["tracer"] == "silhouette"
    sc = score(s.truth, ds)
    assert sc["n_flagged"] == 0 and sc["n_silent"] == 0, list(ds.flag.values)
    assert np.all(sc["dv_tol"] <= 1.0), sc["dv_tol"]  # the issue's tolerance (measured: worst at Vtilde 0.05)
    assert np.all(np.abs(sc["rim_bias_px"]) < 0.5), sc["rim_bias_px"]
    # lambda_pre within the issue's 0.3 % (measured: <= 0.12 % on every look, 2 um/px included)
    assert np.all(np.abs(sc["lambda_err"]) < 0.003), sc["lambda_err"]
    # the mid-surface's area, with the film's thickness from incompressibility (not in the issue's list)
    np.testing.assert_allclose(ds.area_ratio, s.truth.area_ratio, rtol=0.015)
    # heights within 1 px; on the 26 um film the pole's is the assumed thickness law's (l0 / lambda1^2) error:
    # measured -0.98 px at Vtilde 0.6 (the film is thinner at the pole than a uniform meridional stretch makes it)
    tol_h = 1.2 if name == "film_26um" else 1.0
    np.testing.assert_allclose(ds.bulge_height, s.truth.bulge_height, atol=tol_h * s.truth.attrs["pixel_size"])


def test_the_profile_is_the_mid_surface(edge_dark):
    """The stored profile lies on the true mid-surface (not on the outer face, l/2 outside it)."""
    ds = _extract(edge_dark)
    t = edge_dark.truth
    p = t.attrs["pixel_size"]
    i = 3
    r_true, z_true = t.profile_r[i].values, t.profile_z[i].values
    arc = np.r_[0.0, np.cumsum(np.hypot(np.diff(r_true), np.diff(z_true)))]
    fine = np.linspace(0.0, arc[-1], 20000)  # the truth as a dense polyline
    r_true, z_true = np.interp(fine, arc, r_true), np.interp(fine, arc, z_true)
    x, z = ds.profile_x[i].values, ds.profile_z[i].values
    # distance of each stored point of the right half from the true midline, above 3 l0 (the feet: below)
    right = (x > 0.2 * t.attrs["chamber_radius"]) & (z > 3 * t.attrs["membrane_thickness"])
    d = np.min(np.hypot(x[right, None] - r_true[None, :], z[right, None] - z_true[None, :]), axis=1)
    assert np.median(d) < 0.6 * p
    assert np.max(d) < 2.0 * p
    # the feet: the outer face merges with the flat film's lines there, the curve is bridged to the rim
    # (measured: up to 8 px off the true midline within l0 of the rim plane, 1.6 px below 3 l0)
    foot = (x > 0) & (z <= 3 * t.attrs["membrane_thickness"])
    d = np.min(np.hypot(x[foot, None] - r_true[None, :], z[foot, None] - z_true[None, :]), axis=1)
    assert np.max(d) < 10.0 * p
    # the film's thickness here is about 10 um: tracing its outer face would put the curve ~ 6 px off
    assert float(t.profile_thickness[i].max()) / p > 6.0


def test_the_volume_has_no_bias_from_the_feet_or_the_film(edge_dark):
    """In focus the volume is unbiased to 0.15 % at Vtilde 0.6 and 2 (measured -0.01 % and -0.06 %).

    The rim is a point of the mid-surface: the outer face meets the top face
    about (l/2) tan(beta/2) outside it, so an outer-face curve forced through
    the rim cut a wedge out of the dome there; and the film over the well is
    the flat frame's, l0 pi R0**2, which the rim's widening (lambda_pre, 2 % at
    Vtilde 2 here) stretches, not l0 pi R**2.  Together they read -0.31 % and
    -0.34 % low.
    """
    ds = _extract(edge_dark)
    v, vt = ds.volume.values[2:], edge_dark.truth.volume.values[2:]
    assert np.all(np.abs(v / vt - 1.0) < 1.5e-3), 100 * (v / vt - 1.0)


def test_the_film_thickness_law_conserves_the_flat_frames_film():
    """_thickness on a spherical-cap mid-surface whose rim has widened from R0 to R = 1.03 R0: the film over the
    well, integral of l dA, is the flat frame's l0 pi R0**2 (within 1e-4; R in its place: +6 %), its thickness
    l0 / lambda1**2 at the pole and l0 / (lambda1 lambda_pre) at the rim, lambda1 = L / R0."""
    from osmobulge.imaging._facetrace import _thickness

    r0, rim, l0 = 150.0, 154.5, 20.0
    for h in (30.0, 150.0, 260.0):
        rho = (rim**2 + h**2) / (2.0 * h)  # the cap's sphere
        half = np.arcsin(rim / rho) if h <= rho else np.pi - np.arcsin(rim / rho)
        phi = np.linspace(-half, half, 1201)
        u, z = rho * np.sin(phi), rho * np.cos(phi) - (rho - h)
        lt = _thickness(u, z, r0, r0, l0)
        ds = rho * np.diff(phi)
        mid = 0.5 * (lt[1:] + lt[:-1]) * 2.0 * np.pi * 0.5 * np.abs(u[1:] + u[:-1]) * ds
        assert 0.5 * mid.sum() == pytest.approx(l0 * np.pi * r0**2, rel=1e-4)  # (each half revolved: halved)
        # each half its own material radius: each half revolved holds its own film
        lt = _thickness(u, z, r0, 0.9 * r0, l0)
        halves = 0.5 * (lt[1:] + lt[:-1]) * 2.0 * np.pi * 0.5 * np.abs(u[1:] + u[:-1]) * ds
        assert halves[:600].sum() == pytest.approx(l0 * np.pi * r0**2, rel=1e-4)
        assert halves[600:].sum() == pytest.approx(l0 * np.pi * (0.9 * r0) ** 2, rel=1e-4)
        lam1 = rho * half / r0
        assert lt[600] == pytest.approx(l0 / lam1**2, rel=1e-3)
        assert lt[0] == pytest.approx(l0 / (lam1 * rim / r0), rel=1e-6)  # (L: the polyline's)


def test_the_points_scatter_sets_the_faces_smoothing():
    """_scatter reads the points' scatter across a curve from their second differences: within 15 % of the noise
    put on points every 3 px on a circle of 200 px (0.05-0.17 px measured on the 21 looks); the face's spline
    then follows noisy points (0.5 px) without loops: its mid-surface, 12 px inside, never turns back."""
    from osmobulge.imaging._facetrace import _FACE_SIGMA, _scatter
    from osmobulge.imaging.geometry import smooth_profile

    rng = np.random.default_rng(8)
    phi = np.arange(0.05, np.pi - 0.05, 3.0 / 200.0)
    for sigma in (0.1, 0.3, 0.5):
        r = 200.0 + rng.normal(0.0, sigma, phi.size)
        u, z = r * np.cos(phi), r * np.sin(phi)
        got = _scatter(u, z)
        assert got == pytest.approx(sigma, rel=0.15)
        face = smooth_profile(np.column_stack((u, z)), sigma=max(_FACE_SIGMA, got))
        s, xy = face.sample(step=1.0)
        t = face.tangent(s)
        mid = xy - 12.0 * np.column_stack((-t[:, 1], t[:, 0]))
        step = np.diff(mid, axis=0)
        assert np.all(np.einsum("ij,ij->i", step, np.diff(xy, axis=0)) > 0)  # (the mid-surface runs on)
    assert _scatter(np.arange(4.0), np.zeros(4)) == 0.0


def test_what_lies_in_front_of_the_dome_is_told_from_it():
    """_in_front on the full search's rays (as _rays samples them: 361 rays from the rim plane's centre, from
    outside in): a dome's face of radius 250 px; a neighbour's dome coming in at the field's right edge (its well
    beyond it), a time stamp's digits in the top corner and a speck, all in the water outside the dome, are
    returned.  A film's second face 25 px inside its outer face (a film of 25 px: nearer than 2 l0) is not, nor a
    piece of the face cut off from the rest, nor anything when the dome is out of the field's top or touches the
    neighbour."""
    from scipy import ndimage

    from osmobulge.imaging._facetrace import _in_front

    shape, centre, l0 = (860, 1000), (500.0, 600.0), 25.0
    phis = np.linspace(np.radians(1.0), np.pi - np.radians(1.0), 361)
    t = np.arange(800.0, 0.0, -1.0)
    cols = centre[0] + t[None, :] * np.cos(phis)[:, None]
    rows = centre[1] - t[None, :] * np.sin(phis)[:, None]
    inside = (cols >= 0) & (cols <= shape[1] - 1) & (rows >= 0)  # (outside the field the change is 0)

    def ring(c, r, radius, half=2.5):
        return inside & (np.abs(np.hypot(cols - c, rows - r) - radius) < half)

    def front(on):
        return _in_front(on, phis, t, centre, shape[1], 2.0 * l0)

    dome, neighbour = ring(500.0, 600.0, 250.0), ring(1150.0, 600.0, 200.0)
    speck = inside & (np.hypot(cols - 800.0, rows - 300.0) < 5.0)
    digits = np.zeros_like(inside)
    for k in range(6):  # (six digits 20 px wide, 36 high, 30 px apart, 10 px below the top)
        digits |= inside & (np.abs(cols - (700.0 + 30 * k)) < 10.0) & (rows > 10.0) & (rows < 46.0)
    assert neighbour.sum() > 100 and speck.sum() > 5 and digits.sum() > 100
    np.testing.assert_array_equal(front(dome | neighbour | speck | digits), neighbour | speck | digits)
    assert front(dome) is None
    # a neighbour at the field's side nearer than 2 l0 (its dome 30 px from this one): still in front
    near = ring(1030.0, 600.0, 250.0)
    assert near.sum() > 100
    np.testing.assert_array_equal(front(dome | near), near)
    # ... but not a speck in the field that near
    close = inside & (np.hypot(cols - 500.0, rows - 320.0) < 5.0)
    assert close.sum() > 5 and front(dome | close) is None
    # the film's two faces: the inner one is no foreign thing in front of it, whichever piece is the dome's
    inner = ring(500.0, 600.0, 225.0)
    assert front(dome | inner) is None
    assert front((dome & (rows > 560.0) & (cols > 500.0)) | inner) is None  # (the inner face outermost on most)
    # a piece of the face cut off from the rest: nothing of the dome behind it
    cut = dome & ~((rows > 560.0) & (rows < 570.0) & (cols > 500.0))
    assert ndimage.label(cut, np.ones((3, 3)))[1] == 2 and front(cut) is None
    # a dome out of the field's top: field_margin's business, whatever is in front
    assert front(ring(500.0, 700.0, 720.0) | speck) is None
    # a neighbour touching the dome is one piece with it: not told apart here (touching is flagged elsewhere)
    assert front(dome | ring(1150.0, 600.0, 402.0, 4.0)) is None


def test_the_least_bend_of_a_dome_and_of_a_flat_topped_one():
    """_least_bend on points every 3 px with 0.3 px of noise through the face's spline, as the tracer fits them: a
    circle of 200 px bends the same everywhere (1), an ellipse of 200 x 150 px least at its top (its curvature there
    over its mean: 0.66); a circle whose cap is cut off flat (the cut 30 and 60 deg from the pole) not at all on
    the flat (0); a glitch of 4 px in the circle barely changes it; a dome turning under 40 deg in all: no word."""
    from osmobulge.imaging._facetrace import _FACE_SIGMA, _least_bend
    from osmobulge.imaging.geometry import smooth_profile

    rng = np.random.default_rng(9)

    def bend(u, z):
        face = smooth_profile(np.column_stack((u + rng.normal(0.0, 0.3, u.size), z + rng.normal(0.0, 0.3, u.size))),
                              sigma=max(_FACE_SIGMA, 0.3))
        return _least_bend(face.sample(step=1.0)[1], 16.0)

    phi = np.arange(0.05, np.pi - 0.05, 3.0 / 200.0)[::-1]  # (left foot -> over the top -> right foot)
    assert bend(200 * np.cos(phi), 200 * np.sin(phi)) == pytest.approx(1.0, abs=0.1)
    b = 150.0
    t = np.linspace(0.0, np.pi, 20001)
    arc = np.trapezoid(np.hypot(200 * np.sin(t), b * np.cos(t)), t)
    assert bend(200 * np.cos(phi), b * np.sin(phi)) == pytest.approx(b / 200**2 / (np.pi / arc), abs=0.1)
    bump = 4.0 * np.exp(-0.5 * ((phi - 2.0) / 0.02) ** 2)  # (a glitch 8 px wide, 4 px out)
    assert bend((200 + bump) * np.cos(phi), (200 + bump) * np.sin(phi)) > 0.5
    for cut_deg in (30.0, 60.0):
        u, z = 200 * np.cos(phi), 200 * np.sin(phi)
        cut = 200.0 * np.cos(np.radians(cut_deg))
        inner = np.flatnonzero(z >= cut)
        top = np.arange(u[inner[0] - 1] + 3.0, u[inner[-1] + 1] - 1.5, 3.0)  # (the flat top, every 3 px)
        u = np.r_[u[: inner[0]], top, u[inner[-1] + 1:]]
        z = np.r_[z[: inner[0]], np.full(top.size, cut), z[inner[-1] + 1:]]
        assert abs(bend(u, z)) < 0.05, cut_deg
    low = np.linspace(np.pi / 2 + 0.3, np.pi / 2 - 0.3, 200)  # (a cap turning 34 deg)
    assert np.isnan(bend(600 * np.cos(low), 600 * np.sin(low)))


def test_the_lift_of_the_first_frames_film_over_the_well():
    """_flat_lift on a face drawn as a sharp silhouette (a smoothed step, noise 0.02): flat, 0; a paraboloid dome of
    height H over the rim disc (V = pi a^2 H / 2), its layer H / 2 within 0.06 px; tilted by 1 px across the field
    (the most _check_upright lets through) with no dome, 0; a speck 8 px wide on the face over the well, 0 (each
    0 within 0.03); the face too near the field's edge, or no columns beside the well, no word (nan)."""
    from types import SimpleNamespace

    from osmobulge.imaging._facetrace import _flat_lift

    rng = np.random.default_rng(3)
    shape, top, axis, rim = (400, 900), 300.0, 450.0, 250.0
    rows, cols = np.mgrid[: shape[0], : shape[1]].astype(float)
    w = SimpleNamespace(top_row=top, rim_radius=rim, axis_col=axis)

    def face(lift):  # (the face's row per column at top - lift: dark just below it, fading over 2 px)
        return -1.0 / (1.0 + np.exp(-(rows - (top - lift[None, :])) / 1.0)) + rng.normal(0.0, 0.02, shape)

    u = np.arange(shape[1]) - axis
    flat = np.zeros(shape[1])
    assert abs(_flat_lift(face(flat), w, 20.0)) < 0.03  # (10 seeds: within 0.017, a dome's error too)
    for height in (1.0, 3.0, 8.0):
        dome = np.where(np.abs(u) < rim, height * (1.0 - (u / rim) ** 2), 0.0)
        assert _flat_lift(face(dome), w, 20.0) == pytest.approx(0.5 * height, abs=0.06), height
    assert abs(_flat_lift(face(u / shape[1]), w, 20.0)) < 0.03  # (tilted: one side up, the other down)
    specked = face(flat)
    specked[int(top) - 4 : int(top) + 4, 500:508] = 1.0
    assert abs(_flat_lift(specked, w, 20.0)) < 0.03
    assert np.isnan(_flat_lift(face(flat)[:310], w, 20.0))  # (the face's rows run out of the frame)
    assert np.isnan(_flat_lift(face(flat), w, 20.0, bounds=(axis - rim - 12.0, axis + rim + 12.0)))


def test_a_first_frame_with_a_low_dome_flags_every_frame():
    """halo from Vtilde 0.005 (a dome 2.5 px high, a 1.25 px layer: 2.5 volume tolerances): the first frame is the
    reference every change is measured from, so each frame is poor_fit (flat_lift) saying why, its figure 0.3-1.0 of
    the true layer (a low dome's silhouette fades into the face: measured 0.53 px).  Before, frame 0 read flat and ok
    (2.5x the tolerance) and frames 1-2 ok at 1.7x and 1.3x (the dome's sign was learned from the old dome's ghost)."""
    s = render_look("halo", [0.005, 0.6, 1.2, 2.0], shape=SHAPE, lambda_pre=PRE)
    ds = _extract(s)
    assert ds.attrs["tracer"] == "silhouette"
    # (said before the events and the outline's gates: frames 2-3 read least_bend and fractured, traced on the ghost)
    assert set(ds.flag.values) == {"poor_fit"} and set(ds.flag_figure.values) == {"flat_lift"}
    layer = float(s.truth.volume[0] / (np.pi * s.truth.rim_radius[0] ** 2)) / s.truth.attrs["pixel_size"]
    assert layer == pytest.approx(1.25, rel=0.01)
    assert 0.3 * layer < float(ds.flag_value[0]) / s.truth.attrs["pixel_size"] < layer  # (a length: m)
    message = str(ds.message.values[1])
    assert "the first frame is not flat" in message and "reference_frame=" in message


def test_debris_drifting_past_the_dome_is_flagged_or_read_right():
    """halo with 20 particles drifting in the water in every frame after the first (Nuisances.debris, each a dark
    blur of 4-12 px, as dark as the dome's change): no frame silently wrong.  Measured: frame 1 (Vtilde 0.05, a dome
    25 px high, a particle 21 px off its face) fractured, 22x the tolerance off; frame 2 (particles 18 and 24 px off
    the face) poor_fit least_bend, its volume right (0.28 of the tolerance); frame 3 ok within 0.02.  With 10
    particles every frame read ok, within 0.16."""
    s = render_look("halo", VT, shape=SHAPE, lambda_pre=PRE, nuisances=replace(LOOKS["halo"].nuisances, debris=20))
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert sc["n_silent"] == 0 and ds.flag.values[0] == "ok" and ds.flag.values[-1] == "ok"
    ok = ds.flag.values == "ok"
    assert np.all(sc["dv_tol"][ok] <= 1.0), sc["dv_tol"]
    assert ds.flag.values[1] != "ok" and sc["dv_tol"][1] > 1.0  # (the lost frame is flagged, not read ok)


def test_the_light_plane_through_a_domes_change():
    """_light_plane: a plane (0.02 + 1e-4 col - 5e-5 row) under noise of 0.01, with a dome's lines (change -0.5,
    3 px wide, where each row crosses a circle) and the band over its pole (-0.3 over 150 columns of the two rows
    it touches) as outliers: its coefficients within 5 % of the plane's change over 1000 px; no plane from fewer
    than 6 finite medians."""
    rng = np.random.default_rng(3)
    rows = np.linspace(2.0, 400.0, 12)
    cols = np.arange(0.0, 1000.0)[None, :] + 0.5 * (np.arange(12) % 2)[:, None]
    want = np.array([0.02, 1e-4, -5e-5])
    v = want[0] + want[1] * cols + want[2] * rows[:, None] + 0.01 * rng.standard_normal(cols.shape)
    for i, r in enumerate(rows):  # (a dome of radius 380 px about (500, 420): its outline's two crossings)
        half = np.sqrt(max(380.0**2 - (420.0 - r) ** 2, 0.0))
        for c in (500.0 - half, 500.0 + half):
            v[i, np.abs(cols[i] - c) < 1.5] = -0.5
    v[:2, 425:575] = -0.3
    got = _light_plane(v, cols, rows)
    assert abs(got[0] - want[0]) < 0.05 * 0.1 and np.all(np.abs(got[1:] - want[1:]) * 1000.0 < 0.05 * 0.1)
    assert _light_plane(np.full((1, 80), np.nan), cols[:1, :80], rows[:1]) is None


def test_the_walls_light_change_is_stray_light_plus_a_lamps(edge_dark):
    """SilhouetteTracer._light_change on the first frame's own walls' crop relit: this frame = L flat + s, with L = 1
    + 0.08 + 0.1 x - 0.05 y and s = 0.1 + 0.05 x + 0.04 y of the light's mean (x, y: -0.5 .. 0.5 over the crop's
    columns and rows): the planes it returns (s, L - 1) give s + (L - 1) light to rounding (the model is exact),
    within 0.3 % of the light with noise of 1 % of it added (0.12 % measured); 0 when the frame is the first."""
    tr = SilhouetteTracer(edge_dark.frames[0], **_known(edge_dark))
    img = np.rot90(np.asarray(edge_dark.frames[0], float), tr.k)
    w0 = tr.walls0
    rows = np.arange(int(w0.base_row + 15), int(w0.base_row + 110))
    moved = np.r_[np.arange(int(w0.left) - 40, int(w0.left) + 26), np.arange(int(w0.right) - 26, int(w0.right) + 40)]
    flat, light = img[np.ix_(rows, moved)], tr._bg[np.ix_(rows, moved)].astype(float)
    x = ((moved - moved.mean()) / np.ptp(moved))[None, :]
    y = ((rows - rows.mean()) / np.ptp(rows))[:, None]
    level = light.mean()
    lamp, stray = 0.08 + 0.1 * x - 0.05 * y, level * (0.1 + 0.05 * x + 0.04 * y)
    def change(frame):
        add, gain = tr._light_change(frame, flat, rows, moved, light)  # (the planes s and L - 1)
        assert add.shape == gain.shape == flat.shape
        return add + gain * light

    got = change(flat * (1.0 + lamp) + stray)
    assert np.max(np.abs(got - (stray + lamp * light))) < 1e-9 * level
    noise = 0.01 * level * np.random.default_rng(1).standard_normal(flat.shape)
    got = change(flat * (1.0 + lamp) + stray + noise)
    assert np.max(np.abs(got - (stray + lamp * light))) < 0.003 * level
    assert np.max(np.abs(change(flat))) < 1e-9 * level


@pytest.mark.parametrize(("name", "drift", "rtol"), [("halo", 0.2, 0.15), ("absorbing_band", 0.25, 0.03)])
def test_light_whose_gradient_drifts_is_divided_out(name, drift, rtol):
    """The light's gradient across the field drifting over the series (Nuisances.light_drift: the last frame's light
    +-drift at the field's sides against the first's; a lamp or a window warming one side): the plane through the
    water's change (``light_tilt``, its range over the view) reads the drift, every frame is ok, within the volume
    tolerance and within 1 % of the same series' in unchanged light, whose tilt reads under 0.01.

    halo, 0.2: before the tilt was divided out it raised the change's noise (0.010 -> 0.075 with +-10 % by the
    last of 9 frames) until the dome's contrast fell below 10x it: frames 2-3 read no dome (poor_fit
    dome_contrast).  absorbing_band, 0.25: its dyed film, a dark band along the dome, darkens long stretches of the
    water's rows near its top; the plane is fitted without the samples within 40 px of the last frame's dome
    (:meth:`SilhouetteTracer._near_last_dome`), within 3 % of the drift (with them: 0.366 and 0.75 for 0.333 and
    0.5; in unchanged light 0.058 and 0.231 at Vtilde 0.6 and 2)."""
    s = render_look(name, VT, shape=SHAPE, lambda_pre=PRE, nuisances=replace(LOOKS[name].nuisances, light_drift=drift))
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok"] * len(VT), list(ds.flag_figure.values)
    assert np.all(sc["dv_tol"] <= 1.0), sc["dv_tol"]
    want = 2.0 * drift * np.arange(len(VT)) / (len(VT) - 1)  # (drift from the field's centre to its side)
    np.testing.assert_allclose(ds.light_tilt.values, want, rtol=rtol, atol=0.005)
    plain = _extract(render_look(name, VT, shape=SHAPE, lambda_pre=PRE))
    assert np.all(plain.light_tilt.values < 0.01), plain.light_tilt.values  # (unchanged light: read as before)
    np.testing.assert_allclose(ds.volume.values, plain.volume.values, rtol=0.01)


@pytest.mark.parametrize("name", ["inverted", "halo"])
def test_stray_light_growing_on_one_side_is_read_through(name):
    """Stray light (Nuisances.stray_light: none in the first frame, 30 % of full scale on the field's right side by
    the last, a window or the room's lamps): every frame ok, its volume within the tolerance and its rim within
    0.5 px.  Against the first frame's light the walls' half level was read off: here the last frame's walls were
    lost on both looks (``wall_rms``); held out, a bright look with 10 % of full scale read its rim 2.5 px off, ok.
    The light over the walls' crop is now the first frame's plus stray light and a lamp's change, planes each,
    fitted to their difference (:meth:`SilhouetteTracer._light_change`).  Measured: rims +0.09..+0.23 px
    (inverted), -0.24..-0.28 (halo, as without stray light)."""
    s = render_look(name, VT, shape=SHAPE, lambda_pre=PRE,
                    nuisances=replace(LOOKS[name].nuisances, stray_light=0.3, illumination_angle=0.0))
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok"] * len(VT), list(ds.flag_figure.values)
    assert np.all(sc["dv_tol"] <= 1.0), sc["dv_tol"]
    assert np.all(np.abs(sc["rim_bias_px"]) <= 0.5), sc["rim_bias_px"]


def test_a_noisy_look_smooths_its_face_by_its_own_scatter(monkeypatch):
    """edge_dark with 8x its read noise (0.08 of full scale): the face's points scatter 0.34-0.37 px, above
    _FACE_SIGMA, and set the spline's smoothing; every frame ok and within 0.6 of the volume tolerance (0.39
    measured).  With the smoothing held at _FACE_SIGMA the spline follows the noise: the Vtilde-0.05 frame then
    reads +7.7 %, 1.9x the tolerance, flagged ok (a silent error)."""
    import osmobulge.imaging._facetrace as ft

    seen, own = [], ft._scatter

    def recorded(u, z):
        seen.append(own(u, z))
        return seen[-1]

    monkeypatch.setattr(ft, "_scatter", recorded)
    look = LOOKS["edge_dark"]
    s = render_look("edge_dark", VT, shape=SHAPE, lambda_pre=PRE, nuisances=replace(look.nuisances, noise_sigma=0.08))
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert len(seen) == len(VT) - 1  # (each frame with a dome)
    assert all(ft._FACE_SIGMA < v < 0.6 for v in seen), seen
    assert list(ds.flag.values) == ["ok"] * len(VT)
    assert np.all(sc["dv_tol"] <= 0.6), sc["dv_tol"]
    assert sc["n_silent"] == 0


def test_too_few_outer_face_points_are_a_poor_fit_not_an_error(edge_dark):
    """A frame whose outer face left fewer than 4 points is flagged poor_fit with the reason, not raised."""
    tr = SilhouetteTracer(edge_dark.frames[0], **_known(edge_dark))
    out = tr.process(edge_dark.frames[2], 2)
    assert out.flag == "ok"
    w = tr.walls0
    bad = tr._finish(np.array([-10.0, 0.0, 10.0]), np.array([5.0, 9.0, 5.0]), w, out.geometry,
                     type(out)(index=3))
    assert bad.flag == "poor_fit" and "too few outer-face points" in bad.message


def test_thickness_and_depth_are_measured_without_the_chamber(edge_dark):
    p = edge_dark.truth.attrs["pixel_size"]
    tr = SilhouetteTracer(edge_dark.frames[0])
    assert tr.bulge_direction == "up"
    assert tr.l0 == pytest.approx(20e-6 / p, abs=0.5)
    assert tr.depth == pytest.approx(110e-6 / p, abs=1.0)
    ds = extract(edge_dark.frames, pixel_size=p, frame_interval=600.0, progress=False)
    assert ds.attrs["tracer"] == "silhouette"
    assert ds.attrs["reference_radius"] == pytest.approx(200e-6, abs=0.5 * p)
    assert ds.attrs["reference_depth"] == pytest.approx(110e-6, abs=1.0 * p)


def test_a_rotated_series_is_read_in_its_orientation(edge_dark):
    frames = np.rot90(edge_dark.frames, -1, axes=(1, 2))  # the dome grows to the right
    ds = extract(frames, pixel_size=0.8e-6, frame_interval=600.0, chamber=_chamber(edge_dark.truth),
                 progress=False)
    assert ds.attrs["bulge_direction"] == "right" and ds.attrs["tracer"] == "silhouette"
    sc = score(edge_dark.truth, ds)
    assert sc["n_flagged"] == 0 and np.all(sc["dv_tol"] <= 1.0)


def test_a_drifting_series_is_registered_and_measured():
    """The stage drifts by px between frames (the renderer moves the whole scene): the tracer reads the drift off
    the base and measures every frame within the issue's tolerances, as without drift."""
    drift = np.array([[0.0, 0.0], [1.6, -0.9], [-2.3, 1.4], [3.1, 0.7]])  # (col, row) px of each frame
    s = render_look("edge_dark", VT, shape=SHAPE, lambda_pre=PRE,
                    nuisances=replace(LOOKS["edge_dark"].nuisances, drift=drift))
    ds = _extract(s)
    assert ds.attrs["tracer"] == "silhouette"
    sc = score(s.truth, ds)
    assert sc["n_flagged"] == 0 and np.all(sc["dv_tol"] <= 1.0), (list(ds.flag.values), sc["dv_tol"])
    assert np.all(np.abs(sc["rim_bias_px"]) < 0.5) and np.all(np.abs(sc["lambda_err"]) < 0.003)
    # the drift itself, to the registration's 1/20 px grid and the base's own small changes (measured: 0.1 px)
    np.testing.assert_allclose(ds.drift_x, drift[:, 0], atol=0.15)
    np.testing.assert_allclose(ds.drift_y, drift[:, 1], atol=0.15)


def test_band_looks_keep_the_band_route_and_silhouette_can_be_forced():
    s = render_look("painted_band", [0.0, 1.0], shape=(700, 900))
    assert _extract(s).attrs["tracer"] == "band"
    s = render_look("edge_dark", [0.0, 0.6], shape=(700, 900))
    ds = _extract(s, tracer="silhouette")
    assert ds.attrs["tracer"] == "silhouette" and score(s.truth, ds)["n_silent"] == 0
    with pytest.raises(ValueError, match="tracer must be"):
        _extract(s, tracer="guess")
    with pytest.raises(ValueError, match="chamber_region"):
        _extract(s, tracer="silhouette", chamber_region=(100, 200))


def test_a_band_off_the_chambers_rim_is_not_this_chamber():
    """ho_dyed_film (a lightly dyed film: a flat band, a dome of thin lines): the band route finds a band whose rim
    lies 45 % inside the well's (88 px against 160) and reads its own flat frame ok; measured blind, auto kept it
    and read every frame flat, flagged ok.  With the chamber given, auto checks the band's rim against its radius
    (ROUTE_RIM_TOL) and takes the silhouette route, whose rim is the well's: every frame ok and within the
    tolerances.  Without a chamber the band was kept and its flat reading warned about (measured on the 100
    cached looks read without a chamber: the band route took a band not the well's film on 8, 3-9 of 9 frames ok
    and wrong); now its rim is checked against the walls' (the silhouette route's) and the silhouette route taken,
    with a warning, when they lie more than ROUTE_RIM_TOL apart: the same reading as with the chamber."""
    from osmobulge.imaging.extract import ROUTE_RIM_TOL
    from osmobulge.imaging.trace import ChamberTracer

    s = render_look("ho_dyed_film", [0.0, 0.6, 2.0], lambda_pre=PRE)
    p, true_rim = s.truth.attrs["pixel_size"], s.truth.rim_radius.values[0]
    band = ChamberTracer(s.frames[0])
    assert band.process(s.frames[0], 0).flag == "ok"  # (so the own-flat-frame check does not catch it)
    assert abs(band.ref.rim_radius * p / true_rim - 1.0) > 2 * ROUTE_RIM_TOL
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert ds.attrs["tracer"] == "silhouette"
    assert list(ds.flag.values) == ["ok"] * 3 and sc["n_silent"] == 0 and sc["worst_dv_tol"] <= 1.0
    assert np.all(np.abs(sc["rim_bias_px"]) <= 0.5)
    # without a chamber the band's rim is checked against the walls'
    with pytest.warns(UserWarning, match=r"the band route's rim \(\d+\.\d px\) lies \d+ % off the walls'"):
        free = extract(s.frames, pixel_size=p, progress=False, frame_interval=600.0)
    assert free.attrs["tracer"] == "silhouette"
    sc = score(s.truth, free)
    assert list(free.flag.values) == ["ok"] * 3 and sc["n_silent"] == 0 and sc["worst_dv_tol"] <= 1.0
    # a band that is the well's film (painted_band: the band and the walls agree) is kept
    painted = render_look("painted_band", [0.0, 1.0], shape=(700, 900), lambda_pre=PRE)
    assert _extract(painted).attrs["tracer"] == extract(painted.frames, pixel_size=painted.truth.attrs["pixel_size"],
                                                         progress=False, frame_interval=600.0).attrs["tracer"] == "band"


def test_dark_field_is_refused_not_measured():
    s = render_look("dark_field", [0.0, 0.6], shape=(700, 900))
    ratio, why = dark_background(s.frames[0])
    assert ratio < 0.01 and "dark-field" in why
    for route in ("silhouette", "auto"):  # refused with the reason and the way in, not traced
        with pytest.raises(ChamberNotFound, match="background is dark.*Profile picker"):
            _extract(s, tracer=route)
    ds = _extract(s, tracer="band")  # asked for: the band route finds something, and flags every frame
    assert score(s.truth, ds)["n_silent"] == 0 and (ds.flag != "ok").all()


def test_a_bulged_first_frame_is_refused(edge_dark):
    with pytest.raises(ChamberNotFound, match="dome already stands|flat film|top face"):
        SilhouetteTracer(edge_dark.frames[2], l0_px=25.0, depth_px=137.5)
    # through extract: refused, or (the band search finding something) every frame flagged -- never a silent ok
    try:
        ds = extract(edge_dark.frames[2:], pixel_size=0.8e-6, frame_interval=600.0, progress=False,
                     chamber=_chamber(edge_dark.truth))
    except ChamberNotFound as err:
        assert "needs reference_frame=" in str(err)
    else:
        assert (ds.flag != "ok").all()
    ds = extract(edge_dark.frames[2:], pixel_size=0.8e-6, frame_interval=600.0, chamber=_chamber(edge_dark.truth),
                 progress=False, reference_frame=edge_dark.frames[0])
    sc = score(edge_dark.truth.isel(time=slice(2, None)), ds)
    assert sc["n_flagged"] == 0 and np.all(sc["dv_tol"] <= 1.0)


def test_a_tilted_view_is_refused():
    look = LOOKS["edge_dark"]
    s = render_look("edge_dark", [0.0], shape=(700, 900), nuisances=replace(look.nuisances, tilt=0.5))
    with pytest.raises(ChamberNotFound, match="tilted|no straight top face"):
        SilhouetteTracer(s.frames[0], l0_px=25.0, depth_px=137.5)


# ------------------------------------------------------------------------------------------ gates
def _tracer_and_frames(s):
    return SilhouetteTracer(s.frames[0], l0_px=25.0, depth_px=137.5), [np.asarray(f, float) for f in s.frames]


def test_part_of_the_dome_gone_is_flagged(edge_dark):
    """A third of the dome wiped out (replaced by the flat frame there): rays without an edge, not an ok volume."""
    tr, fr = _tracer_and_frames(edge_dark)
    f = fr[3].copy()
    axis = float(edge_dark.truth.axis_x[3])
    f[:, int(axis) + 60 :] = fr[0][:, int(axis) + 60 :]
    res = tr.process(f, 3)
    assert res.flag != "ok"
    assert res.figures["edge_lost"] > 0.1


def test_dust_off_the_dome_does_not_pass_as_the_dome(edge_dark):
    """Dark specks outside the dome catch a few rays first: their edges jump and are dropped (or flagged)."""
    tr, fr = _tracer_and_frames(edge_dark)
    t = edge_dark.truth
    p = t.attrs["pixel_size"]
    f = fr[3].copy()
    rng = np.random.default_rng(3)
    level = float(np.median(f[:50]))
    for _ in range(6):
        r, c = int(rng.uniform(20, 200)), int(rng.uniform(200, 800))
        f[r : r + 4, c : c + 4] = 0.2 * level
    res = tr.process(f, 3)
    v_true = float(t.volume[3]) / p**3
    tol = max(0.03 * v_true, 0.5 * np.pi * (float(t.rim_radius[3]) / p) ** 2)
    assert res.figures["edge_jumps"] > 0.0
    assert res.flag != "ok" or abs(res.volume - v_true) <= tol


def test_a_film_gone_from_the_flat_frame_is_no_membrane(edge_dark):
    """The flat film's faces over the well missing: not a flat membrane (flagged, its figure says why)."""
    tr, fr = _tracer_and_frames(edge_dark)
    w = tr.walls0
    f = fr[0].copy()
    r0, r1 = int(w.top_row) - 4, int(w.base_row) + 5
    c0, c1 = int(w.left) + 10, int(w.right) - 10
    f[r0:r1, c0:c1] = f[r0 - 30 : r1 - 30, c0:c1]  # water where the film was
    assert tr.process(fr[0], 0).flag == "ok"
    res = tr.process(f, 0)
    # (the vanished face lines are a change along the top face: read as a dome too low to measure)
    assert res.flag in ("no_membrane", "poor_fit") and res.flag_figure in ("dome_contrast", "low_dome")


@pytest.mark.slow
@pytest.mark.parametrize("name", ["edge_dark", "edge_bright", "defocus"])
def test_end_to_end_permeability_on_optics_looks(name):
    """Reference chamber, PDMS Table-3 law -> simulate -> render in the look -> extract -> Eqn 27 fit: P_w(1)
    within 5 %."""
    from osmobulge.imaging.synthetic import render_simulation
    from osmobulge.modeling.fitting import fit_permeability
    from osmobulge.modeling.materials import PDMS
    from osmobulge.modeling.permeability import DoubleExponential
    from osmobulge.modeling.simulate import simulate
    from osmobulge.modeling.transport import paper_chamber

    look = LOOKS[name]
    ch = paper_chamber("reference")
    t = np.arange(0.0, 24.01, 1.0) * 3600.0
    sim = simulate(ch, PDMS, DoubleExponential.PDMS, t, lambda_pre=PRE)
    s = render_simulation(sim, chamber=ch, pixel_size=2e-6, shape=(512, 512), lambda_pre=PRE,
                          nuisances=look.nuisances, optics=look.optics, seed=1)
    ds = extract(s.frames, pixel_size=2e-6, frame_interval=3600.0, chamber=ch, progress=False)
    assert ds.attrs["tracer"] == "silhouette"
    assert (ds.flag == "ok").all()
    # (measured: within 1.1 % at V/V0 12, i.e. the volume added within 1.2 %, under the issue's 3 %)
    np.testing.assert_allclose(ds.volume_ratio, sim.volume_ratio, rtol=0.015)
    ok = ds.where(ds.flag == "ok", drop=True)
    measured = PreStretch(ds.attrs["prestretch_c1"], ds.attrs["prestretch_c2"])
    fit = fit_permeability([ok], PDMS, model="double_exponential", lambda_pre=measured)
    assert fit.p_at_rest == pytest.approx(DoubleExponential.PDMS(1.0), rel=0.05, abs=0)


def test_a_wrong_membrane_thickness_flags_every_frame(edge_dark):
    """A Chamber whose l0 (26 um) disagrees with the flat film's two faces (20 um apart): the top face, the
    mid plane every height is measured from, is in doubt -- every frame poor_fit (flat_film), none silently ok."""
    a, h, _ = (edge_dark.truth.attrs[k] for k in ("chamber_radius", "chamber_depth", "membrane_thickness"))
    ds = extract(edge_dark.frames, pixel_size=0.8e-6, chamber=Chamber(a, h, 26e-6, 3000.0), progress=False,
                 frame_interval=600.0)
    assert ds.attrs["tracer"] == "silhouette"
    assert list(ds.flag.values) == ["poor_fit"] * len(VT)
    assert set(ds.flag_figure.values) == {"flat_film"}
    assert float(ds.flag_value[0]) == pytest.approx(6e-6, abs=0.4e-6)  # (a length: m)


def test_a_manual_profile_replaces_the_silhouette_trace(edge_dark):
    """The true mid-surface picked by hand in frame 2: its volume and area, not the trace's (which also holds)."""
    p = edge_dark.truth.attrs["pixel_size"]
    t = edge_dark.truth.isel(time=2)
    cols = np.r_[t.midline_col.values[0][::-1], t.midline_col.values[1][1:]]
    rows = np.r_[t.midline_row.values[0][::-1], t.midline_row.values[1][1:]]
    pick = np.c_[cols, rows][::-1] * p  # picked right rim to left: the order along the curve is what counts
    ds = _extract(edge_dark, manual_profiles={2: pick})
    assert ds.attrs["tracer"] == "silhouette"
    assert list(ds.profile_source.values) == ["auto", "auto", "manual", "auto"]
    assert float(ds.volume[2]) == pytest.approx(float(t.volume), rel=2e-3, abs=0)
    assert float(ds.area_ratio[2]) == pytest.approx(float(t.area_ratio), rel=2e-3, abs=0)
    assert list(ds.flag.values) == ["ok"] * 4


def test_a_given_rim_is_the_way_in_when_the_search_fails():
    """A scratch on the cover glass across the field, darker than the top face 60 px above it: the search takes
    it for the top face and finds no chamber; the rim given within 2 px (its flat mid-line's ends) is measured."""
    s = render_look("edge_dark", [0.0, 0.6, 2.0], shape=SHAPE, lambda_pre=PRE)
    t, p = s.truth, s.truth.attrs["pixel_size"]
    row, col, r = t.attrs["anchor_row"], t.attrs["anchor_col"], float(t.rim_radius[0]) / p
    rows = np.arange(SHAPE[0], dtype=float)[:, None]
    scratch = 1.0 - 0.35 * np.exp(-0.5 * ((rows - (row - 60.0)) / 1.5) ** 2)
    s.frames[:] = np.rint(s.frames * scratch).astype(s.frames.dtype)
    with pytest.raises(ChamberNotFound, match="give the rim"):
        _extract(s)
    rim = np.array([[col - r + 1.5, row - 2.0], [col + r - 1.0, row + 1.0]]) * p  # (x, y) m, picked roughly
    ds = _extract(s, rim=rim)
    sc = score(t, ds)
    assert ds.attrs["tracer"] == "silhouette" and sc["n_flagged"] == 0 and sc["n_silent"] == 0
    assert np.all(sc["dv_tol"] <= 0.3), sc["dv_tol"]  # (measured 0.10-0.11)
    assert np.all(np.abs(sc["rim_bias_px"]) < 0.2), sc["rim_bias_px"]  # (measured -0.06..-0.07)
    with pytest.raises(ChamberNotFound, match="no chamber at the given rim"):
        _extract(s, rim=rim - np.array([0.0, 200.0]) * p)  # 200 px up, in the water
    with pytest.raises(ValueError, match="rim= locates"):
        _extract(s, rim=rim, tracer="band")
    with pytest.raises(ValueError, match="shape \\(2, 2\\)"):
        _extract(s, rim=rim[:1])
    with pytest.raises(ValueError, match="px apart"):  # both points on one wall
        _extract(s, rim=np.array([rim[0], rim[0] + np.array([10.0, 0.0]) * p]))


def test_tracked_frames_agree_with_the_full_search():
    """A series filmed slowly enough to track: after the first dome frames, frames are found along the last outer
    face's normals (no ray search; one pass where the prediction holds), and their volumes and rims equal the full
    search's within a tenth of the tolerance (both against the truth within it)."""
    vt = np.linspace(0.3, 1.2, 7)
    s = render_look("edge_dark", np.r_[0.0, vt], shape=SHAPE, lambda_pre=PRE)
    p = s.truth.attrs["pixel_size"]
    tracked, full = SilhouetteTracer(s.frames[0], **_known(s)), SilhouetteTracer(s.frames[0], **_known(s))
    tol = _volume_tolerance(s)
    for i, f in enumerate(s.frames):
        a = tracked.process(f, i)
        full._track = None  # (never tracked: every frame searched by rays)
        b = full.process(f, i)
        assert a.flag == b.flag == "ok"
        va, vb = (0.5 * (o.volume_left + o.volume_right) for o in (a, b))
        assert abs(va - vb) < 0.1 * tol[i]
        assert abs(va - s.truth.volume.values[i] / p**3) < tol[i]
        assert abs(a.geometry.rim_radius - b.geometry.rim_radius) < 0.01
    # (the flat reference frame itself is not searched: its change is 0 on every ray); from the third dome frame
    # on the prediction holds, and the track takes one pass (measured: frames 4-7)
    assert full.searches == len(s.frames) - 1 and tracked.searches <= 3 and tracked.one_pass >= 4


def test_the_reference_frame_is_flat_without_a_search(edge_dark):
    """The first frame (the reference itself) is the flat film without the ray search, as the search finds it
    in a copy that differs by a count here and there."""
    tr = SilhouetteTracer(edge_dark.frames[0], **_known(edge_dark))
    a = tr.process(edge_dark.frames[0], 0)
    assert tr.searches == 0
    copy = np.asarray(edge_dark.frames[0]).copy()
    copy[::7, ::5] += 1
    b = tr.process(copy, 0)
    assert tr.searches == 1
    for o in (a, b):
        assert (o.mode, o.flag, o.volume_left, o.volume_right) == ("flat", "ok", 0.0, 0.0)
    assert a.figures["dome_contrast"] == 0.0 and b.figures["dome_contrast"] < 10.0


def test_a_dome_that_turns_and_shrinks_is_tracked_back():
    """The dome grows, then shrinks (a leak, or the bath made saltier): the track's prediction (on by the last
    step) is then wrong by two steps; the frames stay ok, within tolerance of the truth, and equal to the full
    search's."""
    vt = [0.0, 0.6, 0.7, 0.8, 0.7, 0.6, 0.5, 0.4]
    s = render_look("edge_dark", vt, shape=SHAPE, lambda_pre=PRE)
    p = s.truth.attrs["pixel_size"]
    tracked, full = SilhouetteTracer(s.frames[0], **_known(s)), SilhouetteTracer(s.frames[0], **_known(s))
    tol = _volume_tolerance(s)
    searched = []
    for i, f in enumerate(s.frames):
        n = tracked.searches
        a = tracked.process(f, i)
        searched.append(tracked.searches > n)
        full._track = None
        b = full.process(f, i)
        assert a.flag == b.flag == "ok", (i, a.flag, a.flag_figure, a.flag_value)
        va, vb = (0.5 * (o.volume_left + o.volume_right) for o in (a, b))
        assert abs(va - s.truth.volume.values[i] / p**3) < tol[i], i
        assert abs(va - vb) < 0.1 * tol[i], i
    # the frame after the turn misses the prediction and is searched (measured); the shrinking frames after it
    # are found by the track, in one pass once it has two frames to predict from (measured: frames 5-7)
    assert not any(searched[5:]), searched
    assert tracked.one_pass >= 3


def test_the_frame_after_a_flagged_one_is_searched_and_measured():
    """A frame with part of the dome wiped out is flagged; it ends the track, and the next frames (searched
    anew) are ok and within tolerance: one bad frame costs one frame."""
    vt = [0.0, 0.3, 0.45, 0.6, 0.75, 0.9]
    s = render_look("edge_dark", vt, shape=SHAPE, lambda_pre=PRE)
    p = s.truth.attrs["pixel_size"]
    tr = SilhouetteTracer(s.frames[0], **_known(s))
    frames = [np.asarray(f, float) for f in s.frames]
    axis = int(s.truth.axis_x.values[3])
    frames[3][:, axis + 60 :] = frames[0][:, axis + 60 :]
    tol = _volume_tolerance(s)
    out, searched = [], []
    for i, f in enumerate(frames):
        n = tr.searches
        out.append(tr.process(f, i))
        searched.append(tr.searches > n)
    assert out[3].flag != "ok" and out[3].figures["edge_lost"] > 0.1
    for i in (1, 2, 4, 5):
        assert out[i].flag == "ok", (i, out[i].flag)
        v = 0.5 * (out[i].volume_left + out[i].volume_right)
        assert abs(v - s.truth.volume.values[i] / p**3) < tol[i], i
    assert searched[4], searched  # the flag ended the track (steps of 0.15 here are past the track's reach)


def test_the_drift_registration_is_skimages_phase_correlation():
    """_Shift1D (the base's profiles registered frame to frame) against skimage's phase_cross_correlation
    (normalization None, upsampled 20x) on shifted noisy random walks of many lengths."""
    from skimage.registration import phase_cross_correlation

    from osmobulge.imaging._facetrace import _Shift1D

    rng = np.random.default_rng(5)
    for _ in range(60):
        n = int(rng.integers(100, 1100))
        x = np.cumsum(rng.normal(size=n + 40))
        shift = rng.uniform(-15, 15)
        a = np.interp(np.arange(n) + 20, np.arange(n + 40), x)
        b = np.interp(np.arange(n) + 20 - shift, np.arange(n + 40), x) + rng.normal(0, 0.3, n)
        a, b = a - a.mean(), b - b.mean()
        want = phase_cross_correlation(a, b, upsample_factor=20, normalization=None)[0][0]
        got = _Shift1D(a).shift(b)
        assert got == pytest.approx(want, abs=1e-9)
    # and it is the shift, to its 1/20 px grid, on a periodic profile (b is a moved by +shift)
    t = np.arange(512) / 512
    for shift in (-7.33, 0.0, 2.21, 11.86):
        a, b = (sum(np.sin(2 * np.pi * f * (t - s / 512) + f) / f for f in range(1, 40)) for s in (0.0, shift))
        assert _Shift1D(a).shift(b) == pytest.approx(-shift, abs=0.026)


def test_the_local_light_is_the_gaussian_of_the_frame(edge_dark):
    """_relative (block means, a coarse Gaussian, linear interpolation back) against scipy's Gaussian of 25 px of
    the full frame: within 0.2 % more than 25 px inside the frame, 1 % at its edges."""
    from scipy import ndimage

    from osmobulge.imaging._facetrace import _relative

    img = np.asarray(edge_dark.frames[0], float)
    want = ndimage.gaussian_filter(img, 25.0, mode="nearest")
    err = np.abs(_relative(img) / want - 1.0)
    assert err[25:-25, 25:-25].max() < 2e-3 and err.max() < 1e-2
    odd = img[:501, :333]  # (sizes that are not multiples of the block)
    err = np.abs(_relative(odd) / ndimage.gaussian_filter(odd, 25.0, mode="nearest") - 1.0)
    assert err[25:-25, 25:-25].max() < 2e-3 and err.max() < 1e-2


def test_stations_are_denser_at_the_feet():
    """_station_arcs: every foot_step px within foot_arc of either end, every ~step px between, the ends (the
    feet) left out; a curve shorter than two foot arcs is all foot_step; _station_shares add up to the arc."""
    from osmobulge.imaging._facetrace import _station_arcs, _station_shares

    s = _station_arcs(500.0, 3.0, 1.5, foot_arc=40.0)
    d = np.diff(s)
    assert s[0] == pytest.approx(1.5) and s[-1] == pytest.approx(498.5) and np.all(d > 0)
    foot = d[(s[1:] <= 40.0) | (s[:-1] >= 460.0)]
    assert np.all(foot <= 1.5 + 1e-9) and np.sum(np.abs(foot - 1.5) < 1e-9) >= foot.size - 2
    mid = d[(s[:-1] >= 40.0) & (s[1:] <= 460.0)]
    assert np.all(mid <= 3.0) and np.all(mid > 2.9)
    np.testing.assert_allclose(np.diff(_station_arcs(60.0, 3.0, 1.5, foot_arc=40.0)), 1.5)
    np.testing.assert_allclose(np.diff(_station_arcs(90.0, 4.5, None)), 4.5)  # (uniform: the two-pass track)
    # shares on a straight line: the stations' span, each end station's whole gap
    xy = np.column_stack((s, np.zeros_like(s)))
    shares = _station_shares(xy)
    assert shares.sum() == pytest.approx(s[-1] - s[0] + 0.5 * (d[0] + d[-1]))


def test_the_tracks_curve_is_the_face_sampled_by_arc_length():
    """_Polyline (the one-pass track's curve): through a half circle of 300 px sampled every px between two feet
    it is the circle by arc length (points within 5e-4 px of it, the length within 1e-5 of pi R), its tangents
    the circle's within half a segment's turn (0.5/R rad); a repeated point adds no segment; arcs outside
    [0, length] are its ends."""
    from osmobulge.imaging._facetrace import _Polyline

    R = 300.0
    phi = np.linspace(np.pi, 0.0, int(np.pi * R) + 1)  # (left foot -> over the top -> right foot, ~1 px apart)
    xy = np.column_stack((R * np.cos(phi), R * np.sin(phi)))
    line = _Polyline(np.vstack((xy[:1], xy)))  # (the first point twice)
    assert line.length == pytest.approx(np.pi * R, rel=1e-5)
    s = np.random.default_rng(3).uniform(0.0, line.length, 500)
    p = line(s)
    np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]), R, atol=5e-4)
    ang = np.pi - s / R  # (where the circle is at that arc)
    np.testing.assert_allclose(p, np.column_stack((R * np.cos(ang), R * np.sin(ang))), atol=2e-3)
    t = line.tangent(s)
    want = np.column_stack((np.sin(ang), -np.cos(ang)))  # (d/ds of the point: clockwise)
    assert np.max(np.abs(np.einsum("ij,ij->i", t, want) - 1.0)) < 0.5 / R**2  # (1 - cos(0.5 / R) = 1.4e-6)
    np.testing.assert_allclose(line([-5.0, line.length + 5.0]), xy[[0, -1]])
    np.testing.assert_allclose(line.tangent([-5.0, line.length + 5.0]), line.dirs[[0, -1]])


def test_the_tracks_feet_carry_the_face_down_to_the_top_face():
    """_foot: a face's end 4 px up going on outwards-down (0.6, -0.8) meets the top face 5 px on, at (103, 0); a
    shallow end is carried at most 40 px; an end that does not come down (level or rising), or is at the top
    face already, adds no point."""
    from osmobulge.imaging._facetrace import _foot

    np.testing.assert_allclose(_foot(np.array([100.0, 4.0]), np.array([0.6, -0.8])), [[103.0, 0.0]])
    t = np.array([np.cos(0.01), -np.sin(0.01)])
    np.testing.assert_allclose(_foot(np.array([100.0, 4.0]), t), [[100.0 + 40.0 * t[0], 4.0 + 40.0 * t[1]]])
    assert _foot(np.array([100.0, 4.0]), np.array([1.0, 0.0])).shape == (0, 2)
    assert _foot(np.array([100.0, 4.0]), np.array([0.6, 0.8])).shape == (0, 2)
    assert _foot(np.array([100.0, -0.5]), np.array([0.6, -0.8])).shape == (0, 2)  # (an end at the top face)


def test_the_noise_is_the_changes_spread_over_the_water(edge_dark):
    """The noise figure (12 rows, a sample every px, every other row half a px on) against the scaled MAD of the
    same change on 64 rows sampled every 0.5 px: within 8 % (on the 21 looks at 9 frames: -4..+8 %), and against
    the rendered read noise: the change (this frame less the flat one, over the light) has sqrt(2) times the
    frame's; the 0.7 px Gaussian along a row keeps (2 sqrt(pi) 0.7)**-0.5 = 0.64 of white noise, and the rows'
    bilinear samples between two pixel rows 0.71-1 of that: 0.45-0.64 (measured 0.51)."""
    from osmobulge.imaging._kernels import median

    tr = SilhouetteTracer(edge_dark.frames[0], **_known(edge_dark))
    frame = np.asarray(edge_dark.frames[2])
    img = np.rot90(frame, tr.k)
    w, dx, dy, *_ = tr._walls(img, *_profiles(img[slice(*tr._reg_rows)])[:2])

    def sample(points, directions, offsets, own=True):  # (no neighbours: the same either way)
        return tr._change(frame, points, directions, offsets, dx, dy)

    got, tilt, _ = tr._noise(sample, w)
    assert tilt is None  # (the light did not change)
    rows = np.linspace(2.0, w.top_row - 5.0, 64)
    v = sample(np.column_stack((np.zeros_like(rows), rows)), np.tile([1.0, 0.0], (64, 1)),
               np.arange(0.0, tr.view_shape[1] - 1.0, 0.5))
    want = 1.4826 * median(np.abs(v - median(v)))
    assert got == pytest.approx(want, rel=0.08)
    light = float(np.median(np.asarray(edge_dark.frames[0], float)[:50]))
    read = 0.01 * (2**16 - 1) / light  # (the look's noise_sigma, of full scale, over the water's level)
    assert 0.42 < got / (np.sqrt(2) * read) < 0.66


def test_a_change_of_the_whole_views_light_is_taken_off_the_change(edge_dark):
    """The light of the whole view changed by 15 % more than the base's gain took off (its rows clipped): the
    water's change stands 0.15 off 0, 14x the noise, which the noise, a MAD, does not see, and every sample of the
    water reads as a change over 10x the noise.  When the base's rows hold clipped light, the plane through the
    water's change is now taken off when its level over the water (and the change of the rows highest above the top
    face) stands over 2x the noise off 0, tilted or not; in unchanged light, or with the base not clipped, as
    before."""
    tr = SilhouetteTracer(edge_dark.frames[0], **_known(edge_dark))
    frame = np.asarray(edge_dark.frames[2])
    img = np.rot90(frame, tr.k)
    w, dx, dy, *_ = tr._walls(img, *_profiles(img[slice(*tr._reg_rows)])[:2])

    def sample(points, directions, offsets, own=True):  # (the frame's light 1.15x, not divided out)
        return 1.15 * tr._change(frame, points, directions, offsets, dx, dy) + 0.15

    def unchanged(points, directions, offsets, own=True):
        return tr._change(frame, points, directions, offsets, dx, dy)

    before, tilt0, _ = tr._noise(unchanged, w, clipped_base=True)
    assert tilt0 is None
    assert tr._noise(sample, w)[1] is None  # (the base's gain trusted: its rows not clipped)
    noise, tilt, figure = tr._noise(sample, w, clipped_base=True)
    assert 0.15 / before > 12.0  # (the level, in the noise: 14)
    assert tilt is not None and figure < 2.0 * noise  # (a level, no tilt)
    level = tilt[0] + tilt[1] * 0.5 * tr.view_shape[1] + tilt[2] * 0.5 * w.top_row
    assert level == pytest.approx(0.15, abs=0.1 * before)
    assert noise == pytest.approx(before, rel=0.02)  # ((v - p) / (1 + p): the change in the first frame's light)


def test_light_the_bases_gain_did_not_take_off_is_not_a_neighbours_dome():
    """drawn_20261207_62, measured blind: its exposure turned up 39 % over the series, its base at 0.97 of full
    scale in the first frame, clipped after, so the gain read from the base was 1.04-1.08 for 1.10-1.39, and the
    water read 9-14x the noise brighter than the first frame everywhere: taken for the neighbour's dome merging
    with the face's change, 6 of 9 frames were flagged touching (the neighbour 52-182 px off), one of them 2.3x the
    tolerance off beneath that flag; the last frame's rim 0.98 px small, ok.  Now the water's level is taken off:
    every frame ok (9 of 9: volumes within 0.14 of the tolerance, rims within 0.45 px).  Here a flat frame and two
    domes (on the code before: touching, touching, the second 2.0x the tolerance off)."""
    s = render_look("drawn_20261207_62", [0.0, 1.5, 3.0], shape=(600, 1024), lambda_pre=PRE)
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert np.all(ds.light_gain.values[1:] < 1.1) and s.truth.light_gain.values[-1] > 1.35  # (the base clipped)
    assert list(ds.flag.values) == ["ok"] * 3, list(ds.flag.values)
    assert sc["n_silent"] == 0 and np.all(sc["dv_tol"] < 0.5), sc["dv_tol"]
    assert np.all(np.abs(sc["rim_bias_px"]) < 0.5), sc["rim_bias_px"]


def test_a_particle_against_a_wall_does_not_move_the_rim():
    """coarse_2um (2 um/px: a wall 30-odd rows long), its Vtilde 2 frame five times, four with a particle (a disc
    darker by 0.3-0.45, 5-9 px in radius, blurred by 1 px) against the right wall below the base's top surface:
    two outside it, two over its edge from the well's side.  Their rows' edges are read against the darkened
    light, or the particle's silhouette merges with the wall's, and the wall's line, fitted through them, moved
    the rim by 0.08-0.14 px outside and 0.28-0.49 px over the edge (drawn_20261207_59 frame 3, measured blind:
    0.18 px, lambda_pre 0.33 % off, ok).  Those rows are left out now: the rim as without the particle, within
    0.05 px."""
    s = render_look("coarse_2um", [0.0, 2.0], shape=(400, 600), lambda_pre=PRE)
    t, p = s.truth, s.truth.attrs["pixel_size"]
    rim_row, axis = t.attrs["anchor_row"], t.attrs["anchor_col"]
    right = axis + t.rim_radius.values[1] / p  # (the right wall, px)
    depth = t.attrs["chamber_depth"] / p
    yy, xx = np.mgrid[: s.frames.shape[1], : s.frames.shape[2]]
    frames = [s.frames[0], s.frames[1]]
    for below, out, radius, opacity in ((0.3, 8.0, 6.0, 0.3), (0.2, 7.0, 9.0, 0.45), (0.25, -4.0, 8.0, 0.45),
                                        (0.2, 0.0, 5.0, 0.45)):
        disc = ndimage.gaussian_filter((np.hypot(yy - rim_row - below * depth, xx - right - out) <= radius) * 1.0, 1.0)
        frames.append(np.rint(s.frames[1] * (1.0 - opacity * disc)).astype(s.frames.dtype))
    ds = extract(np.stack(frames), pixel_size=p, chamber=_chamber(t), progress=False, frame_interval=600.0)
    assert list(ds.flag.values) == ["ok"] * 6
    rim = ds.rim_radius.values / p
    assert np.all(np.abs(rim[2:] - rim[1]) < 0.05), rim[2:] - rim[1]


def test_a_neighbouring_well_is_not_this_chambers_wall():
    """ho_blind_1206c: a neighbouring well 430 um to the right (its dome 0.7 of this one's).  Measured blind, its
    left wall's zone was as strong as this well's two, the search paired this well's right wall with it and the
    silhouette route refused the frame; auto kept a band route 80 % off the chamber's radius, 6 of 25 frames ok and
    wrong.  The walls are paired by their zones' sides now, the dome searched for only up to half-way to the
    neighbour's wall, and a dome that comes near there is flagged touching."""
    s = render_look("ho_blind_1206c", [0.0, 0.6, 3.2], lambda_pre=PRE)
    p, a = s.truth.attrs["pixel_size"], s.truth.attrs["chamber_radius"]
    t = SilhouetteTracer(s.frames[0], **_known(s))
    axis = s.truth.attrs["anchor_col"]  # (the chamber's axis, px)
    assert abs(t.walls0.rim_radius - a / p) < 0.5 and abs(t.walls0.axis_col - axis) < 0.5
    # half-way between this well's right wall and the neighbour's left one (430 um - a from the axis); none left
    assert t.bounds[0] == -np.inf and abs(t.bounds[1] - (axis + 0.5 * 430e-6 / p)) < 1.0
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert ds.attrs["tracer"] == "silhouette" and sc["n_silent"] == 0
    assert list(ds.flag.values[:2]) == ["ok", "ok"] and np.all(sc["dv_tol"][:2] <= 1.0), sc["dv_tol"]
    # the domes meet half-way (this one 3 px from there at Vtilde 3.0 of the blind series)
    assert ds.flag.values[2] == "touching" and ds.neighbour_gap.values[2] < 2.5 * p
    assert ds.flag_value.values[2] == ds.neighbour_gap.values[2]  # (the figure's own value, in m)


def test_a_stage_moved_past_max_drift_is_flagged_saying_how_to_follow_it(edge_dark):
    """A stage moved 60 px right and 25 px up after the first frame (the whole frame rolled): past max_drift (40
    px by default) the frame is no_membrane and the message names the setting; with max_drift 100 it is measured
    as the unmoved frame is (measured blind on a series bumped by 120 and 40 px at frame 8: the 17 frames after
    flagged; with max_drift 200 all 25 ok, worst 0.44 of the tolerance)."""
    p = edge_dark.truth.attrs["pixel_size"]
    moved = np.roll(np.asarray(edge_dark.frames[2]), (-25, 60), axis=(0, 1))
    out = SilhouetteTracer(edge_dark.frames[0], **_known(edge_dark)).process(moved, 2)
    assert out.flag == "no_membrane" and "max_drift (40 px)" in out.message and "--max-drift-px" in out.message
    t = SilhouetteTracer(edge_dark.frames[0], **_known(edge_dark), settings=TraceSettings(max_drift=100.0))
    out = t.process(moved, 2)
    assert out.flag == "ok" and out.drift == pytest.approx((60.0, -25.0), abs=0.1)
    want = SilhouetteTracer(edge_dark.frames[0], **_known(edge_dark)).process(edge_dark.frames[2], 2)
    assert out.volume == pytest.approx(want.volume, rel=2e-3)
    assert out.volume * p**3 == pytest.approx(float(edge_dark.truth.volume[2]), rel=0.03)


def test_three_wells_40_um_apart_growing_sideways_are_read_as_three():
    """Measured blind (1.6 um/px, the domes growing right, wells 340 um apart, 40 um of base between them): the
    renderer lost the top face's line of a dome growing sideways (fixed), then the walls were the first well's
    left and the third's right (the inner walls' zones 30 px apart, within find_walls' min_width): one well of
    3.3x the radius, the flat frame ok with it.  Now the middle well, with or without the chamber's radius, the
    neighbours' walls found, and the frame where the domes meet touching.  A chamber whose radius the walls found
    are more than 10 % off is refused, saying so."""
    from osmobulge.imaging.optics import Optics
    from osmobulge.imaging.synthetic import Nuisances, SceneGeometry, render_series

    p = 1.6e-6
    s = render_series([0.0, 0.5, 1.5], lambda_pre=PRE, shape=(720, 420), chamber=(150e-6, 110e-6, 22e-6),
                      pixel_size=p, scene=SceneGeometry(bulge_direction="right"), seed=97,
                      optics=Optics(n_elastomer=1.42, objective_na=0.2, condenser_na=0.1, defocus=4e-6,
                                    halo_strength=0.25),
                      nuisances=Nuisances(noise_sigma=0.012, blur_sigma=0.6, bit_depth=12,
                                          neighbours=((-340e-6, 0.8), (340e-6, 1.0))))
    assert list(s.truth.flag.values) == ["ok", "ok", "touching"]
    t = SilhouetteTracer(s.frames[0])
    assert t.walls0.rim_radius == pytest.approx(150e-6 / p, abs=0.5) and np.all(np.isfinite(t.bounds))
    for chamber in (None, _chamber(s.truth)):
        ds = extract(s.frames, pixel_size=p, frame_interval=600.0, chamber=chamber, progress=False)
        sc = score(s.truth, ds)
        assert list(ds.flag.values) == ["ok", "ok", "touching"] and sc["n_silent"] == 0
        assert np.all(sc["dv_tol"][:2] <= 1.0) and np.all(np.abs(sc["rim_bias_px"]) < 0.5), sc
    wide = Chamber(200e-6, 110e-6, 22e-6, 3000.0)
    with pytest.raises(ChamberNotFound, match=r"rim radius 1(49|50)\.\d um\) are not this chamber's \(radius 200.0 um"):
        extract(s.frames, pixel_size=p, frame_interval=600.0, chamber=wide, progress=False, tracer="silhouette")


def test_wells_a_third_of_a_radius_apart_with_zones_alike_on_both_sides():
    """drawn_20261207_23 (wells 2.27 radii apart, 36 um of base between them at 1.27 um/px, the domes growing
    right): every wall's silhouette zone falls alike on both sides, so no zone's side is known.  The neighbours'
    walls were not taken (only zones of the near wall's side were), the three domes were traced as one and the
    touching frames flagged fractured; cut to 820 x 420 px, the view was refused even with the chamber given (the
    bottom face's outside columns lay in the neighbours' wells).  Now the middle well, the neighbours seen and
    the touching frame touching; without the chamber the two strongest zones were the chamber's left wall and
    the neighbour's left one (the flat frame ok, its rim 17 px off), and (rendered since with the view turned a
    quarter blended right, :func:`osmobulge.imaging.optics._blend_silhouettes`) the chamber's left wall and the
    other neighbour's right one, two zones between them (the flat frame ok, its rim 118 px off).  With zones
    between the two strongest whose sides are not known, the well nearest the field's centre is taken
    (``_silhouette._wells_between``): the chamber, as with it given."""
    s = render_look("drawn_20261207_23", [0.0, 0.35, 1.41], shape=(820, 420), lambda_pre=PRE)
    p = s.truth.attrs["pixel_size"]
    assert list(s.truth.flag.values) == ["ok", "ok", "touching"]
    t = SilhouetteTracer(s.frames[0], **_known(s), radius_px=s.truth.attrs["chamber_radius"] / p)
    assert t.walls0.rim_radius == pytest.approx(s.truth.attrs["chamber_radius"] / p, abs=0.5)
    (off, _), (off2, _) = get_look("drawn_20261207_23").nuisances.neighbours
    gap = (off2 - 2.0 * s.truth.attrs["chamber_radius"]) / p  # (the base between the wells, px: 28)
    assert off == -off2 and np.all(np.isfinite(t.bounds))
    np.testing.assert_allclose(np.array(t._nb) - [t.walls0.left, t.walls0.right], [-gap, gap], atol=2.0)
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok", "ok", "touching"] and sc["n_silent"] == 0, ds.flag_figure.values
    assert np.all(sc["dv_tol"][:2] <= 1.0) and np.all(np.abs(sc["rim_bias_px"]) < 0.5), sc
    ds = extract(s.frames, pixel_size=p, frame_interval=600.0, progress=False, tracer="silhouette")
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok", "ok", "touching"] and sc["n_silent"] == 0, ds.flag_figure.values
    assert np.all(np.abs(sc["rim_bias_px"]) < 0.5), sc["rim_bias_px"]


def test_a_well_with_one_wall_outside_the_field_is_refused_saying_so():
    """Measured blind: a well whose left wall lies outside the field was refused as walls that are not straight
    lines (the one wall paired with another zone).  With the chamber's radius, the error says where the other
    wall would be."""
    from osmobulge.imaging.optics import Optics
    from osmobulge.imaging.synthetic import Nuisances, SceneGeometry, render_series

    p = 0.8e-6
    with pytest.warns(UserWarning, match="leaves the field"):  # (the well does)
        s = render_series([0.0, 0.3], lambda_pre=PRE, shape=(560, 700), chamber=(150e-6, 110e-6, 20e-6),
                          pixel_size=p, seed=112, scene=SceneGeometry(axis_position=(150.0, 330.0)),
                          optics=Optics(n_elastomer=1.415, objective_na=0.25, condenser_na=0.12, defocus=2e-6),
                          nuisances=Nuisances(noise_sigma=0.01, blur_sigma=0.7))
    with pytest.raises(ChamberNotFound, match=r"up: one wall silhouette of a well of the chamber's radius \(188 px\) "
                                              r"only, at column 33\d: its other wall would lie at column -\d+, "
                                              r"outside the frame's 700 columns"):
        _extract(s, tracer="silhouette")


def test_a_dome_past_the_half_way_column_is_measured_until_the_domes_meet():
    """ho_blind_1206c: this dome, larger than its neighbour's, passes the column half-way to the neighbour's well
    while the neighbour's dome is still far (the search stopped there and the frames were flagged touching 4
    frames before the domes met: 19 of 23 frames without contact measured).  Once the dome comes within
    _NEAR_PX of that column, the gap to the neighbour's dome is measured row by row (independent truth: the
    renderer's least gap between the two bands) and the next frame is searched up to its middle: every frame
    before contact ok and within tolerance, the frame where the domes meet touching."""
    vt = [0.0, 2.18, 2.60, 3.04, 3.27, 3.75]  # (frames 0, 16, 18, 20, 21 and 23 of the 25-frame blind series)
    s = render_look("ho_blind_1206c", vt, lambda_pre=PRE)
    p = s.truth.attrs["pixel_size"]
    ds = _extract(s)
    sc = score(s.truth, ds)
    truth_gap = s.truth.neighbour_gap.values / p
    assert list(s.truth.flag.values) == ["ok"] * 5 + ["touching"]
    assert list(ds.flag.values) == ["ok"] * 5 + ["touching"], ds.flag.values
    assert sc["n_silent"] == 0 and np.all(sc["dv_tol"][:5] <= 1.0), sc["dv_tol"]
    # (measured on the 25 frames: 58, 48, 39, 29, 19, 9 px against 58.3, 48.5, 38.7, 28.9, 19.1, 9.5)
    got = ds.neighbour_gap.values[1:5] / p
    np.testing.assert_allclose(got, truth_gap[1:5], atol=1.5)
    assert truth_gap[1] > 50 and truth_gap[4] < 12  # (from far to near)


def test_pixels_at_full_scale_are_not_specks():
    """Water exposed past full scale: about half its pixels sit at the ceiling and the MAD of the deviation of all
    of them is 0.  The specks' scale is that of the pixels not clipped: the noise below the ceiling is no speck,
    a dust speck 30 % dark is."""
    from osmobulge.imaging._facetrace import _speck_map

    rng = np.random.default_rng(5)
    raw = np.rint(4095.0 * (1.0 + 0.01 * rng.standard_normal((60, 300))))
    raw[20:24, 100:104] *= 0.7  # (a speck of dust)
    img = np.minimum(raw, 4095.0)
    assert 0.4 < np.mean(img == 4095.0) < 0.6
    sd = img / 4095.0 - 1.0
    m = _speck_map(sd, img == img.max())
    assert np.all(m[20:24, 100:104] == 0.0)
    assert np.mean(m == 0.0) == pytest.approx(16 / img.size)  # (nothing else)


def test_a_neighbours_dome_is_seen_in_saturated_water():
    """ho_blind_1206q (three wells 40 um apart, the water exposed past full scale): measured blind, a quarter of
    the pixels above the top face read as specks of the flat frame (their MAD about 0), the gap scan saw no
    neighbour's dome (read 32 px where the renderer's was 12) and the frame before the domes met was traced 2.7x
    the tolerance off.  Another such scene (other seed, radius, focus): the gap within 1.5 px of the truth's, the
    frames before contact within tolerance (measured 0.11-0.14 of it; 2.36 with the MAD of all pixels)."""
    from osmobulge.imaging.optics import Optics
    from osmobulge.imaging.synthetic import Nuisances, render_series

    p = 0.8e-6
    s = render_series([0.0, 1.0, 1.2, 1.4], lambda_pre=PRE, shape=(560, 700), chamber=(110e-6, 110e-6, 21e-6),
                      pixel_size=p, seed=103,
                      optics=Optics(n_elastomer=1.42, n_liquid=1.35, objective_na=0.25, condenser_na=0.12,
                                    defocus=-2e-6, halo_strength=0.35, halo_width=2.5e-6, brightness=1.0),
                      nuisances=Nuisances(noise_sigma=0.01, blur_sigma=0.7, bit_depth=12,
                                          neighbours=((-260e-6, 1.0), (260e-6, 1.0))))
    assert np.mean(s.frames[0] == s.frames[0].max()) > 0.4  # (saturated)
    truth_gap = s.truth.neighbour_gap.values / p
    assert list(s.truth.flag.values) == ["ok"] * 4 and 3.0 < truth_gap[3] < 5.0  # (4 px apart: no contact yet)
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert ds.attrs["tracer"] == "silhouette" and sc["n_silent"] == 0
    np.testing.assert_allclose(ds.neighbour_gap.values[1:3] / p, truth_gap[1:3], atol=1.5)
    assert np.all(sc["dv_tol"] <= 1.0), sc["dv_tol"]


@pytest.mark.parametrize("route", ["silhouette", "band"])
def test_a_dome_grown_out_of_the_field_is_flagged_as_such(route):
    """A dome growing out of the top of the field (the renderer warns): measured blind, both routes read the
    stretch outside the frame as a tear (fractured, gap_length) and the band route, once the dome was mostly out,
    found no membrane.  Those frames are poor_fit (field_margin) saying the dome left the field, and the frames
    before are ok and within tolerance."""
    from osmobulge.imaging.optics import Optics
    from osmobulge.imaging.synthetic import Nuisances, SceneGeometry, render_series

    p = 0.8e-6
    optics = Optics(n_elastomer=1.418, objective_na=0.25, condenser_na=0.12, defocus=3e-6, halo_strength=0.2)
    with pytest.warns(UserWarning, match="the dome leaves the field from frame 2 on"):
        s = render_series([0.0, 0.92, 1.98, 3.27], lambda_pre=PRE, shape=(700, 700),
                          chamber=(150e-6, 110e-6, 22e-6), pixel_size=p, seed=111,
                          optics=optics if route == "silhouette" else None,
                          nuisances=Nuisances(noise_sigma=0.01, blur_sigma=0.7, drift_sigma=0.3, bit_depth=12),
                          scene=SceneGeometry(axis_position=(350.0, 300.0)))
    ds = _extract(s, tracer=route)
    sc = score(s.truth, ds)
    assert ds.attrs["tracer"] == route
    assert list(ds.flag.values) == ["ok", "ok", "poor_fit", "poor_fit"], list(ds.flag_figure.values)
    assert list(ds.flag_figure.values[2:]) == ["field_margin"] * 2
    assert np.all(ds.flag_value.values[2:] < 3.0 * p) and np.all(sc["dv_tol"][:2] <= 1.0), sc["dv_tol"]
    assert all("the field's edge: the dome may have grown out of the field" in str(m) for m in ds.message.values[2:])


def test_a_frame_in_other_light_is_read_in_the_first_frames(edge_dark):
    """The lamp or the exposure changed between frames: measured blind, every frame's light scaled by 1 +- 0.3 at
    random left 1-8 of 9 frames flagged on six looks (the change in the water over 10x the noise everywhere).
    A frame whose base is more than 5 % brighter or darker than the first frame's is divided by that ratio
    first (light_gain): the same volumes."""
    want = _extract(edge_dark)
    f = np.asarray(edge_dark.frames, float)
    f[1:] *= np.array([0.65, 1.3, 0.75])[:, None, None]
    scaled = np.clip(np.round(f), 0, np.iinfo(edge_dark.frames.dtype).max).astype(edge_dark.frames.dtype)
    ds = _extract(edge_dark.__class__(scaled, edge_dark.truth))
    assert list(ds.flag.values) == ["ok"] * 4
    np.testing.assert_allclose(ds.light_gain.values, [1.0, 0.65, 1.3, 0.75], rtol=0.01)
    np.testing.assert_allclose(ds.volume.values[2:], want.volume.values[2:], rtol=5e-3)
    got, base = score(edge_dark.truth, ds)["dv_tol"], score(edge_dark.truth, want)["dv_tol"]
    assert np.all(got <= 1.0) and np.all(np.abs(got - base) < 0.1), (got, base)


def test_a_film_lifted_off_beside_the_rims_is_delaminated_on_this_route():
    """The renderer's delaminated frames (the film lifted 1.5 l0 at the rims, over 0.3 a; painted: the optics
    renderer draws no events).  Measured: this route, forced, read them ok 7.2x and 4.8x the tolerance off (no
    delamination check).  The change on the film's rows beyond each foot, loud from the foot on against the same
    rows' 0.5-0.8 radii out, is the lift: those frames delaminated, the others' rim contact near 1."""
    vt = [0.0, 0.5, 0.92, 1.41, 1.98]
    nu = replace(LOOKS["painted_band"].nuisances, delaminated_frames=(2, 3))
    s = render_look("painted_band", vt, lambda_pre=PRE, nuisances=nu)
    assert list(s.truth.flag.values) == ["ok", "ok", "delaminated", "delaminated", "ok"]
    ds = _extract(s, tracer="silhouette")
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok", "ok", "delaminated", "delaminated", "ok"], ds.rim_contact.values
    assert sc["n_silent"] == 0 and np.all(ds.rim_contact.values[[1, 4]] > 0.8)
    assert np.all(ds.rim_contact.values[2:4] < 0.5)


@pytest.mark.parametrize("mode", ["gap", "collapsed"])
def test_optically_rendered_events_are_flagged(mode):
    """Events drawn by the optics model (the renderer drew them painted only until now): the film lifted beyond
    the rims (a skirt of revolution with liquid under it), a piece torn out of the dome's side, the dome torn away
    (the well open, its flaps hanging in).  Each is flagged as what it is, or as no membrane, and the frames after
    it are read within the tolerance again.  Measured on the 14 presets (Vtilde 0..4, 8 frames, 1024 px): every
    delaminated and collapsed frame flagged, 0 silent."""
    vt = [0.0, 0.6, 1.2, 2.0, 2.6]  # (seed 0: frame 3's tear lies on the right, arc 0.51-0.66 from the left rim)
    nu = replace(LOOKS["edge_dark"].nuisances, delaminated_frames=(2,), fractured_frames=(3,), fracture_mode=mode)
    s = render_look("edge_dark", vt, shape=SHAPE, lambda_pre=PRE, nuisances=nu)
    assert list(s.truth.flag.values) == ["ok", "ok", "delaminated", "fractured", "ok"]
    ds = _extract(s)
    sc = score(s.truth, ds)
    got = list(ds.flag.values)
    assert got[:3] == ["ok", "ok", "delaminated"] and got[4] == "ok", (got, ds.message.values)
    assert got[3] == ("fractured" if mode == "gap" else "no_membrane"), (got, ds.message.values)
    assert sc["n_silent"] == 0 and sc["dv_tol"][4] < 0.5 and ds.rim_contact.values[2] < 0.5


def test_a_dome_with_its_cap_torn_off_is_not_read_ok():
    """A tear spanning the pole (fracture_gap 0.4: the cap above 0.3 of the arc from the rim gone; optics.Hole):
    the defocused look shows a flat-topped dome, which this route read ok 4x the tolerance off at Vtilde 1.2 (its
    edge followed along the cut).  Its straight top (least_bend about 0, over 0.29 on the looks' domes) flags
    it."""
    vt = [0.0, 0.6, 1.2, 2.0]
    nu = replace(LOOKS["defocus"].nuisances, fractured_frames=(2,), fracture_gap=0.4)
    s = render_look("defocus", vt, shape=SHAPE, lambda_pre=PRE, nuisances=nu)
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert sc["dv_tol"][2] > 2.0  # (the frame's volume is wrong: it must not be read ok)
    assert ds.flag.values[2] == "poor_fit" and ds.flag_figure.values[2] == "least_bend", ds.message.values
    assert "straight stretch" in ds.message.values[2] and abs(ds.least_bend.values[2]) < 0.05
    assert list(ds.flag.values[[0, 1, 3]]) == ["ok"] * 3 and np.all(ds.least_bend.values[[1, 3]] > 0.5)
    assert sc["n_silent"] == 0


def test_a_delaminated_frame_between_close_neighbours_is_not_read_ok():
    """Wells 2.8 radii apart: the rim-contact check's reference (0.5-0.8 radii beyond the rim) is cut off by the
    half-way columns, so it has no word (nan), and the delaminated frame was read ok 6.7x the tolerance off.  The
    lifted film's skirt, traced as part of the dome, bends the outline the other way (least_bend -4.3): the frame
    is poor_fit.  (Found with the optics events on the held-out neighbour look ho_blind_1206k: 9.6x off.)"""
    a = 200e-6
    vt = [0.0, 0.5, 1.0, 1.2]
    nu = replace(LOOKS["edge_dark"].nuisances, neighbours=((-2.8 * a, 0.7), (2.8 * a, 0.8)), delaminated_frames=(2,))
    s = render_look("edge_dark", vt, shape=SHAPE, lambda_pre=PRE, nuisances=nu, seed=3)
    assert list(s.truth.flag.values) == ["ok", "ok", "delaminated", "ok"]
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert np.isnan(ds.rim_contact.values[2]) and sc["dv_tol"][2] > 2.0
    assert ds.flag.values[2] == "poor_fit" and ds.flag_figure.values[2] == "least_bend", ds.flag.values
    assert sc["n_silent"] == 0 and list(ds.flag.values[[0, 1, 3]]) == ["ok"] * 3


def test_neighbours_whose_wells_lie_beyond_the_field_are_not_taken_for_the_dome():
    """Wells 3 radii apart in a 1000 px field: the neighbours' walls lie at the field's edges, out of sight, so
    no bounds are known, and their domes come in at the sides as they grow.  The full search's low rays met them
    first and the trace ran out to the field's edges: every dome frame was poor_fit (field_margin), 5.7-29x the
    tolerance off.  The pieces that came in at the sides, with this dome's face behind them on their rays, are
    passed over (_in_front): the frames are read, within 0.02 of the tolerance."""
    a = 200e-6
    vt = [0.0, 0.5, 1.0, 2.2]
    nu = replace(LOOKS["edge_dark"].nuisances, neighbours=((-3.0 * a, 0.8), (3.0 * a, 0.8)))
    s = render_look("edge_dark", vt, shape=SHAPE, lambda_pre=PRE, nuisances=nu, seed=3)
    frames = np.asarray(s.frames, float)
    top = int(s.truth.attrs["anchor_row"]) - 20
    for i in (2, 3):  # (the neighbours' domes are in the field, at both sides, above the top face)
        moved = np.abs(frames[i, :top] - frames[0, :top]) > 0.1 * frames[0].max()
        assert moved[:, :20].any() and moved[:, -20:].any()
    t = SilhouetteTracer(s.frames[0], **_known(s))
    assert t.bounds is None  # (no neighbour's wall seen)
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok"] * 4, ds.message.values
    assert np.all(np.abs(sc["dv_tol"]) < 0.1) and sc["n_silent"] == 0


def test_a_series_exported_as_jpeg_files_is_read(edge_dark, tmp_path):
    """A folder of 8-bit JPEG frames at quality 40 (a video or an export at its smallest): 8x8 blocks and ringing
    beside every face and wall in the change.  Measured on the 14 presets (9 frames, Vtilde 0-4): at quality 75
    none flagged, worst 0.24 of the tolerance; at 40 one frame flagged (halo, Vtilde 0.02, delaminated), worst
    0.26, none silent."""
    from PIL import Image

    frames = np.asarray(edge_dark.frames, float)
    for i, f in enumerate(frames):
        Image.fromarray(np.rint(f / frames.max() * 255.0).astype(np.uint8)).save(tmp_path / f"t{i:03d}.jpg",
                                                                                 quality=40)
    ds = extract(tmp_path, pixel_size=edge_dark.truth.attrs["pixel_size"], chamber=_chamber(edge_dark.truth),
                 progress=False, frame_interval=600.0)
    sc = score(edge_dark.truth, ds)
    assert list(ds.flag.values) == ["ok"] * len(VT), ds.message.values
    assert np.all(sc["dv_tol"] < 0.3) and np.all(np.abs(sc["rim_bias_px"]) < 0.5), sc["dv_tol"]


@pytest.mark.parametrize(("name", "drift"), [("edge_dark", -15e-6), ("edge_bright", 24e-6)])
def test_the_focal_plane_drifting_and_the_liquid_diluting_leave_the_volumes(name, drift):
    """A day without autofocus: the focal plane drifts 15 um off (edge_dark), or through focus from -12 to
    +12 um (edge_bright: the fringes swap sides), while the salt solution is diluted by the water that came in
    (Optics.dilution).  The tracer reads the change from the first frame, whose faces' fringes were at another
    focus: measured on the 12 optics presets over Vtilde 0-4 (9 frames), a drift of +12 um, and of -15 um and
    +30 um with the dilution, left every frame ok within 0.26 of the tolerance; -30 um flagged 21 of 108 frames
    and read one 1.04x off, ok (coarse_2um's last)."""
    look = LOOKS[name]
    s = render_look(name, VT, shape=SHAPE, lambda_pre=PRE, optics=replace(look.optics, dilution=True),
                    nuisances=replace(look.nuisances, focus_drift=drift))
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok"] * len(VT), ds.message.values
    assert np.all(sc["dv_tol"] < 0.3) and np.all(np.abs(sc["rim_bias_px"]) < 0.5), sc["dv_tol"]


def test_a_neighbour_coming_in_at_the_fields_side_is_measured_and_touching_is_flagged():
    """Wells 3.1 radii apart (halo look): the neighbours' walls lie beyond the field, so no bounds are known and
    there was no gap measured and no touching flag: the last frame, the domes overlapping by 2 px, read ok
    (0.55 of the tolerance off).  Their domes come in at the field's sides: the gap to the change that comes in
    there is measured on a 2 px grid (_side_gap), and is 0 when that change is one piece with the dome's face."""
    a = 200e-6
    nu = replace(LOOKS["halo"].nuisances, neighbours=((-3.1 * a, 0.9), (3.1 * a, 0.9)))
    s = render_look("halo", [0.0, 3.0, 3.4, 3.7, 4.0], shape=SHAPE, nuisances=nu)
    p = s.truth.attrs["pixel_size"]
    truth = s.truth.neighbour_gap.values / p
    assert list(s.truth.flag.values) == ["ok"] * 4 + ["touching"] and truth[3] > 15.0  # (the truth: 2 px overlap)
    assert SilhouetteTracer(s.frames[0], **_known(s)).bounds is None
    ds = _extract(s)
    assert list(ds.flag.values) == ["ok"] * 4 + ["touching"], ds.message.values
    gap = ds.neighbour_gap.values / p
    # (measured to the neighbour's change, its halo 3.75 px wide included: 1.9-3.2 px short of the bands' gap)
    assert np.all(np.abs(gap[1:4] - truth[1:4] + 2.5) < 1.5), (gap, truth)
    assert gap[4] == 0.0 and score(s.truth, ds)["n_silent"] == 0
    # the frame after (a full search: after a flagged frame) is traced on along the neighbour's dome to the
    # field's edge; its message says a dome came in at the side
    t = SilhouetteTracer(s.frames[0], **_known(s))
    outs = [t.process(f, i) for i, f in enumerate(s.frames)] + [t.process(s.frames[-1], 5)]
    assert [o.flag for o in outs[-2:]] == ["touching", "poor_fit"], outs[-1].message
    assert "a dome has come in at the field's side since frame 1" in outs[-1].message


def test_a_neighbour_coming_in_at_the_side_with_no_well_seen_is_measured_beside_a_known_one():
    """A neighbour's well seen on the left (flat: a well, no dome), another's beyond the field on the right
    (halo look, the axis 660 px from the left edge of a 1130 px field): the right side had no bound and was
    not watched; the gap read was the left one's search (45 px where the domes were 39 px apart).  The side
    with no well seen is watched as with none (_side_gap): the gap is the right neighbour's, 3.6 px short of
    the bands' (its halo).  The frames after, the domes within 18 px, then touching, are flagged (the trace
    takes part of the neighbour's face: touching and fractured)."""
    a = 200e-6
    nu = replace(LOOKS["halo"].nuisances, neighbours=((-3.36 * a, 0.0), (3.1 * a, 0.9)))
    s = render_look("halo", [0.0, 3.0, 3.4, 3.7, 4.0], shape=(860, 1130), nuisances=nu,
                    scene=SceneGeometry(axis_position=(660.0, 630.0)))
    p = s.truth.attrs["pixel_size"]
    bounds = SilhouetteTracer(s.frames[0], **_known(s)).bounds
    assert np.isfinite(bounds[0]) and bounds[1] == np.inf
    ds = _extract(s)
    truth = s.truth.neighbour_gap.values / p
    assert list(ds.flag.values[:3]) == ["ok"] * 3 and "ok" not in ds.flag.values[3:], ds.flag.values
    assert -5.0 < ds.neighbour_gap.values[2] / p - truth[2] < 0.0, (ds.neighbour_gap.values / p, truth)
    assert score(s.truth, ds)["n_silent"] == 0


@pytest.mark.parametrize("corner", ["tl", "tr"])
def test_a_time_stamp_burned_into_the_frames_is_not_taken_for_the_dome(edge_dark, corner):
    """A time stamp in a top corner of the frames (a microscope's export with annotations): its digits change
    from frame to frame, so the change shows them in the water above the dome, and the full search's rays
    towards them took them for the dome's edge: every dome frame was flagged (field_margin, gap_length), on the
    12 looks read by this route, in either top corner.  They lie in front of the dome on their rays
    (_in_front): the frames are read as without the stamp."""
    from osmobulge.imaging.synthetic import _stamp  # (what Nuisances(time_stamp=corner) burns in)

    p = edge_dark.truth.attrs["pixel_size"]
    bits = edge_dark.truth.attrs["bit_depth"]
    frames = [_stamp(np.asarray(f), 600.0 * i, corner, p, bits) for i, f in enumerate(edge_dark.frames)]
    stamped = edge_dark.__class__(np.stack(frames), edge_dark.truth)
    ds, plain = _extract(stamped), _extract(edge_dark)
    assert list(ds.flag.values) == ["ok"] * len(VT), ds.message.values
    np.testing.assert_allclose(ds.volume.values, plain.volume.values, rtol=2e-3, atol=1e-15)
    assert score(stamped.truth, ds)["n_silent"] == 0


def test_a_blank_or_partly_blank_frame_says_so(edge_dark):
    """A camera's blank frames mid-series (measured: black and white frames read as chamber walls not found, no
    word of the image): a flagged frame mostly at one value, more than the first frame, says so first."""
    f0 = np.asarray(edge_dark.frames[0])
    cut = np.array(edge_dark.frames[3])
    cut[:585] = 0  # (a transfer cut short: the top 68 % black)
    f = np.stack([f0, edge_dark.frames[1], np.zeros_like(f0), np.full_like(f0, np.iinfo(f0.dtype).max), cut])
    ds = _extract(edge_dark.__class__(f, edge_dark.truth))  # (the truth's attrs: the chamber)
    assert list(ds.flag.values[:2]) == ["ok", "ok"] and all(ds.flag.values[2:] != "ok")
    assert list(ds.message.values[:2]) == ["", ""]
    assert str(ds.message.values[2]).startswith("the frame is blank (every pixel is 0): a transfer cut short")
    assert str(ds.message.values[3]).startswith("the frame is blank (every pixel is 65535):")
    assert str(ds.message.values[4]).startswith("the frame is partly blank (68 % of its pixels are 0; the first "
                                                "frame's most common value, 0 %):")


def test_a_dome_that_reads_flat_after_a_dome_is_flagged(edge_dark):
    """A dome does not fall flat between two frames: a frame without a dome edge after an ok frame with a dome
    is flagged (its contrast), not measured flat.  Measured blind on ho_blind_1206d (neighbours both sides whose
    domes overlap this one, a dyed liquid): the domes over the noise's rows raised the noise until the dome's
    contrast fell below 10 of it, and 8 of 25 frames read flat and ok."""
    t = SilhouetteTracer(edge_dark.frames[0], **_known(edge_dark))
    assert t.process(edge_dark.frames[2], 2).flag == "ok"
    flat = edge_dark.frames[0] + np.uint16(1)  # (not the reference frame itself: searched)
    out = t.process(flat, 3)
    assert out.mode == "flat" and out.flag == "poor_fit" and out.flag_figure == "dome_contrast"
    assert "frame 2 had a dome" in out.message
    # the flat first frames of a series (no dome yet) stay ok
    t = SilhouetteTracer(edge_dark.frames[0], **_known(edge_dark))
    assert t.process(flat, 1).flag == "ok"
    # the blind look: its frames with overlapping domes flagged, none ok and wrong
    s = render_look("ho_blind_1206d", [0.0, 0.6, 2.4], lambda_pre=PRE)
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert sc["n_silent"] == 0 and list(ds.flag.values[:2]) == ["ok", "ok"] and ds.flag.values[2] != "ok"
    assert np.all(sc["dv_tol"][:2] <= 1.0), sc["dv_tol"]


def test_a_dome_not_seen_under_added_light_is_not_read_flat():
    """A frame without a dome edge reads flat only while its film's faces over the well keep their contrast (as
    those beside the well keep it).  ho_blind_1206e (a dim 10-bit look, vignetting, Poisson noise), a flat frame
    and a dome at Vtilde 1, with light added since the first frame: at 3x the first frame's median light the
    gain divided out left the dome's contrast 7.9x the noise, no edge was found, and the flat test (the change
    under 10x the noise) read it flat and ok, 33x the tolerance (the code before; stray light 4-29x a held-out
    look's own light did the same to 8 frames).  Its faces over the well keep 0.05 of their contrast; the flat
    frame's keep 0.23, as beside the well: too little of the faces' contrast is left to tell flat from gone, so
    both are flagged (not ok).  With the light doubled both read ok, and unchanged too."""
    s = render_look("ho_blind_1206e", [0.0, 0.0, 1.0], shape=(700, 900), lambda_pre=PRE)
    frames = np.asarray(s.frames).astype(float)
    light = np.median(frames[0])
    for added, ok in ((0.0, True), (1.0, True), (3.0, False)):
        relit = frames.copy()
        relit[1:] += added * light
        ds = extract(np.rint(relit).astype(np.uint16), pixel_size=s.truth.attrs["pixel_size"],
                     chamber=_chamber(s.truth), progress=False, frame_interval=600.0)
        sc = score(s.truth, ds)
        assert sc["n_silent"] == 0, (added, list(ds.flag.values), sc["dv_tol"])
        if ok:
            assert list(ds.flag.values) == ["ok"] * 3, (added, list(ds.flag.values))
            assert np.all(sc["dv_tol"] < 0.5), sc["dv_tol"]
        else:
            assert list(ds.flag.values) == ["ok", "poor_fit", "poor_fit"]
            assert list(ds.flag_figure.values[1:]) == ["dome_contrast"] * 2
            assert all("faces over the well keep" in m for m in ds.message.values[1:])


def test_auto_refuses_a_band_off_the_chamber_when_the_walls_are_not_found(monkeypatch):
    """When the silhouette route cannot find the chamber and the band route's rim lies more than ROUTE_RIM_TOL
    off the chamber's radius, auto refuses (the band is not this chamber's well) instead of keeping the band."""
    import importlib

    ex = importlib.import_module("osmobulge.imaging.extract")  # (the module: the package exports its function)

    s = render_look("painted_band", [0.0, 1.0], shape=(700, 900))
    ch = _chamber(s.truth)

    def no_walls(*args, **kwargs):
        raise ChamberNotFound("no walls (test)")

    monkeypatch.setattr(ex, "_silhouette_tracer", no_walls)
    assert _extract(s).attrs["tracer"] == "band"  # (its rim is the chamber's: kept)
    wide = Chamber(1.5 * ch.radius, ch.depth, ch.thickness, 3000.0)
    with pytest.raises(ChamberNotFound, match=r"not this chamber's \(radius 300.0 um.*no walls \(test\)"):
        extract(s.frames, pixel_size=s.truth.attrs["pixel_size"], chamber=wide, progress=False,
                frame_interval=600.0)


def test_a_dome_over_most_of_the_noise_rows_does_not_raise_the_noise():
    """ho_blind_1206e (a dyed liquid: the dome's inside darker as it grows): measured blind, the dome over most
    of the noise's rows raised the noise until the dome's own contrast fell below 10 of it.  A sparse series
    whose first dome frame stands at Vtilde 4 then read flat and ok (33x the tolerance); the noise is now at most
    1.25x that of the rows highest above the top face."""
    s = render_look("ho_blind_1206e", [0.0, 4.0, 4.6], lambda_pre=PRE)
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok"] * 3 and sc["n_silent"] == 0 and np.all(sc["dv_tol"] <= 1.0), sc["dv_tol"]
    assert np.all(ds.dome_contrast.values[1:] > 20.0)  # (measured 26; 9.3 and 6.0 with the dome's inside counted)


def test_a_focus_that_drifts_through_the_series_is_read():
    """A day's focus drift: each frame rendered at its own focal plane (-6, +2, +10 um; the faces' halos and
    fringes swap sides through focus), the flat frame's too.  Measured on 25 frames (-6 -> +10 um and +12 -> -12
    um, 180 um chamber): every frame ok, worst volume error 0.09 of the tolerance, rim within 0.2 px."""
    import xarray as xr

    from osmobulge.imaging.optics import Optics
    from osmobulge.imaging.synthetic import Nuisances, SyntheticSeries, render_series

    parts = [render_series([v], lambda_pre=PRE, shape=SHAPE, chamber=(180e-6, 110e-6, 22e-6), pixel_size=0.85e-6,
                           nuisances=Nuisances(blur_sigma=0.7, noise_sigma=0.012), seed=90 + i, times=[600.0 * i],
                           optics=Optics(n_elastomer=1.418, defocus=d, halo_strength=0.3))
             for i, (v, d) in enumerate(zip([0.0, 0.6, 2.0], [-6e-6, 2e-6, 10e-6], strict=True))]
    s = SyntheticSeries(np.concatenate([q.frames for q in parts]),
                        xr.concat([q.truth for q in parts], dim="time", combine_attrs="override"))
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok"] * 3 and sc["n_silent"] == 0 and np.all(sc["dv_tol"] <= 1.0), sc["dv_tol"]
    assert np.all(np.abs(sc["rim_bias_px"]) < 0.5)


def test_a_well_whose_bottom_is_outside_the_frame_is_refused_saying_so():
    """The silhouette route registers the drift on the base (the walls and the well's bottom): a field that cuts
    the well's bottom off is refused, and the error says where the bottom would lie."""
    from osmobulge.imaging.optics import Optics
    from osmobulge.imaging.synthetic import Nuisances, SceneGeometry, render_series

    s = render_series([0.0, 0.6], shape=(900, 1000), chamber=(200e-6, 110e-6, 20e-6), pixel_size=0.8e-6,
                      optics=Optics(), nuisances=Nuisances(blur_sigma=0.5, noise_sigma=0.01),
                      scene=SceneGeometry(axis_position=(500.0, 840.0)))
    with pytest.raises(ChamberNotFound, match=r"bottom lies at row 9\d\d, outside the frame's 900 rows"):
        _extract(s, tracer="silhouette")


def test_wells_each_side_and_dust_on_the_way_to_them():
    """ho_blind_1206k: a neighbouring well each side and 40 specks of dust (fixed to the camera) with drift.
    Measured blind: refused first (the well's bottom against the median of the field's other columns, mostly the
    neighbours' wells, whose bottoms lie on the same row), then, that mended, every frame flagged touching (specks
    on the column half-way to a neighbour, moved by the drift).  Now the bottom stands out against the base beside
    the walls and the flat frame's specks are not a dome's face."""
    s = render_look("ho_blind_1206k", [0.0, 1.0, 2.0], lambda_pre=PRE)
    t = SilhouetteTracer(s.frames[0], **_known(s))
    assert np.all(np.isfinite(t.bounds))  # (a neighbour each side)
    ds = _extract(s)
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok"] * 3 and sc["n_silent"] == 0 and np.all(sc["dv_tol"] <= 1.0), sc["dv_tol"]
    assert np.all(np.abs(sc["rim_bias_px"]) < 0.5)


def test_annotations_at_the_words_full_scale_are_not_the_light():
    """A 12-bit camera's frames in 16-bit words with a time stamp burned in at 65535 (annotations drawn at the
    words' full scale): the background was 1.8-4.2 % of that white on the held-out 12-bit looks, and the frames
    were refused as dark field.  A level more than twice any other pixel's is no light: left out."""
    from osmobulge.imaging.synthetic import _stamp

    s = render_look("edge_dark", [0.0], shape=SHAPE, nuisances=replace(LOOKS["edge_dark"].nuisances, bit_depth=12))
    f = np.asarray(s.frames[0])
    assert f.dtype == np.uint16 and f.max() <= 4095
    white = _stamp(f, 3600.0, "tr", s.truth.attrs["pixel_size"], 16)
    assert np.mean(white[::2, ::2] == 65535) > 0.002  # (more than the 99.9th percentile's share)
    ratio, why = dark_background(white)
    assert why == "" and ratio == pytest.approx(dark_background(f)[0], rel=0.02)
    # ... but dark field (a dark background, bright zones) stays refused, with the stamp too
    d = render_look("dark_field", [0.5], shape=SHAPE)
    assert d.truth.attrs["bit_depth"] == 16
    assert dark_background(_stamp(np.asarray(d.frames[0]), 0.0, "tl", d.truth.attrs["pixel_size"], 16))[1] != ""


@pytest.mark.parametrize(("loud_rows", "expected"), [(1, None), (10, 2.0), (20, 2.0)])
def test_a_change_on_the_gap_scans_last_row_alone_is_no_neighbour(loud_rows, expected):
    """The gap to a neighbour's dome is a running median over _GAP_ROWS rows of each row's gap; its ends were
    padded with the end rows' own values, so a change 2 px past the face on the last row only (the one nearest the
    top face) read as a gap of 2 px: measured on drawn_20261207_25 (frame 5, the true gap 72 px, read 1.0: touching,
    falsely).  Now mirrored at the ends: one row alone reads nothing (the gap: the length scanned), a face over 10
    rows at the end or 20 in the middle is read."""
    from types import SimpleNamespace

    from osmobulge.imaging._facetrace import _GAP_REACH

    top, axis, radius = 300.0, 250.0, 100.0
    phi = np.linspace(0.0, np.pi, 200)
    u, z = radius * np.cos(phi)[::-1], radius * np.sin(phi)[::-1]  # (left rim -> right rim)
    w = SimpleNamespace(top_row=top, axis_col=axis)
    fake = SimpleNamespace(view_shape=(600, 800), _nb=(np.nan, axis + 300.0), bounds=(-np.inf, axis + 200.0),
                           _clear_of_specks=lambda rows, cols, dx, dy: np.ones(np.broadcast(rows, cols).shape, bool))
    noise = 0.01

    def sample(points, directions, offsets, own=True):
        v = np.zeros((len(points), len(offsets)))
        v[:, 0] = 1.0  # (the face's own change)
        at_end = loud_rows < 20
        rows = slice(len(points) - loud_rows, None) if at_end else slice(100, 100 + loud_rows)
        v[rows, 2] = 1.0  # (a change 2 px past it)
        return v

    least, _ = SilhouetteTracer._gap_rows(fake, sample, w, u, z, 1.0, 0.0, 0.0, noise)
    if expected is None:
        assert least == pytest.approx(_GAP_REACH)  # (nothing seen within the reach)
    else:
        assert least == expected


@pytest.mark.parametrize(("bound", "touching"), [(100.5, True), (200.0, False)])
def test_a_gap_closing_where_the_face_meets_the_half_way_column_is_closed(bound, touching):
    """drawn_20261207_44 (turned a quarter since the renderer's blend fix), its domes overlapping in the last
    frame: the neighbour's face came 12, 11, ... 1 px near the outer face over 12 rows, then met it, and on the
    rows where they met its change was taken for the face's own, no gap seen (inf); the running median took 7 px
    from the rows beside, ok.  With the face at the half-way column (within 1 px), rows with no gap next to a
    gap of 2 px or less are rows where the faces met: 0, touching.  With the face far from it, as before."""
    from types import SimpleNamespace

    top, axis, radius = 300.0, 250.0, 100.0
    phi = np.linspace(0.0, np.pi, 200)
    u, z = radius * np.cos(phi)[::-1], radius * np.sin(phi)[::-1]  # (left rim -> right rim)
    w = SimpleNamespace(top_row=top, axis_col=axis)
    fake = SimpleNamespace(view_shape=(600, 800), _nb=(np.nan, axis + 300.0), bounds=(-np.inf, axis + bound),
                           _clear_of_specks=lambda rows, cols, dx, dy: np.ones(np.broadcast(rows, cols).shape, bool))

    def sample(points, directions, offsets, own=True):
        v = np.zeros((len(points), len(offsets)))
        i0 = len(points) // 2 - 10
        for k in range(12):  # (the neighbour's face nearing)
            v[i0 + k, 12 - k] = 1.0
        v[i0 + 12 : i0 + 20, :3] = 1.0  # (met: its change from the face on)
        return v

    least, _ = SilhouetteTracer._gap_rows(fake, sample, w, u, z, 1.0, 0.0, 0.0, 0.01)
    assert (least < TraceSettings().touching_flag) == touching, least


@pytest.mark.parametrize("speck", [False, True])
def test_a_speck_on_the_face_does_not_end_the_faces_own_change(speck):
    """ho_blind_1206k frame 7 (the neighbour 10.5 px away, read 9 px): on one row the scan's first sample lay on a
    speck of the flat frame and counted as quiet water, so the face's own change just past it was taken for the
    neighbour's, a gap of 1 px; with the face at the half-way column the rows with no gap seen beside it were
    closed (0) and the frame flagged touching.  A sample on a speck is neither loud nor quiet: the face's own
    change goes on through it."""
    from types import SimpleNamespace

    top, axis, radius = 300.0, 250.0, 100.0
    phi = np.linspace(0.0, np.pi, 200)
    u, z = radius * np.cos(phi)[::-1], radius * np.sin(phi)[::-1]  # (left rim -> right rim)
    w = SimpleNamespace(top_row=top, axis_col=axis)
    row_speck = {}

    def clear(rows, cols, dx, dy):
        out = np.ones(np.broadcast(rows, cols).shape, bool)
        if speck:
            i = out.shape[0] // 2
            out[i, 0] = False  # (the first sample of one row on a speck)
            row_speck["row"] = i
        return out

    fake = SimpleNamespace(view_shape=(600, 800), _nb=(np.nan, axis + 300.0), bounds=(-np.inf, axis + 100.5),
                           _clear_of_specks=clear)

    def sample(points, directions, offsets, own=True):
        v = np.zeros((len(points), len(offsets)))
        v[:, :3] = 1.0  # (the face's own change, 3 px past its outermost column on every row; no neighbour)
        return v

    least, _ = SilhouetteTracer._gap_rows(fake, sample, w, u, z, 1.0, 0.0, 0.0, 0.01)
    assert least > 40.0, least  # (nothing seen up to the reach or the neighbour's wall)
    assert not speck or row_speck


@pytest.mark.parametrize(("beyond", "cut"),
                         [("quiet", False), ("outer_face_of_edge_look", True), ("band_goes_on", True)])
def test_a_dome_at_its_search_limit_is_cut_only_if_its_face_goes_on(beyond, cut):
    """A dome that reaches the columns it was searched for between (half-way to what the last frame took for the
    neighbour's dome) was flagged touching, its face maybe cut off there.  Measured on drawn_20261207_27 frame 6:
    a drifting particle 52 px out had set that limit, the dome grew 26 px sideways and reached it, the water
    beyond quiet (touching, falsely).  The face is taken as cut (touching) only when the change goes on beyond it
    along its outward normal: its band continuing, or, in an edge-only look whose inner face was taken for the
    outer one, the outer face a film's thickness further out."""
    from types import SimpleNamespace

    top, axis, radius, noise = 300.0, 250.0, 100.0, 0.01
    phi = np.linspace(np.pi, 0.0, 121)  # (left rim -> over the top -> right rim)
    u, z = radius * np.cos(phi), radius * np.sin(phi)
    close = (phi > 0.2) & (phi < 0.6)  # (some points on the right flank)
    w = SimpleNamespace(top_row=top, axis_col=axis)

    def sample(points, directions, offsets, own=True):
        radial = np.column_stack((points[:, 0] - axis, points[:, 1] - top))  # (view: rows down)
        radial /= np.hypot(radial[:, 0], radial[:, 1])[:, None]
        assert np.all(np.sum(radial * directions, axis=1) > 0.99) and not own  # (outward, unmasked)
        d = np.broadcast_to(offsets, (len(points), len(offsets)))
        v = 70.0 * noise * np.exp(-0.5 * ((d + 1.0) / 1.5) ** 2)  # (the face's own edge fading)
        if beyond == "outer_face_of_edge_look":
            v = v + 50.0 * noise * (np.abs(d - 22.0) < 1.5)
        elif beyond == "band_goes_on":
            v = v + 60.0 * noise * (d < 25.0)
        return v

    fake = SimpleNamespace(l0=22.0)
    assert SilhouetteTracer._cut_at_limit(fake, sample, w, u, z, close, noise) is cut


def test_growing_domes_that_touched_do_not_part(monkeypatch):
    """A frame after one whose dome came within the touching flag of a neighbour's keeps that gap while its dome
    does not shrink by a tenth (:meth:`SilhouetteTracer._still_touching`).  Found on drawn_20261207_111 rendered
    without its focus and light drift: the domes overlapping, frame 7's gap read 16 px (to the neighbour's far
    face) between frames flagged touching, its rim 0.5 % off, ok.  Here the gap measured in the last frame is made
    16 px: touching, saying why; with the rule off, not touching (the test can fail); a dome that lost over a tenth
    of its volume has parted (collapsed, torn)."""
    from osmobulge.imaging.optics import Optics
    from osmobulge.imaging.synthetic import Nuisances, SceneGeometry, render_series

    p = 1.6e-6
    s = render_series([0.0, 0.5, 1.5, 2.0], lambda_pre=PRE, shape=(720, 420), chamber=(150e-6, 110e-6, 22e-6),
                      pixel_size=p, scene=SceneGeometry(bulge_direction="right"), seed=97,
                      optics=Optics(n_elastomer=1.42, objective_na=0.2, condenser_na=0.1, defocus=4e-6,
                                    halo_strength=0.25),
                      nuisances=Nuisances(noise_sigma=0.012, blur_sigma=0.6, bit_depth=12,
                                          neighbours=((-340e-6, 0.8), (340e-6, 1.0))))
    assert list(s.truth.flag.values) == ["ok", "ok", "touching", "touching"]
    ds = _extract(s)
    assert list(ds.flag.values) == ["ok", "ok", "touching", "touching"], ds.neighbour_gap.values

    at, gap = {}, SilhouetteTracer._neighbour_gap
    process = SilhouetteTracer.process

    def indexed(self, frame, index=0, **kw):
        at["frame"] = index
        return process(self, frame, index, **kw)

    monkeypatch.setattr(SilhouetteTracer, "process", indexed)
    monkeypatch.setattr(SilhouetteTracer, "_neighbour_gap",
                        lambda self, *a: 16.0 if at["frame"] == 3 else gap(self, *a))
    ds = _extract(s)
    assert list(ds.flag.values) == ["ok", "ok", "touching", "touching"]
    assert ds.neighbour_gap.values[3] == pytest.approx(ds.neighbour_gap.values[2])
    assert ds.neighbour_gap.values[3] < 2.5 * p
    assert "frame 2" in str(ds.message.values[3]) and "16.0 px" in str(ds.message.values[3])
    monkeypatch.setattr("osmobulge.imaging._facetrace._PARTED_VOLUME", np.inf)  # (the rule off)
    ds = _extract(s)
    assert ds.flag.values[3] != "touching"
    tr = SilhouetteTracer.__new__(SilhouetteTracer)  # (the rule itself: a dome that shrank, a gap that closed)
    tr._touched = (2, 0.5, 100.0)
    for volume, measured, carried in ((95.0, 16.0, (2, 0.5, 16.0)), (85.0, 16.0, None), (120.0, 0.2, None)):
        fig = {"neighbour_gap": measured}
        monkeypatch.setattr("osmobulge.imaging._facetrace._PARTED_VOLUME", 0.9)
        assert tr._still_touching(fig, volume) == carried
        assert fig["neighbour_gap"] == (0.5 if carried else measured)


def test_a_scale_bar_burned_into_the_base_does_not_hold_the_drift():
    """A scale bar and its label burned in at the full scale do not move with the stage: in the base's registration
    window they pulled the drift read towards none.  Found blind on drawn_20261207_128 (2 um/px, the chamber low in
    the field, the bar in the bottom corner): the vertical drift read -0.2 px for -1.2 (the top face 0.9 px off in
    every frame: 1.7x the volume tolerance at Vtilde 0.18, ok; the full search's lowest rays then took the film's
    fringes beyond the dome, 16 % over at Vtilde 4, ok).  The window's rows and columns that hold the first
    frame's clipped pixels, when they are an annotation's (:func:`_facetrace._unannotated`), are now left out: the
    vertical drift reads within 0.15 px of the truth, as without the bar."""
    from osmobulge.imaging import _facetrace as ft

    name = "drawn_20261207_128"
    drift = [(0.0, 0.0), (0.8, -1.2), (0.3, -2.5)]
    nu = replace(get_look(name).nuisances, drift=drift, time_stamp="tr", focus_drift=0.0)
    s = render_look(name, [0.0, 0.18, 0.5], lambda_pre=PRE, nuisances=nu)
    clip = ft.clip_mask(s.frames[0])
    assert clip is not None and clip[950:].any()  # (the bar in the base's rows, at the full scale)
    ds = _extract(s)
    sc = score(s.truth, ds)
    np.testing.assert_allclose(ds.drift_y.values, [d[1] for d in drift], atol=0.15)
    np.testing.assert_allclose(ds.drift_x.values, [d[0] for d in drift], atol=0.3)  # (without the bar: 0.15-0.26 short)
    assert list(ds.flag.values) == ["ok"] * 3 and sc["n_silent"] == 0 and np.all(sc["dv_tol"] <= 0.6), sc["dv_tol"]
    assert ft._unannotated(None) is None and ft._unannotated(np.ones((10, 40), bool)) is None
