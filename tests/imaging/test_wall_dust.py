"""Wall measurement with a dust speck on a well wall (osmobulge.imaging._chamber.measure_walls).

A speck on or beside a wall darkens the rows it covers and bends their step
crossings by up to a few px while the step stays strong; on a small chamber
(a = 100 px, h = 50 px) with every nuisance on, that bent one wall's line fit
and put the rim radius off by up to 1.5 px.  Target: rim radius within 0.5 px
of the renderer's truth.
"""

import numpy as np
import pytest

from osmobulge.imaging._chamber import _dusty_rows
from osmobulge.imaging.synthetic import Nuisances, render_series
from osmobulge.imaging.trace import trace_series
from osmobulge.modeling import PreStretch

SMALL = {"chamber": (100e-6, 50e-6, 10e-6), "shape": (420, 440), "pixel_size": 1e-6,
         "lambda_pre": PreStretch(0.015, 0.0)}
VT = np.linspace(0.0, 3.0, 16) ** 1.5 / 3.0**0.5
# "all of the above" of benchmarks/imaging.py without the neighbour
ALL = Nuisances(polarity=-1, contrast=0.6, illumination_gradient=0.3, vignetting=0.2, bit_depth=8, noise_sigma=0.02,
                poisson_photons=3000, blur_sigma=1.5, tilt=3.0, drift_sigma=4.0, dust_count=30)


def rim_errors(series, traces):
    p = series.truth.attrs["pixel_size"]
    return np.array([abs(r.geometry.rim_radius - float(series.truth.rim_radius[i]) / p) for i, r in enumerate(traces)])


@pytest.mark.parametrize(("nuisances", "seed", "frames"), [
    (ALL, 100, slice(0, 5)),  # specks on the left wall in frames 1-3 (1.4 px off before)
    (Nuisances(dust_count=40, dust_opacity=0.5), 101, slice(None)),  # a speck on one wall at the last frame
])
def test_rim_radius_with_a_speck_on_a_wall(nuisances, seed, frames):
    s = render_series(VT[frames], nuisances=nuisances, seed=seed, **SMALL)
    _, traces = trace_series(s.frames)
    assert all(r.geometry is not None for r in traces)
    err = rim_errors(s, traces)
    assert err.max() < 0.5, err.round(3)


def test_dusty_rows_finds_a_speck_and_keeps_clean_rows():
    # a blurred vertical step (wall at offset 0.3 px) seen on 40 rows, a speck's shadow over rows 10-16
    rng = np.random.default_rng(0)
    offs = np.arange(-8.0, 8.01, 0.5)
    step = 100.0 + 60.0 * (0.5 + 0.5 * np.tanh((offs[None, :] - 0.3) / 1.2))
    prof = step + 0.5 * rng.standard_normal((40, offs.size))
    r2 = (np.arange(40)[:, None] - 13.0) ** 2 + (offs[None, :] - 2.0) ** 2
    shadow = 1.0 - 0.4 * np.exp(-0.5 * r2 / 3.0**2)
    dusty, grown = _dusty_rows(prof * shadow, offs, np.full(40, 0.3))
    assert dusty[11:16].all() and not dusty[:5].any() and not dusty[25:].any()
    assert grown[dusty].all() and grown.sum() > dusty.sum()  # the faint fringe goes too
    clean, _ = _dusty_rows(prof, offs, np.full(40, 0.3))
    assert clean.sum() <= 1  # noise alone: (almost) no row rejected


def test_rows_without_an_edge_are_not_dust_and_do_not_grow():
    """Rows already dropped (no edge: weak step, outside the view) must not take clean neighbours with them."""
    rng = np.random.default_rng(1)
    offs = np.arange(-8.0, 8.01, 0.5)
    prof = 100.0 + 60.0 * (0.5 + 0.5 * np.tanh((offs[None, :] - 0.3) / 1.2)) + 0.5 * rng.standard_normal((40, 33))
    pos = np.full(40, 0.3)
    pos[:10] = np.nan
    dusty, grown = _dusty_rows(prof, offs, pos)
    assert not dusty[:10].any() and not grown[:15].any()  # (the old rule grew the nan run into rows 10-14)


@pytest.mark.parametrize("seed", [100, 101, 103])
def test_compiled_wall_rows_equal_the_numpy_rows(seed):
    """The compiled rows of a wall fit (steps, sign and strength, dusty rows) are measure_walls' former numpy rows."""
    from osmobulge.imaging._chamber import WALL_WINDOW, FrameView, _wall_rows_numpy
    from osmobulge.imaging._kernels import wall_rows

    s = render_series(VT[[0, 8, 15]], nuisances=ALL.__class__(**{**ALL.__dict__, "dust_count": 60}), seed=seed,
                      **SMALL)
    tracer, traces = trace_series(s.frames)
    n_dropped = 0
    for fr, tr in zip(s.frames, traces, strict=True):
        g = tr.geometry
        view = FrameView(fr, tracer.k)
        top = -0.5 * g.thickness
        zs = top - np.linspace(0.06, 0.92, int(np.clip(0.86 * g.well.depth, 8, 250))) * g.well.depth
        offs = np.arange(-WALL_WINDOW, WALL_WINDOW + 1e-9, 0.5)  # the trace's window
        for u0, slope in ((g.well.u_left, g.well.slope_left), (g.well.u_right, g.well.slope_right)):
            for du in (0.0, 2.5):  # on the wall and a little off it
                d, nv = g.line.direction, g.line.normal
                got = wall_rows(fr, tracer.k, g.line.x0, g.line.y0, d[0], d[1], nv[0], nv[1], u0 + du, slope, zs,
                                top, offs)
                want = _wall_rows_numpy(view, g.line, u0 + du, slope, zs, top, offs)
                np.testing.assert_array_equal(np.isnan(got[1]), np.isnan(want[1]))
                np.testing.assert_allclose(got[0], want[0], rtol=0, atol=1e-12)
                np.testing.assert_allclose(got[1], want[1], rtol=0, atol=1e-9, equal_nan=True)
                n_dropped += int(np.isnan(want[1]).sum())
    assert n_dropped > 0  # some rows were dropped (dust, weak steps): both branches compared
