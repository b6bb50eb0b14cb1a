"""experiment.toml: template, validation messages (key, value, unit), frames, units."""

import math
import tomllib

import pytest

from osmobulge.experiments.metadata import (
    MetadataError,
    experiment_template,
    find_experiments,
    load_experiment,
    material_from_spec,
    resolve_frames,
    validate_metadata,
    write_template,
)


def _doc(**changes):
    data = tomllib.loads(experiment_template("exp1", frames="frames/*.tif", date="2024-05-17"))
    for dotted, value in changes.items():
        sec, key = dotted.split(".")
        if value is _DEL:
            data[sec].pop(key, None)
        else:
            data.setdefault(sec, {})[key] = value
    return data


_DEL = object()


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "frames").mkdir()
    for i in (10, 2, 1):  # natural order must be 1, 2, 10
        (tmp_path / "frames" / f"f{i}.tif").write_bytes(b"II*\x00")
    return tmp_path


def _problems(data, base, **kw):
    with pytest.raises(MetadataError) as info:
        validate_metadata(data, base, **kw)
    return info.value.problems


def test_template_loads_in_si(folder):
    write_template(folder, name="ref-1", condition="reference")
    exp = load_experiment(folder)
    assert exp.name == "ref-1" and exp.condition == "reference"
    assert exp.chamber.radius == pytest.approx(200e-6)
    assert exp.chamber.depth == pytest.approx(110e-6)
    assert exp.chamber.thickness == pytest.approx(20e-6)
    assert exp.chamber.concentration == pytest.approx(3000.0)  # mol/m^3
    assert exp.chamber.feed_concentration == 0.0
    assert exp.chamber.temperature == 298.15
    assert exp.imaging.pixel_size == pytest.approx(2e-6)
    assert exp.imaging.frame_interval == pytest.approx(900.0)
    assert [f.name for f in exp.frame_files()] == ["f1.tif", "f2.tif", "f10.tif"]
    assert pytest.approx(0.37e6) == exp.material.E
    assert exp.analysis.linear_window_volume_ratio == 1.3
    assert set(exp.groups()) == {"geometry", "loading", "material"}


def test_template_refuses_to_overwrite(folder):
    write_template(folder)
    with pytest.raises(FileExistsError, match="force"):
        write_template(folder)
    write_template(folder, name="new", force=True)
    assert (folder / "experiment.toml.bak").exists()
    assert load_experiment(folder).name == "new"


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("chamber.radius_um", 0.0002, r"radius_um = 0.0002.*looks like metres \(did you mean 200 um\?\)"),
        ("chamber.depth_um", 1.1e-4, r"depth_um.*looks like metres"),
        ("chamber.membrane_thickness_um", 2e-5, r"membrane_thickness_um.*looks like metres"),
        ("chamber.concentration_M", 3000, r"concentration_M = 3000.*looks like mol/m\^3"),
        ("chamber.temperature_K", 25, r"temperature_K = 25.*between 250 and 400 K"),
        ("imaging.pixel_size_um", 2e-6, r"pixel_size_um.*looks like metres"),
        ("imaging.frame_interval_min", 0.0, r"frame_interval_min = 0.0"),
        ("chamber.radius_um", -200, r"radius_um = -200"),
        ("chamber.radius_um", math.inf, r"finite"),
    ],
)
def test_unit_mistakes_are_caught(folder, key, value, match):
    (msg,) = _problems(_doc(**{key: value}), folder)
    assert key.split(".")[1] in msg
    import re

    assert re.search(match, msg), msg


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("chamber.radius_um", "200", r"radius_um = '200': expected a number in um, got str"),
        ("chamber.radius_um", True, r"radius_um = True: expected a number"),
        ("experiment.name", 3, r"name = 3: expected a string, got int"),
        ("experiment.date", "yesterday", r"date = 'yesterday': expected a date"),
        ("imaging.bulge_direction", "sideways", r"bulge_direction = 'sideways': expected one of 'auto', 'up'"),
        ("imaging.frames", ["a.tif"], r"frames = \['a.tif'\]: expected a string, got list"),
        ("analysis.models", ["constant", "double_exponential"], r"models.*unknown 'constant'"),
        ("analysis.instantaneous", "yes", r"instantaneous = 'yes': expected true or false"),
        ("imaging.chamber_regions", [{"name": "a", "rows": [0, 10], "cols": [5, 5]}], r"cols = \[5, 5\]"),
        ("imaging.timestamps_min", [0, 15, 10], r"strictly increasing"),
    ],
)
def test_wrong_types(folder, key, value, match):
    data = _doc(**{key: value})
    if key == "imaging.timestamps_min":
        data["imaging"].pop("frame_interval_min")
    problems = _problems(data, folder)
    import re

    assert any(re.search(match, p) for p in problems), problems


