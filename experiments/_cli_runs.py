"""CLI commands for experiment folders: init, process, fit, report, run, catalog, campaign, demo.

Every command takes ``--quiet/-q`` (nothing on stdout; errors still on stderr)
and ``--json`` (one JSON document on stdout, also for errors:
``{"exit_code": N, "error": "..."}``; progress bars off).  Progress bars go to
stderr.

Exit codes
----------
0  every experiment is up to date (init: template written; catalog: experiments found)
1  some experiments failed in a step (the others' results are intact; re-run to resume)
2  bad input: no experiment found, invalid experiment.toml, frames missing or not as described, bad option
3  environment: dask.distributed missing or the scheduler cannot be reached
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from osmobulge.experiments.cli import app
from osmobulge.experiments.runs import EXIT_BAD_INPUT, EXIT_ENVIRONMENT

_DIRS = Annotated[list[Path], typer.Argument(help="Experiment folders, or folders that contain experiments.")]
_SCHED = Annotated[str, typer.Option("--scheduler", help="'processes' (local pool), 'serial', or a dask "
                                     "scheduler address such as tcp://10.0.0.5:8786.")]
_WORKERS = Annotated[int, typer.Option("--workers", "-j", help="Local worker processes (0: one per CPU).")]
_FORCE = Annotated[bool, typer.Option("--force", help="Recompute even if the inputs did not change.")]
_QUIET = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar, no table.")]
_JSON = Annotated[bool, typer.Option("--json", help="Print the outcome as JSON (for scripts).")]


def _fail(message: str, code: int, as_json: bool = False):
    """Print the error (stderr; and as JSON on stdout with ``--json``) and exit with ``code``."""
    typer.echo(f"error: {message}", err=True)
    if as_json:
        typer.echo(json.dumps({"exit_code": code, "error": message}))
    raise typer.Exit(code)


def _expand(dirs, as_json: bool = False) -> list[Path]:
    from osmobulge.experiments.metadata import find_experiments, is_experiment_dir

    out: list[Path] = []
    for d in dirs:
        d = Path(d)
        if is_experiment_dir(d):
            out.append(d)
        elif d.is_dir():
            found = find_experiments(d)
            if not found:
                _fail(f"{d}: no experiment.toml at or under it (write one with `osmobulge init`)", EXIT_BAD_INPUT,
                      as_json)
            out.extend(found)
        else:
            _fail(f"{d}: not a folder", EXIT_BAD_INPUT, as_json)
    # keep order, drop duplicates
    seen, uniq = set(), []
    for p in out:
        r = p.resolve()
        if r not in seen:
            seen.add(r)
            uniq.append(p)
    return uniq


def _batch(dirs, steps, *, scheduler, workers, force, quiet, as_json, options=None):
    paths = _expand(dirs, as_json)
    res = _run_batch(paths, steps, scheduler=scheduler, workers=workers, force=force, options=options,
                     progress=not (quiet or as_json), as_json=as_json)
    if as_json:
        typer.echo(json.dumps(res.to_dict(), default=str))
    elif not quiet:
        _print_outcomes(res)
    else:
        for o in res.outcomes:
            if o.status != "ok":
                typer.echo(f"{o.path}: {o.status}: {o.error}", err=True)
    raise typer.Exit(res.exit_code)


def _run_batch(paths, steps, *, scheduler, workers, force=False, options=None, progress=True, as_json=False):
    """run_batch with the CLI's exit codes for a bad scheduler (2) or an unusable cluster (3)."""
    from osmobulge.experiments.runs import run_batch

    try:
        return run_batch(paths, steps, scheduler=scheduler, workers=workers or None, force=force, options=options,
                         progress=progress)
    except ImportError as err:
        _fail(str(err), EXIT_ENVIRONMENT, as_json)
    except (OSError, TimeoutError) as err:
        _fail(f"cannot reach the scheduler {scheduler!r}: {err}", EXIT_ENVIRONMENT, as_json)
    except ValueError as err:
        _fail(str(err), EXIT_BAD_INPUT, as_json)


