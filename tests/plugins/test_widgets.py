"""The napari plugin end to end: manifest, reader, widgets, shortcuts, screenshot (Xvfb via pytest-xvfb)."""

import numpy as np
import pytest
import xarray as xr
from plugin_helpers import BAD, CHAMBER, PIXEL, truth_midline_rc

from osmobulge.experiments.curation import load_curation

napari = pytest.importorskip("napari")
pytestmark = pytest.mark.gui

V0 = np.pi * CHAMBER[0] ** 2 * CHAMBER[1]


def test_manifest_is_valid_and_discovered():
    from npe2 import PluginManager
    from npe2.manifest import PluginManifest

    pm = PluginManager.instance()
    pm.discover()
    mf = pm.get_manifest("osmobulge")
    PluginManifest.model_validate(mf.model_dump())  # what `npe2 validate osmobulge` checks
    assert [w.display_name for w in mf.contributions.widgets] == ["Curation", "Profile picker"]
    assert mf.contributions.readers[0].accepts_directories


def test_reader_rejects_other_paths(tmp_path):
    from osmobulge.plugins._reader import napari_get_reader

    assert napari_get_reader(str(tmp_path)) is None
    assert napari_get_reader([str(tmp_path), str(tmp_path)]) is None
    (tmp_path / "a.tif").write_bytes(b"")
    assert napari_get_reader(str(tmp_path / "a.tif")) is None


def _open(viewer, folder):
    layers = viewer.open(str(folder), plugin="osmobulge")
    return layers[0]


def _clicks(truth, frame, n=12, seed=0):
    tr = truth_midline_rc(truth, frame)
    idx = np.linspace(0, len(tr) - 1, n).astype(int)
    rng = np.random.default_rng(seed)
    return tr[idx] + rng.uniform(-2, 2, size=(n, 2))


def test_reader_opens_the_experiment(make_napari_viewer, experiment):
    folder, truth = experiment
    viewer = make_napari_viewer()
    image = _open(viewer, folder)
    assert image.data.shape == (truth.sizes["time"], 200, 240)
    np.testing.assert_allclose(image.scale, [1.0, PIXEL * 1e6, PIXEL * 1e6])
    assert tuple(viewer.dims.axis_labels) == ("frame", "y", "x")
    assert image.metadata["osmobulge"]["folder"] == str(folder)
    assert "auto profiles" not in viewer.layers  # not processed yet
    # experiment.toml itself is claimed by this reader alone (no reader choice needed)
    viewer2 = make_napari_viewer()
    (layer,) = viewer2.open(str(folder / "experiment.toml"), plugin=None)
    assert layer.metadata["osmobulge"]["folder"] == str(folder)


def test_widgets_pick_accept_exclude(make_napari_viewer, experiment, qtbot):
    from osmobulge.plugins._widget import CurationWidget, ProfilePicker

    folder, truth = experiment
    viewer = make_napari_viewer()
    _open(viewer, folder)
    cw = CurationWidget(viewer)
    pp = ProfilePicker(viewer)
    viewer.window.add_dock_widget(cw, name="Curation")
    viewer.window.add_dock_widget(pp, name="Profile picker")
    # go to the bad frame with the widget's buttons
    viewer.dims.set_current_step(0, 0)
    for _ in range(BAD):
        cw._next.clicked.emit()
    assert viewer.dims.current_step[0] == BAD
    assert cw._status.value.startswith(f"frame {BAD + 1}/6")
    # click points on the membrane: they land in the points layer and snap
    clicks = _clicks(truth, BAD)
    pts = pp.points_layer
    for p in clicks:
        pts.add([BAD, *p])
    picks = pp.session.picks[BAD]
    assert len(picks) == len(clicks)
    layer_rows = np.asarray(pts.data)
    np.testing.assert_allclose(layer_rows[:, 1:], picks)  # the layer shows the snapped points
    assert np.linalg.norm(picks - clicks[np.argsort(clicks[:, 1])], axis=1).max() > 0  # they moved
    # live fits drawn on this frame: spline (pending colour) and ellipse
    assert len(pp.fit_layer.data) == 2 and all(np.all(s[:, 0] == BAD) for s in pp.fit_layer.data)
    assert "V/V0" in pp._info.value
    # accept: saved as a manual profile with the recomputed volume
    fit = pp.accept()
    cur = load_curation(folder)
    assert cur.manual_profiles[BAD]["source"] == "manual"
    true_v = float(truth["volume"].values[BAD])
    assert abs(fit.volume - true_v) < max(0.02 * true_v, np.pi * CHAMBER[0] ** 2 * 0.5 * PIXEL)
    d = cw.plot_data()
    assert d["manual"][BAD] and d["volume_ratio"][BAD] == pytest.approx(1 + fit.volume / V0)
    assert "saved" in pp._info.value
    # exclude the next frame with a reason, from the widget
    cw._next.clicked.emit()
    cw._reason.value = "touching"
    cw._note.value = "neighbour"
    cw._exclude.clicked.emit()
    assert load_curation(folder).excluded[BAD + 1]["reason"] == "touching"
    assert cw.plot_data()["excluded"][BAD + 1]
    assert "EXCLUDED (touching)" in cw._status.value
    # time origin at the current frame
    cw._t0_here.clicked.emit()
    assert load_curation(folder).time_origin == pytest.approx(cw.session.times[BAD + 1])
    assert cw.plot_data()["time_min"][BAD + 1] == pytest.approx(0.0)


