"""The ``osmobulge mechanics`` and ``osmobulge figure3`` commands (typer CliRunner, no subprocess)."""

from __future__ import annotations

import json
import re

import matplotlib.image
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from osmobulge.experiments._cli_modeling import FIGURE3_COLUMNS
from osmobulge.experiments.cli import app
from osmobulge.modeling import bulge_mechanics, bulge_profile, locking_volume, turgor_ratio
from osmobulge.modeling.materials import PDMS, PEO_PDMS
from osmobulge.modeling.plot import figure3_data, plot_figure3

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def run(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def plain(text: str) -> str:
    """Message text without rich's box drawing and line wrapping."""
    return re.sub(r"[\s│╭╮╰╯─]+", " ", text)


def assert_png(path, min_size=(200, 200)):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    img = matplotlib.image.imread(path)
    assert img.ndim == 3 and img.shape[0] >= min_size[0] and img.shape[1] >= min_size[1]
    assert img.std() > 0.05  # not a blank canvas
    return img


# --------------------------------------------------------------------------- mechanics


def test_mechanics_json_matches_bulge_mechanics():
    res = run("mechanics", "--points", 4, "--json")
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["material"] == "PDMS" and out["lambda_pre"] == 1.0
    assert out["vtilde_lock"] == pytest.approx(locking_volume(PDMS), rel=1e-12, abs=0)
    rows = pd.DataFrame(out["rows"])
    expected_v = np.linspace(0.0, 0.98 * locking_volume(PDMS), 4)
    np.testing.assert_allclose(rows["vtilde"], expected_v, rtol=1e-14)
    ds = bulge_mechanics(PDMS, expected_v)
    for col in ("area_ratio", "inverse_thickness", "pressure", "lambda_bar", "pole_thickness_ratio"):
        np.testing.assert_allclose(rows[col], ds[col].values, rtol=1e-12, err_msg=col)


def test_mechanics_options_json_and_csv(tmp_path):
    csv = tmp_path / "out" / "peo.csv"
    res = run("mechanics", "--material", "peo-pdms", "--lambda-pre", 1.02, "--vmax", 2.0, "--points", 3,
              "--json", "--csv", csv)
    assert res.exit_code == 0, res.output
    rows = pd.DataFrame(json.loads(res.stdout)["rows"])
    ds = bulge_mechanics(PEO_PDMS, [0.0, 1.0, 2.0], lambda_pre=1.02)
    np.testing.assert_allclose(rows["area_ratio"], ds.area_ratio.values, rtol=1e-12)
    assert rows["area_ratio"][0] == pytest.approx(1.02**2)
    table = pd.read_csv(csv)
    assert list(table.columns) == ["vtilde", "area_ratio", "inverse_thickness", "pressure", "lambda_bar",
                                   "pole_thickness_ratio"]
    np.testing.assert_allclose(table["pressure"], ds.pressure.values, rtol=1e-12)


def test_mechanics_table_output():
    res = run("mechanics", "--points", 3, "--vmax", 1.0)
    assert res.exit_code == 0, res.output
    assert "f_A" in res.stdout and "locking Vtilde=7.208" in plain(res.stdout)
    # the middle row's f_A printed to 5 significant digits
    f_a = float(bulge_mechanics(PDMS, [0.5]).area_ratio[0])
    assert f"{f_a:.5g}" in res.stdout


def test_mechanics_plot_writes_a_png(tmp_path):
    png = tmp_path / "mech.png"
    res = run("mechanics", "--points", 5, "--vmax", 2.0, "--plot", png)
    assert res.exit_code == 0, res.output
    assert f"wrote {png}" in plain(res.stdout)
    assert_png(png)
    assert [p.name for p in tmp_path.iterdir()] == ["mech.png"]  # atomic write left no temp file


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--material", "unobtainium"], r"Invalid value for --material: unknown material preset 'unobtainium'; "
                                        r"choose one of \['PDMS', 'PEO_PDMS'\]"),
        (["--lambda-pre", 0.9], r"error: lambda_pre must be >= 1 \(rim pre-stretch\), got min 0\.9"),
        (["--vmax", 8.0], r"error: vtilde=\S+ is beyond .*locking limit vtilde_lock=7\.2"),
        (["--points", 1], r"Invalid value for '--points'"),
        (["--plot", "fig.jpg"], r"Invalid value for --plot: 'fig\.jpg' has suffix '\.jpg'; choose one of"),
    ],
)
def test_mechanics_bad_input_fails_clearly(args, message):
    res = run("mechanics", *args)
    assert res.exit_code == 2
    assert re.search(message, plain(res.output)), res.output
    assert "Traceback" not in res.output


