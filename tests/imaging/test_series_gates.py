"""Series gates: a flat first frame with volume, and a frame outside its neighbours' volumes, are flagged."""

import numpy as np
import pytest

from osmobulge.imaging.extract import extract, series_gates
from osmobulge.imaging.looks import render_look
from osmobulge.imaging.synthetic import render_series

P = 1e-6
R = 200e-6
LAYER = 0.5 * P * np.pi * R**2  # the tolerance floor (m3)


def _scal(vol):
    vol = np.asarray(vol, float)
    return {"volume_left": vol.copy(), "volume_right": vol.copy(), "rim_radius": np.full(vol.size, R),
            "flag_value": np.zeros(vol.size)}


def _flags(n):
    return np.array(["ok"] * n, dtype=object), np.array([""] * n, dtype=object)


def test_monotone_series_passes():
    vol = np.r_[0.0, np.cumsum(np.full(9, 40 * LAYER))]
    scal, (flag, fig) = _scal(vol), _flags(vol.size)
    series_gates(scal, flag, fig, P)
    assert list(flag) == ["ok"] * vol.size


def test_outlier_frame_flagged_alone():
    vol = np.r_[0.0, np.cumsum(np.full(9, 40 * LAYER))]
    vol[5] = vol[4] - 20 * LAYER  # a face switch: the volume drops below the frame before
    scal, (flag, fig) = _scal(vol), _flags(vol.size)
    series_gates(scal, flag, fig, P)
    assert [i for i, f in enumerate(flag) if f != "ok"] == [5]
    assert fig[5] == "volume_outlier" and scal["flag_value"][5] > 1


def test_flat_first_frame_with_volume_flagged_unless_a_reference_frame():
    vol = np.r_[1.6 * LAYER, np.cumsum(np.full(5, 40 * LAYER))]
    scal, (flag, fig) = _scal(vol), _flags(vol.size)
    series_gates(scal, flag, fig, P)
    assert flag[0] == "poor_fit" and fig[0] == "flat_volume"
    assert scal["flag_value"][0] == pytest.approx(1.6)
    scal, (flag, fig) = _scal(vol), _flags(vol.size)
    series_gates(scal, flag, fig, P, flat_first=False)
    assert flag[0] == "ok"
    vol[0] = 0.9 * LAYER  # within tolerance
    scal, (flag, fig) = _scal(vol), _flags(vol.size)
    series_gates(scal, flag, fig, P)
    assert flag[0] == "ok"


def test_gates_leave_a_good_extraction_alone():
    s = render_series([0.0, 0.3, 1.0, 2.0, 3.5], shape=(700, 800), seed=3)
    ds = extract(s.frames, pixel_size=P, frame_interval=600.0, progress=False)
    assert list(ds["flag"].values) == ["ok"] * 5


def test_a_look_neither_route_reads_is_an_error_that_names_the_ways_in():
    """Edge-only faces (no band, no grey step) in a tilted view: neither the band nor the silhouette route."""
    from dataclasses import replace

    from osmobulge.imaging.looks import LOOKS

    s = render_look("edge_dark", [0.0, 0.5], shape=(500, 640), pixel_size=1e-6,
                    nuisances=replace(LOOKS["edge_dark"].nuisances, tilt=1.0))
    with pytest.raises(ValueError, match="silhouette.*chamber_region=.*napari"):
        extract(s.frames, pixel_size=1e-6, frame_interval=600.0, progress=False)
