"""Find the chamber in a cross-section micrograph: orientation, flat membrane line, wells, walls, rim.

Works in the *bulge-up view* of a frame: the frame rotated by a multiple of
90 degrees so the dome grows towards row 0.  Points are ``(x=col, y=row)`` in
pixels of that view, the pixel ``(row, col)`` centred on ``(x=col, y=row)``.
No image is copied for the rotation: :class:`FrameView` maps sample
coordinates back to the stored frame.

The flat-membrane *line* is the midline of the membrane band lying on the
base's top surface (the rim plane, ``z = 0``); the base's top surface is half
a band thickness below it.  Chamber coordinates: ``u`` along the line
(positive to the right in the view) from the chamber axis, ``z`` up (bulge
direction) from the line.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
from scipy import ndimage as ndi
from scipy.stats import siegelslopes

from osmobulge.imaging._kernels import (
    WALL_FIT,
    WALL_SIDE,
    band_edges_rows,
    block_mean,
    column_nanmedian,
    dusty_rows,
    line_band,
    nanmedian,
    native_frame,
    ridge_rows,
    robust_line,
    sample_transects,
    signed_profiles,
    step_crossing_rows,
    wall_rows,
)

__all__ = ["FrameView", "Line", "Well", "ChamberGeometry", "ChamberNotFound", "ROTATIONS", "detect_orientation",
           "find_chambers", "measure_line", "measure_walls", "band_edges", "step_crossing"]

#: half-width (px) of the rows across a wall: side levels 7 px and more from the edge (see ``_kernels.WALL_SIDE``)
WALL_WINDOW = 11.0

#: np.rot90 count that turns each bulge direction into "up"
ROTATIONS = {"up": 0, "right": 1, "down": 2, "left": 3}


class FrameView:
    """A frame seen rotated by ``k`` quarter turns (``np.rot90(frame, k)``) without copying it.

    Parameters
    ----------
    frame : ndarray of shape (H, W)
        Any numeric dtype.
    k : int
        Quarter turns counter-clockwise (0..3).
    """

    def __init__(self, frame, k=0):
        self.frame = frame
        self.k = int(k) % 4
        h, w = frame.shape
        self.shape = (h, w) if self.k % 2 == 0 else (w, h)

    def to_frame(self, x, y):
        """View ``(x, y)`` -> stored frame ``(row, col)``."""
        h, w = self.frame.shape
        if self.k == 0:
            return y, x
        if self.k == 1:
            return x, w - 1 - y
        if self.k == 2:
            return h - 1 - y, w - 1 - x
        return h - 1 - x, y

    def from_frame(self, row, col):
        """Stored frame ``(row, col)`` -> view ``(x, y)``."""
        h, w = self.frame.shape
        if self.k == 0:
            return col, row
        if self.k == 1:
            return row, w - 1 - col
        if self.k == 2:
            return w - 1 - col, h - 1 - row
        return h - 1 - row, col

    def sample(self, x, y):
        """Bilinear samples at view points (arrays of any equal shape); nan outside."""
        x = np.asarray(x, float)
        y = np.asarray(y, float)
        r, c = self.to_frame(x, y)
        out = ndi.map_coordinates(self.frame, [np.ravel(r), np.ravel(c)], order=1, mode="constant", cval=np.nan,
                                  output=np.float64, prefilter=False)
        return out.reshape(x.shape)

    def transects(self, points, directions, offsets):
        """Bilinear samples at ``points[i] + offsets[j] * directions[i]`` (view px), shape (N, K); nan outside."""
        return sample_transects(self.frame, self.k, points, directions, offsets)

    def _sub(self, r0, r1, c0, c1):
        """View rows r0:r1, cols c0:c1 clipped to the view (a view of the frame) and their origin."""
        h, w = self.shape
        r0, r1, c0, c1 = max(int(r0), 0), min(int(r1), h), max(int(c0), 0), min(int(c1), w)
        return np.rot90(self.frame, self.k)[r0:r1, c0:c1], (r0, c0)

    def patch(self, r0, r1, c0, c1, dtype=np.float32):
        """Dense copy of view rows r0:r1, cols c0:c1 (clipped to the view)."""
        sub, origin = self._sub(r0, r1, c0, c1)
        return np.asarray(sub, dtype), origin

    def block_mean(self, r0, r1, c0, c1, f):
        """``block_mean(patch(r0, r1, c0, c1)[0], f)`` and the patch origin, without the float32 copy.

        Frames of up to 16-bit integers are exact in float32, so their blocks
        are summed from a copy of the frame's own pixels (2 bytes, not 4, a
        pixel); others through the float32 patch.
        """
        if self.frame.dtype.kind in "bui" and self.frame.dtype.itemsize <= 2:
            sub, origin = self._sub(r0, r1, c0, c1)
            return block_mean(native_frame(np.array(sub, order="C")), int(f)), origin  # (a writable copy)
        patch, origin = self.patch(r0, r1, c0, c1)
        return block_mean(patch, int(f)), origin


@dataclass(frozen=True)
class Line:
    """The flat-membrane midline: ``p(u) = point + u * direction`` in view pixels."""

    x0: float
    y0: float
    angle: float  # rad, direction (cos, sin) in (x, y)

    @cached_property
    def _dn(self):
        """``(d0, d1, n0, n1)``: direction and normal as floats (computed once)."""
        c, s = float(np.cos(self.angle)), float(np.sin(self.angle))
        return c, s, s, -c

    @cached_property
    def direction(self):
        """Unit vector along the line (read-only, computed once)."""
        d = np.array(self._dn[:2])
        d.flags.writeable = False
        return d

    @cached_property
    def normal(self):
        """Unit normal pointing up (bulge side, towards row 0 for angle 0; read-only)."""
        n = np.array(self._dn[2:])
        n.flags.writeable = False
        return n

    def point(self, u, z=0.0):
        """View points at line coordinate ``u`` and height ``z`` (arrays broadcast), shape (..., 2)."""
        d0, d1, n0, n1 = self._dn
        if isinstance(u, (float, int)) and isinstance(z, (float, int)):  # one point (the same arithmetic, float64)
            return np.array([float(self.x0) + u * d0 + z * n0, float(self.y0) + u * d1 + z * n1])
        u = np.asarray(u, float)
        z = np.asarray(z, float)
        x = self.x0 + u * d0 + z * n0
        out = np.empty((*x.shape, 2))
        out[..., 0] = x
        out[..., 1] = self.y0 + u * d1 + z * n1
        return out

    def coords(self, pts):
        """View points (N, 2) -> (u, z)."""
        p = np.asarray(pts, float) - (self.x0, self.y0)
        return p @ self.direction, p @ self.normal

    def shifted(self, du=0.0, dz=0.0):
        """Same line with its origin moved by ``du`` along and ``dz`` across it."""
        x, y = self.point(float(du), float(dz))
        return Line(float(x), float(y), self.angle)


@dataclass(frozen=True)
class Well:
    """A well in line coordinates: wall tops ``u_left < u_right`` at the base's top surface."""

    u_left: float
    u_right: float
    slope_left: float = 0.0  # du/dz of the wall (z up, z < 0 in the well)
    slope_right: float = 0.0
    depth: float = np.nan  # px, from the base's top surface to the bottom

    @property
    def centre(self):
        return 0.5 * (self.u_left + self.u_right)

    @property
    def half_width(self):
        return 0.5 * (self.u_right - self.u_left)


