"""Micrograph readers, the synthetic renderer and profile extraction.

Readers (:mod:`osmobulge.imaging.io`) open TIFF/OME-TIFF, CZI or image folders
lazily; :mod:`osmobulge.imaging.synthetic` renders cross-section series with
known ground truth; :func:`extract` turns a series into an ``xarray.Dataset``.
"""

from osmobulge.imaging.extract import extract, load_extraction, save_extraction
from osmobulge.imaging.geometry import (
    EllipseFit,
    ProfileSpline,
    fit_ellipse,
    revolution_area,
    revolution_measures,
    revolution_volume,
    smooth_profile,
    to_chamber_frame,
)
from osmobulge.imaging.io import FrameReadError, FrameSeries, MetadataError, open_series, read_truth, write_series
from osmobulge.imaging.synthetic import (
    Nuisances,
    SceneGeometry,
    SyntheticSeries,
    render_frame,
    render_series,
    render_simulation,
)
from osmobulge.imaging.trace import FLAGS, ChamberTracer, TraceSettings

__all__ = [
    "extract",
    "save_extraction",
    "load_extraction",
    "EllipseFit",
    "ProfileSpline",
    "fit_ellipse",
    "smooth_profile",
    "revolution_measures",
    "revolution_volume",
    "revolution_area",
    "to_chamber_frame",
    "ChamberTracer",
    "TraceSettings",
    "FLAGS",
    "FrameSeries",
    "MetadataError",
    "FrameReadError",
    "open_series",
    "write_series",
    "read_truth",
    "SceneGeometry",
    "Nuisances",
    "SyntheticSeries",
    "render_series",
    "render_frame",
    "render_simulation",
]
