"""Tests of ``osmobulge paper``: Table 2 and Figs 4-7 regenerated from synthetic data."""

import json

import numpy as np
import pandas as pd
import pytest
from PIL import Image
from typer.testing import CliRunner

from osmobulge.experiments._cli_transport import OUTPUT_FILES
from osmobulge.experiments.cli import app
from osmobulge.modeling.permeability import DoubleExponential


@pytest.fixture(scope="module")
def paper_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper")
    result = CliRunner().invoke(app, ["paper", str(out), "--seed", "3", "--chambers-per-condition", "1"])
    assert result.exit_code == 0, result.output
    return out, result.output


@pytest.mark.slow
def test_paper_writes_every_file(paper_dir):
    out, output = paper_dir
    for name in OUTPUT_FILES:
        assert (out / name).is_file(), name
        assert (out / name).stat().st_size > 0, name
    for name in OUTPUT_FILES:
        if name.endswith(".png"):
            with Image.open(out / name) as im:
                assert im.size[0] > 600 and im.size[1] > 400
                # not a blank canvas
                assert len(im.convert("L").getcolors(maxcolors=1 << 16) or range(300)) > 20
    assert "Table 2" in output and f"wrote {len(OUTPUT_FILES)} files" in output


@pytest.mark.slow
def test_table2_recovers_the_generating_law(paper_dir):
    out, _ = paper_dir
    table = pd.read_csv(out / "table2.csv")
    row = table.set_index("model").loc["hyperelastic PDMS, P_w(lambda_bar=1)"]
    truth = float(DoubleExponential.PDMS(1.0))
    assert truth == pytest.approx(1.99e-12, rel=0.005, abs=0)
    assert row["P_w_ours_m2_s"] == pytest.approx(truth, rel=0.05, abs=0)
    assert row["P_w_paper_m2_s"] == 1.99e-12
    peo = table.set_index("model").loc["hyperelastic PEO-PDMS, P_w(lambda_bar=1)"]
    assert peo["P_w_ours_m2_s"] == pytest.approx(float(DoubleExponential.PEO_PDMS(1.0)), rel=0.05, abs=0)
    # a constant P_w fitted to data from a falling P_w(lambda_bar) lies below P_w(1)
    const = table.set_index("model").loc["hyperelastic PDMS, constant P_w"]
    assert const["P_w_ours_m2_s"] < 0.6 * truth
    lin = table.set_index("model").loc["linear elastic PDMS, constant P_w"]
    assert 0.7 * truth < lin["P_w_ours_m2_s"] < 1.1 * truth
    np.testing.assert_allclose(table["ours_over_paper"], table["P_w_ours_m2_s"] / table["P_w_paper_m2_s"], rtol=1e-5)


@pytest.mark.slow
def test_figure_csvs_hold_the_plotted_numbers(paper_dir):
    out, _ = paper_dir
    fig4 = pd.read_csv(out / "fig4.csv")
    assert {"variable", "units", "value"} <= set(fig4.columns)
    assert {"t_tilde", "volume_ratio", "geometry", "driving_force", "tau"} <= set(fig4["variable"])
    fig6a = pd.read_csv(out / "fig6a.csv")
    firpo = fig6a[fig6a["variable"] == "p_henry"]
    # Eqn 26 through P_w(1) at l0 = 20 um: P_Henry = P_w(1) (1 + l0/L_c) / (l0/L_c); paper: 3, 4, 6, 10, 22 e-12
    np.testing.assert_allclose(firpo["value"].values / 1e-12, [2.9, 3.9, 5.8, 9.7, 21], rtol=0.06)
    summary = json.loads((out / "summary.json").read_text())
    spread = summary["fig4_collapse_spread_t_tilde_le_0.5"]
    assert spread["reference_thick_low"] < 2e-3 < 0.3 < spread["reference_small_radius"]
    ratio = summary["peo_over_pdms_at_lambda_bar_1_and_3"]
    assert ratio[0] == pytest.approx(1.0, abs=0.05)
    assert ratio[1] > 1.2  # PEO-PDMS keeps more of its permeability at large stretch (Sec. 3.7.1)


def test_paper_refuses_to_overwrite(tmp_path):
    (tmp_path / "table2.csv").write_text("keep me")
    result = CliRunner().invoke(app, ["paper", str(tmp_path)])
    assert result.exit_code == 2
    assert "--overwrite" in result.output
    assert (tmp_path / "table2.csv").read_text() == "keep me"


def test_paper_rejects_a_file_as_outdir(tmp_path):
    f = tmp_path / "x.txt"
    f.write_text("")
    result = CliRunner().invoke(app, ["paper", str(f)])
    assert result.exit_code != 0
    assert "not a folder" in result.output


def test_paper_rejects_bad_options(tmp_path):
    result = CliRunner().invoke(app, ["paper", str(tmp_path / "o"), "--chambers-per-condition", "0"])
    assert result.exit_code != 0
    result = CliRunner().invoke(app, ["paper", str(tmp_path / "o"), "--noise", "-0.1"])
    assert result.exit_code != 0
