"""Runs: content-hash skipping, resume after a crash, atomic outputs, batches (serial, pool, dask)."""

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from osmobulge.experiments import runs
from osmobulge.experiments.curation import exclude_frame, set_manual_profile
from osmobulge.experiments.metadata import write_template
from osmobulge.experiments.runs import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_OK,
    Step,
    atomic_path,
    experiment_status,
    read_state,
    run_batch,
    run_experiment,
)

# ---- a small real pipeline: sums of the frame bytes, then a derived number --------------------------
CALLS: list = []


def _fp_sum(exp, options):
    from osmobulge.experiments.curation import curation_fingerprint, load_curation

    return {"frames": runs.frames_fingerprint(exp), "toml": exp.raw.get("chamber"),
            "cur": curation_fingerprint(load_curation(exp.path), "extraction")}


def _sum(exp, results, options):
    CALLS.append(("sum", exp.name))
    if (exp.path / "FAIL").exists():
        raise RuntimeError("injected failure")
    total = sum(int(np.frombuffer(f.read_bytes(), np.uint8).sum()) for f in exp.frame_files())
    runs.atomic_write_text(results / "sum.json", json.dumps({"total": total}))
    return {"total": total}


def _fp_scale(exp, options):
    return {"radius": exp.raw["chamber"]["radius_um"], "scale": options.get("scale", 1)}


def _scale(exp, results, options):
    CALLS.append(("scale", exp.name))
    total = json.loads((results / "sum.json").read_text())["total"]
    value = total * exp.chamber.radius * options.get("scale", 1)
    runs.atomic_write_text(results / "scaled.json", json.dumps({"value": value}))
    return {"value": value}


PIPE = (Step("process", ("sum.json",), (), _fp_sum, _sum),
        Step("fit", ("scaled.json",), ("process",), _fp_scale, _scale))


def _make(root: Path, name: str, seed: int) -> Path:
    d = root / name
    (d / "frames").mkdir(parents=True)
    rng = np.random.default_rng(seed)
    for i in range(3):
        (d / "frames" / f"f{i}.tif").write_bytes(rng.integers(0, 255, 64, dtype=np.uint8).tobytes())
    write_template(d, name=name)
    return d


@pytest.fixture
def three(tmp_path):
    CALLS.clear()
    return [_make(tmp_path, f"e{i}", i) for i in range(3)]


def test_skip_when_inputs_unchanged(three):
    d = three[0]
    out = run_experiment(d, ["fit"], pipeline=PIPE)
    assert out.status == "ok" and [s.status for s in out.steps] == ["done", "done"]
    assert experiment_status(d) == "fitted"
    out = run_experiment(d, ["fit"], pipeline=PIPE)
    assert [s.status for s in out.steps] == ["skipped", "skipped"]
    assert CALLS == [("sum", "e0"), ("scale", "e0")]
    # editing a comment in the toml changes nothing; a value that the step reads re-runs it and downstream
    toml = d / "experiment.toml"
    toml.write_text(toml.read_text().replace("[chamber]", "# a comment\n[chamber]"))
    assert [s.status for s in run_experiment(d, ["fit"], pipeline=PIPE).steps] == ["skipped", "skipped"]
    toml.write_text(toml.read_text().replace("radius_um = 200.0", "radius_um = 100.0"))
    assert [s.status for s in run_experiment(d, ["fit"], pipeline=PIPE).steps] == ["done", "done"]
    # a frame's content changed
    f = d / "frames" / "f1.tif"
    f.write_bytes(bytes(reversed(f.read_bytes())) + b"\x01")
    assert [s.status for s in run_experiment(d, ["fit"], pipeline=PIPE).steps] == ["done", "done"]
    # curation: manual profiles feed the process step, exclusions do not (in this pipeline)
    exclude_frame(d, 0, "other")
    assert [s.status for s in run_experiment(d, ["fit"], pipeline=PIPE).steps] == ["skipped", "skipped"]
    set_manual_profile(d, 0, [[0, 0], [1e-4, -1e-4], [2e-4, -1e-4], [3e-4, 0]])
    assert [s.status for s in run_experiment(d, ["fit"], pipeline=PIPE).steps] == ["done", "skipped"]
    # options are inputs; force re-runs
    assert [s.status for s in run_experiment(d, ["fit"], pipeline=PIPE, options={"scale": 2}).steps] == [
        "skipped", "done"]
    assert [s.status for s in run_experiment(d, ["fit"], pipeline=PIPE, options={"scale": 2},
                                             force=True).steps] == ["done", "done"]