def _print_outcomes(res):
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"{len(res.outcomes)} experiments, {res.seconds:.1f} s, {res.scheduler}")
    table.add_column("experiment")
    steps = []
    for o in res.outcomes:
        for s in o.steps:
            if s.name not in steps:
                steps.append(s.name)
    for s in steps:
        table.add_column(s)
    table.add_column("error", overflow="fold")
    style = {"done": "green", "skipped": "dim", "failed": "bold red", "not_run": "yellow"}
    for o in res.outcomes:
        cells = []
        for name in steps:
            st = o.step(name)
            cells.append("" if st is None else f"[{style.get(st.status, '')}]{st.status}[/]")
        table.add_row(o.name or o.path, *cells, o.error.splitlines()[0] if o.error else "")
    Console(stderr=False).print(table)


@app.command()
def init(
    directory: Annotated[Path, typer.Argument(help="Experiment folder (created if missing).")],
    name: Annotated[str, typer.Option(help="Experiment name (default: the folder name).")] = "",
    material: Annotated[str, typer.Option(help="Material preset: PDMS or PEO_PDMS.")] = "PDMS",
    frames: Annotated[str, typer.Option(help="Frames: glob, file or folder, relative to DIR.")] = "frames/*.tif",
    condition: Annotated[str, typer.Option(help="Condition label for grouping.")] = "",
    force: Annotated[bool, typer.Option("--force", help="Replace an existing experiment.toml (a .bak is kept).")]
    = False,
    quiet: _QUIET = False,
    as_json: _JSON = False,
):
    """Write a commented experiment.toml template into DIR."""
    from osmobulge.experiments.metadata import write_template

    try:
        path = write_template(directory, name=name or None, material=material, frames=frames,
                              condition=condition, force=force)
    except (FileExistsError, ValueError) as err:
        _fail(str(err), EXIT_BAD_INPUT, as_json)
    if as_json:
        typer.echo(json.dumps({"exit_code": 0, "path": str(path)}))
    elif not quiet:
        typer.echo(f"wrote {path}; edit it, put the frames in place, then `osmobulge run {directory}`")


@app.command()
def process(dirs: _DIRS, scheduler: _SCHED = "processes", workers: _WORKERS = 0, force: _FORCE = False,
            quiet: _QUIET = False, as_json: _JSON = False):
    """Extract profiles and volumes from the frames -> DIR/results/extraction.nc."""
    _batch(dirs, ["process"], scheduler=scheduler, workers=workers, force=force, quiet=quiet, as_json=as_json)


@app.command()
def fit(dirs: _DIRS,
        model: Annotated[list[str], typer.Option("--model", "-m", help="constant_linear, constant_hyperelastic or "
                                                 "double_exponential (repeat; default: [analysis] models).")] = None,
        scheduler: _SCHED = "processes", workers: _WORKERS = 0, force: _FORCE = False, quiet: _QUIET = False,
        as_json: _JSON = False):
    """Fit the permeability models (processing first if needed) -> DIR/results/fits.json, fits.nc."""
    from osmobulge.experiments.metadata import MODELS

    bad = [m for m in (model or []) if m not in MODELS]
    if bad:
        _fail(f"--model {bad[0]!r}: expected one of {', '.join(MODELS)}", EXIT_BAD_INPUT, as_json)
    options = {"models": list(model)} if model else None
    _batch(dirs, ["fit"], scheduler=scheduler, workers=workers, force=force, quiet=quiet, as_json=as_json,
           options=options)


@app.command()
def report(dirs: _DIRS, scheduler: _SCHED = "processes", workers: _WORKERS = 0, force: _FORCE = False,
           quiet: _QUIET = False, as_json: _JSON = False):
    """Write the HTML report (processing and fitting first if needed) -> DIR/results/report.html."""
    _batch(dirs, ["report"], scheduler=scheduler, workers=workers, force=force, quiet=quiet, as_json=as_json)


