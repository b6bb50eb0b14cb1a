"""Import and export picked membrane points as CSV tables and ImageJ ROI files.

Picked points are kept per frame as ``{frame: ndarray of shape (N, 2)}`` in napari's
pixel convention: ``(row, col)`` with the centre of pixel ``(i, j)`` at ``(i, j)``.
These functions need no Qt and no napari, so annotation can be scripted::

    pts = read_points("annotated.zip")          # ImageJ ROI set, one ROI per frame
    write_points_csv("picked.csv", pts)          # frame, x_px, y_px

ImageJ puts pixel corners at integer coordinates (the centre of pixel ``(i, j)`` is at
``x = j + 0.5, y = i + 0.5``) when a ROI stores sub-pixel (float) coordinates, while integer
point coordinates name the pixel itself. Export therefore writes float coordinates shifted by
``+0.5`` and import undoes the shift for sub-pixel ROIs only.
"""

from __future__ import annotations

import csv
import io
import os
import re
import tempfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

__all__ = [
    "IMAGEJ_PIXEL_CENTER",
    "ROI_KINDS",
    "read_points",
    "read_points_csv",
    "read_points_imagej",
    "write_points",
    "write_points_csv",
    "write_points_imagej",
]

#: Offset between napari's pixel-centre and ImageJ's pixel-corner sub-pixel coordinates, px.
IMAGEJ_PIXEL_CENTER = 0.5
#: ImageJ ROI types written by :func:`write_points_imagej`.
ROI_KINDS = ("point", "polyline")

_CSV_PX = ("x_px", "y_px")
_CSV_UM = ("x_um", "y_um")
_NAME_RE = re.compile(r"frame[-_ ]?(\d+)", re.IGNORECASE)


def _as_points(points: Mapping[int, object]) -> dict[int, np.ndarray]:
    out: dict[int, np.ndarray] = {}
    for frame, pts in points.items():
        arr = np.asarray(pts, dtype=float).reshape(-1, 2) if np.size(pts) else np.empty((0, 2))
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"points of frame {frame} contain non-finite coordinates")
        if int(frame) != frame or frame < 0:
            raise ValueError(f"frame must be a non-negative integer, got {frame!r}")
        out[int(frame)] = arr
    return out


# ---------------------------------------------------------------------------- CSV


def write_points_csv(path, points: Mapping[int, object], *, pixel_size_um: float | None = None) -> Path:
    """Write picked points to a CSV table, one row per point.

    Parameters
    ----------
    path : str or Path
        Output file (``.csv``); written atomically.
    points : mapping of int to array_like of shape (N, 2), px
        ``(row, col)`` pixel coordinates per frame index.
    pixel_size_um : float, um, optional
        If given, ``x_um`` and ``y_um`` columns are added (pixel coordinate times pixel size).

    Returns
    -------
    Path
        The file written.

    Notes
    -----
    Columns: ``frame`` (0-based), ``point`` (order within the frame), ``x_px`` (column),
    ``y_px`` (row) and, with a pixel size, ``x_um``, ``y_um``.
    """
    from osmobulge.experiments._io import atomic_write_text

    pts = _as_points(points)
    if pixel_size_um is not None and not (np.isfinite(pixel_size_um) and pixel_size_um > 0):
        raise ValueError(f"pixel_size_um must be a positive number of micrometres, got {pixel_size_um!r}")
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    header = ["frame", "point", *_CSV_PX]
    if pixel_size_um is not None:
        header += list(_CSV_UM)
    writer.writerow(header)
    for frame in sorted(pts):
        for k, (row, col) in enumerate(pts[frame]):
            line = [frame, k, repr(float(col)), repr(float(row))]
            if pixel_size_um is not None:
                line += [repr(float(col * pixel_size_um)), repr(float(row * pixel_size_um))]
            writer.writerow(line)
    return atomic_write_text(path, buf.getvalue())