def test_tampered_output_is_recomputed(three):
    d = three[0]
    run_experiment(d, ["fit"], pipeline=PIPE)
    (d / "results" / "sum.json").write_text('{"total": 0}')
    assert [s.status for s in run_experiment(d, ["fit"], pipeline=PIPE).steps] == ["done", "skipped"]
    (d / "results" / "scaled.json").unlink()
    assert [s.status for s in run_experiment(d, ["fit"], pipeline=PIPE).steps] == ["skipped", "done"]


def test_crash_in_one_experiment_then_resume(three):
    (three[1] / "FAIL").write_text("")
    res = run_batch(three, ["fit"], scheduler="serial", pipeline=PIPE)
    assert res.exit_code == EXIT_FAILED
    assert [o.status for o in res.outcomes] == ["ok", "failed", "ok"]
    assert "injected failure" in res.outcomes[1].error
    assert [s.status for s in res.outcomes[1].steps] == ["failed", "not_run"]
    st = read_state(three[1])["steps"]["process"]
    assert st["status"] == "failed" and "RuntimeError: injected failure" in st["traceback"]
    assert experiment_status(three[1]) == "failed"
    good = {d: (d / "results" / "scaled.json").read_bytes() for d in (three[0], three[2])}
    # fix the cause and re-run: only the failed experiment is computed
    (three[1] / "FAIL").unlink()
    CALLS.clear()
    res = run_batch(three, ["fit"], scheduler="serial", pipeline=PIPE)
    assert res.exit_code == EXIT_OK
    assert CALLS == [("sum", "e1"), ("scale", "e1")]
    assert all((d / "results" / "scaled.json").read_bytes() == b for d, b in good.items())


def test_bad_input_is_exit_2(three, tmp_path):
    toml = three[2] / "experiment.toml"
    toml.write_text(toml.read_text().replace("radius_um = 200.0", "radius_um = 0.0002"))
    res = run_batch(three, ["fit"], scheduler="serial", pipeline=PIPE)
    assert res.exit_code == EXIT_BAD_INPUT
    assert res.outcomes[2].status == "invalid" and "looks like metres" in res.outcomes[2].error
    assert res.outcomes[0].status == "ok"
    assert run_batch([], ["fit"], scheduler="serial", pipeline=PIPE).exit_code == EXIT_BAD_INPUT
    with pytest.raises(ValueError, match="step 'fitt'"):
        run_batch(three, ["fitt"], scheduler="serial", pipeline=PIPE)


def test_errors_raise_mode(three):
    (three[0] / "FAIL").write_text("")
    with pytest.raises(RuntimeError, match="injected"):
        run_experiment(three[0], ["process"], pipeline=PIPE, errors="raise")
    assert read_state(three[0])["steps"]["process"]["status"] == "failed"


def test_lock_of_a_live_run_and_stale_lock(three):
    d = three[0]
    (d / "results").mkdir(exist_ok=True)
    lock = d / "results" / ".lock"
    import socket

    lock.write_text(json.dumps({"pid": os.getpid(), "host": socket.gethostname()}))
    out = run_experiment(d, ["process"], pipeline=PIPE)
    assert out.status == "invalid" and "holds the lock" in out.error
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    lock.write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname()}))
    assert run_experiment(d, ["process"], pipeline=PIPE).status == "ok"
    assert not lock.exists()


def test_atomic_path_on_exception(tmp_path):
    target = tmp_path / "out.nc"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("boom")
    assert target.read_text() == "old" and list(tmp_path.iterdir()) == [target]
    with atomic_path(target) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new"


