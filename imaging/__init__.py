"""Micrograph readers, the synthetic renderer and profile extraction.

Readers (:mod:`osmobulge.imaging.io`) open TIFF/OME-TIFF, CZI or image folders
lazily; :mod:`osmobulge.imaging.synthetic` renders cross-section series with
known ground truth; :func:`extract` turns a series into an ``xarray.Dataset``.
"""

from osmobulge.imaging.io import FrameReadError, FrameSeries, MetadataError, open_series, read_truth, write_series
from osmobulge.imaging.synthetic import (
    Nuisances,
    SceneGeometry,
    SyntheticSeries,
    render_frame,
    render_series,
    render_simulation,
)

__all__ = [
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