def read_points_csv(path, *, pixel_size_um: float | None = None) -> dict[int, np.ndarray]:
    """Read picked points from a CSV table.

    Parameters
    ----------
    path : str or Path
        A CSV file with a ``frame`` column and either ``x_px``/``y_px`` (pixels) or
        ``x_um``/``y_um`` (micrometres, then ``pixel_size_um`` is required). A ``point``
        column, if present, gives the order of the points within each frame.
    pixel_size_um : float, um, optional
        Pixel size used to convert micrometre columns to pixels.

    Returns
    -------
    dict of int to ndarray of shape (N, 2), px
        ``(row, col)`` per frame.

    Raises
    ------
    ValueError
        If a required column is missing or a value is not a number.
    """
    path = Path(path)
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        cols = [c.strip() for c in (reader.fieldnames or [])]
        rows = [{k.strip(): v for k, v in r.items() if k is not None} for r in reader]
    if "frame" not in cols:
        raise ValueError(f"{path}: CSV needs a 'frame' column, found {cols}")
    if all(c in cols for c in _CSV_PX):
        xk, yk, scale = *_CSV_PX, 1.0
    elif all(c in cols for c in _CSV_UM):
        if pixel_size_um is None or not pixel_size_um > 0:
            raise ValueError(f"{path}: columns x_um/y_um need pixel_size_um (um per px), got {pixel_size_um!r}")
        xk, yk, scale = *_CSV_UM, 1.0 / pixel_size_um
    else:
        raise ValueError(f"{path}: CSV needs columns x_px,y_px (pixels) or x_um,y_um (micrometres), found {cols}")
    grouped: dict[int, list[tuple[float, float, float]]] = {}
    for i, r in enumerate(rows, start=2):
        try:
            frame_f = float(r["frame"])
            x, y = float(r[xk]) * scale, float(r[yk]) * scale
            order = float(r["point"]) if r.get("point") not in (None, "") else float(i)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}, line {i}: not a number in {r}") from exc
        if frame_f != int(frame_f) or frame_f < 0:
            raise ValueError(f"{path}, line {i}: frame must be a non-negative integer, got {r['frame']!r}")
        grouped.setdefault(int(frame_f), []).append((order, y, x))
    out = {}
    for frame, items in grouped.items():
        items.sort(key=lambda t: t[0])
        out[frame] = np.array([(y, x) for _, y, x in items], dtype=float)
    return _as_points(out)


# ---------------------------------------------------------------------- ImageJ ROI


def _frame_of(roi, fallback: int) -> int:
    for pos in (roi.t_position, roi.position, roi.z_position):
        if pos and pos > 0:
            return int(pos) - 1
    m = _NAME_RE.search(roi.name or "")
    if m:
        return int(m.group(1))
    return fallback


def write_points_imagej(path, points: Mapping[int, object], *, kind: str = "point") -> Path:
    """Write picked points as ImageJ ROIs: one multi-point (or polyline) ROI per frame.

    Parameters
    ----------
    path : str or Path
        ``.zip`` (a ROI set, any number of frames) or ``.roi`` (exactly one frame).
    points : mapping of int to array_like of shape (N, 2), px
        ``(row, col)`` pixel coordinates per frame index.
    kind : {"point", "polyline"}
        ImageJ ROI type: a multi-point selection or a segmented line through the points.

    Returns
    -------
    Path
        The file written (atomically).

    Notes
    -----
    Each ROI is named ``frame-NNNN`` and carries the frame as its stack position and
    ``t_position`` (1-based, as ImageJ counts). Coordinates are stored with sub-pixel
    resolution in ImageJ's pixel-corner convention (``+0.5`` px).
    """
    import roifile

    from osmobulge.experiments._io import atomic_write_bytes

    if kind not in ROI_KINDS:
        raise ValueError(f"kind must be one of {ROI_KINDS}, got {kind!r}")
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".zip", ".roi"):
        raise ValueError(f"path must end in .zip (ROI set) or .roi (one frame), got {path.name!r}")
    pts = {f: p for f, p in _as_points(points).items() if len(p)}
    if not pts:
        raise ValueError("points holds no frame with points; nothing to write")
    if suffix == ".roi" and len(pts) != 1:
        raise ValueError(f"a .roi file holds one frame, got {len(pts)} frames; use a .zip ROI set")
    rois = []
    for frame in sorted(pts):
        xy = pts[frame][:, ::-1] + IMAGEJ_PIXEL_CENTER
        roi = roifile.ImagejRoi.frompoints(xy.astype(np.float64), name=f"frame-{frame:04d}", position=frame, t=frame)
        roi.roitype = roifile.ROI_TYPE.POINT if kind == "point" else roifile.ROI_TYPE.POLYLINE
        rois.append(roi)
    if suffix == ".roi":
        return atomic_write_bytes(path, rois[0].tobytes())
    # roifile writes zip archives to a file name; write next to the target, then move atomically
    fd, tmp = tempfile.mkstemp(dir=path.parent if path.parent.exists() else None, suffix=".zip")
    os.close(fd)
    try:
        roifile.roiwrite(tmp, rois, mode="w")
        data = Path(tmp).read_bytes()
    finally:
        Path(tmp).unlink(missing_ok=True)
    return atomic_write_bytes(path, data)


