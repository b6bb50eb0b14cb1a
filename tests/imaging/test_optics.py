"""The optics renderer against independent truth: Monte Carlo apertures, sphere chords, silhouettes."""

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree

from osmobulge.imaging.extract import extract
from osmobulge.imaging.looks import HELD_OUT_LOOKS, LOOKS, OUTSIDE_LOOKS, render_look, score
from osmobulge.imaging.optics import Collapse, Hole, Optics, _splat, optical_path, transmission
from osmobulge.imaging.synthetic import Nuisances, SceneGeometry, _Frame, _Scene, render_series
from osmobulge.modeling import PreStretch
from osmobulge.modeling.transport import Chamber


def _mc_transmission(theta, o):
    """Monte Carlo: uniform directions in the condenser annulus, bent by theta, inside the objective."""
    rng = np.random.default_rng(0)
    n = 400_000
    r = np.sqrt(rng.uniform(o.condenser_inner_na**2, o.condenser_na**2, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    x, y = r * np.cos(phi) + theta, r * np.sin(phi)
    return np.mean(np.hypot(x, y) <= o.objective_na)


@pytest.mark.parametrize(
    "optics",
    [Optics(), Optics(condenser_na=0.2), Optics(condenser_na=0.4, condenser_inner_na=0.3), Optics(objective_na=0.1)],
)
@pytest.mark.parametrize("theta", [0.0, 0.1, 0.2, 0.3, 0.45])
def test_transmission_matches_monte_carlo(optics, theta):
    assert float(transmission(theta, optics)) == pytest.approx(_mc_transmission(theta, optics), abs=4e-3)


def test_transmission_limits():
    o = Optics(objective_na=0.25, condenser_na=0.1)
    assert transmission(0.0, o) == pytest.approx(1.0)
    assert transmission(0.149, o) == pytest.approx(1.0)  # inside NA_o - NA_c
    assert transmission(0.351, o) == 0.0  # beyond NA_o + NA_c
    point = Optics(condenser_na=0.0)
    np.testing.assert_array_equal(transmission([0.2, 0.3], point), [1.0, 0.0])


def _spherical_cap(rho, zc, n=2001):
    """Half profile (pole -> rim) of a sphere of radius rho centred at height zc (units of a)."""
    top = zc + rho
    rim_angle = math.acos(-zc / rho)  # where the sphere meets z = 0 at r = 1 (rho^2 = 1 + zc^2)
    ang = np.linspace(0.0, rim_angle, n)
    return rho * np.sin(ang), zc + rho * np.cos(ang), top


@pytest.mark.parametrize("zc", [-0.5, 0.0, 0.4])  # below, at and above the hemisphere
def test_optical_path_of_a_spherical_shell_is_sphere_chords(zc):
    a, h, l0 = 200e-6, 110e-6, 20e-6
    o = Optics()
    rho = math.sqrt(1 + zc * zc)
    r, z, _ = _spherical_cap(rho, zc)
    t = np.ones_like(r)  # uniform thickness: faces are concentric spheres of radius rho a +- l0/2
    ro, ri = rho * a + 0.5 * l0, rho * a - 0.5 * l0
    rng = np.random.default_rng(1)
    # points above the top face, well inside the cap's height range
    u = rng.uniform(-1.3 * rho * a, 1.3 * rho * a, 400)
    w = rng.uniform(l0, (zc + rho) * a - l0, 400)
    opd, film, _, liq = optical_path(u, w, [(0.0, r, z, t, 1.0)], a, h, l0, o)

    def sphere_chord(rad):
        return 2 * np.sqrt(np.clip(rad**2 - u**2 - (w - zc * a) ** 2, 0, None))

    np.testing.assert_allclose(liq, sphere_chord(ri), atol=0.5e-6)
    np.testing.assert_allclose(film, sphere_chord(ro) - sphere_chord(ri), atol=0.5e-6)
    want = (o.n_elastomer - o.n_water) * film + (o.n_liquid - o.n_water) * liq
    np.testing.assert_allclose(opd, want, rtol=1e-12)


def _ray_paths(u, w, liquid_at, film_at, half_depth, n=40001):
    """Brute force: path lengths (m) of rays along y through the points (u, w), each sampled at n points over
    the slab's depth; ``liquid_at(rho, y, u, w)`` and ``film_at(...)`` classify 3-D points (rho: from the axis)."""
    y = np.linspace(-half_depth, half_depth, n)
    dy = y[1] - y[0]
    liq, film = np.empty(len(u)), np.empty(len(u))
    for k, (uk, wk) in enumerate(zip(u, w, strict=True)):
        rho = np.hypot(uk, y)
        lq = liquid_at(rho, y, uk, wk)
        liq[k] = dy * np.count_nonzero(lq)
        film[k] = dy * np.count_nonzero(film_at(rho, y, uk, wk) & ~lq)
    return liq, film


@pytest.mark.parametrize("side", [1, -1, 0])
def test_a_hole_torn_in_a_dome_is_water_over_its_wedge(side):
    """A fractured frame's hole (optics.Hole) against rays sampled through the 3-D shell: a spherical shell whose
    faces and liquid within 60 degrees of the image plane on one side (or, side 0, above a height: the cap) are
    water over the hole's heights."""
    a, h, l0, zc = 200e-6, 110e-6, 20e-6, 0.0
    rho = math.sqrt(1 + zc * zc)
    r, z, _ = _spherical_cap(rho, zc)
    ro, ri = rho * a + 0.5 * l0, rho * a - 0.5 * l0
    hole = Hole(60e-6, 120e-6 if side else np.inf, side, math.pi / 3)
    rng = np.random.default_rng(3)
    u = rng.uniform(-1.1 * ro, 1.1 * ro, 60)
    w = rng.uniform(30e-6, 150e-6, 60)
    liq, film = optical_path(u, w, [(0.0, r, z, np.ones_like(r), 1.0, hole)], a, h, l0, Optics())[3:0:-2]

    def torn(y, uk, wk):
        if not hole.w_lo <= wk <= hole.w_hi:
            return np.zeros(y.shape, bool)
        if side == 0:
            return np.ones(y.shape, bool)
        return (side * uk > 0) & (np.abs(y) < abs(uk) * math.tan(hole.half_angle))

    def d(rho_, wk):
        return np.hypot(rho_, wk - zc * a)

    want_liq, want_film = _ray_paths(
        u, w, lambda rr, y, uk, wk: (d(rr, wk) < ri) & ~torn(y, uk, wk),
        lambda rr, y, uk, wk: (d(rr, wk) < ro) & ~torn(y, uk, wk), 1.2 * ro)
    np.testing.assert_allclose(liq, want_liq, atol=0.1e-6)
    np.testing.assert_allclose(film, want_film, atol=0.1e-6)
    assert np.any(want_film[(w > 60e-6) & (w < 120e-6)] == 0.0) and np.any(want_film > 0.0)  # (the hole is met)


def test_a_collapsed_dome_opens_the_well_and_hangs_its_flaps_in_it():
    """A collapsed frame (optics.Collapse) against rays sampled through the 3-D well: the film over the well gone
    (liquid through its layer), a conical shell of flaps from the rim's mid-surface down at 60 degrees."""
    a, h, l0, depth = 200e-6, 110e-6, 20e-6, 1e-3
    o = Optics(depth=depth)
    r = np.linspace(0, 1, 50)
    col = Collapse(length=120e-6, angle=math.radians(60), thickness=20e-6)
    top = 0.5 * l0
    rng = np.random.default_rng(4)
    u = rng.uniform(-1.1 * a, 1.1 * a, 60)
    w = rng.uniform(-top - 0.9 * h, 0.9 * top, 60)
    _, film, base, liq = optical_path(u, w, [(0.0, r, np.zeros_like(r), np.ones_like(r), 1.0, col)], a, h, l0, o)

    def flap(rr, wk):
        mid = a + wk / math.tan(col.angle)
        return (wk <= 0) & (wk >= -col.length * math.sin(col.angle)) & (
            np.abs(rr - mid) < 0.5 * col.thickness / math.sin(col.angle))

    def liquid(rr, y, uk, wk):  # the well (a cylinder: no pre-stretch) and the opened layer over it, less the flaps
        return (rr < a) & (wk < top) & ~flap(rr, wk)

    want_liq, want_el = _ray_paths(u, w, liquid, lambda rr, y, uk, wk: np.ones(y.shape, bool), 0.5 * depth)
    np.testing.assert_allclose(liq, want_liq, atol=0.1e-6)
    np.testing.assert_allclose(film + base, want_el, atol=0.1e-6)
    plain = depth - 2.0 * np.sqrt(np.clip(a * a - u * u, 0.0, None))  # (the elastomer beside a plain well)
    assert np.any((w < -top) & (want_el > plain + 1e-6))  # (rays through the flaps are met)


def test_a_delaminated_film_is_a_lifted_skirt_in_the_optics():
    """A delaminated frame's film beyond the rim (peeled off over 0.3 a, 1.5 l0 high at the rim: the painted
    model's ``lift (1 - s / dl)**2``) against rays sampled through the 3-D skirt: liquid under it, film within l0/2
    of its mid-surface, the device's slab below the top face."""
    a, h, l0, depth = 200e-6, 110e-6, 20e-6, 1e-3
    nuis = Nuisances(delaminated_frames=(0,))
    sc = _Scene(a, h, l0, 1e-6, (400, 600), SceneGeometry(), nuis)
    r = np.linspace(0, 1, 200)
    fr = _Frame(r=r, z=0.1 * (1 - r**2), t=np.ones_like(r), lam=1.0, flag="delaminated")
    chamber = sc._optical_chamber(fr)
    lift, dl, top = 1.5 * l0, 0.3 * a, 0.5 * l0
    rng = np.random.default_rng(5)
    u = rng.uniform(a + 15e-6, a + dl + 20e-6, 60) * rng.choice([-1, 1], 60)
    w = rng.uniform(-0.9 * top, lift + top, 60)
    o = Optics(depth=depth)
    _, film, base, liq = optical_path(u, w, [chamber], a, h, l0, o)
    ss = np.linspace(0.0, dl, 6001)
    mid = np.column_stack((a + ss, lift * (1 - ss / dl) ** 2))
    tree = cKDTree(mid)

    def dist(rr, wk):  # distance in (rho, w) to the skirt's mid-surface and the flat film's beyond it
        d = tree.query(np.column_stack((rr, np.full(rr.shape, wk))))[0]
        return np.where(rr > a + dl, np.minimum(d, abs(wk)), d)

    def under(rr, wk):
        return (wk > -top) & (wk < np.interp(rr, mid[:, 0], mid[:, 1])) & (dist(rr, wk) > 0.5 * l0)

    def elastomer(rr, y, uk, wk):
        return (dist(rr, wk) < 0.5 * l0) | (wk < top)

    want_liq, want_el = _ray_paths(u, w, lambda rr, y, uk, wk: under(rr, wk), elastomer, 0.5 * depth)
    np.testing.assert_allclose(liq, want_liq, atol=0.3e-6)
    np.testing.assert_allclose(film + base, want_el, atol=0.3e-6)
    assert np.any(want_liq > 50e-6)  # (rays under the skirt are met)


def test_optical_path_of_the_flat_device():
    a, h, l0 = 200e-6, 110e-6, 20e-6
    o = Optics(depth=1e-3)
    r = np.linspace(0, 1, 50)
    flat = [(0.0, r, np.zeros_like(r), np.ones_like(r), 1.0)]
    u = np.array([0.0, 150e-6, 250e-6, 0.0, 0.0])
    w = np.array([-l0 / 2 - h / 2, -l0 / 2 - h / 2, -l0 / 2 - h / 2, 0.0, l0])
    opd, *_ = optical_path(u, w, flat, a, h, l0, o)
    dp, ds = o.n_elastomer - o.n_water, o.n_elastomer - o.n_liquid
    want = [dp * o.depth - ds * 2 * a, dp * o.depth - ds * 2 * math.sqrt(a * a - u[1] ** 2), dp * o.depth,
            dp * o.depth, 0.0]
    np.testing.assert_allclose(opd, want, rtol=1e-12, atol=1e-15)


def test_splat_conserves_light():
    rng = np.random.default_rng(2)
    rows, cols = rng.uniform(0, 19, 1000), rng.uniform(0, 29, 1000)
    wgt = rng.uniform(0, 1, 1000)
    assert _splat((20, 30), rows, cols, wgt).sum() == pytest.approx(wgt.sum(), rel=1e-12)


def _column_profile(series, i, col):
    return series.frames[i][:, col].astype(float)


@pytest.mark.parametrize("vt", [1.0, 3.0])
def test_in_focus_dome_edge_is_the_outer_face(vt):
    """The silhouette's outer edge (half level between water and the dark face) is the outer face at the pole."""
    p = 1e-6
    s = render_series([vt], pixel_size=p, shape=(700, 600), optics=Optics(),
                      nuisances=Nuisances(blur_sigma=0.0, polarity=1))
    tr = s.truth.isel(time=0)
    col = int(round(float(tr.axis_x)))
    prof = _column_profile(s, 0, col)
    pole_row = float(tr.midline_row.values[0, 0])
    outer_row = pole_row - 0.5 * float(tr.profile_thickness.values[0]) / p
    bg = np.median(prof[: int(outer_row) - 20])
    lo = prof[int(outer_row) - 2 : int(outer_row) + 6].min()
    half = 0.5 * (bg + lo)
    k = int(outer_row) - 8
    while prof[k] > half:
        k += 1
    crossing = k - 1 + (prof[k - 1] - half) / (prof[k - 1] - prof[k])
    assert abs(crossing - outer_row) < 0.6
    assert lo < 0.3 * bg  # the silhouette is dark: its light is bent out of the objective


def test_defocus_puts_bent_light_on_opposite_sides():
    """Through focus the bright fringe beside the pole's face moves from one side to the other."""
    p = 1e-6
    res = {}
    for d in (-12e-6, 12e-6):
        s = render_series([2.0], pixel_size=p, shape=(700, 600), optics=Optics(defocus=d, condenser_na=0.05),
                          nuisances=Nuisances(blur_sigma=0.0))
        tr = s.truth.isel(time=0)
        prof = _column_profile(s, 0, int(round(float(tr.axis_x))))
        pole = float(tr.midline_row.values[0, 0])
        bg = np.median(prof[: int(pole) - 40])
        above = prof[int(pole) - 25 : int(pole) - 8].max() / bg  # outside the dome
        below = prof[int(pole) + 8 : int(pole) + 25].max() / bg  # inside the dome
        res[d] = (above, below)
    (a_neg, b_neg), (a_pos, b_pos) = res[-12e-6], res[12e-6]
    # (measured: 1.05 inside the dome at +12 um, 0.98 at -12 um; nothing outside)
    assert (b_neg > 1.03) != (b_pos > 1.03) or (a_neg > 1.03) != (a_pos > 1.03)


def test_the_optics_image_does_not_depend_on_the_devices_orientation():
    """The same flat frame and dome rendered growing up, right, down and left, each turned back to up: the top
    face's and the film's lower face's lines (the steps of their area-weighted paths) are the same.  Measured
    before the fix: growing right or left, the top face's line was gone (its step along the columns met the
    one-sided, smaller slope, which is 0 across a step) and the lower face's was 0.16 dark, not 0.45."""
    from osmobulge.imaging.synthetic import SceneGeometry

    kw = {"optics": Optics(n_elastomer=1.42, objective_na=0.2, condenser_na=0.1, defocus=4e-6),
          "nuisances": Nuisances(noise_sigma=0.0, blur_sigma=0.6), "chamber": (150e-6, 110e-6, 22e-6),
          "pixel_size": 1.6e-6, "shape": (512, 512)}
    lines = {}
    for k, d in enumerate(("up", "right", "down", "left")):
        s = render_series([0.0, 2.5], scene=SceneGeometry(bulge_direction=d), **kw)
        up = np.rot90(s.frames.astype(float), k, axes=(1, 2))
        # (the rim line's row once turned up: np.rot90 takes row r of "down" to 511 - r, column c of "right"
        # to row 511 - c and of "left" to row c)
        rim = {"up": float(s.truth.rim_y[0]), "down": 511 - float(s.truth.rim_y[0]),
               "right": 511 - float(s.truth.axis_x[0]), "left": float(s.truth.axis_x[0])}[d]
        bg = np.median(up[0, :60])
        r = int(round(rim))
        for name, c in (("outside", 60), ("centre", 256)):
            prof = up[0, r - 15 : r + 16, c] / bg - 1.0
            lines[d, name] = (prof.min(), r - 15 + int(np.argmin(prof)) - rim)
        lines[d, "dome"] = (up[1] / bg).mean()  # (the light the dome frame's faces and walls take)
    for d in ("right", "down", "left"):
        for name in ("outside", "centre"):
            depth, at = lines[d, name]
            assert depth == pytest.approx(lines["up", name][0], abs=0.01), (d, name, lines)
            assert at == pytest.approx(lines["up", name][1], abs=1.0), (d, name, lines)
        assert lines[d, "dome"] == pytest.approx(lines["up", "dome"], abs=0.002)
    assert lines["up", "outside"][0] < -0.2 and lines["up", "centre"][0] < -0.4  # (the top face; the lower face)


def test_focus_drift_and_dilution_render_each_frame_in_its_own_optics():
    """Nuisances(focus_drift) moves the focal plane linearly in time from the first frame to the last, and
    Optics(dilution=True) dilutes the salt solution by the water that came in (index above the water's and the
    dye's absorption as V0/V, V/V0 the truth's volume_ratio): each frame is the one rendered alone with those
    optics."""
    ch, p = (150e-6, 110e-6, 20e-6), 1.6e-6
    vt, times = [0.0, 1.0, 3.0], [0.0, 1000.0, 3000.0]
    base = Optics(defocus=2e-6, absorption_liquid=800.0)
    nu = Nuisances(blur_sigma=0.5)
    s = render_series(vt, times=times, chamber=ch, pixel_size=p, shape=(420, 400),
                      optics=replace(base, dilution=True), nuisances=replace(nu, focus_drift=-12e-6))
    share = 1.0 / s.truth["volume_ratio"].values  # (the concentration over the first frame's)
    assert share[0] == 1.0 and 0.1 < share[2] < 0.3
    for i, (v, t) in enumerate(zip(vt, times, strict=True)):
        alone = replace(base, defocus=2e-6 - 12e-6 * t / 3000.0, n_liquid=1.333 + 0.029 * share[i],
                        absorption_liquid=800.0 * share[i])
        one = render_series([v], chamber=ch, pixel_size=p, shape=(420, 400), optics=alone, nuisances=nu)
        np.testing.assert_array_equal(s.frames[i], one.frames[0])
    # the dilution alone is seen in the liquid (well and dome: nearer the water's index, its dye paler), not in
    # the water above the dome
    kw = {"chamber": ch, "pixel_size": p, "shape": (420, 400), "nuisances": nu}
    plain = render_series([3.0], optics=base, **kw).frames[0].astype(float)
    diluted = render_series([3.0], optics=replace(base, dilution=True), **kw)
    well = int(diluted.truth.rim_y[0]) + 20  # (rows inside the well, below the film)
    pole = int(diluted.truth.midline_row[0, 0, 0]) - 10  # (the water above the dome's outer face and halo)
    change = np.abs(diluted.frames[0] - plain) / plain.max()
    assert change[well : well + 40].mean() > 0.02 and change[:pole].max() == 0.0
    assert s.truth.attrs["optics_dilution"] == 1 and s.truth.attrs["nuisance_focus_drift"] == -12e-6
    with pytest.raises(ValueError, match="focus_drift needs optics"):
        render_series([0.0, 1.0], nuisances=Nuisances(focus_drift=5e-6))
    with pytest.raises(ValueError, match="focus_drift"):
        Nuisances(focus_drift=0.01)  # (1 cm: um given as m * 1e4)
    with pytest.raises(ValueError, match="dilution"):
        Optics(dilution=1)


def test_debris_drifts_through_every_frame_after_the_first():
    """Nuisances(debris=N): N particles in each frame after the first, each a blurred dark disc at a new place (the
    truth's ``debris`` attr, frame by frame); the first frame, and every pixel outside the squares of 4 radii about
    them, as without debris (their own random stream); the darkening at each centre is its opacity."""
    ch, p = (150e-6, 110e-6, 20e-6), 1.6e-6
    kw = {"chamber": ch, "pixel_size": p, "shape": (420, 400), "optics": Optics(), "seed": 5}
    nu = Nuisances(blur_sigma=0.5)
    plain = render_series([0.0, 1.0, 2.0], nuisances=nu, **kw)
    s = render_series([0.0, 1.0, 2.0], nuisances=replace(nu, debris=4, debris_radius=(3.0, 6.0)), **kw)
    d = s.truth.attrs["debris"].reshape(-1, 5)  # (frame, x, y, radius, opacity)
    assert d.shape == (8, 5) and list(np.unique(d[:, 0])) == [1, 2]
    assert np.all((d[:, 3] >= 3.0) & (d[:, 3] <= 6.0))
    assert not np.allclose(d[d[:, 0] == 1, 1:3], d[d[:, 0] == 2, 1:3])  # (new places)
    np.testing.assert_array_equal(s.frames[0], plain.frames[0])
    rows, cols = np.mgrid[:420, :400]
    for i in (1, 2):
        near = np.zeros((420, 400), bool)
        for _, x, y, r, op in d[d[:, 0] == i]:
            near |= (np.abs(cols - x) <= np.ceil(4.0 * r) + 1) & (np.abs(rows - y) <= np.ceil(4.0 * r) + 1)
            if 2 <= x < 398 and 2 <= y < 418:  # (the centre's darkening, within the 16-bit rounding)
                ratio = s.frames[i][int(round(y)), int(round(x))] / plain.frames[i][int(round(y)), int(round(x))]
                assert ratio == pytest.approx(1.0 - op, abs=0.02)
        np.testing.assert_array_equal(s.frames[i][~near], plain.frames[i][~near])
        assert np.any(s.frames[i][near] != plain.frames[i][near])
    with pytest.raises(ValueError, match="debris"):
        Nuisances(debris=-1)
    with pytest.raises(ValueError, match="debris_radius"):
        Nuisances(debris_radius=(5.0, 2.0))


def test_the_lights_gradient_drifts_over_the_series():
    """Nuisances(light_drift=d): frame i's light is the field of gradient g + d (t_i - t_0)/(t_last - t_0) along the
    illumination angle: its ratio to the same series without the drift is (1 + g_i s) / (1 + g s), s the
    position along the angle (-1 .. 1 from the field's centre to its side), within the rounding (no noise); the
    first frame as without it."""
    ch, p = (150e-6, 110e-6, 20e-6), 1.6e-6
    kw = {"chamber": ch, "pixel_size": p, "shape": (420, 400), "optics": Optics(), "seed": 5,
          "times": [0.0, 600.0, 2400.0]}
    nu = Nuisances(blur_sigma=0.5, illumination_gradient=0.1, illumination_angle=30.0)
    plain = render_series([0.0, 1.0, 2.0], nuisances=nu, **kw)
    s = render_series([0.0, 1.0, 2.0], nuisances=replace(nu, light_drift=-0.2), **kw)
    np.testing.assert_array_equal(s.frames[0], plain.frames[0])
    rows, cols = np.mgrid[:420, :400]
    xc, yc = (cols - 199.5) / 200.0, (209.5 - rows) / 210.0
    along = xc * np.cos(np.radians(30.0)) + yc * np.sin(np.radians(30.0))
    for i, frac in ((1, 0.25), (2, 1.0)):
        want = (1.0 + (0.1 - 0.2 * frac) * along) / (1.0 + 0.1 * along)
        lit = plain.frames[i] > 1000
        got = s.frames[i][lit].astype(float) / plain.frames[i][lit]
        # (each frame rounded to whole counts: half a count of each over the plain frame's counts, and float32's)
        assert np.all(np.abs(got - want[lit]) <= 1.0 / plain.frames[i][lit] + 1e-5)
        assert lit.mean() > 0.9
    with pytest.raises(ValueError, match="light_drift"):
        Nuisances(illumination_gradient=0.5, light_drift=0.5)  # (a gradient of 1: black at one side)


def test_stray_light_grows_over_the_series_on_one_side():
    """Nuisances(stray_light=s): frame i gains s (t_i - t_0)/(t_last - t_0) (1 + p)/2 of full scale, p the position
    along the illumination angle (-1 .. 1), added to the frame without it (no noise: within the rounding); the first
    frame as without it."""
    ch, p = (150e-6, 110e-6, 20e-6), 1.6e-6
    kw = {"chamber": ch, "pixel_size": p, "shape": (420, 400), "optics": Optics(), "seed": 5,
          "times": [0.0, 600.0, 2400.0]}
    nu = Nuisances(blur_sigma=0.5, illumination_angle=-60.0)
    plain = render_series([0.0, 1.0, 2.0], nuisances=nu, **kw)
    s = render_series([0.0, 1.0, 2.0], nuisances=replace(nu, stray_light=0.1), **kw)
    np.testing.assert_array_equal(s.frames[0], plain.frames[0])
    rows, cols = np.mgrid[:420, :400]
    xc, yc = (cols - 199.5) / 200.0, (209.5 - rows) / 210.0
    along = xc * np.cos(np.radians(-60.0)) + yc * np.sin(np.radians(-60.0))
    unclipped = s.frames[2] < 65535
    for i, frac in ((1, 0.25), (2, 1.0)):
        got = (s.frames[i].astype(float) - plain.frames[i]) / 65535.0
        want = 0.1 * frac * 0.5 * (1.0 + along)
        assert np.all(np.abs(got - want)[unclipped] <= 1.0 / 65535.0 + 1e-6)
    assert unclipped.mean() > 0.9
    with pytest.raises(ValueError, match="stray_light"):
        Nuisances(stray_light=-0.1)


def test_optics_rejects_bad_input():
    with pytest.raises(ValueError, match="n_elastomer"):
        Optics(n_elastomer=0.5)
    with pytest.raises(ValueError, match="defocus"):
        Optics(defocus=0.1)  # 10 cm: a unit slip (um given as m * 1e4)
    with pytest.raises(ValueError, match="condenser_inner_na"):
        Optics(condenser_na=0.1, condenser_inner_na=0.2)
    with pytest.raises(TypeError, match="optics"):
        render_series([0.0], optics={"defocus": 1e-6})


def test_looks_render_and_held_out_is_disjoint():
    assert not set(LOOKS) & set(HELD_OUT_LOOKS) and not set(OUTSIDE_LOOKS) & (set(LOOKS) | set(HELD_OUT_LOOKS))
    assert "dark_field" in OUTSIDE_LOOKS
    required = {"absorbing_band", "edge_dark", "edge_bright", "bright_band", "halo", "no_grey_step",
                "defocus", "inverted", "film_10um", "film_26um", "coarse_2um", "uneven_8bit"}
    assert required <= set(LOOKS)
    s = render_look("edge_dark", [0.0, 1.0], shape=(300, 400), pixel_size=2e-6)
    assert s.truth.attrs["look"] == "edge_dark" and s.truth.attrs["appearance"] == "optics"
    assert s.truth.attrs["optics_n_elastomer"] == pytest.approx(1.412)
    with pytest.raises(ValueError, match="unknown look"):
        render_look("nope", [0.0])


def test_drawn_looks_keep_to_their_stated_ranges():
    """drawn_look: the same batch and k give the same look; 300 draws keep to the ranges its docstring states,
    each optional nuisance in about its stated share of the looks, every dome at Vtilde 4 within 900 px."""
    from osmobulge.imaging.looks import DRAWN_BATCHES, drawn_look, get_look

    assert drawn_look(7, 3) == drawn_look(7, 3) == get_look("drawn_7_3") != drawn_look(7, 4)
    looks = [drawn_look(1, k) for k in range(300)]
    o = {f: np.array([getattr(lk.optics, f) for lk in looks]) for f in
         ("n_elastomer", "n_liquid", "objective_na", "condenser_na", "defocus", "halo_strength", "absorption_film",
          "absorption_base", "dilution")}
    n = {f: np.array([getattr(lk.nuisances, f) for lk in looks], dtype=object) for f in
         ("noise_sigma", "drift_sigma", "exposure_drift", "stray_light", "focus_drift", "debris", "bit_depth",
          "polarity", "time_stamp", "neighbours")}
    a = np.array([lk.chamber[0] for lk in looks])
    px = np.array([lk.pixel_size for lk in looks])
    assert np.all((o["n_elastomer"] >= 1.405) & (o["n_elastomer"] <= 1.435))
    assert np.all((o["n_liquid"] >= 1.34) & (o["n_liquid"] <= 1.365))
    assert np.all(o["condenser_na"] <= np.minimum(0.2, 0.8 * o["objective_na"]))
    assert np.all(np.abs(o["defocus"]) <= 8e-6) and np.all((a >= 100e-6) & (a <= 200e-6))
    assert np.all((2.5 * a + 200e-6) / px <= 900.0 + 1e-9)
    for share, hit in ((0.5, o["halo_strength"] > 0), (0.15, o["absorption_film"] > 0), (0.5, o["dilution"]),
                       (0.15, px == 2e-6), (0.3, n["exposure_drift"] != 0), (0.3, n["stray_light"] != 0),
                       (0.4, n["focus_drift"] != 0), (0.3, n["debris"] > 0), (0.15, n["polarity"] == -1),
                       (0.2, n["time_stamp"] != "none"), (0.25, np.array([len(x) > 0 for x in n["neighbours"]]))):
        assert abs(np.mean(hit.astype(float)) - share) < 4 * np.sqrt(share * (1 - share) / len(looks)), share
    assert set(n["bit_depth"]) == {8, 10, 12, 16}
    directions = {lk.scene.bulge_direction for lk in looks}
    assert directions == {"up", "down", "left", "right"}
    assert 20261207 in DRAWN_BATCHES


def test_a_drawn_look_measured_blind_reads_right():
    """drawn_20261207_3, measured once blind (9 frames: all ok, worst 0.32 of the tolerance): a dyed film, halos,
    the focal plane drifting 4.6 um, particles drifting in the water, a time stamp, 1.45 um pixels, 16 bits."""
    s = render_look("drawn_20261207_3", [0.0, 1.0, 4.0], lambda_pre=PreStretch(0.01, 0.0))
    assert s.truth.attrs["look"] == "drawn_20261207_3"
    a, h, l0 = (s.truth.attrs[k] for k in ("chamber_radius", "chamber_depth", "membrane_thickness"))
    ds = extract(s.frames, pixel_size=s.truth.attrs["pixel_size"], chamber=Chamber(a, h, l0, 3000.0),
                 progress=False, frame_interval=600.0)
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok"] * 3 and sc["n_silent"] == 0
    assert np.all(sc["dv_tol"] <= 1.0) and np.all(np.abs(sc["rim_bias_px"]) <= 0.5), (sc["dv_tol"], sc["rim_bias_px"])


def test_score_counts_silent_errors():
    import xarray as xr

    p = 1e-6
    truth = xr.Dataset({"volume": ("time", [0.0, 1e-12]), "rim_radius": ("time", [200e-6, 201e-6]),
                        "lambda_pre": ("time", [1.0, 1.005])}, attrs={"pixel_size": p})
    tol0 = 0.5 * p * np.pi * (200e-6) ** 2
    ds = xr.Dataset({"volume": ("time", [2 * tol0, 1e-12]), "rim_radius": ("time", [200e-6, 201.8e-6]),
                     "lambda_pre": ("time", [1.0, 1.009]), "flag": ("time", ["ok", "poor_fit"])})
    sc = score(truth, ds)
    np.testing.assert_allclose(sc["dv_tol"], [2.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(sc["rim_bias_px"], [0.0, 0.8], atol=1e-9)
    assert sc["n_silent"] == 1 and sc["n_flagged"] == 1 and sc["silent"].tolist() == [True, False]
    assert sc["frac_volume_ok"] == 0.5 and sc["n_events"] == 0
    # a frame the truth marks as an event (the domes touching) is left out of the share within tolerance
    truth["flag"] = ("time", ["ok", "touching"])
    ds["volume"] = ("time", [0.0, 2e-12])
    sc = score(truth, ds)
    assert sc["frac_volume_ok"] == 1.0 and sc["n_events"] == 1 and sc["n_events_flagged"] == 1
    assert sc["event"].tolist() == [False, True]


def test_the_exposure_drifts_over_the_series_and_clips_at_full_scale():
    """Nuisances(exposure_drift=d): frame i's light times 1 + d (t_i - t_0)/(t_last - t_0) (no noise: within the
    rounding of each), the first frame as without it, the light over the full scale at it (a camera's clip), and
    the truth's light_gain the factor."""
    ch, p = (150e-6, 110e-6, 20e-6), 1.6e-6
    kw = {"chamber": ch, "pixel_size": p, "shape": (420, 400), "optics": Optics(), "seed": 5,
          "times": [0.0, 600.0, 2400.0]}
    nu = Nuisances(blur_sigma=0.5)
    plain = render_series([0.0, 1.0, 2.0], nuisances=nu, **kw)
    s = render_series([0.0, 1.0, 2.0], nuisances=replace(nu, exposure_drift=0.6), **kw)
    np.testing.assert_array_equal(s.frames[0], plain.frames[0])
    np.testing.assert_allclose(s.truth.light_gain.values, [1.0, 1.15, 1.6])
    for i, gain in ((1, 1.15), (2, 1.6)):
        want = plain.frames[i].astype(float) * gain
        under = want < 65535.0 - gain
        assert np.all(np.abs(s.frames[i][under] - want[under]) <= 0.5 * gain + 0.5 + 1e-6)
        assert np.all(s.frames[i][want > 65535.0 + gain] == 65535)
    assert np.mean(s.frames[2] == 65535) > 0.3 and np.all(plain.frames[2] < 65535)  # (the water clips)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_compiled_splat_is_numpys_to_the_bit(dtype):
    """The defocus shift's bilinear splat is compiled (it took 6.7 of a frame's 11.5 s); it adds the same sums
    in the same order as numpy's four bincounts, so the renders (and every figure measured on them) are
    unchanged: equal to the bit, samples moved by up to ~10 px, some off the grid."""
    from osmobulge.imaging.optics import _splat, _splat_numpy

    rng = np.random.default_rng(3)
    shape = (150, 170)
    rr, cc = np.mgrid[0 : shape[0], 0 : shape[1]].astype(float)
    shift = np.where(rng.random(shape) < 0.2, rng.normal(0.0, 3.0, shape), 0.0)
    rows, cols = rr + shift, cc - 0.7 * shift
    weight = rng.random(shape).astype(dtype)
    got, ref = _splat(shape, rows, cols, weight), _splat_numpy(shape, rows, cols, weight)
    assert np.any((rows < 0) | (rows > shape[0] - 1))  # (some samples land off the grid)
    assert np.array_equal(got, ref)
    assert got.sum() == pytest.approx(ref.sum()) and got.sum() < weight.sum()  # (those are lost)


@pytest.mark.parametrize("axis_col", [40.0, 40.17, 40.5])
def test_a_view_turned_over_or_a_quarter_is_the_upright_one_mirrored_or_transposed(axis_col):
    """The walls' and the dome's silhouettes blend each crossed sample's inside and outside light along the
    grid's axis the scene's u runs along, its way: a view turned over (u running back along the columns) renders
    the upright one mirrored, a view turned a quarter (u along the rows) its transpose, to float precision.
    Stepping along the columns in every view (the code before) swapped the crossed samples' inside and outside
    in the view turned over, the walls' edges up to a sample off (a flat frame's rim read 0.30 px small on
    drawn_20261207_26, a view turned over, at one phase of the grid; right at others)."""
    from osmobulge.imaging.optics import render_optical

    p, a, h, l0 = 1e-6, 20e-6, 15e-6, 4e-6
    rows, cols = 50, 80
    rho = np.linspace(0.0, 1.0, 41)
    flat = (0.0, rho, np.zeros_like(rho), np.ones_like(rho), 1.0)
    dome = (0.0, rho, 0.5 * (1.0 - rho**2), np.ones_like(rho), 1.02)
    optics = Optics(oversample=3, defocus=2e-6, halo_strength=0.3)

    def upright(c, r):
        return (np.asarray(c) - axis_col) * p, -(np.asarray(r) - 30.0) * p

    def over(c, r):  # (the same scene, its u running back along the columns)
        return upright(cols - 1.0 - np.asarray(c), r)

    def quarter(c, r):  # (u along the rows)
        return upright(r, c)

    for chamber in (flat, dome):
        up = render_optical((rows, cols), upright, [chamber], a, h, l0, p, optics)
        turned = render_optical((rows, cols), over, [chamber], a, h, l0, p, optics)
        np.testing.assert_allclose(turned[:, ::-1], up, atol=2e-6)
        np.testing.assert_allclose(render_optical((cols, rows), quarter, [chamber], a, h, l0, p, optics).T, up,
                                   atol=2e-6)