def test_keep_picks_as_priors_button(make_napari_viewer, experiment):
    """Semi-automatic mode from the dock: the picks are saved as priors and the extraction uses them."""
    from osmobulge.plugins._widget import ProfilePicker

    folder, truth = experiment
    viewer = make_napari_viewer()
    _open(viewer, folder)
    pp = ProfilePicker(viewer)
    viewer.dims.set_current_step(0, BAD)
    for p in _clicks(truth, BAD):
        pp.points_layer.add([BAD, *p])
    pp._keep_priors.clicked.emit()
    cur = load_curation(folder)
    assert list(cur.priors) == [BAD] and BAD not in cur.manual_profiles
    np.testing.assert_allclose(np.asarray(cur.priors[BAD]["points"]), pp.session.picks[BAD][:, ::-1] * PIXEL)
    ds = xr.load_dataset(folder / "results" / "extraction.nc", engine="h5netcdf")
    assert list(np.atleast_1d(ds.attrs["prior_frames"])) == [BAD]
    assert "priors" in pp._message.value


def test_rim_from_the_picks_button(make_napari_viewer, experiment):
    """The Profile picker saves the two ends of the first frame's picks as the chamber's rim (curation.json,
    what the next extraction locates the chamber by) and clears it; too few picks is said, nothing saved."""
    from osmobulge.plugins._widget import ProfilePicker

    folder, truth = experiment
    viewer = make_napari_viewer()
    _open(viewer, folder)
    pp = ProfilePicker(viewer)
    pp._snap.value = False  # (the points stay where clicked)
    viewer.dims.set_current_step(0, 0)
    mid = truth_midline_rc(truth, 0)
    left, right = mid[np.argmin(mid[:, 1])], mid[np.argmax(mid[:, 1])]
    pp.points_layer.add([0, *right])
    with pytest.raises(Exception, match="two ends"):  # (psygnal's EmitLoopError around the ValueError)
        pp._rim.clicked.emit()
    assert load_curation(folder).rim is None and "error" in pp._message.value
    pp.points_layer.add([0, *left])
    pp._rim.clicked.emit()
    rim = load_curation(folder).rim
    np.testing.assert_allclose(rim, [left[1], left[0], right[1], right[0]], rtol=0, atol=1e-9)  # (col, row)
    assert pp.session.rim() == rim and "rim saved" in pp._message.value
    pp._rim_clear.clicked.emit()
    assert load_curation(folder).rim is None and pp.session.rim() is None and "cleared" in pp._message.value