@dataclass(frozen=True)
class ChamberGeometry:
    """Geometry of one chamber in one frame (view pixels).

    ``line`` has its origin on the chamber axis (``u = 0``).
    """

    line: Line
    thickness: float  # px, membrane band on the surface
    polarity: int  # +1 dark membrane, -1 bright
    rim_radius: float  # px
    well: Well  # in the line coordinates (centred: u_left = -rim_radius)
    others: tuple = ()  # other wells (line coordinates)
    contrast: float = np.nan  # band contrast (grey levels)
    line_rms: float = np.nan  # px, scatter of the band points about the line
    wall_rms: float = np.nan  # px

    @property
    def axis_point(self):
        return np.array([self.line.x0, self.line.y0])


class ChamberNotFound(ValueError):
    """The frame shows no chamber the search recognises (no flat band, no well, no walls)."""


# ---------------------------------------------------------------------------------- 1-D helpers
def _nanmedian(a, **kw):
    """``np.nanmedian`` without the all-nan warning (returns nan there); plain median when all finite (fast)."""
    if not kw:
        return nanmedian(a)
    a = np.asarray(a)
    if np.isfinite(a).all():
        return np.median(a, **kw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(a, **kw)


def band_edges(profiles, offsets, polarity, *, centre=None, search=None, side=4):
    """Sub-pixel edges, midline and contrast of the membrane band in each profile.

    The band is the extreme (dark for ``polarity=+1``) run of each profile;
    each edge lies where the profile crosses half-way between the band's
    peak and the level on that side, so the midline is unbiased by a
    symmetric blur and by different levels on the two sides (base below,
    water above).

    Parameters
    ----------
    profiles : ndarray of shape (N, K)
        Grey levels along N transects (evenly spaced ``offsets``).
    offsets : ndarray of shape (K,)
        Sample positions along the transects (px).
    polarity : int
        +1 dark band, -1 bright band.
    centre : ndarray of shape (N,), optional
        Index near the band (default: the peak of the whole profile).
    search : int or ndarray of int, shape (N,), optional
        Half-width (samples) around ``centre`` to look for the peak.
    side : int
        Samples at each end of the profile averaged for the side levels.

    Returns
    -------
    mid, lo, hi, contrast, width : ndarray of shape (N,)
        Midline offset, edge offsets (lower and higher offset side), peak
        contrast over the mean side level, and band width (px); nan when an
        edge is not found.
    """
    # the band high; each row's non-finite samples -> the median of its finite ones (0 if none)
    q = signed_profiles(np.ascontiguousarray(profiles, np.float64), float(polarity))
    n, k = q.shape
    if centre is None:
        c, s = np.zeros(n, np.int64), k
    else:
        c = np.asarray(centre, np.int64)
        s = k if search is None else np.asarray(search, np.int64)
    return tuple(band_edges_rows(q, offsets, c, s, side))


def step_crossing(profiles, offsets, *, side=4, fit=0):
    """Sub-pixel position of a step edge (mid-level crossing nearest the profile centre).

    Parameters
    ----------
    profiles : ndarray of shape (N, K)
        Grey levels across the edge.
    offsets : ndarray of shape (K,)
        Sample positions (px).
    side : int
        Samples at each end whose median is the level on that side.
    fit : int
        0: the crossing between the two samples straddling the mid level; else
        of the least-squares line through the ``2 fit`` samples around them
        (less noise: ``fit=2`` on the walls).

    Returns
    -------
    pos, step : ndarray of shape (N,)
        Edge offset (nan if no crossing) and signed step (last level - first level).
    """
    return tuple(step_crossing_rows(np.asarray(profiles, float), offsets, side, fit))


def _robust_line(x, y, *, iters=4, clip=3.0, floor=0.1):
    """Least-squares line y = a + b x with sigma clipping (at least ``floor``); returns a, b, rms, inliers."""
    a, b, rms, ok = robust_line(np.asarray(x, np.float64), np.asarray(y, np.float64), int(iters), float(clip),
                                float(floor))
    return (float(a), float(b), float(rms), ok) if np.isfinite(a) else (np.nan, np.nan, float(rms), ok)


# ---------------------------------------------------------------------------------- orientation
def _ridge_rows(img, w_max=8):
    """Per column: row and signed value of the strongest ridge (band) response over widths 1..w_max.

    For each width ``w``, ``(up + dn) / 2 - img`` with the pixels ``w`` rows
    above and below (> 0 for a dark ridge), where both differ from the pixel
    with the same sign (a step gives a response on one side only), 0 within
    ``w`` rows of the ends; the strongest over the widths, then over the rows.
    Compiled (:func:`~osmobulge.imaging._kernels.ridge_rows`, float32 as here).
    """
    return ridge_rows(np.ascontiguousarray(img, np.float32), int(w_max))


def _coarse(frame, f):
    """The frame averaged over f x f blocks (float32; a partial last block row or column dropped)."""
    return block_mean(native_frame(np.ascontiguousarray(frame)), int(f))


def smoothed_coarse(frame):
    """The frame as the band searches see it: block means (``min(H, W) // 256`` px), Gaussian sigma 1 (float32)."""
    f = max(1, min(frame.shape) // 256)
    return ndi.gaussian_filter(_coarse(frame, f), 1.0)


def _sobel_rows(img, r0, r1):
    """``ndi.sobel(img, axis=1)[r0:r1]``, bit for bit, from rows ``r0 - 1 .. r1`` only (the 3 x 3 neighbourhood;
    at the image's own edges the same reflection)."""
    lo, hi = max(r0 - 1, 0), min(r1 + 1, img.shape[0])
    return ndi.sobel(img[lo:hi], axis=1)[r0 - lo: r1 - lo]


def detect_orientation(frame, *, coarse=None):
    """Bulge direction of a (flat-membrane) frame: the side of the straight membrane band away from the wells.

    Parameters
    ----------
    frame : ndarray of shape (H, W)
        A frame, ideally the first (flat membrane) of a series.
    coarse : ndarray, optional
        ``smoothed_coarse(frame)`` when already computed.

    Returns
    -------
    direction : str
        One of ``"up", "down", "left", "right"``.
    score : float
        Ratio of the well-wall evidence on the base side to the other side (> 1).
    """
    img = smoothed_coarse(frame) if coarse is None else coarse
    best = None
    for k in (0, 1):  # band horizontal in the view rotated by k
        v = np.rot90(img, k)
        rows, val = _ridge_rows(v)
        cols = np.arange(v.shape[1])
        a, b, rms, ok = _robust_line(cols.astype(float), rows.astype(float), floor=1.5)
        strength = float(np.median(np.abs(val[ok]))) * ok.mean() if np.isfinite(a) else 0.0
        if best is None or strength > best[0]:
            best = (strength, k, a, b, float(np.sign(np.median(val[ok]))) if np.isfinite(a) else 1.0)
    _, k, a, b, pol = best
    v = np.rot90(img, k)
    h, w = v.shape
    cols = np.arange(w)
    line_rows = a + b * cols
    offs = np.arange(4, 4 + max(6, h // 24))
    rows = {sign: np.clip(np.round(line_rows[None, :] + sign * offs[:, None]).astype(int), 0, h - 1)
            for sign in (1, -1)}
    # the horizontal gradient on the rows the strips use (not the whole image)
    r0 = min(int(r.min()) for r in rows.values())
    r1 = max(int(r.max()) for r in rows.values()) + 1
    gx = _sobel_rows(v, r0, r1)

    def wall_score(sign):
        # median over a strip of rows beside the band of the horizontal gradient: walls are
        # vertical edges crossing the whole strip; dust is local and drops out of the median
        strip = gx[rows[sign] - r0, cols[None, :]]
        med = np.abs(np.median(strip, axis=0))
        return float(np.sort(med)[-max(4, w // 64):].mean())

    below, above = wall_score(+1), wall_score(-1)
    base_below = below >= above
    if k == 0:
        direction = "up" if base_below else "down"
    else:  # view = rot90(frame, 1): view "up" is frame "right"
        direction = "right" if base_below else "left"
    score = max(below, above) / max(min(below, above), 1e-12)
    del pol
    return direction, score


# ---------------------------------------------------------------------------------- chamber finding
def _transects(view, line, u, z0, z1, step=0.5, along=False):
    """Samples along transects across (default) or along the line: returns (N, K) and offsets."""
    offs = np.arange(z0, z1 + 1e-9, step)
    u = np.atleast_1d(np.asarray(u, float))
    if along:  # rows of constant z = u, samples along u = offs
        base, d = line.point(0.0, u), line.direction
    else:
        base, d = line.point(u, 0.0), line.normal
    return view.transects(base, np.broadcast_to(d, base.shape), offs), offs


def measure_line(view, line, u, *, polarity, thickness, window):
    """Refit the flat-membrane midline from the band centres at line positions ``u``.

    Parameters
    ----------
    view : FrameView
    line : Line
        Current estimate (origin anywhere on the line).
    u : ndarray of shape (N,)
        Positions along the line where the band lies flat on the surface (px).
    polarity : int
    thickness : float
        Band thickness estimate (px).
    window : float
        Half-height of the search window about the line (px).

    Returns
    -------
    Line
        Refitted line, origin at the projection of the old origin.
    thickness, contrast, rms : float
        Median band width (px), median band contrast, RMS scatter (px).
    inliers : ndarray of bool
    """
    # transects across the line, band edges, a clipped line through the good midlines: one compiled call
    # (the numpy form is `_measure_line_numpy`)
    u = np.ascontiguousarray(np.atleast_1d(np.asarray(u, float)))
    offs = np.arange(-window, window + 1e-9, 0.5)
    a, b, rms, inl, wmed, cmed = line_band(native_frame(view.frame), view.k, float(line.x0), float(line.y0),
                                           *line._dn, u, offs,
                                           float(polarity), int((0.5 * thickness + 4) / 0.5), 4)
    if not np.isfinite(a):
        return line, thickness, np.nan, np.nan, inl
    # new line: z = a + b u in the old frame
    new = line.shifted(0.0, float(a))
    # offsets along the normal grow as sin(angle - true angle) * u: subtract the slope
    new = Line(new.x0, new.y0, line.angle - np.arctan(float(b)))
    return new, float(wmed), float(cmed), float(rms), inl


def _measure_line_numpy(view, line, u, *, polarity, thickness, window):
    """:func:`measure_line` in numpy (the reference of its test)."""
    prof, offs = _transects(view, line, u, -window, window)
    mid, lo, hi, con, width = band_edges(prof, offs, polarity, centre=np.full(len(u), len(offs) // 2),
                                         search=int((0.5 * thickness + 4) / 0.5))
    good = np.isfinite(mid) & (con > 0.25 * _nanmedian(con))
    a, b, rms, ok = _robust_line(u[good], mid[good])
    inl = np.zeros(len(u), bool)
    inl[np.flatnonzero(good)[ok]] = True
    if not np.isfinite(a):
        return line, thickness, np.nan, np.nan, inl
    new = line.shifted(0.0, a)
    new = Line(new.x0, new.y0, line.angle - np.arctan(b))
    return new, _nanmedian(width[inl]), _nanmedian(con[inl]), rms, inl


def _dusty_rows(prof, offs, pos, *, gap=2.0, clip=3.0):
    """Rows of a wall whose grey level on either side of the edge is darker than the wall's trend (dust).

    A speck on or beside a wall bends the mid-level crossing of every row it
    covers, by up to a few px while the step stays strong: its shadow falls on
    the side levels (the end samples set the crossing level) or on the edge
    itself.  Either way the mean level of that side, more than ``gap`` px from
    the edge, drops below the level the clean rows share.  Dust only absorbs
    light, so the clean level is the *upper* trend over the rows; a speck can
    cover more than half the rows of a short wall (and, covering one end,
    looks like a slope to a symmetric fit), so each side's trend starts from a
    constant at its upper quartile and is refitted (twice) as a line on the
    rows from ``clip`` noise sigmas below to ``2 clip`` above it only.  The
    noise sigma comes from differences of neighbouring rows (a speck is smooth
    along the wall and drops out of them).  Compiled
    (:func:`~osmobulge.imaging._kernels.dusty_rows`): it runs for both walls of
    every frame.

    Parameters
    ----------
    prof : ndarray of shape (N, K)
        Transects across the wall, one per row (nan outside the view).
    offs : ndarray of shape (K,)
        Their sample offsets (px).
    pos : ndarray of shape (N,)
        Edge offset per row (nan: row not used).

    Returns
    -------
    dusty, grown : ndarray of bool, shape (N,)
        True for rows darkened on either side (and rows with an edge but no
        level to check); ``grown``: each run of darkened rows grown by half its
        length on both ends (a speck's fringe, too faint to detect row by row,
        still bends the crossings).  Rows without an edge are never dusty and
        never grow.
    """
    return dusty_rows(np.ascontiguousarray(prof, np.float64), np.ascontiguousarray(offs, np.float64),
                      np.ascontiguousarray(pos, np.float64), float(gap), float(clip))


def _wall_rows_numpy(view, line, u0, slope, zs, top, offs):
    """:func:`~osmobulge.imaging._kernels.wall_rows` in numpy (the reference of its test)."""
    uc = u0 + slope * (zs - top)
    prof = view.transects(line.point(uc, zs), np.broadcast_to(line.direction, (len(zs), 2)), offs)
    pos, step = step_crossing(prof, offs, side=WALL_SIDE, fit=WALL_FIT)
    med = _nanmedian(step)
    pos = np.where((np.sign(step) == np.sign(med)) & (np.abs(step) > 0.5 * abs(med)), pos, np.nan)
    for dusty in _dusty_rows(prof, offs, pos)[::-1]:
        kept = ~dusty & np.isfinite(pos)
        if kept.sum() >= 6 and (kept.sum() >= 0.3 * len(zs) or np.std(zs[kept]) >= 0.5 * np.std(zs)):
            pos = np.where(dusty, np.nan, pos)
            break
    return zs - top, uc + pos


def measure_walls(view, line, well, *, thickness, window, n_rows=None):
    """Sub-pixel wall lines of a well; returns the refined :class:`Well` and the wall RMS (px).

    The walls are measured on rows (one per pixel by default, ``window`` px each side
    of the predicted wall; the trace uses :data:`WALL_WINDOW`) between 6 % and
    92 % of the well depth below the base's top surface (``z = -thickness / 2``;
    the longer the run of rows, the less the extrapolation to the rim amplifies
    their noise), fitted with clipped least squares (dust on a wall only
    removes rows: so do rows whose step is weaker than half the median or of
    the other sign, and rows a speck darkens on either side, see
    :func:`_dusty_rows`), once more centred on the first fit when that was poor
    (RMS > 0.5 px), starting from a repeated-median line
    (:func:`scipy.stats.siegelslopes`; the better of the two fits is kept), and
    extrapolated to that surface: the wall tops are the rim.  A wall left with
    a much shorter spread of rows than the other takes the other's slope,
    mirrored, into its own (weighted by the spread).
    """
    top = -0.5 * thickness
    depth = well.depth if np.isfinite(well.depth) else 4.0 * thickness
    if n_rows is None:
        n_rows = int(np.clip(0.86 * depth, 8, 250))
    zs = top - np.linspace(0.06, 0.92, n_rows) * depth
    out = {}
    rms_all = []
    offs = np.arange(-window, window + 1e-9, 0.5)
    d, nv = line.direction, line.normal
    frame = native_frame(view.frame)
    rows = {}  # name -> (zz, uu) of the rows behind the kept fit (inliers only)
    for name, u0, slope in (("left", well.u_left, well.slope_left), ("right", well.u_right, well.slope_right)):
        first = (np.nan, np.nan, np.inf, None)  # (a, b, rms, rows) of the first fit
        for attempt in range(2):
            # step crossings on rows along the line at the predicted wall; rows whose step is not the wall's
            # (dust on the wall, a speck in a side window) are not used, nor rows a speck darkens on either
            # side (it bends their crossings by up to a few px while their step stays strong), unless that
            # would leave too few rows (then the clipped fits decide): compiled, the numpy form is
            # `_wall_rows_numpy`
            zz, uu = wall_rows(frame, view.k, float(line.x0), float(line.y0), float(d[0]), float(d[1]),
                               float(nv[0]), float(nv[1]), float(u0), float(slope), zs, float(top), offs)
            if attempt:
                # a poor first fit (dust over part of the wall): start from the repeated-median line
                # (50 % breakdown), keep the rows near it, then the clipped least squares
                fin = np.isfinite(uu)
                if fin.sum() >= 3:
                    b0, a0 = siegelslopes(uu[fin], zz[fin])
                    res = uu - (a0 + b0 * zz)
                    mad = 1.4826 * _nanmedian(np.abs(res))
                    uu = np.where(np.abs(res) <= max(3.0 * mad, 0.5), uu, np.nan)
            a, b, rms, ok = _robust_line(zz, uu, clip=2.5)
            good = np.isfinite(a) and ok.sum() >= 3
            used = (zz[ok], uu[ok])
            if attempt:  # keep the better of the two fits
                if not good or not rms < first[2]:
                    a, b, rms, used = first
                break
            if not good:
                return None, np.nan
            if rms <= 0.5:
                break
            first = (a, b, rms, used)
            u0, slope = a, b  # a poor fit from a rough start: once more, centred on it, robustly
        out[name] = (a, b)
        rows[name] = used
        rms_all.append(rms)
    # a wall that lost most of its rows to dust (or kept a short run of them) has a poorly known slope, and
    # its extrapolation to the rim with it is worse still: the walls lean out alike (mirror images about the
    # axis: the rim widens with the pre-stretch), so that wall's slope is combined with the other's mirrored,
    # weighted by the spread of the rows behind each (inverse variance for equal row noise)
    szz = {k: float(np.sum((zr - zr.mean()) ** 2)) if len(zr) else 0.0 for k, (zr, _) in rows.items()}
    weak, strong = sorted(szz, key=szz.get)
    if szz[weak] < 0.5 * szz[strong] and len(rows[weak][0]) >= 3:
        zr, ur = rows[weak]
        b = (szz[weak] * out[weak][1] - szz[strong] * out[strong][1]) / (szz[weak] + szz[strong])
        out[weak] = (float(np.mean(ur) - b * np.mean(zr)), b)
    return replace(well, u_left=float(out["left"][0]), slope_left=float(out["left"][1]),
                   u_right=float(out["right"][0]), slope_right=float(out["right"][1])), float(np.max(rms_all))


def _well_intervals(profile, ratio_levels):
    """Runs where the strip profile is liquid-like (True) as (start, stop) index pairs."""
    mask = profile
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def find_chambers(view, *, thickness=None, min_width=20, chamber=None, coarse=None):
    """Detect the flat membrane line and every well in a frame (bulge-up view).

    Parameters
    ----------
    view : FrameView
        Bulge-up view of a frame with a flat (or nearly flat) membrane.
    thickness : float, optional
        Expected membrane thickness (px), else measured.
    min_width : float
        Narrowest well accepted (px).
    chamber : int or tuple of float, optional
        Which well: index from the left, or ``(col0, col1)`` view columns
        containing its axis; default the well nearest the view centre whose
        walls are both inside the view.
    coarse : ndarray, optional
        ``smoothed_coarse`` of the view (``np.rot90(view.frame, view.k)``) when already computed.

    Returns
    -------
    ChamberGeometry
        With ``line`` centred on the chosen well's axis.

    Raises
    ------
    ValueError
        No band or no well found (message says what was looked for).
    """
    h, w = view.shape
    f = max(1, min(h, w) // 256)
    img = smoothed_coarse(np.rot90(view.frame, view.k)) if coarse is None else coarse
    rows, val = _ridge_rows(img)
    cols = np.arange(img.shape[1]).astype(float)
    a, b, _, ok = _robust_line(cols, rows.astype(float), floor=1.5)
    if not np.isfinite(a) or ok.mean() < 0.3:
        raise ChamberNotFound("no straight membrane band found across the frame "
                              "(is the membrane flat in the first frame?)")
    polarity = 1 if np.median(val[ok]) > 0 else -1
    # coarse -> full-resolution line (coarse pixel centres at f*i + (f-1)/2)
    ang = float(np.arctan(b))
    x0 = w / 2.0
    y0 = f * (a + b * ((x0 - (f - 1) / 2) / f)) + (f - 1) / 2
    line = Line(x0, y0, ang)
    # refine on the whole width with a generous window, then measure the thickness
    us = np.arange(-x0 + 8, w - x0 - 8, 4.0)
    win = 6.0 * f + (thickness if thickness else 20.0)
    line, thick, con, rms, inl = measure_line(view, line, us, polarity=polarity,
                                              thickness=thickness or 2.0 * f, window=win)
    if thickness is None:
        # the band over wells is as thick as on the surface: re-measure with a matched window
        line, thick, con, rms, inl = measure_line(view, line, us[inl] if inl.sum() > 10 else us, polarity=polarity,
                                                  thickness=thick, window=thick + 10)
        thickness = thick
    # wells: strips just under the base's top surface versus just above the band (water)
    top = -0.5 * thickness
    ucol = np.arange(-x0, w - x0, 1.0)
    zs_base = top - np.linspace(4.0, 4.0 + max(8.0, 1.5 * thickness), 7)
    zs_water = 0.5 * thickness + np.linspace(6.0, 6.0 + max(8.0, 1.5 * thickness), 7)
    pb = line.point(ucol[None, :], zs_base[:, None])
    pw = line.point(ucol[None, :], zs_water[:, None])
    base = column_nanmedian(view.sample(pb[..., 0], pb[..., 1]))
    water = column_nanmedian(view.sample(pw[..., 0], pw[..., 1]))
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.log(np.abs(base) + 1e-6) - np.log(np.abs(water) + 1e-6)
    ratio = ndi.median_filter(np.nan_to_num(ratio, nan=0.0), 5)
    # base is far from water level, wells (liquid) close to it: two clusters of |log ratio|
    mag = np.abs(ratio)
    hi = np.percentile(mag, 90)
    if hi < 0.02:
        raise ChamberNotFound("no wells found: the strip under the membrane has the grey level of the water everywhere")
    liquid = mag < 0.5 * hi
    # runs too short to be a well are dropped (a speck beside a wall looks like liquid), then runs closer
    # than two membrane thicknesses are one well (a speck on the strip splits a well; the base between two
    # real wells is wider than that)
    runs = []
    for s_, e_ in _well_intervals(liquid, None):
        if e_ - s_ < min_width:
            continue
        if runs and s_ - runs[-1][1] < max(2.0 * thickness, 12.0):
            runs[-1] = (runs[-1][0], e_)
        else:
            runs.append((s_, e_))
    inside = [(s, e) for s, e in runs if s > 0 and e < len(ucol)]
    if not runs:
        raise ChamberNotFound("no wells found under the membrane band")
    wells = []
    for s, e in runs:
        wells.append(Well(float(ucol[s] - 0.5), float(ucol[e - 1] + 0.5)))
    # choose
    cand = [wl for (s, e), wl in zip(runs, wells, strict=True) if (s, e) in inside] or wells
    if chamber is None:
        centre = (0.0, 0.0)  # x0 is the view centre
        target = min(cand, key=lambda wl: abs(wl.centre - centre[0]))
    elif isinstance(chamber, int | np.integer):
        if not 0 <= int(chamber) < len(wells):
            raise ValueError(f"chamber index {chamber} out of range: {len(wells)} wells found")
        target = wells[int(chamber)]
    else:
        c0, c1 = (float(v) for v in chamber)
        pick = [wl for wl in wells if c0 - x0 <= wl.centre <= c1 - x0]
        if not pick:
            raise ValueError(f"no well with its axis in columns {chamber!r}")
        target = pick[0]
    # well depth: down columns across the middle of the well, from the base top: the liquid -> base step;
    # the median over 9 columns (a speck of dust in the liquid stops one column early, not the median)
    zz = np.arange(top - 2.0, top - max(12.0 * thickness, 0.5 * h), -0.5)
    us = target.centre + np.linspace(-0.5, 0.5, 9) * target.half_width
    down = np.broadcast_to(-line.normal, (len(us), 2))  # samples at heights zz: down from top - 2 px
    cols = view.transects(line.point(us, top - 2.0), down, (top - 2.0) - zz)
    bas = _nanmedian(base[np.abs(ratio) >= 0.5 * hi]) if np.any(mag >= 0.5 * hi) else np.nan
    depths = []
    for col in cols:
        liq = _nanmedian(col[: max(8, len(col) // 10)])
        if not (np.isfinite(liq) and np.isfinite(bas)):
            continue
        lev = 0.5 * (liq + bas)
        sg = np.sign(col - lev)
        chg = np.flatnonzero((sg[:-1] == np.sign(liq - lev)) & (sg[1:] != sg[:-1]) & np.isfinite(col[1:]))
        if chg.size:
            j = chg[0]
            t = (lev - col[j]) / (col[j + 1] - col[j])
            depths.append(float(-(zz[j] + t * (zz[j + 1] - zz[j])) + top))
    depth = float(np.median(depths)) if len(depths) >= 5 else np.nan
    target = replace(target, depth=depth)
    target, wall_rms = measure_walls(view, line, target, thickness=thickness, window=WALL_WINDOW)
    if target is None:
        raise ChamberNotFound("the well walls could not be located")
    ax = target.centre
    line = line.shifted(ax, 0.0)
    others = tuple(Well(wl.u_left - ax, wl.u_right - ax) for wl in wells if abs(wl.centre - ax) > target.half_width)
    well = replace(target, u_left=target.u_left - ax, u_right=target.u_right - ax)
    return ChamberGeometry(line=line, thickness=float(thickness), polarity=polarity, rim_radius=well.half_width,
                           well=well, others=others, contrast=con, line_rms=rms, wall_rms=wall_rms)
