"""Walls from their silhouettes on the optics looks, against the rendered well radius (issue 16)."""

import numpy as np
import pytest

from osmobulge.imaging._chamber import ChamberNotFound
from osmobulge.imaging._silhouette import find_walls
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
