"""The demo campaign: synthetic frames -> extraction -> fits -> reports recover the truth."""

import json

import pytest


@pytest.mark.slow
def test_demo_campaign_files(tmp_path):
    """The written campaign: five conditions, valid experiment.toml, truth, the demo's curation."""
    import numpy as np
    import xarray as xr

    from osmobulge.experiments.curation import load_curation
    from osmobulge.experiments.demo import CONDITIONS, DEMO_TIMES, write_demo_campaign
    from osmobulge.experiments.metadata import load_experiment

    folders = write_demo_campaign(tmp_path, chambers=1)
    assert [f.parent.name for f in folders] == list(CONDITIONS)
    for f in folders:
        exp = load_experiment(f)
        material, a, h, l0, c0 = CONDITIONS[exp.condition]
        assert exp.material_name == material and exp.chamber.radius == pytest.approx(a)
        assert exp.chamber.concentration == pytest.approx(c0) and exp.chamber.thickness == pytest.approx(l0)
        truth = xr.load_dataset(f / "truth.nc", engine="h5netcdf")
        assert len(exp.frame_files()) == truth.sizes["time"] == len(exp.imaging.timestamps)
        np.testing.assert_allclose(exp.imaging.timestamps, truth["time"].values[: len(exp.imaging.timestamps)])
        assert truth.sizes["time"] <= DEMO_TIMES.size
    cur = load_curation(folders[0])
    assert cur.excluded[20]["reason"] == "delaminated"
    truth = xr.load_dataset(folders[0] / "truth.nc", engine="h5netcdf")
    assert str(truth["flag"].values[20]) == "delaminated"
    meta = json.loads((tmp_path / "truth.json").read_text())
    assert meta["PDMS"]["P_w1"] == pytest.approx(1.99e-12, rel=0.01, abs=0)  # main text Table 3


@pytest.mark.slow
def test_demo_recovers_the_truth(tmp_path):
    pytest.importorskip("osmobulge.imaging.extract", reason="the extraction (issue 4) is needed for the demo")
    from osmobulge.experiments.demo import run_demo

    summary = run_demo(tmp_path / "demo", chambers=1, workers=2)
    assert summary["exit_code"] == 0, summary["failed"]
    assert summary["n_experiments"] == 5
    rec = {r["material"]: r for r in summary["recovery"]}
    assert set(rec) == {"PDMS", "PEO_PDMS"}
    for r in rec.values():  # issue 5: P_w(1) within 5 %
        assert abs(r["rel_error"]) < 0.05, r
    assert (tmp_path / "demo" / "campaign" / "report.html").exists()
    assert json.loads((tmp_path / "demo" / "demo-summary.json").read_text())["exit_code"] == 0
    # the demo's own curation survived the processing, and the excluded frame is not fitted
    fits = json.loads((tmp_path / "demo" / "reference" / "chamber-1" / "results" / "fits.json").read_text())
    assert fits["n_excluded"] == 1
    # a second run recomputes nothing
    again = run_demo(tmp_path / "demo", chambers=1, workers=2)
    assert again["exit_code"] == 0 and again["seconds_batch"] < summary["seconds_batch"]
