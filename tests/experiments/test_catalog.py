"""CLI: init, catalog (table, --json, --csv, --group-by), exit codes of batch commands."""

import json

import pytest
from typer.testing import CliRunner

from osmobulge.experiments.cli import app
from osmobulge.experiments.curation import exclude_frame
from osmobulge.experiments.runs import EXIT_BAD_INPUT

runner = CliRunner()


def _init(path, *args):
    (path / "frames").mkdir(parents=True, exist_ok=True)
    (path / "frames" / "a.tif").write_bytes(b"II*\x00")
    return runner.invoke(app, ["init", str(path), *args])


def test_init_writes_a_valid_template_and_refuses_overwrite(tmp_path):
    res = _init(tmp_path / "e1", "--name", "first", "--material", "PEO_PDMS", "--condition", "peo")
    assert res.exit_code == 0, res.output
    from osmobulge.experiments.metadata import load_experiment

    exp = load_experiment(tmp_path / "e1")
    assert exp.name == "first" and exp.material_name == "PEO_PDMS" and exp.condition == "peo"
    res = _init(tmp_path / "e1")
    assert res.exit_code == EXIT_BAD_INPUT and "exists" in res.output


def test_catalog_outputs(tmp_path):
    for name, mat in (("a", "PDMS"), ("b", "PDMS"), ("c", "PEO_PDMS")):
        assert _init(tmp_path / name, "--material", mat).exit_code == 0
    exclude_frame(tmp_path / "a", 0, "out_of_focus")
    res = runner.invoke(app, ["catalog", str(tmp_path), "--json"])
    assert res.exit_code == 0, res.output
    rows = json.loads(res.output)
    assert [r["name"] for r in rows] == ["a", "b", "c"]
    assert rows[0]["n_excluded"] == 1 and rows[0]["status"] == "raw" and rows[0]["P_w1"] is None
    assert rows[2]["material"] == "PEO_PDMS" and rows[2]["radius_um"] == 200.0
    res = runner.invoke(app, ["catalog", str(tmp_path), "--json", "--group-by", "material"])
    groups = {g["material"]: g for g in json.loads(res.output)["groups"]}
    assert groups["PDMS"]["n"] == 2 and groups["PEO_PDMS"]["n"] == 1
    res = runner.invoke(app, ["catalog", str(tmp_path), "--csv"])
    lines = res.output.strip().splitlines()
    assert lines[0].startswith("name,condition,status") and len(lines) == 4
    res = runner.invoke(app, ["catalog", str(tmp_path)])
    assert res.exit_code == 0 and "3 experiments" in res.output
    assert runner.invoke(app, ["catalog", str(tmp_path), "--json", "--csv"]).exit_code == EXIT_BAD_INPUT
    assert runner.invoke(app, ["catalog", str(tmp_path), "--group-by", "colour"]).exit_code == EXIT_BAD_INPUT
    empty = tmp_path / "empty"
    empty.mkdir()
    assert runner.invoke(app, ["catalog", str(empty), "--json"]).exit_code == EXIT_BAD_INPUT


@pytest.mark.parametrize("command", ["process", "fit", "report", "run"])
def test_batch_commands_bad_input(tmp_path, command):
    res = runner.invoke(app, [command, str(tmp_path)])
    assert res.exit_code == EXIT_BAD_INPUT and "no experiment.toml" in res.output
    res = runner.invoke(app, [command, str(tmp_path / "missing")])
    assert res.exit_code == EXIT_BAD_INPUT


