"""Curation: decisions beside the data, no silent overwrite, atomic writes, applied to datasets."""

import json
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import xarray as xr

from osmobulge.experiments.curation import (
    CURATION_FILE,
    HISTORY_DIR,
    REASONS,
    Curation,
    CurationConflict,
    apply_curation,
    curation_fingerprint,
    curation_summary,
    exclude_frame,
    include_frame,
    keep_flagged_frame,
    load_curation,
    remove_manual_profile,
    remove_prior,
    save_curation,
    set_chamber_regions,
    set_manual_profile,
    set_prior,
    set_rim,
    set_time_origin,
)

PTS = [[-200e-6, 0.0], [-100e-6, -120e-6], [100e-6, -120e-6], [200e-6, 0.0]]


def test_empty_and_round_trip(tmp_path):
    cur = load_curation(tmp_path)
    assert cur == Curation() and not (tmp_path / CURATION_FILE).exists()
    cur = exclude_frame(cur, 3, "delaminated", "membrane lifted at the left rim", by="ana")
    cur = set_manual_profile(cur, 5, PTS, by="ana")
    cur = set_time_origin(cur, 120.0)
    cur = set_chamber_regions(cur, [{"name": "left", "rows": [0, 100], "cols": [0, 50]}])
    cur = keep_flagged_frame(cur, 7, "tracer wrong, frame fine")
    saved = save_curation(tmp_path, cur)
    assert saved.revision == 1
    back = load_curation(tmp_path)
    assert back.decisions() == cur.decisions()
    assert back.excluded[3]["reason"] == "delaminated" and back.excluded[3]["by"] == "ana"
    assert back.manual_profiles[5]["source"] == "manual" and back.manual_profiles[5]["points"] == PTS
    assert [h["action"] for h in back.history] == ["exclude", "manual_profile", "time_origin", "chamber_regions",
                                                   "keep_flagged"]
    s = curation_summary(back)
    assert s["n_excluded"] == 1 and s["excluded_by_reason"] == {"delaminated": 1} and s["manual_frames"] == [5]


@pytest.mark.parametrize("reason", REASONS)
def test_reasons(reason):
    assert exclude_frame(Curation(), 0, reason).excluded[0]["reason"] == reason


@pytest.mark.parametrize(
    ("call", "exc", "match"),
    [
        (lambda c: exclude_frame(c, 1, "blurry"), ValueError, "reason = 'blurry': expected one of delaminated"),
        (lambda c: exclude_frame(c, -1, "other"), ValueError, "frame = -1"),
        (lambda c: exclude_frame(c, 1.0, "other"), ValueError, "frame = 1.0"),
        (lambda c: set_manual_profile(c, 1, [[0, 0], [1e-6, 1e-6], [2e-6, 1e-6]]), ValueError, "N >= 4"),
        (lambda c: set_manual_profile(c, 1, [[0, 0], [10, 5], [20, 5], [30, 0]]), ValueError, "expected metres"),
        (lambda c: set_time_origin(c, float("nan")), ValueError, "finite time in seconds"),
        (lambda c: set_chamber_regions(c, [{"rows": [5, 2], "cols": [0, 1]}]), ValueError, "start < stop"),
    ],
)
def test_bad_edits(call, exc, match):
    with pytest.raises(exc, match=match):
        call(Curation())


def test_nothing_overwritten_silently():
    cur = exclude_frame(Curation(), 2, "touching", "neighbour bulge")
    assert exclude_frame(cur, 2, "touching", "neighbour bulge") is cur  # same decision: no-op
    with pytest.raises(CurationConflict, match="already excluded"):
        exclude_frame(cur, 2, "fractured")
    assert exclude_frame(cur, 2, "fractured", force=True).excluded[2]["reason"] == "fractured"
    cur = set_manual_profile(cur, 4, PTS)
    with pytest.raises(CurationConflict, match="already has a manual profile"):
        set_manual_profile(cur, 4, np.array(PTS) * 1.1)
    cur = set_time_origin(cur, 60.0)
    with pytest.raises(CurationConflict, match="time origin is already 60"):
        set_time_origin(cur, 0.0)
    with pytest.raises(CurationConflict, match="was excluded"):
        keep_flagged_frame(cur, 2)
    cur = set_chamber_regions(cur, [{"name": "a", "rows": [0, 9], "cols": [0, 9]}])
    with pytest.raises(CurationConflict, match="regions were set before"):
        set_chamber_regions(cur, [{"name": "b", "rows": [0, 9], "cols": [0, 9]}])
    # explicit undo is allowed and logged
    cur = include_frame(remove_manual_profile(cur, 4), 2)
    assert 2 not in cur.excluded and 4 not in cur.manual_profiles
    assert cur.history[-1]["action"] == "include" and cur.history[-2]["action"] == "remove_manual_profile"