@app.command()
def run(dirs: _DIRS, scheduler: _SCHED = "processes", workers: _WORKERS = 0, force: _FORCE = False,
        quiet: _QUIET = False, as_json: _JSON = False):
    """process + fit + report for every experiment (skips what is up to date)."""
    _batch(dirs, ["process", "fit", "report"], scheduler=scheduler, workers=workers, force=force, quiet=quiet,
           as_json=as_json)


@app.command()
def catalog(
    root: Annotated[list[Path], typer.Argument(help="Folder(s) searched for experiments.")],
    as_json: _JSON = False,
    csv: Annotated[bool, typer.Option("--csv", help="Print CSV.")] = False,
    group_by: Annotated[str, typer.Option("--group-by", help="Also summarise per condition: comma-separated "
                                          "keys among geometry, loading, material, condition.")] = "",
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print nothing: the exit code tells whether "
                                        "experiments were found (0) or not (2).")] = False,
):
    """Table of every experiment under ROOT: metadata, status, frames kept/excluded, P_w(1), fit quality."""
    import math

    from osmobulge.experiments.catalog import catalog as make_catalog
    from osmobulge.experiments.catalog import group_catalog

    if as_json and csv:
        _fail("give --json or --csv, not both", EXIT_BAD_INPUT)
    for r in root:
        if not Path(r).is_dir():
            _fail(f"{r}: not a folder", EXIT_BAD_INPUT, as_json)
    df = make_catalog(root)
    groups = None
    if group_by:
        try:
            groups = group_catalog(df, [g.strip() for g in group_by.split(",") if g.strip()])
        except ValueError as err:
            _fail(f"--group-by: {err}", EXIT_BAD_INPUT, as_json)
    if quiet:
        pass
    elif as_json:
        clean = lambda v: None if isinstance(v, float) and math.isnan(v) else v  # noqa: E731
        rows = [{k: clean(v) for k, v in r.items()} for r in df.to_dict(orient="records")]
        if groups is not None:
            g = groups.reset_index()
            typer.echo(json.dumps({"experiments": rows, "groups": [{k: clean(v) for k, v in r.items()}
                                                                    for r in g.to_dict(orient="records")]}))
        else:
            typer.echo(json.dumps(rows))
    elif csv:
        typer.echo((groups if groups is not None else df).to_csv(index=groups is not None), nl=False)
    else:
        _print_catalog(df, groups)
    raise typer.Exit(EXIT_BAD_INPUT if df.empty else 0)


def _fmt(v, spec):
    import math

    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    try:
        return format(v, spec)
    except (TypeError, ValueError):
        return str(v)


def _print_catalog(df, groups):
    from rich.console import Console
    from rich.table import Table

    console = Console()
    if not console.is_terminal:  # piped into a file or a pager: no terminal width to respect
        console = Console(width=max(console.width, 160))
    table = Table(title=f"{len(df)} experiments")
    cols = [("name", "", "s"), ("condition", "", "s"), ("status", "", "s"), ("material", "", "s"),
            ("radius_um", "a um", "g"), ("membrane_thickness_um", "l0 um", "g"), ("concentration_M", "C0 M", "g"),
            ("n_kept", "kept", "g"), ("n_excluded", "excl", "g"), ("n_flagged", "flag", "g"),
            ("P_w1", "P_w(1) m2/s", ".3e"), ("fit_rms", "rms V/V0", ".2g"), ("fit_model", "model", "s")]
    for key, head, spec in cols:
        table.add_column(head or key, justify="left" if spec == "s" else "right",
                         overflow="fold" if spec == "s" else "ellipsis", no_wrap=spec != "s")
    for _, row in df.iterrows():
        table.add_row(*[_fmt(row[c], spec) for c, _, spec in cols])
    console.print(table)
    if groups is not None:
        gt = Table(title="per condition")
        for n in groups.index.names:
            gt.add_column(str(n))
        for c in groups.columns:
            gt.add_column(c, justify="right")
        for key, row in groups.iterrows():
            key = key if isinstance(key, tuple) else (key,)
            gt.add_row(*map(str, key), *[_fmt(v, ".3g") for v in row.values])
        console.print(gt)