@pytest.mark.parametrize(
    ("section", "typo", "suggestion"),
    [("chamber", "raduis_um", "radius_um"), ("imaging", "pixelsize_um", "pixel_size_um"),
     ("experiment", "operater", "operator"), ("chamber", "radius_mm", "radius_um")],
)
def test_unknown_keys_get_a_suggestion(folder, section, typo, suggestion):
    data = _doc()
    data[section][typo] = 1.0
    (msg,) = _problems(data, folder)
    assert f"unknown key {typo!r}" in msg and f"did you mean {suggestion!r}" in msg


def test_unknown_section(folder):
    data = _doc()
    data["chambre"] = {}
    (msg,) = _problems(data, folder)
    assert "[chambre]" in msg and "'chamber'" in msg


def test_missing_required_and_all_problems_listed(folder):
    data = _doc(**{"chamber.radius_um": _DEL, "experiment.name": _DEL, "chamber.depth_um": "x"})
    problems = _problems(data, folder)
    assert len(problems) == 3
    assert any("[chamber] radius_um: missing (required in um" in p for p in problems)
    assert any("[experiment] name: missing" in p for p in problems)


def test_missing_frames(tmp_path):
    data = _doc()
    (msg,) = _problems(data, tmp_path)
    assert "frames = 'frames/*.tif': no frame file found" in msg
    validate_metadata(data, tmp_path, check_frames=False)  # the catalog may skip the check


def test_frames_as_folder_and_file(folder):
    assert [f.name for f in resolve_frames(folder, "frames")] == ["f1.tif", "f2.tif", "f10.tif"]
    assert [f.name for f in resolve_frames(folder, "frames/f2.tif")] == ["f2.tif"]
    assert resolve_frames(folder, "nothing/*.png") == []


def test_timing_sources(folder):
    (msg,) = _problems(_doc(**{"imaging.frame_interval_min": _DEL}), folder)
    assert "no frame times" in msg
    (msg,) = _problems(_doc(**{"imaging.timestamps": "files"}), folder)
    assert "only one of frame_interval_min, timestamps" in msg
    exp = validate_metadata(_doc(**{"imaging.frame_interval_min": _DEL, "imaging.timestamps": "files"}), folder)
    assert exp.imaging.timestamps_from_files and exp.imaging.frame_interval is None
    exp = validate_metadata(_doc(**{"imaging.frame_interval_min": _DEL, "imaging.timestamps_min": [0, 10, 25]}),
                            folder)
    assert exp.imaging.timestamps == (0.0, 600.0, 1500.0)
    (msg,) = _problems(_doc(**{"imaging.frame_interval_min": _DEL, "imaging.timestamps_min": [0, 10]}), folder)
    assert "2 times for 3 frame files" in msg


def test_material_table(folder):
    data = _doc(**{"experiment.material": _DEL})
    data["material"] = {"law": "gent-gent", "c1_Pa": 31600.0, "c2_Pa": 29700.0, "jm": 26.0}
    exp = validate_metadata(data, folder)
    assert exp.material.c1 == 31600.0 and exp.material.jm == 26.0
    data["material"]["c1_Pa"] = 0.0316  # MPa by mistake
    (msg,) = _problems(data, folder)
    assert "c1_Pa = 0.0316" in msg and "looks like MPa" in msg
    data["material"] = {"law": "gent", "c1_Pa": 3e4}
    (msg,) = _problems(data, folder)
    assert "[material] jm: missing (required by law = 'gent')" in msg
    data["material"] = {"law": "linear", "E_Pa": 3e5, "jm": 3.0}
    (msg,) = _problems(data, folder)
    assert "jm = 3.0: not a constant of law = 'linear'" in msg
    data = _doc()
    data["material"] = {"law": "linear", "E_Pa": 3e5}
    (msg,) = _problems(data, folder)
    assert "both given" in msg
    (msg,) = _problems(_doc(**{"experiment.material": "steel"}), folder)
    assert "material = 'steel'" in msg
    assert material_from_spec({"law": "neo-hookean", "c1_Pa": 1e5}).c1 == 1e5


def test_invalid_toml_and_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="osmobulge init"):
        load_experiment(tmp_path)
    (tmp_path / "experiment.toml").write_text("[chamber\nradius_um = 1")
    with pytest.raises(MetadataError, match="not valid TOML"):
        load_experiment(tmp_path)


def test_find_experiments_skips_results(tmp_path):
    for name in ("b10", "b2", "a/x"):
        write_template(tmp_path / name)
    write_template(tmp_path / "b2" / "results" / "copy")
    found = [p.relative_to(tmp_path).as_posix() for p in find_experiments(tmp_path)]
    assert found == ["a/x", "b2", "b10"]
