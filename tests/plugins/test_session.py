"""CurationSession: the Qt-free state behind the widgets, on a synthetic experiment folder."""

import json

import numpy as np
import pytest
from plugin_helpers import BAD, CHAMBER, INTERVAL_MIN, PIXEL, truth_midline_rc

from osmobulge.experiments.curation import CurationConflict, load_curation
from osmobulge.plugins._session import CurationSession

V0 = np.pi * CHAMBER[0] ** 2 * CHAMBER[1]


def clicks(truth, frame, n=12, jitter=2.0, seed=0):
    """n clicks from rim to rim near the true midline, in random order."""
    tr = truth_midline_rc(truth, frame)
    idx = np.linspace(0, len(tr) - 1, n).astype(int)
    rng = np.random.default_rng(seed)
    pts = tr[idx] + rng.uniform(-jitter, jitter, size=(n, 2))
    return pts[rng.permutation(n)]


def test_session_opens_the_folder(experiment):
    folder, truth = experiment
    s = CurationSession(folder)
    assert s.n_frames == truth.sizes["time"]
    assert s.shape == tuple(truth.attrs.get("shape", s.shape))
    assert s.pixel_size == pytest.approx(PIXEL, rel=1e-9, abs=0)
    np.testing.assert_allclose(s.times, np.arange(s.n_frames) * INTERVAL_MIN * 60)
    assert s.chamber_volume == pytest.approx(V0, rel=1e-9, abs=0)
    np.testing.assert_array_equal(s.frame(2), np.asarray(s.frames[2]))
    assert s.curation.revision == 0 and not s.picks
    with pytest.raises(ValueError, match=r"frame = 99: expected an integer in \[0, 5\]"):
        s.frame(99)


def test_pick_accept_saves_manual_profile_with_its_volume(experiment):
    folder, truth = experiment
    s = CurationSession(folder)
    fit = s.set_picks(BAD, clicks(truth, BAD))
    assert fit, fit.message
    true_v = float(truth["volume"].values[BAD])
    # rim placed from the picked ends: within 2 % or a 0.5 px layer over the well
    tol = max(0.02 * true_v, np.pi * CHAMBER[0] ** 2 * 0.5 * PIXEL)
    assert abs(fit.volume - true_v) < tol
    assert fit.area == pytest.approx(float(truth["area_ratio"].values[BAD]) * np.pi * CHAMBER[0] ** 2, rel=0.03, abs=0)
    s.accept(BAD, by="tester")
    on_disk = load_curation(folder)
    prof = on_disk.manual_profiles[BAD]
    assert prof["source"] == "manual" and prof["units"] == "m" and prof["by"] == "tester"
    np.testing.assert_allclose(np.asarray(prof["points"]), fit.points_rc[:, ::-1] * PIXEL)
    # the file is valid JSON written in one piece, with the history
    assert json.loads((folder / "curation.json").read_text())["revision"] == 1
    # V/V0 of that frame now comes from the manual profile
    vs = s.volume_series()
    assert vs["volume_ratio"].values[BAD] == pytest.approx(1 + fit.volume / V0)
    assert str(vs["profile_source"].values[BAD]) == "manual" and bool(vs["kept"].values[BAD])


def test_reopen_finds_the_manual_profile(experiment):
    folder, truth = experiment
    s = CurationSession(folder)
    s.set_picks(BAD, clicks(truth, BAD))
    fit = s.accept(BAD)
    s.close()
    s2 = CurationSession(folder)
    assert s2.is_manual(BAD)
    np.testing.assert_allclose(s2.picks[BAD], fit.points_rc, atol=1e-9)
    assert s2.manual_fit(BAD).volume == pytest.approx(fit.volume, rel=1e-9, abs=0)


def test_exclude_include_time_origin_regions(experiment):
    folder, _ = experiment
    s = CurationSession(folder)
    seen = []
    s.listeners.append(lambda what, frame: seen.append((what, frame)))
    s.exclude(1, "out_of_focus", "blurred")
    vs = s.volume_series()
    assert bool(vs["excluded"].values[1]) and not bool(vs["kept"].values[1])
    assert str(vs["exclusion_reason"].values[1]) == "out_of_focus"
    assert load_curation(folder).excluded[1]["note"] == "blurred"
    s.exclude(1, "other")  # changing the reason in the GUI is an explicit decision
    assert load_curation(folder).excluded[1]["reason"] == "other"
    s.include(1)
    assert 1 not in load_curation(folder).excluded
    s.set_time_origin_frame(2)
    vs = s.volume_series()
    np.testing.assert_allclose(vs["time"].values, (np.arange(s.n_frames) - 2) * INTERVAL_MIN * 60)
    assert not vs["kept"].values[:2].any()
    regions = [{"name": "left", "rows": [0, 200], "cols": [0, 120]}]
    s.set_chamber_regions(regions)
    assert s.chamber_regions() == regions == [dict(r) for r in load_curation(folder).chamber_regions]
    assert [w for w, _ in seen] == ["excluded", "excluded", "excluded", "time_origin", "regions"]
    with pytest.raises(ValueError, match="reason"):
        s.exclude(0, "bored")


def test_concurrent_save_is_refused(experiment):
    folder, _ = experiment
    a, b = CurationSession(folder), CurationSession(folder)
    a.exclude(0, "other")
    with pytest.raises(CurationConflict, match="revision"):
        b.exclude(4, "other")
    assert 4 not in load_curation(folder).excluded