@app.command()
def campaign(
    dirs: _DIRS,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder of the campaign report.")] = Path("campaign"),
    group_by: Annotated[str, typer.Option("--group-by", help="Simultaneous fits per group: material (paper's "
                                          "Table 3) or condition, geometry, loading.")] = "material",
    scheduler: _SCHED = "processes", workers: _WORKERS = 0, quiet: _QUIET = False, as_json: _JSON = False,
):
    """Run every experiment, then fit each group simultaneously -> OUT/campaign.json, campaign.nc, report.html."""
    from osmobulge.experiments.runs import run_campaign

    paths = _expand(dirs, as_json)
    res = _run_batch(paths, ["process", "fit", "report"], scheduler=scheduler, workers=workers,
                     progress=not (quiet or as_json), as_json=as_json)
    ok = [Path(o.path) for o in res.outcomes if o.status == "ok"]
    if not ok:
        _fail("campaign: no experiment ran successfully: " + "; ".join(f"{o.path}: {o.error}" for o in
                                                                        res.outcomes), res.exit_code, as_json)
    try:
        summary = run_campaign(ok, out, group_by=group_by, progress=not (quiet or as_json))
    except ValueError as err:
        _fail(str(err), EXIT_BAD_INPUT, as_json)
    if as_json:
        typer.echo(json.dumps({"batch": res.to_dict(), "campaign": summary}, default=str))
    elif not quiet:
        _print_outcomes(res)
        _print_campaign(summary)
    raise typer.Exit(res.exit_code)


def _print_campaign(summary):
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"campaign fits -> {summary.get('report')}")
    for c in ("group", "experiments", "model", "P_w(1) m2/s", "stderr", "rms V/V0"):
        table.add_column(c)
    for g in summary.get("groups", []):
        for name, m in g.get("models", {}).items():
            table.add_row(g["group"], str(g["n_experiments"]), name, _fmt(m.get("P_w1"), ".4e"),
                          _fmt(m.get("P_w1_stderr"), ".2e"), _fmt(m.get("rms"), ".3g") if m.get("ok") else
                          m.get("error", "")[:60])
    Console().print(table)


@app.command()
def demo(
    directory: Annotated[Path, typer.Argument(help="Folder for the demo campaign.")] = Path("osmobulge-demo"),
    chambers: Annotated[int, typer.Option(help="Chambers per condition.")] = 2,
    workers: _WORKERS = 0,
    scheduler: _SCHED = "processes",
    force: _FORCE = False,
    quiet: _QUIET = False,
    as_json: _JSON = False,
):
    """Write a small synthetic campaign (the paper's five conditions) and run it end to end to reports."""
    from osmobulge.experiments.demo import run_demo

    try:
        summary = run_demo(directory, chambers=chambers, workers=workers or None, scheduler=scheduler,
                           force=force, progress=not (quiet or as_json))
    except ImportError as err:
        _fail(str(err), EXIT_ENVIRONMENT, as_json)
    except (OSError, TimeoutError) as err:
        _fail(f"cannot reach the scheduler {scheduler!r}: {err}", EXIT_ENVIRONMENT, as_json)
    except (FileExistsError, ValueError) as err:
        _fail(str(err), EXIT_BAD_INPUT, as_json)
    if as_json:
        typer.echo(json.dumps(summary, default=str))
    elif not quiet:
        from rich.console import Console
        from rich.table import Table

        t = Table(title=f"demo: {summary['n_experiments']} experiments in {summary['seconds']:.0f} s "
                  f"-> {summary['campaign_report']}")
        for c in ("material", "P_w(1) fitted m2/s", "truth m2/s", "error %"):
            t.add_column(c)
        for row in summary["recovery"]:
            t.add_row(row["material"], _fmt(row["P_w1"], ".4e"), _fmt(row["P_w1_true"], ".4e"),
                      _fmt(row["rel_error"] * 100 if row["rel_error"] is not None else None, ".2f"))
        Console().print(t)
    raise typer.Exit(summary["exit_code"])