def test_keyboard_shortcuts(make_napari_viewer, experiment):
    from osmobulge.plugins._widget import CurationWidget, ProfilePicker

    folder, truth = experiment
    viewer = make_napari_viewer()
    _open(viewer, folder)
    cw, pp = CurationWidget(viewer), ProfilePicker(viewer)
    viewer.dims.set_current_step(0, 0)
    handler = viewer.window._qt_viewer._key_map_handler  # dispatches as the canvas does: layer keymap first

    def press(key):
        handler.press_key(key)
        handler.release_key(key)

    assert viewer.layers.selection.active is pp.points_layer  # picking mode: the points layer is active
    press("n")
    press("n")
    assert viewer.dims.current_step[0] == 2
    press("b")
    assert viewer.dims.current_step[0] == 1
    press("Shift-Right")
    assert viewer.dims.current_step[0] == 2
    press("Shift-Left")
    assert viewer.dims.current_step[0] == 1
    pp.set_points(_clicks(truth, 1))
    press("Enter")
    assert 1 in load_curation(folder).manual_profiles
    cw._reason.value = "out_of_focus"
    press("Shift-X")
    assert load_curation(folder).excluded[1]["reason"] == "out_of_focus"
    press("Shift-U")
    assert 1 not in load_curation(folder).excluded


def _canvas_to_data(viewer, rows, cols, shot_shape):
    """Canvas pixel (row, col) -> data (row, col) px of the image layer (2-D view, no rotation)."""
    h, w = shot_shape[:2]
    canvas_h, canvas_w = viewer.window._qt_viewer.canvas.size  # logical pixels
    ratio = h / canvas_h
    cy, cx = viewer.scene.camera.center[-2:]
    zoom = viewer.scene.camera.zoom * ratio
    scale = PIXEL * 1e6
    y = cy + (np.asarray(rows) + 0.5 - h / 2) / zoom
    x = cx + (np.asarray(cols) + 0.5 - w / 2) / zoom
    return y / scale, x / scale


def test_screenshot_overlay_is_on_the_profile(make_napari_viewer, experiment, tmp_path):
    """A screenshot with the accepted profile overlaid: its pixels lie on the true membrane midline."""
    import os

    from skimage.io import imsave

    from osmobulge.plugins._widget import COLORS, open_experiment

    folder, truth = experiment
    docs_dir = os.environ.get("OSMOBULGE_SCREENSHOT_DIR")
    if docs_dir:  # the docs figure shows the automatic profiles too
        from osmobulge.experiments.runs import run_experiment

        run_experiment(folder, ["process"], errors="raise")
    viewer, cw, pp = open_experiment(folder, make_napari_viewer(show=True), frame=BAD)
    assert set(viewer.window.dock_widgets) >= {"Curation", "Profile picker"}
    assert viewer.dims.current_step[0] == BAD
    pp.set_points(_clicks(truth, BAD, n=14))
    pp.accept()
    assert COLORS["accepted"] == "lime"
    pp.points_layer.visible = False  # only the fitted curves in the colour test
    viewer.reset_view()
    shot = viewer.screenshot(canvas_only=True, flash=False)
    imsave(tmp_path / "overlay.png", shot, check_contrast=False)
    assert (tmp_path / "overlay.png").stat().st_size > 1000
    r, g, b = (shot[..., i].astype(int) for i in range(3))
    lime = (g > 180) & (r < 110) & (b < 110)  # the accepted spline
    cyan = (g > 180) & (b > 180) & (r < 110)  # the ellipse
    assert lime.sum() > 100 and cyan.sum() > 20
    rows, cols = np.nonzero(lime | cyan)
    assert rows.size > 100, "no overlay pixels in the screenshot"
    y, x = _canvas_to_data(viewer, rows, cols, shot.shape)
    mid = truth_midline_rc(truth, BAD)
    # every overlay pixel is within 1.5 data px of the true midline ...
    d = np.min(np.hypot(y[:, None] - mid[None, :, 0], x[:, None] - mid[None, :, 1]), axis=1)
    zoom_px = viewer.scene.camera.zoom * PIXEL * 1e6  # screen pixels per data pixel
    assert np.percentile(d, 99) < 1.5 + 1.5 / zoom_px, np.percentile(d, [50, 90, 99])
    # ... and the overlay covers the midline from rim to rim
    cover = np.min(np.hypot(mid[:, None, 0] - y[None, :], mid[:, None, 1] - x[None, :]), axis=1)
    assert np.mean(cover < 1.5) > 0.95
    if docs_dir:  # regenerate the docs figure: OSMOBULGE_SCREENSHOT_DIR=docs/img pytest -k screenshot
        pp.points_layer.visible = True
        viewer.layers.selection.active = pp.points_layer
        from qtpy.QtCore import Qt
        from qtpy.QtWidgets import QApplication

        win = viewer.window._qt_window
        win.resize(1500, 900)
        docks = [viewer.window.dock_widgets[n].native.parent() for n in ("Curation", "Profile picker")]
        for dw in docks:
            dw.show()
        QApplication.processEvents()
        win.resizeDocks(docks, [430, 430], Qt.Orientation.Horizontal)
        win.resizeDocks(docks, [470, 330], Qt.Orientation.Vertical)
        QApplication.processEvents()
        viewer.reset_view()
        shot = viewer.window.screenshot(canvas_only=False, flash=False)  # the whole window, docks included
        imsave(os.path.join(docs_dir, "curation.png"), shot[..., :3], check_contrast=False)