def test_concurrent_saves_conflict_and_history(tmp_path):
    a = load_curation(tmp_path)
    b = load_curation(tmp_path)
    save_curation(tmp_path, exclude_frame(a, 1, "other", "a's note"))
    with pytest.raises(CurationConflict, match="someone saved in between"):
        save_curation(tmp_path, exclude_frame(b, 2, "other"))
    # b reloads and redoes: both decisions survive
    b = exclude_frame(load_curation(tmp_path), 2, "other")
    saved = save_curation(tmp_path, b)
    assert saved.revision == 2 and set(load_curation(tmp_path).excluded) == {1, 2}
    backups = sorted(p.name for p in (tmp_path / HISTORY_DIR).iterdir())
    assert backups == ["curation.rev00001.json"]
    assert set(json.loads((tmp_path / HISTORY_DIR / backups[0]).read_text())["excluded"]) == {"1"}
    # forcing an old copy over the new file keeps the new one in the history
    save_curation(tmp_path, exclude_frame(a, 3, "other"), force=True)
    assert len(list((tmp_path / HISTORY_DIR).iterdir())) == 2


def test_edit_by_folder(tmp_path):
    cur = exclude_frame(tmp_path, 0, "out_of_focus")
    assert cur.revision == 1 and load_curation(tmp_path).excluded[0]["reason"] == "out_of_focus"
    with pytest.raises(CurationConflict):
        exclude_frame(tmp_path, 0, "other")
    assert load_curation(tmp_path).excluded[0]["reason"] == "out_of_focus"
    set_manual_profile(tmp_path, 1, PTS)
    assert load_curation(tmp_path).revision == 2
    with pytest.raises(TypeError, match="Curation or an experiment folder"):
        exclude_frame(42, 0, "other")


def test_corrupt_file_is_a_clear_error(tmp_path):
    (tmp_path / CURATION_FILE).write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON.*restore it"):
        load_curation(tmp_path)
    (tmp_path / CURATION_FILE).write_text(json.dumps({"excluded": {"1": {"reason": "bad"}}}))
    with pytest.raises(ValueError, match=r"excluded\[1\].reason = 'bad'"):
        load_curation(tmp_path)


