"""The real process step (osmobulge.imaging.extract) on synthetic frames with a known truth.

Small frames (160 x 220 px at 2 um/px, a 100 um chamber) so each extraction
takes about a second.
"""

import json

import numpy as np
import pytest
import tifffile
import xarray as xr

from osmobulge.experiments.curation import exclude_frame, load_curation, remove_prior, set_manual_profile, set_prior
from osmobulge.experiments.metadata import load_experiment
from osmobulge.experiments.runs import (
    EXIT_BAD_INPUT,
    FramesError,
    open_experiment_frames,
    read_state,
    run_batch,
    run_experiment,
)

P = 2e-6  # m/px
SHAPE = (160, 220)
CHAMBER = (100e-6, 60e-6, 10e-6)
DT = 600.0


def _render(vtilde, seed):
    from osmobulge.imaging.synthetic import Nuisances, render_series

    return render_series(np.asarray(vtilde, float), chamber=CHAMBER, pixel_size=P, shape=SHAPE,
                         times=np.arange(len(vtilde)) * DT,
                         nuisances=Nuisances(noise_sigma=0.01, blur_sigma=1.0, bit_depth=16), seed=seed)


def _toml(name, extra=""):
    return f'''[experiment]
name = "{name}"
material = "PDMS"

[chamber]
radius_um = 100.0
depth_um = 60.0
membrane_thickness_um = 10.0
concentration_M = 3.0

[imaging]
frames = "frames/*.tif"
pixel_size_um = 2.0
frame_interval_min = 10.0
bulge_direction = "up"
{extra}
[analysis]
models = ["constant_hyperelastic"]
instantaneous = false
'''


def _write(folder, frames, name="exp", extra=""):
    (folder / "frames").mkdir(parents=True, exist_ok=True)
    for i, f in enumerate(frames):
        tifffile.imwrite(folder / "frames" / f"frame_{i:03d}.tif", f)
    (folder / "experiment.toml").write_text(_toml(name, extra))
    return folder


def _truth_profile_m(truth, i, height_scale=1.0):
    """The true midline of frame i, rim to rim, as image coordinates in metres, heights scaled."""
    col = truth["midline_col"].values[i]  # (side, s): from the axis out to each rim
    row = truth["midline_row"].values[i]
    cols = np.r_[col[0][::-1], col[1][1:]]
    rows = np.r_[row[0][::-1], row[1][1:]]
    rim = float(truth["rim_y"].values[i])
    rows = rim - height_scale * (rim - rows)
    return np.c_[cols, rows] * P


def test_process_step_measures_the_truth(tmp_path):
    series = _render(np.linspace(0, 1.2, 8), seed=1)
    d = _write(tmp_path / "e", series.frames)
    out = run_experiment(d, ["process"])
    assert out.status == "ok", out.error
    ds = xr.load_dataset(d / "results" / "extraction.nc", engine="h5netcdf")
    truth = series.truth
    np.testing.assert_allclose(ds["time"].values, truth["time"].values)
    assert list(ds["frame"].values) == list(range(8))
    assert (ds["flag"].values == "ok").all()
    np.testing.assert_allclose(ds["volume"].values[1:], truth["volume"].values[1:], rtol=0.02)
    np.testing.assert_allclose(ds["volume_ratio"].values, truth["volume_ratio"].values, rtol=0.01)
    # the experiment's chamber and metadata are in the attrs; profiles are in frame pixels
    assert ds.attrs["chamber_radius"] == pytest.approx(CHAMBER[0], rel=1e-9, abs=0)
    assert ds.attrs["experiment_name"] == "exp"
    mid = np.nanmax(ds["profile_row"].values[-1])
    assert mid == pytest.approx(float(truth["rim_y"].values[-1]), abs=3.0)
    axis = float(np.nanmean(ds["profile_col"].values[-1]))
    assert axis == pytest.approx(float(truth["axis_x"].values[-1]), abs=3.0)