def test_invalid_experiment_is_exit_2_with_json(tmp_path):
    assert _init(tmp_path / "e").exit_code == 0
    toml = tmp_path / "e" / "experiment.toml"
    toml.write_text(toml.read_text().replace("radius_um = 200.0", "raduis_um = 200.0"))
    res = runner.invoke(app, ["run", str(tmp_path), "--scheduler", "serial", "--json"])
    assert res.exit_code == EXIT_BAD_INPUT
    out = json.loads(res.output)
    assert out["exit_code"] == 2 and "did you mean 'radius_um'" in out["experiments"][0]["error"]
    res = runner.invoke(app, ["fit", str(tmp_path), "--model", "constant"])
    assert res.exit_code == EXIT_BAD_INPUT and "expected one of" in res.output
    res = runner.invoke(app, ["run", str(tmp_path), "--scheduler", "nonsense", "-q"])
    assert res.exit_code == EXIT_BAD_INPUT and "scheduler" in res.output


def _frames_experiment(path, frames):
    import numpy as np
    import tifffile

    from osmobulge.experiments.metadata import write_template

    (path / "frames").mkdir(parents=True)
    for i, f in enumerate(np.asarray(frames)):
        tifffile.imwrite(path / "frames" / f"f{i:02d}.tif", f)
    write_template(path, name=path.name)
    return path


@pytest.mark.parametrize("args", [
    ["init", "{d}/new"],
    ["catalog", "{d}"],
    ["process", "{d}/nothing-here"],
    ["fit", "{d}/nothing-here"],
    ["report", "{d}/nothing-here"],
    ["run", "{d}/nothing-here"],
    ["campaign", "{d}/nothing-here", "--out", "{d}/camp"],
    ["demo", "{d}/demo", "--chambers", "0"],
])
def test_every_command_has_quiet_and_json(tmp_path, args):
    """--quiet prints nothing on stdout; --json prints one JSON document with the exit code, also on errors."""
    assert _init(tmp_path / "e").exit_code == 0
    (tmp_path / "nothing-here").mkdir()
    argv = [a.format(d=tmp_path) for a in args]
    quiet = runner.invoke(app, [*argv, "--quiet"])
    if argv[0] == "init":
        (tmp_path / "new" / "experiment.toml").unlink()
    as_json = runner.invoke(app, [*argv, "--json"])
    assert quiet.stdout == ""
    assert quiet.exit_code == as_json.exit_code
    doc = json.loads(as_json.stdout)
    if isinstance(doc, dict) and "exit_code" in doc:
        assert doc["exit_code"] == as_json.exit_code
    if argv[0] in ("init", "catalog"):
        assert as_json.exit_code == 0
    else:  # an empty folder, or --chambers 0: bad input, named on stderr and in the JSON
        assert as_json.exit_code == EXIT_BAD_INPUT and doc["error"] and "error:" in as_json.stderr


def test_exit_code_1_failed_step_and_3_environment(tmp_path, monkeypatch):
    import sys

    import numpy as np

    from osmobulge.experiments import runs
    from osmobulge.experiments.runs import EXIT_ENVIRONMENT, EXIT_FAILED

    # frames without any chamber: the extraction fails (a failed step, not bad input) -> 1
    d = _frames_experiment(tmp_path / "blank", np.full((4, 60, 80), 30000, np.uint16))
    res = runner.invoke(app, ["process", str(d), "--scheduler", "serial", "--json"])
    assert res.exit_code == EXIT_FAILED, res.output
    out = json.loads(res.stdout)["experiments"][0]
    assert out["status"] == "failed" and out["error"].startswith("process:")
    # a scheduler address without dask.distributed -> 3
    monkeypatch.setitem(sys.modules, "distributed", None)
    res = runner.invoke(app, ["run", str(d), "--scheduler", "tcp://127.0.0.1:9", "--json"])
    assert res.exit_code == EXIT_ENVIRONMENT and "not installed" in json.loads(res.stdout)["error"]
    monkeypatch.delitem(sys.modules, "distributed")
    # a scheduler nobody listens on -> 3
    pytest.importorskip("distributed")
    monkeypatch.setattr(runs, "SCHEDULER_TIMEOUT", "1s")
    res = runner.invoke(app, ["run", str(d), "--scheduler", "tcp://127.0.0.1:9", "-q"])
    assert res.exit_code == EXIT_ENVIRONMENT and "cannot reach the scheduler" in res.stderr
