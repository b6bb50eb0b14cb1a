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