def test_curation_survives_reextraction(tmp_path):
    """Manual profile + excluded frame, then a frame file changes: extraction re-runs and keeps both."""
    series = _render(np.linspace(0, 1.2, 8), seed=2)
    truth = series.truth
    d = _write(tmp_path / "e", series.frames)
    scale = 1.25  # the person's profile is deliberately taller than the truth: its volume tells it was used
    set_manual_profile(d, 3, _truth_profile_m(truth, 3, scale), by="tester")
    exclude_frame(d, 5, "out_of_focus", "blurred", by="tester")
    cur_bytes = (d / "curation.json").read_bytes()
    out = run_experiment(d, ["fit"])
    assert out.status == "ok", out.error

    def check():
        ds = xr.load_dataset(d / "results" / "extraction.nc", engine="h5netcdf")
        assert str(ds["profile_source"].values[3]) == "manual"
        assert (ds["profile_source"].values[[0, 1, 2, 4, 5, 6, 7]] == "auto").all()
        assert ds["volume"].values[3] == pytest.approx(scale * truth["volume"].values[3], rel=0.02, abs=0)
        assert ds["volume"].values[4] == pytest.approx(truth["volume"].values[4], rel=0.02, abs=0)
        fits = json.loads((d / "results" / "fits.json").read_text())
        assert fits["n_excluded"] == 1 and fits["n_kept"] == 7
        fnc = xr.load_dataset(d / "results" / "fits.nc", engine="h5netcdf")
        assert not bool(fnc["kept"].values[5]) and str(fnc["exclusion_reason"].values[5]) == "out_of_focus"
        return ds

    before = check()
    # the report shows the person's decisions and draws the manual profile in red over its frame
    assert run_experiment(d, ["report"]).status == "ok"
    html = (d / "results" / "report.html").read_text()
    for text in ("Quality", "Curation", "out_of_focus", "blurred", "Frames and traced profiles", "Volume ratio",
                 "Rim pre-stretch", "Instantaneous permeability", "Parameters", "Software and parameters"):
        assert text in html, text
    # a frame file changes (re-exported with other noise): process must run again
    frame7 = _render(np.linspace(0, 1.2, 8), seed=99).frames[7]
    tifffile.imwrite(d / "frames" / "frame_007.tif", frame7)
    again = run_experiment(d, ["fit"])
    assert again.status == "ok", again.error
    assert again.step("process").status == "done" and again.step("fit").status == "done"
    after = check()
    assert after["volume"].values[7] != before["volume"].values[7]  # really re-extracted
    # extraction never writes the curation: same bytes, no new revision in the history
    assert (d / "curation.json").read_bytes() == cur_bytes
    assert load_curation(d).revision == 2
    assert len(list((d / ".curation-history").iterdir())) == 1
    # nothing changed: everything is skipped
    third = run_experiment(d, ["fit"])
    assert [s.status for s in third.steps] == ["skipped", "skipped"]


def test_priors_in_the_curation_guide_the_process_step(tmp_path):
    """A decoy membrane fools the tracker on one frame; a prior there (curation.json) fixes it on every run.

    Frame 3 jumps from vtilde 0.2 to 0.8 and carries a second dark arc at vtilde 0.2
    (where the previous frame's trace leads): the automatic trace follows the decoy.  The
    person's points on the true membrane, saved as a prior, make ``process`` trace the
    truth; the step re-runs when the prior is added and removed, and is skipped otherwise.
    """
    vt = np.array([0.0, 0.1, 0.2, 0.8, 0.9, 1.0])
    series = _render(vt, seed=2)
    decoy = _render(np.where(np.arange(vt.size) == 3, 0.2, vt), seed=2)  # same noise: only the dome differs
    frames = series.frames.astype(float)
    frames[3] *= np.minimum(decoy.frames[3] / np.maximum(series.frames[3].astype(float), 1.0), 1.0)
    truth = series.truth
    d = _write(tmp_path / "p", frames.astype(series.frames.dtype))
    true_v3 = float(truth["volume"].values[3])

    def volumes():
        return xr.load_dataset(d / "results" / "extraction.nc", engine="h5netcdf")

    assert run_experiment(d, ["process"]).status == "ok"
    auto = volumes()
    assert auto["volume"].values[3] < 0.5 * true_v3  # the tracker followed the decoy
    assert auto.attrs["prior_frames"] == "none"
    set_prior(d, 3, _truth_profile_m(truth, 3)[::8], by="tester")
    out = run_experiment(d, ["process"])
    assert out.step("process").status == "done" and out.step("process").summary["n_priors"] == 1
    guided = volumes()
    assert list(np.atleast_1d(guided.attrs["prior_frames"])) == [3]
    assert guided["volume"].values[3] == pytest.approx(true_v3, rel=0.02, abs=0)
    assert str(guided["profile_source"].values[3]) == "auto"  # a prior guides; it does not replace the trace
    np.testing.assert_allclose(guided["volume"].values[[1, 2, 4, 5]], truth["volume"].values[[1, 2, 4, 5]], rtol=0.03)
    # unchanged curation: skipped; the prior removed: re-run, back to the automatic result
    assert run_experiment(d, ["process"]).step("process").status == "skipped"
    remove_prior(d, 3)
    assert run_experiment(d, ["process"]).step("process").status == "done"
    np.testing.assert_allclose(volumes()["volume"].values, auto["volume"].values)


