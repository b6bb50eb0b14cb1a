"""Qt-free logic behind the osmobulge napari widgets.

Everything the dock widgets do lives here as plain functions and one state
object, :class:`CurationSession`, so it runs (and is tested) with no Qt and no
display.  The numerics are the imaging library's: sub-pixel edge tracing and
snapping (:mod:`osmobulge.imaging.trace`), ellipse and spline fits and the
solid-of-revolution volume and area (:mod:`osmobulge.imaging.geometry`), and the
extraction itself (:func:`osmobulge.imaging.extract`).  Decisions are stored
with :mod:`osmobulge.experiments.curation` (atomic writes).

Coordinates
-----------
- napari layers of an experiment: data ``(frame, row, col)`` in pixels, with the
  image's ``scale = (1, p, p)`` (``p`` the pixel size in micrometres), so world
  coordinates are ``(frame, y_um, x_um)``.
- picked points, per frame: ``ndarray of shape (N, 2)``, ``(row, col)`` px.
- the curation's manual profiles: ``(x, y)`` in metres, ``x = col * p``,
  ``y = row * p`` (see :func:`osmobulge.experiments.curation.set_manual_profile`).
- chamber coordinates: signed radial position and height above the flat
  membrane (:func:`osmobulge.imaging.geometry.to_chamber_frame`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree, shortest_path
from scipy.spatial.distance import pdist, squareform

from osmobulge.imaging._chamber import band_edges
from osmobulge.imaging._normals import polyline_normals, sample_normals
from osmobulge.imaging.geometry import (
    EllipseFit,
    fit_ellipse,
    revolution_measures,
    smooth_profile,
    to_chamber_frame,
)

__all__ = [
    "BULGE_DIRECTIONS",
    "ChamberGeometry",
    "POLARITIES",
    "ProfileFit",
    "SnapResult",
    "fit_picked_profile",
    "geometry_from_points",
    "layer_data_to_picks",
    "order_along_curve",
    "picks_to_layer_data",
    "points_m_to_rc",
    "points_rc_to_m",
    "snap_points",
]

#: membrane contrast: +1 dark band on a light background, -1 bright band, or detect it
POLARITIES = ("auto", 1, -1)
#: how the end (rim) points are snapped
SNAP_ENDS = ("flat", "normal")
#: bulge directions in the image, and the unit ``(dcol, drow)`` vector of each
BULGE_DIRECTIONS = {"up": (0.0, -1.0), "down": (0.0, 1.0), "left": (-1.0, 0.0), "right": (1.0, 0.0)}


# --------------------------------------------------------------------------- conversions
def picks_to_layer_data(picks: Mapping[int, np.ndarray]) -> np.ndarray:
    """Per-frame ``(row, col)`` points -> napari points data ``(frame, row, col)``.

    Parameters
    ----------
    picks : mapping of int to ndarray of shape (N, 2), px

    Returns
    -------
    ndarray of shape (M, 3)
        Rows sorted by frame, the order within each frame kept.
    """
    rows = [np.column_stack([np.full(len(p), f, float), np.asarray(p, float).reshape(-1, 2)])
            for f, p in sorted(picks.items()) if len(p)]
    return np.concatenate(rows) if rows else np.empty((0, 3))


def layer_data_to_picks(data) -> dict[int, np.ndarray]:
    """napari points data ``(frame, row, col)`` -> per-frame ``(row, col)`` points.

    Parameters
    ----------
    data : array_like of shape (M, 3)
        The frame coordinate is rounded to the nearest integer.

    Returns
    -------
    dict of int to ndarray of shape (N, 2), px
    """
    data = np.asarray(data, float).reshape(-1, 3)
    frames = np.rint(data[:, 0]).astype(int)
    return {int(f): data[frames == f, 1:].copy() for f in np.unique(frames)}


def points_rc_to_m(points_rc, pixel_size: float) -> np.ndarray:
    """``(row, col)`` px -> the curation's ``(x, y)`` m.

    Parameters
    ----------
    points_rc : array_like of shape (N, 2), px
    pixel_size : float, m

    Returns
    -------
    ndarray of shape (N, 2), m
    """
    p = np.asarray(points_rc, float).reshape(-1, 2)
    return p[:, ::-1] * float(pixel_size)


def points_m_to_rc(points_m, pixel_size: float) -> np.ndarray:
    """The curation's ``(x, y)`` m -> ``(row, col)`` px (inverse of :func:`points_rc_to_m`).

    Parameters
    ----------
    points_m : array_like of shape (N, 2), m
    pixel_size : float, m

    Returns
    -------
    ndarray of shape (N, 2), px
    """
    p = np.asarray(points_m, float).reshape(-1, 2)
    return p[:, ::-1] / float(pixel_size)


# --------------------------------------------------------------------------- ordering
def order_along_curve(points_rc) -> np.ndarray:
    """Order clicked points along the curve they sample (click order does not matter).

    Parameters
    ----------
    points_rc : array_like of shape (N, 2)

    Returns
    -------
    ndarray of int, shape (N,)
        Permutation putting the points in order from one end of the curve to the
        other, starting at the end with the smaller column (then row).

    Notes
    -----
    The ends are the two ends of the longest path through the points' Euclidean
    minimum spanning tree; points are then visited along that path, and any
    point off it (a side branch) is inserted next to its nearest path point.
    For points spread along a curve the spanning tree is the curve itself, so
    the order holds for domes that overhang their rim, where sorting by a
    coordinate fails.
    """
    p = np.asarray(points_rc, float).reshape(-1, 2)
    n = len(p)
    if n < 3:
        return np.arange(n)
    dist = squareform(pdist(p))
    mst = minimum_spanning_tree(dist)
    hops = shortest_path(mst, directed=False)
    end_a = int(np.argmax(hops[0]))
    end_b = int(np.argmax(hops[end_a]))
    _, pred = breadth_first_order(mst, end_a, directed=False, return_predecessors=True)
    path = [end_b]
    while path[-1] != end_a:
        path.append(int(pred[path[-1]]))
    path = path[::-1]
    on_path = set(path)
    order = list(path)
    # off-path points: insert next to the nearest path point, on the side of its nearer neighbour
    for i in (j for j in range(n) if j not in on_path):
        k = int(np.argmin(dist[i, order]))
        before = dist[i, order[k - 1]] if k > 0 else np.inf
        after = dist[i, order[k + 1]] if k + 1 < len(order) else np.inf
        order.insert(k if before < after else k + 1, i)
    order = np.asarray(order)
    # a fixed direction: from the end with the smaller column (then row) to the other
    if tuple(p[order[-1], ::-1]) < tuple(p[order[0], ::-1]):
        order = order[::-1]
    return order


# --------------------------------------------------------------------------- chamber frame
@dataclass(frozen=True)
class ChamberGeometry:
    """Where the chamber is in a frame: the origin and axes of the chamber coordinates.

    Attributes
    ----------
    axis_point : tuple of float, px
        ``(col, row)`` where the chamber axis meets the flat membrane line.
    angle : float, rad
        Direction of the flat membrane line from the column axis (image tilt).
    up : tuple of float
        Unit bulge direction ``(dcol, drow)`` (default: towards row 0).
    source : str
        Where it came from (``"extraction"``, ``"picked ends"``, ...).
    """

    axis_point: tuple
    angle: float = 0.0
    up: tuple = (0.0, -1.0)
    source: str = ""

    def to_chamber(self, points_rc) -> tuple[np.ndarray, np.ndarray]:
        """``(row, col)`` px -> signed radial position and height (px)."""
        p = np.asarray(points_rc, float).reshape(-1, 2)[:, ::-1]
        return to_chamber_frame(p, axis_point=self.axis_point, angle=self.angle, up=self.up)

    def to_image(self, x, z) -> np.ndarray:
        """Chamber coordinates (px) -> ``(row, col)`` px (inverse of :meth:`to_chamber`)."""
        x, z = np.asarray(x, float), np.asarray(z, float)
        ux, uy = np.cos(self.angle), np.sin(self.angle)
        nx, ny = uy, -ux
        if np.dot((nx, ny), self.up) < 0:
            nx, ny = -nx, -ny
        col = self.axis_point[0] + x * ux + z * nx
        row = self.axis_point[1] + x * uy + z * ny
        return np.column_stack([row, col])


def geometry_from_points(points_rc, *, up=(0.0, -1.0)) -> ChamberGeometry:
    """Chamber frame from picked points whose two ends lie on the rim.

    Parameters
    ----------
    points_rc : array_like of shape (N, 2), px
        Points along the membrane, N >= 2; the ends of the curve are taken as the
        two rim points (the flat membrane line passes through them).
    up : tuple of float
        Bulge direction ``(dcol, drow)``; orients the height axis.

    Returns
    -------
    ChamberGeometry
        Axis point halfway between the ends, angle of the line through them.
    """
    p = np.asarray(points_rc, float).reshape(-1, 2)
    if len(p) < 2:
        raise ValueError(f"points_rc: need at least 2 points to place the rim, got {len(p)}")
    p = p[order_along_curve(p)]
    (r0, c0), (r1, c1) = p[0], p[-1]
    if (c1 - c0) * up[1] - (r1 - r0) * up[0] > 0:  # keep the line direction to the right of `up`
        (r0, c0), (r1, c1) = (r1, c1), (r0, c0)
    angle = float(np.arctan2(r1 - r0, c1 - c0))
    return ChamberGeometry(axis_point=(0.5 * (c0 + c1), 0.5 * (r0 + r1)), angle=angle, up=tuple(up),
                           source="picked ends")


# --------------------------------------------------------------------------- fits
@dataclass(frozen=True)
class ProfileFit:
    """Fits of one frame's picked points (falsy when no spline could be fitted).

    Attributes
    ----------
    points_rc : ndarray of shape (N, 2), px
        The points, ordered along the curve.
    spline_rc : ndarray of shape (M, 2), px
        Smoothing spline through the points, sampled every half pixel (empty if N < 4).
    ellipse_rc : ndarray of shape (K, 2), px
        Arc of the fitted ellipse above the flat membrane line (empty if N < 5 or the fit failed).
    ellipse : EllipseFit
        The ellipse fit in ``(col, row)`` pixel coordinates.
    geometry : ChamberGeometry or None
    volume, area : float, m**3 and m**2
        Solid of revolution of the spline (mean of the two halves), nan without a spline.
    volume_ellipse : float, m**3
        The same for the ellipse arc (the paper's description), nan without an ellipse.
    height : float, m
        Height of the spline on the chamber axis.
    volume_disagreement : float
        ``|V_left - V_right| / V`` of the spline.
    message : str
        Why a fit is missing (empty when both fits exist).
    """

    points_rc: np.ndarray
    spline_rc: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    ellipse_rc: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    ellipse: EllipseFit = field(default_factory=EllipseFit)
    geometry: ChamberGeometry | None = None
    volume: float = np.nan
    area: float = np.nan
    volume_ellipse: float = np.nan
    height: float = np.nan
    volume_disagreement: float = np.nan
    message: str = ""

    def __bool__(self) -> bool:
        return bool(len(self.spline_rc) > 0 and np.isfinite(self.volume))


def _ellipse_arc(ell: EllipseFit, geom: ChamberGeometry, n: int = 721) -> np.ndarray:
    """The arc of the ellipse on the dome side of the flat line, as ``(row, col)`` px."""
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    pts = ell.points(t)  # (col, row)
    _, z = to_chamber_frame(pts, axis_point=geom.axis_point, angle=geom.angle, up=geom.up)
    above = z >= 0
    if above.all() or not above.any():
        return np.empty((0, 2))
    start = int(np.argmax(~above & np.roll(above, -1))) + 1  # first point of the run above the line
    idx = (start + np.arange(n)) % n
    m = int(np.argmin(above[idx]))
    run = idx[:m]
    # close the arc on the line: linear interpolation to z = 0 at both ends
    ends = []
    for i_in, i_out in ((run[0], idx[-1]), (run[-1], idx[m])):
        w = z[i_in] / (z[i_in] - z[i_out])
        ends.append(pts[i_in] + w * (pts[i_out] - pts[i_in]))
    return np.vstack([ends[0], pts[run], ends[1]])[:, ::-1]


def fit_picked_profile(points_rc, *, pixel_size: float, geometry: ChamberGeometry | None = None,
                       sigma: float | None = None, up=(0.0, -1.0)) -> ProfileFit:
    """Ellipse and smoothing spline through picked points, with the dome's volume and area.

    Parameters
    ----------
    points_rc : array_like of shape (N, 2), px
        Membrane points of one frame, in any order (see :func:`order_along_curve`).
    pixel_size : float, m
        Converts pixel results to SI.
    geometry : ChamberGeometry, optional
        The chamber frame (from the extraction); default: the line through the two
        end points (:func:`geometry_from_points`).
    sigma : float, px, optional
        Expected scatter of the points about the membrane (spline smoothing,
        :func:`osmobulge.imaging.geometry.smooth_profile`); default: interpolate.
    up : tuple of float
        Bulge direction ``(dcol, drow)`` when ``geometry`` is not given.

    Returns
    -------
    ProfileFit
        Falsy (with ``message``) with fewer than 4 points or when the curve does
        not cross the chamber axis.

    Notes
    -----
    Volume and area are the solids of revolution of each half profile about
    the chamber axis (main text Sec. 2.3, :func:`osmobulge.imaging.geometry.revolution_measures`).
    """
    if not (np.isfinite(pixel_size) and pixel_size > 0):
        raise ValueError(f"pixel_size must be a positive length in metres, got {pixel_size!r}")
    p = np.asarray(points_rc, float).reshape(-1, 2)
    p = p[np.all(np.isfinite(p), axis=1)]
    if len(p) == 0:
        return ProfileFit(points_rc=p, message="no points")
    p = p[order_along_curve(p)]
    if geometry is None:
        if len(p) < 2:
            return ProfileFit(points_rc=p, message="need at least 2 points")
        geometry = geometry_from_points(p, up=up)
    kw: dict = {"points_rc": p, "geometry": geometry}
    msgs = []
    ell = fit_ellipse(p[:, ::-1]) if len(p) >= 5 else EllipseFit(message=f"need 5 points for an ellipse, got {len(p)}")
    kw["ellipse"] = ell
    if ell:
        arc = _ellipse_arc(ell, geometry)
        kw["ellipse_rc"] = arc
        if len(arc) >= 2:
            x, z = geometry.to_chamber(arc)
            try:
                kw["volume_ellipse"] = revolution_measures(x, z).volume * pixel_size**3
            except ValueError as err:
                msgs.append(f"ellipse: {err}")
    else:
        msgs.append(ell.message)
    if len(p) < 4:
        msgs.append(f"need 4 points for a spline, got {len(p)}")
        return ProfileFit(**kw, message="; ".join(msgs))
    spl = smooth_profile(p[:, ::-1], sigma=sigma)
    _, xy = spl.sample(step=0.5)
    kw["spline_rc"] = xy[:, ::-1]
    x, z = geometry.to_chamber(kw["spline_rc"])
    try:
        m = revolution_measures(x, z)
    except ValueError as err:
        msgs.append(f"spline: {err}")
        return ProfileFit(**kw, message="; ".join(msgs))
    kw.update(volume=m.volume * pixel_size**3, area=m.area * pixel_size**2, height=m.height * pixel_size,
              volume_disagreement=m.volume_disagreement)
    return ProfileFit(**kw, message="; ".join(msgs))


# --------------------------------------------------------------------------- snapping
@dataclass(frozen=True)
class SnapResult:
    """Picked points moved onto the membrane band's midline.

    Attributes
    ----------
    points_rc : ndarray of shape (N, 2), px
        Snapped points, in the order given (points that found no band are left where they were).
    moved : ndarray of shape (N,), px
        Distance each point moved (0 where it did not snap).
    snapped : ndarray of bool, shape (N,)
        Which points found the band.
    polarity : int
        The band contrast used (+1 dark, -1 bright).
    """

    points_rc: np.ndarray
    moved: np.ndarray
    snapped: np.ndarray
    polarity: int


def _normals_rc(points_rc, up, ends="flat"):
    """Unit search directions ``(dcol, drow)``: the curve's normals (the ends along ``up`` if ``ends="flat"``)."""
    p = np.asarray(points_rc, float)
    if len(p) == 1:
        return np.array([up], float)
    order = order_along_curve(p)
    xy = p[order][:, ::-1]
    nrm = polyline_normals(xy, smooth=0.0)
    if ends == "flat" and len(p) >= 3:
        nrm[[0, -1]] = np.asarray(up, float)
    out = np.empty_like(nrm)
    out[order] = nrm
    return out


def _pixel_noise(img, points_rc, margin):
    """Robust pixel noise sigma near the points: MAD of each pixel minus its 4 neighbours' mean."""
    h, w = img.shape
    r0, c0 = np.floor(points_rc.min(axis=0) - margin - 2).astype(int)
    r1, c1 = np.ceil(points_rc.max(axis=0) + margin + 3).astype(int)
    patch = img[max(r0, 0):min(r1, h), max(c0, 0):min(c1, w)]
    if min(patch.shape) < 3:
        return 0.0
    core = patch[1:-1, 1:-1]
    d = core - 0.25 * (patch[:-2, 1:-1] + patch[2:, 1:-1] + patch[1:-1, :-2] + patch[1:-1, 2:])
    # var(d) = sigma**2 (1 + 4/16) for white noise
    return 1.4826 * float(np.median(np.abs(d - np.median(d)))) / np.sqrt(1.25)


def snap_points(image, points_rc, *, search: float = 6.0, step: float = 0.25, polarity="auto",
                up=(0.0, -1.0), ends: str = "flat", passes: int = 2, min_snr: float = 8.0) -> SnapResult:
    """Move picked points onto the midline of the membrane band, with sub-pixel accuracy.

    Parameters
    ----------
    image : array_like of shape (H, W)
        The frame the points were picked on.
    points_rc : array_like of shape (N, 2), px
        Picked points ``(row, col)``, in any order.
    search : float, px
        How far along the curve's normal to look on either side of each point.
    step : float, px
        Sample spacing along the normals.
    polarity : {"auto", 1, -1}
        +1 dark membrane on a light background, -1 bright; ``"auto"`` takes the
        sign with the larger median band contrast.
    up : tuple of float
        Bulge direction ``(dcol, drow)``: the normal of the flat membrane.
    ends : {"flat", "normal"}
        How the two end points of the curve (the rim points) are snapped: ``"flat"``
        along ``up`` onto the flat membrane band they sit on (at the rim the dome's
        band meets the flat band, so the curve's normal there is ambiguous), or
        along the curve's normal like the other points.
    passes : int
        Snapping passes; each pass after the first searches along the normals of
        the curve through the points snapped so far.
    min_snr : float
        Smallest band contrast, in units of the pixel noise (estimated from the
        sampled grey levels), that counts as the membrane; points with none stay.

    Returns
    -------
    SnapResult

    Notes
    -----
    The normals are those of the polyline through the points ordered along the
    curve (:func:`order_along_curve`); the grey levels along each normal are
    sampled with :func:`osmobulge.imaging._normals.sample_normals` and the band's
    sub-pixel midline (half-level crossings of its two edges) is located with
    :func:`osmobulge.imaging._chamber.band_edges`, the same edge model as the
    automatic tracer.
    """
    if polarity not in POLARITIES:
        raise ValueError(f"polarity must be one of {POLARITIES}, got {polarity!r}")
    if ends not in SNAP_ENDS:
        raise ValueError(f"ends must be one of {SNAP_ENDS}, got {ends!r}")
    if not (search > 0 and step > 0 and step < search):
        raise ValueError(f"search and step must be positive px with step < search, got {search!r}, {step!r}")
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 2:
        raise ValueError(f"image must be 2-D (H, W), got shape {img.shape}")
    p = np.asarray(points_rc, float).reshape(-1, 2)
    if len(p) == 0:
        return SnapResult(p, np.zeros(0), np.zeros(0, bool), 1 if polarity == "auto" else int(polarity))
    noise = _pixel_noise(img, p, search)
    offsets = np.arange(-search, search + 0.5 * step, step)
    centre = np.full(len(p), int(np.argmin(np.abs(offsets))))
    pols = (1, -1) if polarity == "auto" else (int(polarity),)
    current, ok = p, np.zeros(len(p), bool)
    for _ in range(max(int(passes), 1)):
        # normals of the curve through the current points: the second pass uses the snapped
        # points, whose normals are those of the membrane rather than of the clicks' scatter
        nrm = _normals_rc(current, up, ends)
        profiles = sample_normals(img, current[:, ::-1], nrm, offsets)
        results = {}
        for pol in pols:
            mid, _, _, contrast, _ = band_edges(profiles, offsets, pol, centre=centre)
            good = (np.isfinite(mid) & (np.nan_to_num(contrast) > max(min_snr * noise, 0.0))
                    & (np.abs(np.nan_to_num(mid)) <= search))
            results[pol] = (mid, good, float(np.median(contrast[good])) if good.any() else -np.inf)
        pol = max(results, key=lambda k: results[k][2])
        pols = (pol,)
        mid, good, _ = results[pol]
        shifted = current + np.where(good, mid, 0.0)[:, None] * nrm[:, ::-1]
        # a point that lost the band in a later pass keeps its earlier snap
        current = np.where(good[:, None], shifted, current)
        ok |= good
    snapped = current
    shift = np.linalg.norm(snapped - p, axis=1)
    return SnapResult(points_rc=snapped, moved=shift, snapped=ok, polarity=int(pol))


# --------------------------------------------------------------------------- chamber regions
def regions_to_rectangles(regions) -> list[np.ndarray]:
    """Chamber regions ``{"name", "rows": [r0, r1], "cols": [c0, c1]}`` -> napari rectangles.

    Parameters
    ----------
    regions : sequence of dict
        Pixel regions (stop excluded), as in the curation and ``experiment.toml``.

    Returns
    -------
    list of ndarray of shape (4, 2)
        Corners ``(row, col)`` of each rectangle (pixel edges: ``r0 - 0.5`` to ``r1 - 0.5``).
    """
    out = []
    for r in regions:
        (r0, r1), (c0, c1) = r["rows"], r["cols"]
        out.append(np.array([[r0, c0], [r0, c1], [r1, c1], [r1, c0]], float) - 0.5)
    return out


def rectangles_to_regions(rectangles, names=None, *, shape=None) -> list[dict]:
    """napari rectangles -> chamber regions (inverse of :func:`regions_to_rectangles`).

    Parameters
    ----------
    rectangles : sequence of array_like of shape (4, 2) or (4, 3)
        Corners ``([frame,] row, col)``; the bounding box of each is used.
    names : sequence of str, optional
        Region names (default ``chamber0``, ``chamber1``, ... from left to right).
    shape : tuple of int, optional
        ``(H, W)`` of the frames: regions are clipped to it.

    Returns
    -------
    list of dict
        ``{"name", "rows": [r0, r1], "cols": [c0, c1]}``, integer pixel bounds, stop excluded.
    """
    boxes = []
    for rect in rectangles:
        p = np.asarray(rect, float)[:, -2:]
        lo = np.rint(p.min(axis=0) + 0.5).astype(int)
        hi = np.rint(p.max(axis=0) + 0.5).astype(int)
        lo = np.maximum(lo, 0)
        if shape is not None:
            hi = np.minimum(hi, shape)
        if np.any(hi <= lo):
            raise ValueError(f"rectangle {p.tolist()} is empty inside the frame")
        boxes.append((lo, hi))
    if names is None:
        order = np.argsort([b[0][1] for b in boxes], kind="stable")
        names = [None] * len(boxes)
        for k, i in enumerate(order):
            names[i] = f"chamber{k}"
    if len(names) != len(boxes):
        raise ValueError(f"names: expected {len(boxes)} names, got {len(names)}")
    return [{"name": str(n), "rows": [int(lo[0]), int(hi[0])], "cols": [int(lo[1]), int(hi[1])]}
            for n, (lo, hi) in zip(names, boxes, strict=True)]
