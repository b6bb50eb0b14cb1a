"""Walls from their silhouettes on the optics looks, against the rendered well radius (issue 16)."""

import pytest

from osmobulge.imaging._chamber import ChamberNotFound
from osmobulge.imaging._silhouette import find_walls
from osmobulge.imaging.looks import LOOKS, render_look

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