# --------------------------------------------------------------------------- figure3


@pytest.fixture(scope="module")
def default_figure(tmp_path_factory):
    """``osmobulge figure3`` with its defaults (the paper's figure), run once."""
    d = tmp_path_factory.mktemp("fig3")
    png, csv = d / "fig3.png", d / "fig3.csv"
    res = run("figure3", png, "--csv", csv)
    return res, png, csv


@pytest.mark.slow
def test_figure3_writes_png_and_csv(default_figure):
    res, png, csv = default_figure
    assert res.exit_code == 0, res.output
    assert png.stat().st_size > 0
    img = assert_png(png, min_size=(1000, 1200))
    assert img.shape[1] > img.shape[0]  # landscape 2 x 2 panels
    table = pd.read_csv(csv)
    assert tuple(table.columns) == FIGURE3_COLUMNS
    assert set(table["panel"]) == {"b-d", "e"}
    curves = table[table["panel"] == "b-d"]
    assert set(curves["material"]) == {"linear elastic (E = 0.37 MPa)", "PDMS", "PEO-PDMS"}
    assert curves["vtilde"].max() == pytest.approx(0.99 * locking_volume(PDMS), rel=1e-9, abs=0)
    profiles = table[table["panel"] == "e"]
    assert set(profiles["material"]) == {"PDMS"}
    assert sorted(set(profiles["vtilde"])) == [0.0, 0.5, 1.0, 2.0, 3.0, 4.0]


@pytest.mark.slow
def test_figure3_csv_numbers_are_the_model(default_figure):
    _, _, csv = default_figure
    table = pd.read_csv(csv)
    curves = table[table["panel"] == "b-d"]
    lin = curves[curves["material"].str.startswith("linear")]
    v = lin["vtilde"].to_numpy()
    np.testing.assert_allclose(lin["area_ratio"], 1.0 + 4.0 * v**2, rtol=1e-12)  # Eqn 12 corrected
    np.testing.assert_allclose(lin["inverse_thickness"], 1.0)  # Eqn 13
    np.testing.assert_allclose(lin["turgor_ratio"], 128.0 / 3.0 * 0.1 * v**3, rtol=1e-12)  # Eqn 11, l0/a = 0.1
    pdms = curves[curves["material"] == "PDMS"].set_index("vtilde")
    check = np.array([0.5, 2.0])
    check = pdms.index.to_numpy()[np.searchsorted(pdms.index.to_numpy(), check)]
    ds = bulge_mechanics(PDMS, check)
    np.testing.assert_allclose(pdms.loc[check, "area_ratio"], ds.area_ratio.values, rtol=1e-9)
    np.testing.assert_allclose(pdms.loc[check, "turgor_ratio"], turgor_ratio(ds.pressure.values, PDMS, 0.1),
                               rtol=1e-9)
    # f_p by hand: Ptilde C1 (l0/a) / E with supplement Table 1 values
    np.testing.assert_allclose(pdms.loc[check, "turgor_ratio"], ds.pressure.values * 0.0316e6 * 0.1 / 0.37e6,
                               rtol=1e-9)
    prof = table[(table["panel"] == "e") & (table["vtilde"] == 2.0)].sort_values("rho")
    ref = bulge_profile(PDMS, 2.0)
    np.testing.assert_allclose(prof["z"], ref.z.values, rtol=1e-9, atol=1e-12)
    assert prof["r"].iloc[-1] == pytest.approx(1.0) and prof["z"].iloc[-1] == pytest.approx(0.0, abs=1e-12)