def test_killed_writer_leaves_old_file_whole(tmp_path):
    """os.kill of a process in the middle of writing: the file is the old one or the new one, never half."""
    save_curation(tmp_path, exclude_frame(Curation(), 0, "other"))
    before = (tmp_path / CURATION_FILE).read_bytes()
    code = textwrap.dedent(f"""
        import os, sys, time
        from pathlib import Path
        import osmobulge.experiments._io as io
        from osmobulge.experiments.curation import load_curation, save_curation, set_manual_profile
        real = os.replace
        def slow_replace(src, dst):
            if str(dst).endswith("curation.json"):
                print("written", flush=True)
                time.sleep(30)  # killed here: the new content is in the tmp file, not yet moved
            real(src, dst)
        io.os.replace = slow_replace
        d = Path({str(tmp_path)!r})
        cur = load_curation(d)
        for i in range(1, 200):
            cur = set_manual_profile(cur, i, [[0, 0], [1e-4, 1e-4], [2e-4, 1e-4], [3e-4, 0]])
        save_curation(d, cur)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == "written\n"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(10)
    assert (tmp_path / CURATION_FILE).read_bytes() == before
    assert load_curation(tmp_path).revision == 1
    assert (tmp_path / HISTORY_DIR / "curation.rev00001.json").read_bytes() == before  # backup came first
    assert all(p.name.startswith(".") for p in tmp_path.iterdir() if p.name.endswith(".tmp"))


def _dataset(n=6):
    t = np.arange(n) * 900.0
    return xr.Dataset(
        {
            "volume": ("time", np.linspace(0, 1e-11, n), {"units": "m3"}),
            "flag": ("time", np.array(["ok", "ok", "delaminated", "ok", "ok", "ok"][:n])),
            "profile_source": ("time", np.array(["auto"] * n, dtype="<U6")),
        },
        coords={"time": ("time", t, {"units": "s"}), "frame": ("time", np.arange(n))},
    )


def test_apply_curation():
    ds = _dataset()
    cur = exclude_frame(Curation(), 4, "fractured", "crack at the pole")
    cur = keep_flagged_frame(cur, 2, "flag wrong")
    cur = set_time_origin(cur, 900.0)
    out = apply_curation(ds, cur)
    np.testing.assert_array_equal(out["excluded"].values, [0, 0, 0, 0, 1, 0])
    np.testing.assert_array_equal(out["kept"].values, [0, 1, 1, 1, 0, 1])  # frame 0 is before the origin
    assert out["exclusion_reason"].values[4] == "fractured"
    np.testing.assert_allclose(out["time"].values, ds["time"].values - 900.0)
    assert out.attrs["curation_hash"] == curation_fingerprint(cur)
    assert "kept" not in ds  # input untouched
    # automatic flags alone drop frames
    np.testing.assert_array_equal(apply_curation(ds, Curation())["kept"].values, [1, 1, 0, 1, 1, 1])


def test_apply_curation_requires_manual_profiles_used():
    cur = set_manual_profile(Curation(), 1, PTS)
    with pytest.raises(ValueError, match="re-run the process step"):
        apply_curation(_dataset(), cur)
    ds = _dataset()
    ds["profile_source"].values[1] = "manual"
    assert apply_curation(ds, cur)["kept"].values[1]


def test_fingerprint_parts():
    base = Curation()
    ex = exclude_frame(base, 1, "other")
    mp = set_manual_profile(base, 1, PTS)
    assert curation_fingerprint(ex, "extraction") == curation_fingerprint(base, "extraction")
    assert curation_fingerprint(ex, "fit") != curation_fingerprint(base, "fit")
    assert curation_fingerprint(mp, "extraction") != curation_fingerprint(base, "extraction")
    assert curation_fingerprint(mp, "fit") == curation_fingerprint(base, "fit")
    # who/when do not count
    assert curation_fingerprint(exclude_frame(base, 1, "other", by="x")) == curation_fingerprint(ex)
    with pytest.raises(ValueError, match="part = 'x'"):
        curation_fingerprint(base, "x")


def test_priors_round_trip_conflicts_and_history(tmp_path):
    cur = set_prior(Curation(), 2, PTS, by="ana")
    assert cur.priors[2]["points"] == PTS and cur.priors[2]["units"] == "m" and cur.priors[2]["by"] == "ana"
    assert set_prior(cur, 2, PTS) is cur  # same points: no-op
    with pytest.raises(CurationConflict, match="frame 2 already has a prior"):
        set_prior(cur, 2, np.array(PTS) * 1.1)
    moved = set_prior(cur, 2, np.array(PTS) * 1.1, force=True)
    np.testing.assert_allclose(moved.priors[2]["points"], np.array(PTS) * 1.1)
    # a prior is not a manual profile: the frame keeps its automatic trace
    assert not moved.manual_profiles and curation_summary(moved)["prior_frames"] == [2]
    saved = save_curation(tmp_path, set_prior(moved, 5, PTS, chamber="left"))
    back = load_curation(tmp_path)
    assert back.priors == saved.priors and back.priors[5]["chamber"] == "left"
    assert json.loads((tmp_path / CURATION_FILE).read_text())["priors"]["5"]["points"] == PTS
    assert [h["action"] for h in back.history] == ["prior", "prior", "prior"]
    # by folder: load, edit, save
    remove_prior(tmp_path, 2)
    back = load_curation(tmp_path)
    assert set(back.priors) == {5} and back.history[-1]["action"] == "remove_prior" and back.revision == 2
    assert remove_prior(back, 7) is back
    with pytest.raises(ValueError, match="N >= 4"):
        set_prior(back, 1, PTS[:3])
    with pytest.raises(ValueError, match="expected metres"):
        set_prior(back, 1, np.array(PTS) * 1e6)
    with pytest.raises(ValueError, match="frame = -1"):
        set_prior(back, -1, PTS)


def test_priors_in_file_validated_and_old_files_load(tmp_path):
    old = save_curation(tmp_path, exclude_frame(Curation(), 1, "other"))
    data = json.loads((tmp_path / CURATION_FILE).read_text())
    data.pop("priors")  # a file written before priors existed
    (tmp_path / CURATION_FILE).write_text(json.dumps(data))
    back = load_curation(tmp_path)
    assert back.priors == {} and back.decisions() == old.decisions()
    assert curation_fingerprint(back) == curation_fingerprint(old)
    data["priors"] = {"3": {"points": [[0.0, 0.0], [1.0, 1.0]]}}
    (tmp_path / CURATION_FILE).write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"priors\[3\].points"):
        load_curation(tmp_path)


def test_priors_count_for_extraction_not_fit():
    base = Curation()
    pr = set_prior(base, 1, PTS)
    assert curation_fingerprint(pr, "extraction") != curation_fingerprint(base, "extraction")
    assert curation_fingerprint(pr, "fit") == curation_fingerprint(base, "fit")
    # the same points as a manual profile are another decision
    assert curation_fingerprint(pr, "extraction") != curation_fingerprint(set_manual_profile(base, 1, PTS),
                                                                          "extraction")
    # without priors the hash is the one of a curation written before priors existed
    assert "priors" not in base.decisions() and "priors" in pr.decisions()


def test_the_rim_is_kept_checked_and_not_overwritten_silently(tmp_path):
    """set_rim: saved and read back, part of the extraction's fingerprint (a changed rim re-runs the process
    step), refused when malformed, replaced or cleared only with force; curations without one keep their
    fingerprint (files written before the rim existed)."""
    plain = exclude_frame(Curation(), 2, "other")
    assert "rim" not in plain.decisions() and curation_summary(plain)["rim_px"] is None
    cur = set_rim(tmp_path, [40.5, 100.0, 440.0, 101.5], by="ana")
    assert cur.rim == (40.5, 100.0, 440.0, 101.5)
    back = load_curation(tmp_path)
    assert back.rim == cur.rim and back.history[-1]["action"] == "rim" and back.history[-1]["by"] == "ana"
    assert curation_summary(back)["rim_px"] == [40.5, 100.0, 440.0, 101.5]
    assert json.loads((tmp_path / CURATION_FILE).read_text())["rim"] == [40.5, 100.0, 440.0, 101.5]
    fp = curation_fingerprint(back, "extraction")
    assert fp != curation_fingerprint(Curation(), "extraction")
    assert curation_fingerprint(back, "fit") == curation_fingerprint(Curation(), "fit")
    assert set_rim(back, [40.5, 100.0, 440.0, 101.5]) is back  # (the same rim: no change)
    with pytest.raises(CurationConflict, match="rim was set before"):
        set_rim(back, [41.0, 100.0, 440.0, 101.5])
    with pytest.raises(CurationConflict, match="force=True to clear"):
        set_rim(back, None)
    moved = set_rim(back, [41.0, 100.0, 440.0, 101.5], force=True)
    assert curation_fingerprint(moved, "extraction") != fp
    assert set_rim(moved, None, force=True).rim is None
    for bad, why in (([1.0, 2.0, 3.0], "expected the two ends"), ([0.0, 0.0, 30.0, 0.0], "30 px apart"),
                     ([0.0, np.nan, 100.0, 0.0], "finite"), ([-5.0, 0.0, 100.0, 0.0], "finite")):
        with pytest.raises(ValueError, match=why):
            set_rim(Curation(), bad)
    # a hand-edited file with a bad rim is refused on loading, not used
    data = json.loads((tmp_path / CURATION_FILE).read_text())
    data["rim"] = [1, 2, 3]
    (tmp_path / CURATION_FILE).write_text(json.dumps(data))
    with pytest.raises(ValueError, match="rim"):
        load_curation(tmp_path)