def test_priors_outside_the_chamber_regions_are_bad_input(tmp_path):
    series = _render(np.linspace(0, 0.5, 3), seed=8)
    w = SHAPE[1]
    regions = (f'chamber_regions = [{{name = "L", rows = [0, {SHAPE[0]}], cols = [0, {w // 2}]}}, '
               f'{{name = "R", rows = [0, {SHAPE[0]}], cols = [{w // 2}, {w}]}}]\n')
    d = _write(tmp_path / "r", series.frames, extra=regions)
    set_prior(d, 1, _truth_profile_m(series.truth, 1), chamber="X")
    with pytest.raises(FramesError, match=r"prior of frame 1: chamber 'X' is not one of the chamber regions"):
        from osmobulge.experiments.runs import process_experiment

        process_experiment(load_experiment(d), tmp_path / "out")
    set_prior(d, 9, _truth_profile_m(series.truth, 1))
    with pytest.raises(FramesError, match=r"priors of frames \[9\]: no such frame"):
        process_experiment(load_experiment(d), tmp_path / "out")


def test_frame_strip_draws_the_traces_on_the_membrane(tmp_path):
    """The strip's lines are the extraction's profile_col/row, and they lie on the dark membrane band."""
    import matplotlib

    matplotlib.use("Agg")
    from osmobulge.experiments.report import plot_frame_strip

    series = _render(np.linspace(0, 1.2, 6), seed=7)
    d = _write(tmp_path / "s", series.frames)
    set_manual_profile(d, 2, _truth_profile_m(series.truth, 2), by="tester")
    assert run_experiment(d, ["process"]).status == "ok"
    ds = xr.load_dataset(d / "results" / "extraction.nc", engine="h5netcdf")
    fig = plot_frame_strip(load_experiment(d), ds, n=6)
    for i, ax in enumerate(fig.axes):
        (line,) = ax.get_lines()
        np.testing.assert_allclose(line.get_xdata(), ds["profile_col"].values[i])
        np.testing.assert_allclose(line.get_ydata(), ds["profile_row"].values[i])
        assert line.get_color() == ("#ff3b30" if i == 2 else "#00d0ff")  # manual in red
        img = np.asarray(ax.get_images()[0].get_array())
        c = np.clip(np.round(line.get_xdata()).astype(int), 0, SHAPE[1] - 1)
        med = [float(np.median(img[np.clip(np.round(line.get_ydata() + shift).astype(int), 0, SHAPE[0] - 1), c]))
               for shift in (0, -5, 5)]
        # the line is on the dark membrane band; 5 px above or below it is bright liquid
        assert med[0] < 0.8 * min(med[1:]), (i, med)
    matplotlib.pyplot.close(fig)


