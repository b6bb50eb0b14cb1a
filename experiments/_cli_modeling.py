"""CLI commands for the membrane mechanics (``osmobulge mechanics``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer

from osmobulge.experiments._io import atomic_write_bytes, atomic_write_text
from osmobulge.experiments.cli import app


def _material(name: str):
    from osmobulge.modeling.materials import get_material

    try:
        return get_material(name)
    except ValueError as err:
        raise typer.BadParameter(str(err), param_hint="--material") from None


@app.command()
def mechanics(
    material: str = typer.Option("PDMS", help="Material preset: PDMS or PEO_PDMS."),
    lambda_pre: float = typer.Option(1.0, help="Constant rim pre-stretch (>= 1)."),
    vmax: float = typer.Option(None, help="Largest dimensionless volume (default: near locking)."),
    points: int = typer.Option(15, help="Number of rows printed."),
    plot: Path = typer.Option(None, help="Write f_A, f_l, f_p vs Vtilde to this PNG."),
    csv: Path = typer.Option(None, help="Write the table to this CSV."),
    as_json: bool = typer.Option(False, "--json", help="Print the table as JSON."),
):
    """Print (and plot) the mechanics table f_A, f_l, pressure vs Vtilde of a material."""
    from rich.console import Console
    from rich.table import Table

    from osmobulge.modeling import bulge_mechanics, locking_volume

    mat = _material(material)
    try:
        vlock = locking_volume(mat, lambda_pre)
        vend = vmax if vmax is not None else (0.98 * vlock if np.isfinite(vlock) else 10.0)
        ds = bulge_mechanics(mat, np.linspace(0.0, vend, points), lambda_pre=lambda_pre)
    except ValueError as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(2) from None
    df = ds[["area_ratio", "inverse_thickness", "pressure", "lambda_bar", "pole_thickness_ratio"]].to_dataframe()
    if as_json:
        typer.echo(json.dumps({"material": material, "vtilde_lock": vlock,
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
        import io

        import matplotlib

        matplotlib.use("Agg")
        from osmobulge.modeling.plot import plot_mechanics

        fig = plot_mechanics(ds, labels=[material])
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=120)
        atomic_write_bytes(plot, buf.getvalue())
        if not as_json:
            typer.echo(f"wrote {plot}")
