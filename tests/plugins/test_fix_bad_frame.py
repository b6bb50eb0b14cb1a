"""Must show (issue 6): open a demo experiment, fix a bad frame by picking points, accept, close,
reopen, find the fix there, and see the fits use it."""

import json

import numpy as np
import pytest
import xarray as xr
from plugin_helpers import BAD, CHAMBER, PIXEL, truth_midline_rc

from osmobulge.experiments.curation import apply_curation, load_curation
from osmobulge.experiments.metadata import load_experiment
from osmobulge.experiments.runs import observations_from_extraction, run_experiment

napari = pytest.importorskip("napari")
pytestmark = [pytest.mark.gui, pytest.mark.slow]

V0 = np.pi * CHAMBER[0] ** 2 * CHAMBER[1]


def _fits(folder):
    return json.loads((folder / "results" / "fits.json").read_text())["models"]["constant_hyperelastic"]


def test_fix_a_bad_frame_end_to_end(make_napari_viewer, experiment):
    from osmobulge.plugins._widget import CurationWidget, ProfilePicker

    folder, truth = experiment
    # the lab's automatic run: the rendered-fractured frame is flagged and left out of the fits
    assert run_experiment(folder, ["process", "fit"], errors="raise")
    ds = xr.open_dataset(folder / "results" / "extraction.nc", engine="h5netcdf").load()
    assert str(ds["flag"].values[BAD]) == "fractured"
    assert _fits(folder)["n_points"] == truth.sizes["time"] - 1

    # open it in napari: frames + automatic profiles
    viewer = make_napari_viewer()
    viewer.open(str(folder), plugin="osmobulge")
    auto = viewer.layers["auto profiles"]
    assert len(auto.data) == truth.sizes["time"]
    expected = np.c_[ds["profile_row"].values[BAD], ds["profile_col"].values[BAD]]
    np.testing.assert_allclose(auto.data[BAD][:, 1:], expected)
    cw, pp = CurationWidget(viewer), ProfilePicker(viewer)
    viewer.dims.set_current_step(0, BAD)
    assert "auto: fractured" in cw._status.value
    assert not cw.plot_data()["kept"][BAD]  # flagged: not used

    # pick points along the membrane (clicks near it, rim to rim), they snap; accept
    mid = truth_midline_rc(truth, BAD)
    rng = np.random.default_rng(11)
    for p in mid[np.linspace(0, len(mid) - 1, 12).astype(int)] + rng.uniform(-2, 2, (12, 2)):
        pp.points_layer.add([BAD, *p])
    fit = pp.accept()
    true_v = float(truth["volume"].values[BAD])
    assert fit.volume == pytest.approx(true_v, rel=0.02, abs=0)
    assert fit.geometry.source == "extraction"
    d = cw.plot_data()
    assert d["kept"][BAD] and d["manual"][BAD]
    assert d["volume_ratio"][BAD] == pytest.approx(1 + fit.volume / V0)
    saved_points = np.asarray(load_curation(folder).manual_profiles[BAD]["points"])
    viewer.close()

    # reopen: the fix is there (points, accepted fit, status)
    viewer2 = make_napari_viewer()
    viewer2.open(str(folder), plugin="osmobulge")
    cw2, pp2 = CurationWidget(viewer2), ProfilePicker(viewer2)
    viewer2.dims.set_current_step(0, BAD)
    rows = np.asarray(pp2.points_layer.data)
    mine = rows[np.rint(rows[:, 0]) == BAD][:, 1:]
    np.testing.assert_allclose(mine[:, ::-1] * PIXEL, saved_points, rtol=1e-12)
    assert "manual profile" in cw2._status.value and "saved" in pp2._info.value
    assert pp2.session.manual_fit(BAD).volume == pytest.approx(fit.volume, rel=1e-9, abs=0)

    # ... and used by the fits: re-running brings the extraction and the fit up to date
    out = run_experiment(folder, ["fit"], errors="raise")
    assert [s.status for s in out.steps] == ["done", "done"]  # process re-ran (curation changed), then fit
    ds = xr.open_dataset(folder / "results" / "extraction.nc", engine="h5netcdf").load()
    assert str(ds["profile_source"].values[BAD]) == "manual" and str(ds["flag"].values[BAD]) == "ok"
    # the extraction integrates the same manual profile: the same volume as the plugin showed
    assert float(ds["volume"].values[BAD]) == pytest.approx(fit.volume, rel=1e-3, abs=0)
    curated = apply_curation(ds, load_curation(folder))
    assert bool(curated["kept"].values[BAD])
    (obs,) = observations_from_extraction(curated, load_experiment(folder))
    t_bad = float(ds["time"].values[BAD])
    assert float(obs["volume_ratio"].sel(time=t_bad)) == pytest.approx(1 + fit.volume / V0, rel=1e-3, abs=0)
    assert _fits(folder)["n_points"] == truth.sizes["time"]  # the fixed frame is in the fit