def test_chamber_regions_stack_along_chamber(tmp_path):
    """One field holding two chambers: each region is extracted on its own and fitted together."""
    left, right = _render(np.linspace(0, 1.2, 6), seed=3), _render(np.linspace(0, 0.6, 6), seed=4)
    field = np.concatenate([left.frames, right.frames], axis=2)
    w = SHAPE[1]
    regions = (f'chamber_regions = [{{name = "L", rows = [0, {SHAPE[0]}], cols = [0, {w}]}}, '
               f'{{name = "R", rows = [0, {SHAPE[0]}], cols = [{w}, {2 * w}]}}]\n')
    d = _write(tmp_path / "two", field, extra=regions)
    out = run_experiment(d, ["report"])
    assert out.status == "ok", out.error
    assert out.step("process").summary["n_chambers"] == 2
    ds = xr.load_dataset(d / "results" / "extraction.nc", engine="h5netcdf")
    assert list(ds["chamber"].values) == ["L", "R"] and ds["volume"].dims == ("time", "chamber")
    np.testing.assert_allclose(ds["volume"].sel(chamber="L").values[1:], left.truth["volume"].values[1:], rtol=0.02)
    np.testing.assert_allclose(ds["volume"].sel(chamber="R").values[1:], right.truth["volume"].values[1:], rtol=0.03)
    # profile columns are in the field's pixels: the right chamber's axis is w px further right
    axis_r = float(np.nanmean(ds["profile_col"].sel(chamber="R").values[-1]))
    assert axis_r == pytest.approx(w + float(right.truth["axis_x"].values[-1]), abs=3.0)
    fits = json.loads((d / "results" / "fits.json").read_text())
    assert fits["chambers"] == ["exp/L", "exp/R"]
    html = (d / "results" / "report.html").read_text()
    assert "frame strip unavailable" not in html and html.count("data:image/png;base64,") >= 3


def test_glob_subset_and_times_from_files(tmp_path):
    """A glob picking some files of a folder; timestamps = "files" from each file's DateTime tag."""
    from osmobulge.imaging.io import write_series

    series = _render(np.linspace(0, 0.5, 5), seed=5)
    d = tmp_path / "g"
    t = np.array([0.0, 700.0, 1300.0, 2000.0, 2600.0])
    write_series(series.frames, d / "frames", fmt="tiff-folder", pixel_size=P, timestamps=t)
    names = sorted(p.name for p in (d / "frames").iterdir())
    # another series' frame in the same folder (taken earlier): not picked by the glob, must not shift the times
    tifffile.imwrite(d / "frames" / "other-chamber.tif", series.frames[0], datetime="2023:12:31 08:00:00")
    (d / "experiment.toml").write_text(
        _toml("g").replace('frames = "frames/*.tif"', f'frames = "frames/{names[0][:3]}*.tif"')
        .replace("frame_interval_min = 10.0", 'timestamps = "files"'))
    exp = load_experiment(d)
    assert len(exp.frame_files()) == 5
    ef = open_experiment_frames(exp)
    assert ef.frames.shape == (5, *SHAPE) and ef.pixel_size == pytest.approx(P, rel=1e-6, abs=0)
    np.testing.assert_allclose(ef.times, t, atol=1e-3)
    np.testing.assert_array_equal(np.asarray(ef.frames[2]), series.frames[2])


def test_frames_in_conflict_with_the_toml_are_bad_input(tmp_path):
    """The files say 2.5 um/px, experiment.toml 2 um/px: exit code 2, named in the error, nothing written."""
    from osmobulge.imaging.io import write_series

    series = _render(np.linspace(0, 0.5, 4), seed=6)
    d = tmp_path / "c"
    write_series(series.frames, d / "frames", fmt="tiff-folder", pixel_size=2.5e-6, timestamps=np.arange(4) * DT)
    (d / "experiment.toml").write_text(_toml("c"))
    with pytest.raises(FramesError, match="pixel size"):
        open_experiment_frames(load_experiment(d))
    res = run_batch([d], ["process"], scheduler="serial")
    assert res.exit_code == EXIT_BAD_INPUT and res.outcomes[0].status == "invalid"
    assert "pixel size" in res.outcomes[0].error
    assert not (d / "results" / "extraction.nc").exists()
    assert read_state(d)["steps"]["process"]["status"] == "failed"


