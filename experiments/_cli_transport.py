"""CLI command ``osmobulge paper``: the paper's Table 2 and Figs 4-7 from synthetic data.

The data are simulated with the flux ODE (:func:`osmobulge.modeling.simulate`) and
the paper's Table 3 permeability laws for its five conditions (main text Sec. 3.1,
Fig. 2c and Sec. 3.7.1): four PDMS chambers (reference a = 200 um, l0 = 20 um,
h = 110 um, C0 = 3 M; a = 100 um; l0 = 26 um; C0 = 1 M) and the PEO-PDMS
reference chamber, sampled every 15 min for 24 h with 1 % multiplicative noise
(V/V0(0) = 1 exactly: it is the normalisation).  Every fit the paper makes is
then run on them.  Nothing is tuned to the paper's numbers: Table 2 puts ours
beside the paper's.
"""

from __future__ import annotations

import dataclasses
import io
import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from osmobulge.experiments._io import atomic_write_bytes, atomic_write_text
from osmobulge.experiments.cli import app

#: the paper's five conditions: (name, material preset, chamber preset)
CONDITIONS = (
    ("reference", "PDMS", "reference"),
    ("small_radius", "PDMS", "small_radius"),
    ("thick_membrane", "PDMS", "thick_membrane"),
    ("low_concentration", "PDMS", "low_concentration"),
    ("peo_reference", "PEO_PDMS", "reference"),
)

#: main text Table 2, m^2/s
PAPER_TABLE2 = {
    "linear elastic PDMS, constant P_w": 2.02e-12,
    "hyperelastic PDMS, constant P_w": 8.35e-13,
    "hyperelastic PDMS, P_w(lambda_bar=1)": 1.99e-12,
    "hyperelastic PEO-PDMS, P_w(lambda_bar=1)": 1.99e-12,
}

#: files written by ``osmobulge paper``
OUTPUT_FILES = (
    "table2.csv",
    "fig4.png", "fig4.csv",
    "fig5.png", "fig5.csv",
    "fig6a.png", "fig6a.csv",
    "fig6b.png", "fig6b.csv",
    "fig7.png", "fig7.csv",
    "summary.json",
)


def _dataset_csv(ds) -> str:
    """A dataset as one tidy CSV: one row per value, columns variable, units, coordinates, value."""
    import pandas as pd

    frames = []
    for name, da in ds.data_vars.items():
        df = da.to_dataframe(name="value").reset_index()
        keep = [c for c in df.columns if c in da.dims or c == "value" or c in da.coords]
        df = df[keep]
        df.insert(0, "units", da.attrs.get("units", ""))
        df.insert(0, "variable", name)
        frames.append(df)
    out = pd.concat(frames, ignore_index=True, sort=False)
    return out.to_csv(index=False, float_format="%.8g")


def _png(fig, dpi=130) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def synthetic_observations(*, seed=0, per_condition=3, noise=0.01, dt=900.0, duration=24 * 3600.0):
    """Simulated, noisy ``V/V0(t)`` of the paper's five conditions.

    Parameters
    ----------
    seed : int
        Seed of the noise.
    per_condition : int
        Chambers per condition (each with its own noise).
    noise : float
        Relative standard deviation of the multiplicative noise.
    dt, duration : float, s
        Sampling interval and length of each record.

    Returns
    -------
    dict
        condition name -> list of ``(chamber, t, volume_ratio, label)``.
    """
    from osmobulge.modeling.materials import get_material
    from osmobulge.modeling.permeability import DoubleExponential
    from osmobulge.modeling.simulate import simulate
    from osmobulge.modeling.transport import paper_chamber

    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration + 0.5 * dt, dt)
    out = {}
    for name, mat_name, chamber_name in CONDITIONS:
        mat = get_material(mat_name)
        law = DoubleExponential.PDMS if mat_name == "PDMS" else DoubleExponential.PEO_PDMS
        chamber = paper_chamber(chamber_name)
        ds = simulate(chamber, mat, law, t, on_limit="truncate")
        v = ds["volume_ratio"].values
        rows = []
        for k in range(per_condition):
            e = 1.0 + noise * rng.standard_normal(v.size)
            e[0] = 1.0
            rows.append((chamber, ds["time"].values, v * e, f"{name} #{k + 1}"))
        out[name] = rows
    return out