def test_regions_import_export_and_plot(make_napari_viewer, experiment, tmp_path):
    from osmobulge.plugins._widget import REGIONS_LAYER, CurationWidget, ProfilePicker

    folder, truth = experiment
    viewer = make_napari_viewer()
    _open(viewer, folder)
    cw, pp = CurationWidget(viewer), ProfilePicker(viewer)
    # chamber regions: the button asks for rectangles, then saves them
    cw._regions.clicked.emit()
    layer = viewer.layers[REGIONS_LAYER]
    assert layer.mode == "add_rectangle" and "draw one rectangle" in cw._message.value
    layer.add_rectangles([np.array([[-0.5, -0.5], [199.5, 119.5]]), np.array([[-0.5, 119.5], [199.5, 239.5]])])
    cw._regions.clicked.emit()
    assert [dict(r) for r in load_curation(folder).chamber_regions] == [
        {"name": "chamber0", "rows": [0, 200], "cols": [0, 120]},
        {"name": "chamber1", "rows": [0, 200], "cols": [120, 240]},
    ]
    # points exported from one viewer, imported into another session's picker
    viewer.dims.set_current_step(0, 2)
    pp.set_points(_clicks(truth, 2))
    pp._file.value = tmp_path / "picked.zip"
    pp._export.clicked.emit()
    assert (tmp_path / "picked.zip").is_file()
    viewer2 = make_napari_viewer()
    _open(viewer2, folder)
    pp2 = ProfilePicker(viewer2)
    pp2._file.value = tmp_path / "picked.zip"
    pp2._import.clicked.emit()
    np.testing.assert_allclose(pp2.session.picks[2], pp.session.picks[2], atol=1e-3)
    rows = np.asarray(pp2.points_layer.data)
    assert np.all(np.rint(rows[:, 0]) == 2) and len(rows) == len(pp.session.picks[2])
    # the plot follows the decisions: an exclusion appears as a red cross
    viewer.dims.set_current_step(0, 4)
    cw._exclude.clicked.emit()
    labels = [ln.get_label() for ln in cw.ax.get_lines()]
    assert "excluded" in labels
    (xline,) = [ln for ln in cw.ax.get_lines() if ln.get_label() == "excluded"]
    np.testing.assert_allclose(xline.get_xdata(), [cw.session.times[4] / 60.0])


def test_widgets_from_the_manifest_before_the_experiment(make_napari_viewer, experiment):
    """Widgets opened from the Plugins menu first; the experiment opened afterwards is picked up."""
    folder, truth = experiment
    viewer = make_napari_viewer()
    _, cw = viewer.window.add_plugin_dock_widget("osmobulge", "Curation")
    _, pp = viewer.window.add_plugin_dock_widget("osmobulge", "Profile picker")
    assert cw.session is None and pp.session is None
    _open(viewer, folder)
    assert cw.session is pp.session is not None
    assert pp.points_layer is not None and pp.fit_layer is not None
    viewer.dims.set_current_step(0, 1)
    assert cw._status.value.startswith("frame 2/6")
    pp.set_points(_clicks(truth, 1))
    assert "V/V0" in pp._info.value
    # a flagged frame can be kept on purpose
    cw._note.value = "flag is a false alarm"
    cw._keep.clicked.emit()
    assert load_curation(folder).kept_flagged[1]["note"] == "flag is a false alarm"
    assert "kept although flagged" in cw._status.value


def test_npe2_validate_command():
    import subprocess
    import sys
    from pathlib import Path

    exe = Path(sys.executable).parent / "npe2"
    if not exe.exists():
        pytest.skip("npe2 command not installed next to this Python")
    out = subprocess.run([str(exe), "validate", "osmobulge"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "valid" in (out.stdout + out.stderr)