def test_a_later_file_of_a_split_series_with_reference_frame(tmp_path):
    """[imaging] reference_frame: the day-2 frames start bulged; the chamber is found in day 1's flat frame."""
    series = _render(np.linspace(0, 1.2, 8), seed=3)
    whole = _write(tmp_path / "whole", series.frames)
    assert run_experiment(whole, ["process"]).status == "ok"
    later = _write(tmp_path / "day2", series.frames[4:], name="day2", extra='reference_frame = "../flat.tif"\n')
    tifffile.imwrite(tmp_path / "flat.tif", series.frames[0])
    out = run_experiment(later, ["process"])
    assert out.status == "ok", out.error
    ds = xr.load_dataset(later / "results" / "extraction.nc", engine="h5netcdf")
    ref = xr.load_dataset(whole / "results" / "extraction.nc", engine="h5netcdf")
    assert (ds["flag"].values == "ok").all() and ds.attrs["reference_frame"] == "../flat.tif"
    np.testing.assert_allclose(ds["volume"].values, series.truth["volume"].values[4:], rtol=0.02, atol=0)
    np.testing.assert_allclose(ds["volume"].values, ref["volume"].values[4:], rtol=5e-3, atol=0)
    np.testing.assert_allclose(ds["rim_radius"].values, series.truth["rim_radius"].values[4:], rtol=0, atol=1e-6)
    # the fit starts from the state measured at the file's first frame (its clock starts late): v0 = that V/V0
    from osmobulge.experiments.metadata import load_experiment as load
    from osmobulge.experiments.runs import observations_from_extraction

    (obs,) = observations_from_extraction(ds, load(later))
    assert obs.attrs["v0"] == pytest.approx(float(ds["volume_ratio"].values[0]), rel=1e-12, abs=0)
    assert obs["time"].values[0] == 0.0 and obs.attrs["v0"] > 1.2
    assert "v0" not in observations_from_extraction(ref, load(whole))[0].attrs
    # up to date until the reference file itself changes
    assert run_experiment(later, ["process"]).steps[0].status == "skipped"
    tifffile.imwrite(tmp_path / "flat.tif", series.frames[0] + np.uint16(1))  # the same flat frame, other bytes
    assert run_experiment(later, ["process"]).steps[0].status == "done"
    # without it the later file is measured with a warning naming the option; a missing reference is an error
    bare = _write(tmp_path / "bare", series.frames[4:], name="bare")
    with pytest.warns(UserWarning, match="needs reference_frame="):
        run_experiment(bare, ["process"])
    gone = _write(tmp_path / "gone", series.frames[4:], name="gone", extra='reference_frame = "nope.tif"\n')
    res = run_experiment(gone, ["process"])
    assert res.status != "ok" and "no such file" in res.error
    for bad, why in (('""', "is empty"), ('"../day2"', "no such file")):  # a folder is not a frame file
        d = _write(tmp_path / f"bad{len(why)}", series.frames[4:], name="bad", extra=f"reference_frame = {bad}\n")
        res = run_experiment(d, ["process"])
        assert res.status != "ok" and why in res.error, res.error
    # a reference of another field of view is refused, also when a chamber region would crop both alike
    tifffile.imwrite(tmp_path / "big.tif", np.pad(series.frames[0], 20, mode="edge"))
    region = '\nchamber_regions = [{ name = "c", rows = [0, 160], cols = [0, 220] }]\n'
    d = _write(tmp_path / "big", series.frames[4:], name="big", extra='reference_frame = "../big.tif"' + region)
    res = run_experiment(d, ["process"])
    assert res.status == "invalid" and "one field of view" in res.error, (res.status, res.error)
    (tmp_path / "notes.tif").write_text("not an image")  # a file named like one
    d = _write(tmp_path / "junk", series.frames[4:], name="junk", extra='reference_frame = "../notes.tif"\n')
    res = run_experiment(d, ["process"])
    assert res.status == "invalid" and "reference_frame" in res.error, (res.status, res.error)