def test_figure3_options(tmp_path):
    svg, csv = tmp_path / "f.svg", tmp_path / "f.csv"
    res = run("figure3", svg, "--csv", csv, "--vtilde-max", 1.5, "--profile", 1.0, "--l0-over-a", 0.13)
    assert res.exit_code == 0, res.output
    assert svg.read_text().lstrip().startswith("<?xml")
    table = pd.read_csv(csv)
    curves = table[table["panel"] == "b-d"]
    assert curves["vtilde"].max() == pytest.approx(1.5)
    lin = curves[curves["material"].str.startswith("linear")]
    np.testing.assert_allclose(lin["turgor_ratio"], 128.0 / 3.0 * 0.13 * lin["vtilde"] ** 3, rtol=1e-12)
    assert sorted(set(table.loc[table["panel"] == "e", "vtilde"])) == [0.0, 1.0]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["fig.jpg"], r"Invalid value for OUT: 'fig\.jpg' has suffix '\.jpg'; choose one of "
                      r"\('\.png', '\.pdf', '\.svg'\)"),
        (["fig.png", "--l0-over-a", 0], r"error: thickness_over_radius \(l0/a\) must be finite and > 0"),
        (["fig.png", "--vtilde-max", -1], r"error: vtilde_max must be finite and > 0"),
        (["fig.png", "--profile", 8.0], r"error: profile_vtildes must lie below the locking volume 7\.208 of PDMS"),
        (["fig.png", "--profile", -1.0], r"error: profile_vtildes must be finite and > 0"),
    ],
)
def test_figure3_bad_input_fails_clearly(tmp_path, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    res = run("figure3", *args)
    assert res.exit_code == 2
    assert re.search(message, plain(res.output)), res.output
    assert list(tmp_path.iterdir()) == []  # nothing written


# --------------------------------------------------------------------------- the library behind figure3


def test_figure3_data_and_figure_structure():
    data = figure3_data(vtilde_max=1.0, profile_vtildes=(0.5,))
    assert list(data["material"].values) == ["linear elastic (E = 0.37 MPa)", "PDMS", "PEO-PDMS"]
    assert data.attrs["thickness_over_radius"] == 0.1 and data.attrs["profile_material"] == "PDMS"
    for name, var in data.variables.items():
        if name != "material":
            assert var.attrs.get("units") == "1" and var.attrs.get("long_name"), name
    # the small-strain regime is resolved (log-spaced points below 0.05)
    assert (data["vtilde"].values < 0.05).sum() >= 10
    fig = plot_figure3(data=data)
    titles = sorted(ax.get_title(loc="left") for ax in fig.axes if ax.get_title(loc="left"))
    assert titles == ["b", "c", "d", "e"]
    by_title = {ax.get_title(loc="left"): ax for ax in fig.axes}
    assert by_title["b"].get_yscale() == "log" and by_title["d"].get_yscale() == "log"
    assert "A/A_0" in by_title["b"].get_ylabel() and "P_t/E" in by_title["d"].get_ylabel()
    # panel e holds the mirrored dome: x spans -r..r symmetrically
    line = [ln for ln in by_title["e"].get_lines() if ln.get_label() == r"$\tilde V$ = 0.5"][0]
    x, y = line.get_data()
    assert x.min() == pytest.approx(-x.max()) and y.max() == pytest.approx(float(data.z.sel(profile_vtilde=0.5)[0]))


def test_figure3_data_validation():
    with pytest.raises(ValueError, match=r"materials must contain at least one law"):
        figure3_data([])
    with pytest.raises(TypeError, match=r"materials entries must be osmobulge material laws, got str"):
        figure3_data(["PDMS"])
    from osmobulge.modeling.materials import LinearElastic

    with pytest.raises(ValueError, match=r"profile_vtildes needs a hyperelastic law"):
        figure3_data([LinearElastic(1e6)], vtilde_max=1.0)
