"""The stage moved between frames (a multi-position series revisiting its positions, a bumped stage): each frame
is read where it now lies, or flagged; never read silently wrong.  Frames are moved by whole pixels here (the
rows or columns the move brings into the field repeat the edge's), the truth's volumes and rims unchanged."""

import numpy as np
import pytest
from scipy import ndimage

from osmobulge.imaging.extract import extract
from osmobulge.imaging.looks import render_look, score
from osmobulge.modeling import PreStretch
from osmobulge.modeling.transport import Chamber

PRE = PreStretch(0.01, 0.0)


def _moved(frames, shifts):
    """Each frame moved by its ``(rows, columns)`` (whole px: down and right positive)."""
    return np.stack([ndimage.shift(f, d, order=0, mode="nearest") for f, d in zip(frames, shifts, strict=True)])


def _extract(s, frames):
    a, h, l0 = (s.truth.attrs[k] for k in ("chamber_radius", "chamber_depth", "membrane_thickness"))
    return extract(frames, pixel_size=s.truth.attrs["pixel_size"], chamber=Chamber(a, h, l0, 3000.0),
                   progress=False, frame_interval=600.0)


@pytest.mark.parametrize("name", ["absorbing_band", "coarse_2um"])
def test_silhouette_route_reads_frames_the_stage_moved(name):
    """The drift is read from the base's row and column profiles below the film.  Those rows started 5 px below
    it: a frame moved 6-8 px down brought the film's band into them, and the drift read 40 px off (the walls
    lost, frames no_membrane: absorbing_band's dyed film lost 2 of 9 frames at moves of +-10 px, coarse_2um 2 of
    9 at +-20 px).  They start half the well's depth below the film now: every frame reads ok and right, its drift
    within 0.15 px of the move."""
    s = render_look(name, [0.0, 0.2, 0.6, 1.2], lambda_pre=PRE)
    shifts = np.array([(0, 0), (8, 7), (-9, -2), (16, 12)])
    ds = _extract(s, _moved(s.frames, shifts))
    assert ds.attrs["tracer"] == "silhouette"
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok"] * 4, list(ds.message.values)
    np.testing.assert_allclose(ds.drift_y.values, shifts[:, 0], atol=0.15)
    np.testing.assert_allclose(ds.drift_x.values, shifts[:, 1], atol=0.15)
    assert np.all(sc["dv_tol"] <= 1.0) and np.all(np.abs(sc["rim_bias_px"]) <= 0.5), (sc["dv_tol"], sc["rim_bias_px"])


def test_band_route_does_not_take_a_band_cut_by_its_window():
    """The band route looks for the flat band first within a few px of the last frame's (its fine window).  The
    stage moved 12 px down: the window held a stretch of the band cut by its edge, fitted 4.5 px from where it was
    (9.7 px wide for 24.9, scattered 1.9 px for 0.03), and the frame read 5x its volume tolerance off, ok.  A band
    that is not the film's width, or is scattered over 1 px, now sends the search wide: the frame reads right."""
    s = render_look("painted_band", [0.0, 0.18, 0.5], lambda_pre=PRE)
    shifts = np.array([(0, 0), (12, 12), (1, -17)])
    ds = _extract(s, _moved(s.frames, shifts))
    assert ds.attrs["tracer"] == "band"
    sc = score(s.truth, ds)
    assert list(ds.flag.values) == ["ok"] * 3, list(ds.message.values)
    np.testing.assert_allclose(ds.drift_y.values, shifts[:, 0], atol=0.15)
    assert np.all(sc["dv_tol"] <= 1.0) and np.all(np.abs(sc["rim_bias_px"]) <= 0.5), (sc["dv_tol"], sc["rim_bias_px"])


def test_band_route_flags_what_it_cannot_follow():
    """Moves of up to 40 px each way between frames (up to 80 px from one frame to the next: beyond the band
    route's max_drift, 40 px frame to frame), by fractions of a px (interpolated).  Its phase correlation and wide
    band search then found other edges: a frame 8x its volume tolerance off read ok (a band 1.9 px wide,
    scattered 9.3 px, taken for the film).  The frames it cannot follow are flagged now, none silent."""
    vt = np.linspace(0.0, 4.0, 9) ** 1.5 / 2.0
    s = render_look("painted_band", vt, lambda_pre=PRE)
    rng = np.random.default_rng(5)
    shifts = np.vstack([[0.0, 0.0], rng.uniform(-40.0, 40.0, (8, 2))])
    frames = np.stack([np.rint(ndimage.shift(f.astype(float), d, order=1, mode="nearest")).astype(f.dtype)
                       for f, d in zip(s.frames, shifts, strict=True)])
    ds = _extract(s, frames)
    sc = score(s.truth, ds)
    assert sc["n_silent"] == 0, (list(ds.flag.values), sc["dv_tol"], sc["rim_bias_px"])
    assert list(ds.flag.values[:2]) == ["ok", "ok"]  # (within max_drift: read)
    assert np.all(sc["dv_tol"][:2] <= 1.0)