def paper_results(*, seed=0, per_condition=3, noise=0.01, progress=None) -> dict:
    """Run every fit of the paper on synthetic data; return tables, figure datasets and figures.

    Parameters
    ----------
    seed, per_condition, noise
        See :func:`synthetic_observations`.
    progress : callable, optional
        Called with a short description before each step.

    Returns
    -------
    dict
        ``table2`` (pandas DataFrame), ``figures`` (name -> (Figure, Dataset)),
        ``summary`` (JSON-safe dict).
    """
    import pandas as pd

    from osmobulge.modeling.fitting import fit_permeability
    from osmobulge.modeling.instantaneous import analyze_instantaneous
    from osmobulge.modeling.materials import PDMS, PEO_PDMS
    from osmobulge.modeling.permeability import DoubleExponential
    from osmobulge.modeling.plot_transport import (
        figure4_data,
        figure5_data,
        figure6a_data,
        figure6b_data,
        figure7_data,
        plot_figure4,
        plot_figure5,
        plot_figure6a,
        plot_figure6b,
        plot_figure7,
    )
    from osmobulge.modeling.simulate import simulate
    from osmobulge.modeling.transport import paper_chamber, time_constant

    step = progress or (lambda _msg: None)
    step("simulating the five conditions")
    data = synthetic_observations(seed=seed, per_condition=per_condition, noise=noise)
    pdms_obs = [o for name, *_ in CONDITIONS[:4] for o in data[name]]
    peo_obs = data["peo_reference"]

    def tup(obs):
        return [(c, t, v) for c, t, v, _ in obs]

    step("fit: linear elastic, constant P_w (V/V0 <= 1.3)")
    linear = fit_permeability(tup(pdms_obs), PDMS, model="constant", mechanics="linear",
                              window={"volume_ratio_max": 1.3})
    step("fit: hyperelastic, constant P_w")
    constant = fit_permeability(tup(pdms_obs), PDMS, model="constant")
    step("fit: hyperelastic, P_w(lambda_bar) (Eqn 27) through the ODE")
    stretch = fit_permeability(tup(pdms_obs), PDMS, model="double_exponential")
    step("fit: PEO-PDMS, P_w(lambda_bar)")
    peo_stretch = fit_permeability(tup(peo_obs), PEO_PDMS, model="double_exponential")
    step("instantaneous permeability (Eqn 25) and Eqn 27 on it")
    # bins of 5 values as in the paper, or more when there are many chambers (about 40 points)
    def per_bin(obs):
        return max(5, sum(t.size for _, t, _, _ in obs) // 40)

    an_pdms = analyze_instantaneous(pdms_obs, PDMS, direct=False, per_bin=per_bin(pdms_obs))
    an_pdms = dataclasses.replace(an_pdms, direct=stretch)
    an_peo = analyze_instantaneous(peo_obs, PEO_PDMS, direct=False, per_bin=per_bin(peo_obs))
    an_peo = dataclasses.replace(an_peo, direct=peo_stretch)

    truth_pdms = float(DoubleExponential.PDMS(1.0))
    truth_peo = float(DoubleExponential.PEO_PDMS(1.0))
    rows = [
        # the data come from a stretch-dependent law: a constant P_w has no generating value
        ("linear elastic PDMS, constant P_w", linear.params["p"], linear.stderr.get("p"), np.nan),
        ("hyperelastic PDMS, constant P_w", constant.params["p"], constant.stderr.get("p"), np.nan),
        ("hyperelastic PDMS, P_w(lambda_bar=1)", stretch.p_at_rest, stretch.p_at_rest_stderr, truth_pdms),
        ("hyperelastic PEO-PDMS, P_w(lambda_bar=1)", peo_stretch.p_at_rest, peo_stretch.p_at_rest_stderr, truth_peo),
    ]
    table = pd.DataFrame(
        [{"model": m, "P_w_ours_m2_s": float(p), "P_w_ours_stderr_m2_s": float(s) if s is not None else np.nan,
          "P_w_paper_m2_s": PAPER_TABLE2[m], "ours_over_paper": float(p) / PAPER_TABLE2[m],
          "generating_truth_m2_s": truth} for m, p, s, truth in rows]
        + [{"model": "hyperelastic PDMS, P_w(lambda_bar=1) from Eqn 27 on instantaneous values",
            "P_w_ours_m2_s": an_pdms.eqn27.params["p_at_rest"],
            "P_w_ours_stderr_m2_s": an_pdms.eqn27.stderr["p_at_rest"],
            "P_w_paper_m2_s": PAPER_TABLE2["hyperelastic PDMS, P_w(lambda_bar=1)"],
            "ours_over_paper": an_pdms.eqn27.params["p_at_rest"] / PAPER_TABLE2[
                "hyperelastic PDMS, P_w(lambda_bar=1)"],
            "generating_truth_m2_s": truth_pdms}]
    )

    figures = {}
    step("Fig. 4: dimensionless-time collapse (constant P_w = 2e-12)")
    curves = []
    for name, _, chamber_name in CONDITIONS[:4]:
        c = paper_chamber(chamber_name)
        tt = np.linspace(0.0, 2.5 * time_constant(c, 2e-12), 250)
        ds = simulate(c, PDMS, 2e-12, tt, on_limit="truncate")
        curves.append((c, ds["time"].values, ds["volume_ratio"].values, name))
    d4 = figure4_data(curves, PDMS, permeability=2e-12)
    figures["fig4"] = (plot_figure4(d4), d4)
    step("Figs 5-7")
    ref = 0  # the first PDMS observation is a reference chamber
    d5 = figure5_data({"linear": linear, "constant": constant, "stretch": stretch}, index=ref,
                      data=(pdms_obs[ref][1], pdms_obs[ref][2]))
    figures["fig5"] = (plot_figure5(d5), d5)
    d6a = figure6a_data(an_pdms, PDMS)
    figures["fig6a"] = (plot_figure6a(d6a), d6a)
    d6b = figure6b_data(stretch, labels=[label for *_, label in pdms_obs])
    figures["fig6b"] = (plot_figure6b(d6b), d6b)
    d7 = figure7_data(an_pdms, an_peo, index_pdms=ref, index_peo=0)
    figures["fig7"] = (plot_figure7(d7), d7)

    lam = np.array([1.0, 3.0])
    summary = {
        "seed": int(seed),
        "chambers_per_condition": int(per_condition),
        "noise_relative": float(noise),
        "conditions": [c[0] for c in CONDITIONS],
        "table2": json.loads(table.to_json(orient="records")),
        "fits": {"linear": linear.summary(), "constant": constant.summary(), "stretch": stretch.summary(),
                 "peo_stretch": peo_stretch.summary()},
        "instantaneous_pdms": an_pdms.summary(),
        "instantaneous_peo": an_peo.summary(),
        "peo_over_pdms_at_lambda_bar_1_and_3": [float(x) for x in
                                               np.asarray(peo_stretch.permeability(lam)) /
                                               np.asarray(stretch.permeability(lam))],
        "fig4_collapse_spread_t_tilde_le_0.5": _spread(d4),
    }
    return {"table2": table, "figures": figures, "summary": summary}


def _spread(collapse) -> dict:
    from osmobulge.modeling.instantaneous import collapse_spread

    labels = list(collapse["label"].values)
    idx = [labels.index(n) for n in ("reference", "thick_membrane", "low_concentration") if n in labels]
    out = {}
    if len(idx) >= 2:
        out["reference_thick_low"] = collapse_spread(collapse, chambers=idx, t_tilde_max=0.5)
    if "small_radius" in labels and "reference" in labels:
        out["reference_small_radius"] = collapse_spread(
            collapse, chambers=[labels.index("reference"), labels.index("small_radius")], t_tilde_max=0.5)
    return out


def _plain(x):
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_plain(v) for v in x]
    if isinstance(x, float | np.floating):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