def read_points_imagej(path) -> dict[int, np.ndarray]:
    """Read picked points from an ImageJ ``.roi`` file or ``.zip`` ROI set.

    Parameters
    ----------
    path : str or Path
        The ROI file. Point, multi-point, polyline, freeline, polygon and freehand ROIs
        are accepted; their vertices are the points.

    Returns
    -------
    dict of int to ndarray of shape (N, 2), px
        ``(row, col)`` per frame in napari's pixel-centre convention. The frame comes from
        the ROI's ``t_position``, else its stack ``position``, else a ``frame-N`` name,
        else the ROI's index in the set. Several ROIs on one frame are concatenated.
    """
    import roifile

    path = Path(path)
    if path.suffix.lower() not in (".zip", ".roi"):
        raise ValueError(f"path must be an ImageJ .roi or .zip file, got {path.name!r}")
    rois = roifile.roiread(path)
    if not isinstance(rois, list):
        rois = [rois]
    out: dict[int, list[np.ndarray]] = {}
    for i, roi in enumerate(rois):
        xy = np.asarray(roi.coordinates(), dtype=float).reshape(-1, 2)
        if roi.subpixel_coordinates is not None:
            xy = xy - IMAGEJ_PIXEL_CENTER
        out.setdefault(_frame_of(roi, i), []).append(xy[:, ::-1])
    return {f: np.concatenate(v) for f, v in sorted(out.items())}


# ------------------------------------------------------------------ by extension


def write_points(path, points: Mapping[int, object], **kwargs) -> Path:
    """Write picked points, choosing the format from the extension (.csv, .zip, .roi).

    Parameters
    ----------
    path : str or Path
        Output file.
    points : mapping of int to array_like of shape (N, 2), px
        ``(row, col)`` per frame.
    **kwargs
        Passed to :func:`write_points_csv` or :func:`write_points_imagej`.

    Returns
    -------
    Path
        The file written.
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".csv":
        return write_points_csv(path, points, **kwargs)
    if suffix in (".zip", ".roi"):
        return write_points_imagej(path, points, **kwargs)
    raise ValueError(f"path must end in .csv, .zip or .roi, got {Path(path).name!r}")


def read_points(path, **kwargs) -> dict[int, np.ndarray]:
    """Read picked points, choosing the format from the extension (.csv, .zip, .roi).

    Parameters
    ----------
    path : str or Path
        Input file.
    **kwargs
        Passed to :func:`read_points_csv`.

    Returns
    -------
    dict of int to ndarray of shape (N, 2), px
        ``(row, col)`` per frame.
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".csv":
        return read_points_csv(path, **kwargs)
    if suffix in (".zip", ".roi"):
        return read_points_imagej(path)
    raise ValueError(f"path must end in .csv, .zip or .roi, got {Path(path).name!r}")