def test_accept_without_a_profile_raises(experiment):
    folder, _ = experiment
    s = CurationSession(folder)
    s.set_picks(2, [[100.0, 100.0], [101.0, 120.0]], snap=False)
    with pytest.raises(ValueError, match="no profile to accept"):
        s.accept(2)
    assert not (folder / "curation.json").exists()


def test_points_export_import_round_trip(experiment, tmp_path):
    folder, truth = experiment
    s = CurationSession(folder)
    s.set_picks(2, clicks(truth, 2, seed=1))
    s.set_picks(4, clicks(truth, 4, seed=2))
    for name in ("p.csv", "p.zip"):
        path = s.export_points(tmp_path / name)
        s2 = CurationSession(folder)
        assert s2.import_points(path) == [2, 4]
        for f in (2, 4):
            np.testing.assert_allclose(s2.picks[f], s.picks[f], atol=1e-4)
            assert s2.fit(f).volume == pytest.approx(s.fit(f).volume, rel=1e-5, abs=0)


@pytest.mark.slow
def test_semi_automatic_tracing_uses_the_picks_as_priors(experiment):
    from osmobulge.experiments.runs import run_experiment

    folder, truth = experiment
    run_experiment(folder, ["process"], errors="raise")
    on_disk = (folder / "results" / "extraction.nc").read_bytes()
    s = CurationSession(folder)
    s.set_picks(1, clicks(truth, 1, seed=4))
    s.set_picks(4, clicks(truth, 4, seed=5))
    seen = []
    s.listeners.append(lambda what, frame: seen.append(what))
    ds = s.trace_with_priors()
    assert list(np.atleast_1d(ds.attrs["prior_frames"])) == [1, 4]
    assert "extraction" in seen and s.extraction is ds
    assert (folder / "results" / "extraction.nc").read_bytes() == on_disk  # a preview: results untouched
    # the frames between and around the picks are traced onto the membrane (sub-pixel)
    for f in (1, 2, 3, 4, 5):
        prof = s.auto_profile_rc(f)
        mid = truth_midline_rc(truth, f)
        d = np.min(np.hypot(prof[:, None, 0] - mid[None, :, 0], prof[:, None, 1] - mid[None, :, 1]), axis=1)
        assert np.sqrt(np.mean(d**2)) < 0.5, (f, np.sqrt(np.mean(d**2)))
    with pytest.raises(ValueError, match="at least one frame"):
        CurationSession(folder).trace_with_priors()
    assert load_curation(folder).revision == 0  # the preview saved nothing


def test_picks_kept_as_priors_are_used_by_the_next_process(experiment):
    """trace_with_priors(save=True): the picks go to curation.json and `process` traces with them."""
    import xarray as xr

    from osmobulge.experiments.runs import run_experiment

    folder, truth = experiment
    s = CurationSession(folder)
    s.set_picks(1, clicks(truth, 1, seed=4))
    s.set_picks(4, clicks(truth, 4, seed=5))
    s.set_picks(5, clicks(truth, 5, n=3, seed=6))  # too few for a prior: left out
    s.accept(4, by="tester")  # a manual profile stands for its frame: not stored again as a prior
    ds = s.trace_with_priors(save=True, by="tester")
    cur = load_curation(folder)
    assert sorted(cur.priors) == [1] and s.is_prior(1) and not s.is_prior(4)
    assert cur.priors[1]["by"] == "tester" and cur.history[-1]["action"] == "prior"
    np.testing.assert_allclose(np.asarray(cur.priors[1]["points"]), s.picks[1][:, ::-1] * PIXEL)
    on_disk = xr.load_dataset(folder / "results" / "extraction.nc", engine="h5netcdf")
    assert list(np.atleast_1d(on_disk.attrs["prior_frames"])) == [1] == list(np.atleast_1d(ds.attrs["prior_frames"]))
    assert str(on_disk["profile_source"].values[4]) == "manual"
    np.testing.assert_allclose(ds["volume"].values, on_disk["volume"].values)
    # a plain `osmobulge process` later: nothing changed, the step is skipped and keeps the guided result
    assert run_experiment(folder, ["process"]).step("process").status == "skipped"
    # a new session shows the saved prior as picks; named frames need >= 4 points
    s2 = CurationSession(folder)
    np.testing.assert_allclose(s2.picks[1], s.picks[1])
    with pytest.raises(ValueError, match=r"frames = \[5\]: fewer than 4 picked points"):
        s.keep_as_priors([5])
    s2.remove_prior(1)
    assert not load_curation(folder).priors


def test_module_entry_point_help(capsys):
    from osmobulge.plugins.__main__ import main

    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    assert "experiment folder" in capsys.readouterr().out


def test_logic_modules_import_no_qt():
    """The logic behind the widgets runs with no Qt and no napari at all."""
    import subprocess
    import sys

    code = ("import sys; import osmobulge.plugins._session, osmobulge.plugins._logic, osmobulge.plugins.roi, "
            "osmobulge.plugins._reader; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('qtpy', 'PyQt5', 'PyQt6', 'PySide6', 'napari', "
            "'magicgui', 'vispy')]; print(bad); sys.exit(1 if bad else 0)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
