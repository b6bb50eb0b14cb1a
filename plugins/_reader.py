"""napari reader for experiment folders (a folder holding ``experiment.toml``).

Opening a folder gives the frame stack as an image layer (axes frame, y, x;
scale = the pixel size in micrometres) and, once the experiment has been
processed (``DIR/results/extraction.nc``), the automatic profiles as a shapes
layer of paths, one per frame.  The :class:`~osmobulge.plugins._session.CurationSession`
behind the widgets travels in the image layer's metadata.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["napari_get_reader", "read_experiment", "experiment_layer_data", "find_session", "SESSION_KEY"]

EXPERIMENT_FILE = "experiment.toml"
#: key of the image layer's metadata holding ``{"folder": str, "session": CurationSession}``
SESSION_KEY = "osmobulge"
AXIS_LABELS = ("frame", "y", "x")
UNITS = ("", "um", "um")
AUTO_LAYER = "auto profiles"


def _experiment_folder(path) -> Path | None:
    if isinstance(path, list | tuple):
        if len(path) != 1:
            return None
        path = path[0]
    try:
        p = Path(path)
    except TypeError:
        return None
    if p.name == EXPERIMENT_FILE:
        p = p.parent
    return p if p.is_dir() and (p / EXPERIMENT_FILE).is_file() else None


def napari_get_reader(path):
    """npe2 reader hook: a reader for experiment folders, else None.

    Parameters
    ----------
    path : str or list of str
        A folder holding ``experiment.toml`` (or that file itself).

    Returns
    -------
    callable or None
        :func:`read_experiment` when ``path`` is an experiment folder.
    """
    return read_experiment if _experiment_folder(path) is not None else None


def auto_profile_layer_data(session) -> tuple:
    """Shapes layer data of the automatic profiles: one path ``(frame, row, col)`` per traced frame.

    Returns
    -------
    tuple
        ``(data, kwargs, "shapes")`` (napari LayerData).
    """
    paths = []
    for f in range(session.n_frames):
        prof = session.auto_profile_rc(f)
        if prof is not None and len(prof) >= 2:
            paths.append(np.column_stack([np.full(len(prof), f, float), prof]))
    p_um = session.pixel_size * 1e6
    kwargs = {
        "name": AUTO_LAYER,
        "shape_type": "path",
        "edge_color": "yellow",
        "edge_width": 1.0,
        "scale": (1.0, p_um, p_um),
        "axis_labels": AXIS_LABELS,
        "units": UNITS,
        "opacity": 0.8,
        "ndim": 3,
    }
    return (paths, kwargs, "shapes")


def experiment_layer_data(session) -> list[tuple]:
    """napari LayerData of an open :class:`~osmobulge.plugins._session.CurationSession`.

    Returns
    -------
    list of tuple
        The image layer (lazy frames, ``scale = (1, p, p)`` um, the session in
        ``metadata["osmobulge"]``) and, if processed, the automatic profiles.
    """
    p_um = session.pixel_size * 1e6
    first = np.asarray(session.frames[0])
    lo, hi = (float(v) for v in np.percentile(first, [0.5, 99.5]))
    if hi <= lo:
        hi = lo + 1.0
    image = (
        session.frames,
        {
            "name": session.experiment.name,
            "scale": (1.0, p_um, p_um),
            "axis_labels": AXIS_LABELS,
            "units": UNITS,
            "contrast_limits": (lo, hi),
            "colormap": "gray",
            "metadata": {SESSION_KEY: {"folder": str(session.folder), "session": session}},
        },
        "image",
    )
    layers = [image]
    if session.extraction is not None:
        layers.append(auto_profile_layer_data(session))
    return layers


def read_experiment(path) -> list[tuple]:
    """Open an experiment folder for napari (see :func:`experiment_layer_data`)."""
    from osmobulge.plugins._session import CurationSession

    folder = _experiment_folder(path)
    if folder is None:
        raise ValueError(f"{path}: not an experiment folder (no {EXPERIMENT_FILE})")
    return experiment_layer_data(CurationSession(folder))


def find_session(viewer):
    """The :class:`CurationSession` of the experiment open in a viewer (the selected one first).

    Parameters
    ----------
    viewer : napari.Viewer or napari.components.ViewerModel

    Returns
    -------
    CurationSession or None
    """
    layers = list(viewer.layers.selection) + list(viewer.layers)
    for layer in layers:
        meta = getattr(layer, "metadata", {}).get(SESSION_KEY)
        if meta:
            if meta.get("session") is None:
                from osmobulge.plugins._session import CurationSession

                meta["session"] = CurationSession(meta["folder"])
            return meta["session"]
    return None
