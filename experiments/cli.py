"""The ``osmobulge`` command line (typer).

Commands are thin: they parse options, call library functions and write files.
Each topic registers its commands from its own module (``_cli_*.py``).
"""

from __future__ import annotations

import importlib
import importlib.util

import typer

from osmobulge import __version__

app = typer.Typer(
    name="osmobulge",
    help="Membrane permeability from time-lapse micrographs of osmotic microactuators.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _version_callback(value: bool):
    if value:
        typer.echo(f"osmobulge {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version_callback, is_eager=True, help="Print the version and exit."
    ),
):
    """osmobulge: membrane bulge mechanics, flux model, fits, image pipeline and reports."""


# Topic modules register their commands on ``app`` when imported.  A module
# that does not exist (yet) is skipped; one that exists but fails to import raises.
_TOPICS = ("_cli_modeling", "_cli_transport", "_cli_imaging", "_cli_runs", "_cli_plugins")
for _topic in _TOPICS:
    if importlib.util.find_spec(f"osmobulge.experiments.{_topic}") is not None:
        importlib.import_module(f"osmobulge.experiments.{_topic}")


def main() -> None:  # entry point of the console script
    app()


if __name__ == "__main__":
    # run the canonical module's app: topic modules register on osmobulge.experiments.cli.app,
    # not on this __main__ copy
    from osmobulge.experiments.cli import main as _main

    _main()