def test_killed_netcdf_write_leaves_no_half_file(tmp_path):
    """A process killed while writing a netCDF through atomic_path leaves the old file whole."""
    import xarray as xr

    target = tmp_path / "extraction.nc"
    xr.Dataset({"v": ("t", np.arange(3.0))}).to_netcdf(target, engine="h5netcdf")
    before = target.read_bytes()
    code = textwrap.dedent(f"""
        import time, numpy as np, xarray as xr
        from osmobulge.experiments.runs import atomic_path
        with atomic_path({str(target)!r}) as tmp:
            xr.Dataset({{"v": ("t", np.arange(1e6))}}).to_netcdf(tmp, engine="h5netcdf")
            print("written", flush=True)
            time.sleep(30)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == "written\n"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(10)
    assert target.read_bytes() == before
    xr.testing.assert_identical(xr.open_dataset(target, engine="h5netcdf").load(),
                                xr.Dataset({"v": ("t", np.arange(3.0))}))
    assert all(p.name.startswith(".") for p in tmp_path.iterdir() if p != target)


def test_leftovers_of_a_killed_write_are_removed_and_modes_are_normal(three):
    """The hidden temporary file a kill leaves in results/ is removed by the next run; outputs get 0666 & ~umask."""
    d = three[0]
    (d / "results").mkdir(exist_ok=True)
    left = d / "results" / ".sum.json.x1y2.tmp"
    left.write_text("half")
    assert run_experiment(d, ["process"], pipeline=PIPE).status == "ok"
    assert not left.exists()
    umask = os.umask(0)
    os.umask(umask)
    with atomic_path(d / "results" / "x.nc") as tmp:
        tmp.write_text("x")
    assert (d / "results" / "x.nc").stat().st_mode & 0o777 == 0o666 & ~umask


# ---- the same small pipeline in an importable module, for worker processes ----------------------------
_WORKER_MODULE = '''
import json, os
import numpy as np
from osmobulge.experiments import runs
from osmobulge.experiments.runs import Step

def fp(exp, options):
    return {"frames": runs.frames_fingerprint(exp), "toml": exp.raw.get("chamber")}

def compute(exp, results, options):
    if (exp.path / "FAIL").exists():
        os._exit(3) if (exp.path / "FAIL").read_text() == "die" else None
        raise RuntimeError("injected failure")
    total = sum(int(np.frombuffer(f.read_bytes(), np.uint8).sum()) for f in exp.frame_files())
    runs.atomic_write_text(results / "sum.json", json.dumps({"total": total * exp.chamber.radius, "pid": os.getpid()}))
    return {"total": total * exp.chamber.radius}

PIPE = (Step("process", ("sum.json",), (), fp, compute),)
'''


@pytest.fixture
def worker_pipe(tmp_path, monkeypatch):
    mod_dir = tmp_path / "mods"
    mod_dir.mkdir()
    (mod_dir / "obworkerpipe.py").write_text(_WORKER_MODULE)
    monkeypatch.syspath_prepend(str(mod_dir))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(mod_dir), os.environ.get("PYTHONPATH", "")]))
    import importlib

    runs.code_version.cache_clear()  # hash the source now, as the workers will
    return importlib.import_module("obworkerpipe").PIPE


def _totals(dirs):
    return [json.loads((d / "results" / "sum.json").read_text())["total"] for d in dirs]


@pytest.mark.slow
def test_process_pool_and_dask_cluster_equal_serial(tmp_path, worker_pipe):
    distributed = pytest.importorskip("distributed")
    serial = [_make(tmp_path / "serial", f"e{i}", i) for i in range(4)]
    pool = [_make(tmp_path / "pool", f"e{i}", i) for i in range(4)]
    dask = [_make(tmp_path / "dask", f"e{i}", i) for i in range(4)]
    r0 = run_batch(serial, ["process"], scheduler="serial", pipeline=worker_pipe)
    r1 = run_batch(pool, ["process"], scheduler="processes", workers=2, pipeline=worker_pipe)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        r2 = run_batch(dask, ["process"], scheduler=cluster.scheduler_address, pipeline=worker_pipe)
    assert r0.exit_code == r1.exit_code == r2.exit_code == EXIT_OK
    assert r1.scheduler == "processes(2)" and r2.scheduler.startswith("dask(tcp://")
    assert _totals(serial) == _totals(pool) == _totals(dask)
    pids = {json.loads((d / "results" / "sum.json").read_text())["pid"] for d in dask}
    assert os.getpid() not in pids
    # the work ran in the workers, and the recorded summaries agree
    for a, b in zip(serial, dask, strict=True):
        assert read_state(a)["steps"]["process"]["summary"] == read_state(b)["steps"]["process"]["summary"]


@pytest.mark.slow
def test_worker_death_is_a_failed_experiment(tmp_path, worker_pipe):
    dirs = [_make(tmp_path, f"e{i}", i) for i in range(2)]
    (dirs[0] / "FAIL").write_text("die")  # the worker process exits abruptly
    res = run_batch(dirs, ["process"], scheduler="processes", workers=1, pipeline=worker_pipe)
    assert res.outcomes[0].status == "failed" and "worker crashed" in res.outcomes[0].error
    assert res.exit_code == EXIT_FAILED
    (dirs[0] / "FAIL").unlink()
    res = run_batch(dirs, ["process"], scheduler="serial", pipeline=worker_pipe)
    assert res.exit_code == EXIT_OK and [o.steps[0].status for o in res.outcomes] == ["done", "skipped"]