@app.command()
def paper(
    outdir: Annotated[Path, typer.Argument(help="Folder for the tables and figures (created if missing).")],
    seed: Annotated[int, typer.Option(help="Seed of the synthetic noise.")] = 0,
    chambers_per_condition: Annotated[int, typer.Option(min=1, max=50,
                                                        help="Synthetic chambers per condition.")] = 3,
    noise: Annotated[float, typer.Option(min=0.0, max=0.2, help="Relative noise of V/V0.")] = 0.01,
    overwrite: Annotated[bool, typer.Option(help="Replace existing output files.")] = False,
):
    """Regenerate the paper's Table 2 and Figs 4, 5, 6 and 7 (PNG + CSV) from synthetic data.

    The data are the five conditions of the paper simulated with its Table 3
    permeability laws, sampled every 15 min for 24 h with NOISE relative noise.
    """
    import matplotlib

    matplotlib.use("Agg")
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
    from rich.table import Table

    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise typer.BadParameter(f"{str(outdir)!r} exists and is not a folder", param_hint="OUTDIR")
    existing = [f for f in OUTPUT_FILES if (outdir / f).exists()]
    if existing and not overwrite:
        typer.echo(f"error: {outdir} already holds {', '.join(existing)}; pass --overwrite to replace them",
                   err=True)
        raise typer.Exit(2)

    console = Console(stderr=True)
    n_steps = 9
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=console, transient=True) as bar:
        task = bar.add_task("starting", total=n_steps + 1)
        count = {"n": 0}

        def progress(msg):
            if count["n"]:
                bar.advance(task)
            count["n"] += 1
            bar.update(task, description=msg)

        results = paper_results(seed=seed, per_condition=chambers_per_condition, noise=noise, progress=progress)
        progress("writing files")
        outdir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(outdir / "table2.csv", results["table2"].to_csv(index=False, float_format="%.6g"))
        for name, (fig, ds) in results["figures"].items():
            atomic_write_bytes(outdir / f"{name}.png", _png(fig))
            atomic_write_text(outdir / f"{name}.csv", _dataset_csv(ds))
        atomic_write_text(outdir / "summary.json", json.dumps(_plain(results["summary"]), indent=2))
        bar.advance(task)

    table = Table(title="Table 2 from synthetic data (Table-3 laws, "
                        f"{chambers_per_condition} chamber(s)/condition, {noise:.0%} noise)")
    for col in ("model", "ours [m^2/s]", "paper [m^2/s]", "ours/paper"):
        table.add_column(col, justify="left" if col == "model" else "right")
    for _, row in results["table2"].iterrows():
        err = row["P_w_ours_stderr_m2_s"]
        ours = f"{row['P_w_ours_m2_s']:.3e}" + (f" +/- {err:.1e}" if np.isfinite(err) else "")
        table.add_row(row["model"], ours, f"{row['P_w_paper_m2_s']:.3e}", f"{row['ours_over_paper']:.3f}")
    Console().print(table)
    typer.echo(f"wrote {len(OUTPUT_FILES)} files to {outdir}")
