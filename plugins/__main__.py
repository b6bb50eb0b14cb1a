"""``python -m osmobulge.plugins DIR [--frame N]``: open an experiment in napari with the osmobulge widgets."""

from __future__ import annotations

import argparse


def main(argv=None) -> int:
    """Open the experiment folder and run the napari event loop."""
    parser = argparse.ArgumentParser(prog="python -m osmobulge.plugins", description=__doc__)
    parser.add_argument("folder", help="experiment folder (holding experiment.toml)")
    parser.add_argument("--frame", type=int, default=0, help="frame to show first (0-based)")
    args = parser.parse_args(argv)
    import napari

    from osmobulge.plugins._widget import open_experiment

    open_experiment(args.folder, frame=args.frame)
    napari.run()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