def test_a_rim_in_the_metadata_locates_the_chamber(tmp_path):
    """[imaging] rim_px: the process step passes it to extract (silhouette route, measured at the rim given)."""
    from osmobulge.imaging.looks import LOOKS
    from osmobulge.imaging.synthetic import render_series

    look = LOOKS["edge_dark"]
    s = render_series([0.0, 0.5, 1.0], chamber=CHAMBER, pixel_size=P, shape=(200, 260), times=np.arange(3) * DT,
                      optics=look.optics, nuisances=look.nuisances, seed=4)
    t = s.truth
    row, col, r = t.attrs["anchor_row"], t.attrs["anchor_col"], float(t["rim_radius"][0]) / P
    rim = f"rim_px = [{col - r + 1.0:.1f}, {row - 1.0:.1f}, {col + r:.1f}, {row + 1.0:.1f}]\n"
    d = _write(tmp_path / "rim", s.frames, name="rim", extra=rim)
    out = run_experiment(d, ["process"])
    assert out.status == "ok", out.error
    ds = xr.load_dataset(d / "results" / "extraction.nc", engine="h5netcdf")
    assert ds.attrs["tracer"] == "silhouette" and (ds["flag"].values == "ok").all()
    tol = np.maximum(0.03 * t["volume"].values, 0.5 * P * np.pi * t["rim_radius"].values ** 2)
    assert np.all(np.abs(ds["volume"].values - t["volume"].values) <= tol)
    assert np.all(np.abs(ds["rim_radius"].values - t["rim_radius"].values) <= 0.5 * P)
    for bad, why in (("rim_px = [1, 2, 3]", "four finite numbers"),
                     ('rim_px = [1, 2, 3, 4]\nchamber_regions = [{ name = "c", rows = [0, 160], cols = [0, 220] }]',
                      "rim_px and chamber_regions")):
        e = _write(tmp_path / f"bad{len(why)}", s.frames, name="bad", extra=bad + "\n")
        res = run_experiment(e, ["process"])
        assert res.status == "invalid" and why in res.error, (res.status, res.error)


def test_a_rim_saved_in_the_curation_is_the_one_used(tmp_path):
    """curation.json's rim (what napari's Profile picker saves) replaces [imaging] rim_px: a rim in the water
    fails the chamber search there, the chamber's own measures the truth, and changing it re-runs the step."""
    from osmobulge.experiments.curation import set_rim
    from osmobulge.imaging.looks import LOOKS
    from osmobulge.imaging.synthetic import render_series

    look = LOOKS["edge_dark"]
    s = render_series([0.0, 0.5, 1.0], chamber=CHAMBER, pixel_size=P, shape=(200, 260), times=np.arange(3) * DT,
                      optics=look.optics, nuisances=look.nuisances, seed=4)
    t = s.truth
    row, col, r = t.attrs["anchor_row"], t.attrs["anchor_col"], float(t["rim_radius"][0]) / P
    good = [col - r + 1.0, row - 1.0, col + r, row + 1.0]
    water = [good[0], good[1] - 40.0, good[2], good[3] - 40.0]
    d = _write(tmp_path / "rim", s.frames, name="rim",
               extra="rim_px = [{:.1f}, {:.1f}, {:.1f}, {:.1f}]\n".format(*good))
    set_rim(d, water)
    out = run_experiment(d, ["process"])
    assert out.status != "ok" and "given rim" in out.error, (out.status, out.error)
    set_rim(d, good, force=True)
    out = run_experiment(d, ["process"])
    assert out.status == "ok" and out.steps[0].status == "done", out.error
    ds = xr.load_dataset(d / "results" / "extraction.nc", engine="h5netcdf")
    assert ds.attrs["tracer"] == "silhouette" and (ds["flag"].values == "ok").all()
    tol = np.maximum(0.03 * t["volume"].values, 0.5 * P * np.pi * t["rim_radius"].values ** 2)
    assert np.all(np.abs(ds["volume"].values - t["volume"].values) <= tol)
    assert np.all(np.abs(ds["rim_radius"].values - t["rim_radius"].values) <= 0.5 * P)
    assert run_experiment(d, ["process"]).steps[0].status == "skipped"
    set_rim(d, [good[0] + 0.5, *good[1:]], force=True)
    assert run_experiment(d, ["process"]).steps[0].status == "done"
    # with chamber regions (here the curation's) the rim is refused: it locates one chamber in the whole field
    from osmobulge.experiments.curation import set_chamber_regions

    set_chamber_regions(d, [{"name": "c", "rows": [0, 200], "cols": [0, 260]}])
    res = run_experiment(d, ["process"])
    assert res.status == "invalid" and "rim (curation.json) and chamber regions" in res.error, res.error
