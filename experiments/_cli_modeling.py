"""CLI commands for the membrane mechanics (``osmobulge mechanics``, ``osmobulge figure3``)."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from osmobulge.experiments._io import atomic_write_bytes, atomic_write_text
from osmobulge.experiments.cli import app

#: figure formats the commands write, chosen by the output file's suffix
FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


def _material(name: str):
    from osmobulge.modeling.materials import get_material

    try:
        return get_material(name)
    except ValueError as err:
        raise typer.BadParameter(str(err), param_hint="--material") from None


def _check_figure_path(path: Path, param_hint: str) -> str:
    suffix = path.suffix.lower()
    if suffix not in FIGURE_SUFFIXES:
        raise typer.BadParameter(
            f"{str(path)!r} has suffix {suffix!r}; choose one of {FIGURE_SUFFIXES}", param_hint=param_hint
        )
    return suffix[1:]


def _figure_bytes(fig, fmt: str, dpi: int) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi)
    return buf.getvalue()


@app.command()
def mechanics(
    material: Annotated[str, typer.Option(help="Material preset: PDMS or PEO_PDMS.")] = "PDMS",
    lambda_pre: Annotated[float, typer.Option(help="Constant rim pre-stretch (>= 1).")] = 1.0,
    vmax: Annotated[float | None, typer.Option(help="Largest dimensionless volume (default: near locking).")] = None,
    points: Annotated[int, typer.Option(min=2, help="Number of rows printed.")] = 15,
    plot: Annotated[Path | None, typer.Option(help="Write f_A, f_l, f_p vs Vtilde to this PNG/PDF/SVG.")] = None,
    csv: Annotated[Path | None, typer.Option(help="Write the table to this CSV.")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the table as JSON.")] = False,
):
    """Print (and plot) the mechanics table f_A, f_l, pressure vs Vtilde of a material."""
    from rich.console import Console
    from rich.table import Table

    from osmobulge.modeling import bulge_mechanics, locking_volume

    mat = _material(material)
    fmt = _check_figure_path(plot, "--plot") if plot is not None else None
    try:
        vlock = locking_volume(mat, lambda_pre)
        vend = vmax if vmax is not None else (0.98 * vlock if np.isfinite(vlock) else 10.0)
        ds = bulge_mechanics(mat, np.linspace(0.0, vend, points), lambda_pre=lambda_pre)
    except (TypeError, ValueError) as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(2) from None
    df = ds[["area_ratio", "inverse_thickness", "pressure", "lambda_bar", "pole_thickness_ratio"]].to_dataframe()
    if as_json:
        typer.echo(json.dumps({"material": material, "lambda_pre": lambda_pre, "vtilde_lock": vlock,
                               "rows": df.reset_index().to_dict(orient="records")}))
    else:
        table = Table(title=f"{material} ({mat!r}), lambda_pre={lambda_pre:g}, locking Vtilde={vlock:.4g}")
        for col in ["Vtilde", "f_A", "f_l", "P a/(C1 l0)", "lambda_bar", "l_pole/l0"]:
            table.add_column(col, justify="right")
        for v, row in df.iterrows():
            table.add_row(f"{v:.4g}", *(f"{x:.5g}" for x in row.values))
        Console().print(table)
    if csv is not None:
        atomic_write_text(csv, df.to_csv())
    if plot is not None:
        from osmobulge.modeling.plot import plot_mechanics

        fig = plot_mechanics(ds, labels=[material])
        atomic_write_bytes(plot, _figure_bytes(fig, fmt, 120))
        if not as_json:
            typer.echo(f"wrote {plot}")


#: columns of the ``figure3 --csv`` table
FIGURE3_COLUMNS = (
    "panel", "material", "vtilde", "area_ratio", "inverse_thickness", "pressure", "lambda_bar", "turgor_ratio",
    "rho", "r", "z",
)


def figure3_table(data):
    """Flatten :func:`osmobulge.modeling.plot.figure3_data` into one tidy table.

    Rows with ``panel == "b-d"`` hold the mechanics functions of each material
    over ``vtilde`` (``pressure`` is P_t a/(C1 l0), ``turgor_ratio`` is
    f_p = P_t/E); rows with ``panel == "e"`` hold the half profile ``r, z`` (in
    units of a) over ``rho`` of the profile material at each ``vtilde``.
    """
    import pandas as pd

    curves = data[["area_ratio", "inverse_thickness", "pressure", "lambda_bar", "turgor_ratio"]]
    curves = curves.to_dataframe().reset_index()
    curves.insert(0, "panel", "b-d")
    prof = data[["r", "z"]].to_dataframe().reset_index().rename(columns={"profile_vtilde": "vtilde"})
    prof.insert(0, "panel", "e")
    prof.insert(1, "material", data.attrs.get("profile_material", ""))
    return pd.concat([curves, prof], ignore_index=True).reindex(columns=list(FIGURE3_COLUMNS))


@app.command()
def figure3(
    out: Annotated[Path, typer.Argument(metavar="OUT", help="Output figure (.png, .pdf or .svg).")],
    csv: Annotated[Path | None, typer.Option(help="Also write the plotted numbers to this CSV.")] = None,
    l0_over_a: Annotated[float, typer.Option(help="Membrane thickness over chamber radius l0/a for f_p.")] = 0.1,
    vtilde_max: Annotated[
        float | None, typer.Option(help="Largest Vtilde of panels b-d (default: 99% of PDMS locking).")
    ] = None,
    profile: Annotated[
        list[float] | None, typer.Option(help="Vtilde of a PDMS profile in panel e (repeatable; default 0.5 1 2 3 4).")
    ] = None,
    dpi: Annotated[int, typer.Option(min=30, max=1200, help="Resolution of raster output.")] = 150,
):
    """Draw the paper's Fig. 3 b-e (f_A, f_l, f_p vs Vtilde; PDMS bulge profiles)."""
    from osmobulge.modeling.plot import figure3_data, plot_figure3

    fmt = _check_figure_path(out, "OUT")
    profiles = tuple(profile) if profile else (0.5, 1, 2, 3, 4)
    try:
        data = figure3_data(thickness_over_radius=l0_over_a, vtilde_max=vtilde_max, profile_vtildes=profiles)
    except (TypeError, ValueError) as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(2) from None
    fig = plot_figure3(data=data)
    atomic_write_bytes(out, _figure_bytes(fig, fmt, dpi))
    typer.echo(f"wrote {out}")
    if csv is not None:
        atomic_write_text(csv, figure3_table(data).to_csv(index=False))
        typer.echo(f"wrote {csv}")
