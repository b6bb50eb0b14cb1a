"""CLI command of the image pipeline: ``osmobulge extract SOURCE OUT.nc``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from osmobulge.experiments.cli import app

#: output formats, chosen by the output path's suffix
OUTPUT_SUFFIXES = (".nc", ".zarr")
DIRECTIONS = ("auto", "up", "down", "left", "right")
ERRORS = ("flag", "raise")


def _chamber(preset, radius_um, depth_um, thickness_um, concentration_molar):
    from osmobulge.modeling.transport import Chamber, paper_chamber

    given = [v is not None for v in (radius_um, depth_um, thickness_um)]
    if preset is not None:
        try:
            ch = paper_chamber(preset)
        except (KeyError, ValueError) as err:
            raise typer.BadParameter(str(err), param_hint="--chamber") from None
        changes = {k: v * 1e-6 for k, v in (("radius", radius_um), ("depth", depth_um),
                                              ("thickness", thickness_um)) if v is not None}
        if concentration_molar is not None:
            changes["concentration"] = concentration_molar * 1000.0
        if changes:
            ch = paper_chamber(preset, **changes)
        return ch
    if not any(given):
        return None
    if not all(given):
        raise typer.BadParameter("give all three of --chamber-radius-um, --chamber-depth-um, "
                                 "--membrane-thickness-um (or a --chamber preset)", param_hint="--chamber-radius-um")
    try:
        return Chamber(radius=radius_um * 1e-6, depth=depth_um * 1e-6, thickness=thickness_um * 1e-6,
                       concentration=(concentration_molar if concentration_molar is not None else 3.0) * 1000.0)
    except ValueError as err:
        raise typer.BadParameter(str(err), param_hint="--chamber-radius-um") from None


@app.command()
def extract(
    source: Annotated[Path, typer.Argument(help="Series: multi-page TIFF/OME-TIFF, CZI, or a folder of images.")],
    out: Annotated[Path, typer.Argument(help="Output dataset: *.nc (netCDF) or *.zarr.")],
    pixel_size_um: Annotated[float | None, typer.Option(help="Pixel size (um/px) when the files carry none.")] = None,
    frame_interval_min: Annotated[float | None, typer.Option(help="Minutes between frames when the files carry "
                                                                  "no timestamps.")] = None,
    chamber: Annotated[str | None, typer.Option(help="Paper chamber preset: reference, small_radius, "
                                                     "thick_membrane, low_concentration.")] = None,
    chamber_radius_um: Annotated[float | None, typer.Option(help="Chamber radius a (um).")] = None,
    chamber_depth_um: Annotated[float | None, typer.Option(help="Chamber depth h (um).")] = None,
    membrane_thickness_um: Annotated[float | None, typer.Option(help="Membrane thickness l0 (um).")] = None,
    concentration_molar: Annotated[float | None, typer.Option(help="Initial salt concentration C0 (M).")] = None,
    bulge_direction: Annotated[str, typer.Option(help="Direction the dome grows: auto, up, down, left, right.")]
    = "auto",
    chamber_region: Annotated[int | None, typer.Option(help="Which well when several are in view "
                                                            "(index from the left of the bulge-up view).")] = None,
    all_chambers: Annotated[bool, typer.Option("--all-chambers", help="Trace every well whose two walls are in "
                                                                       "view, stacked along 'chamber'.")] = False,
    reference_frame: Annotated[Path | None, typer.Option(help="Image or series whose first frame shows the flat "
                                                              "membrane, when SOURCE starts bulged (a later file "
                                                              "of a split series: give the first file).")] = None,
    rim_um: Annotated[str | None, typer.Option(help="When the chamber is not found: its rim in the flat frame, "
                                                    "'x0,y0,x1,y1' (um, x = col * pixel size, y = row * pixel "
                                                    "size), the flat mid-line's ends at the two walls.")] = None,
    max_drift_px: Annotated[float | None, typer.Option(help="Largest stage drift (px) followed (default 40; from the "
                                                            "first frame on the silhouette route, frame to frame on "
                                                            "the band route): raise it when the stage was moved "
                                                            "during the series.")] = None,
    errors: Annotated[str, typer.Option(help="flag: keep unmeasurable frames flagged; raise: stop.")] = "flag",
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
    progress: Annotated[bool, typer.Option(help="Show a progress bar.")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
):
    """Extract bulge profiles, volumes, areas and rim radii from a micrograph series into a dataset."""
    import numpy as np

    from osmobulge.imaging.extract import extract as _extract
    from osmobulge.imaging.extract import save_extraction

    suffix = out.suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise typer.BadParameter(f"{str(out)!r} has suffix {suffix!r}; choose one of {OUTPUT_SUFFIXES}",
                                 param_hint="OUT")
    if bulge_direction not in DIRECTIONS:
        raise typer.BadParameter(f"{bulge_direction!r} is not one of {DIRECTIONS}", param_hint="--bulge-direction")
    if errors not in ERRORS:
        raise typer.BadParameter(f"{errors!r} is not one of {ERRORS}", param_hint="--errors")
    if not source.exists():
        raise typer.BadParameter(f"{str(source)!r} does not exist", param_hint="SOURCE")
    if reference_frame is not None and not reference_frame.exists():
        raise typer.BadParameter(f"{str(reference_frame)!r} does not exist", param_hint="--reference-frame")
    if all_chambers and chamber_region is not None:
        raise typer.BadParameter("give --chamber-region or --all-chambers, not both", param_hint="--all-chambers")
    rim = None
    if rim_um is not None:
        try:
            rim = np.array([float(v) for v in rim_um.split(",")]).reshape(2, 2) * 1e-6
        except ValueError:
            raise typer.BadParameter(f"{rim_um!r} is not four numbers 'x0,y0,x1,y1' (um)",
                                     param_hint="--rim-um") from None
    ch = _chamber(chamber, chamber_radius_um, chamber_depth_um, membrane_thickness_um, concentration_molar)
    settings = None
    if max_drift_px is not None:
        from osmobulge.imaging.trace import TraceSettings

        try:
            settings = TraceSettings(max_drift=max_drift_px)
        except ValueError as err:
            raise typer.BadParameter(str(err), param_hint="--max-drift-px") from None
    if out.exists() and not overwrite:
        raise typer.BadParameter(f"{str(out)!r} exists; pass --overwrite to replace it", param_hint="OUT")
    try:
        ds = _extract(
            source,
            pixel_size=None if pixel_size_um is None else pixel_size_um * 1e-6,
            frame_interval=None if frame_interval_min is None else frame_interval_min * 60.0,
            chamber=ch,
            bulge_direction=bulge_direction,
            chamber_region="all" if all_chambers else chamber_region,
            errors=errors,
            progress=progress and not as_json,
            reference_frame=reference_frame,
            rim=rim,
            settings=settings,
        )
    except (ValueError, RuntimeError) as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(2) from None
    save_extraction(ds, out)
    flags = {str(f): int((ds.flag == f).sum()) for f in sorted(set(ds.flag.values.ravel().tolist()))}
    ok = ds.flag == "ok"
    def per_chamber(da):  # a number, or one per chamber; NaN -> null
        vals = np.atleast_1d(np.asarray(da, float))
        out_ = [None if v != v else float(v) for v in vals]
        return out_ if "chamber" in ds.dims else out_[0]

    pre = ds if "chamber" in ds.dims else ds.attrs
    summary = {
        "source": str(source),
        "out": str(out),
        "frames": int(ds.sizes["time"]),
        "chambers": int(ds.sizes.get("chamber", 1)),
        "flags": flags,
        "pixel_size_m": float(ds.attrs["pixel_size"]),
        "bulge_direction": ds.attrs["bulge_direction"] if "bulge_direction" in ds.attrs else
        sorted(set(ds["bulge_direction"].values.tolist())),
        "volume_max_m3": per_chamber(ds.volume.where(ok).max("time")),
        "vtilde_max": per_chamber(ds.vtilde.where(ok).max("time")),
        "rim_radius_first_m": per_chamber(ds.rim_radius.isel(time=0)),
        "prestretch_c1": per_chamber(pre["prestretch_c1"]),
        "prestretch_c2": per_chamber(pre["prestretch_c2"]),
    }
    if as_json:
        typer.echo(json.dumps(summary))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"{summary['frames']} frames -> {out}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for k, v in summary.items():
        if k in ("source", "out", "frames"):
            continue
        text = json.dumps(v) if isinstance(v, dict) else (f"{v:.6g}" if isinstance(v, float) else str(v))
        if isinstance(v, list):
            text = ", ".join("-" if x is None else (f"{x:.6g}" if isinstance(x, float) else str(x)) for x in v)
        table.add_row(k, text)
    Console().print(table)
