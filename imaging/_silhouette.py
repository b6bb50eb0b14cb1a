"""Chamber walls from their silhouettes, without a grey step between well and base (issue 16).

In bright field the well's liquid and the elastomer base both transmit: what
shows a wall is the light its cylinder bends out of the objective, a dark (or,
in dark field, bright) zone just *inside* the wall whose outer edge is the wall
itself (:mod:`osmobulge.imaging.optics`).  This module finds, in a bulge-up
frame of the flat membrane:

* the top face of the device (the strongest straight line across the frame,
  of either sign), and
* each wall as the outer edge of the strongest silhouette zones in a strip of
  the base below the film, row by row (half-way between the zone's extreme and
  the light just outside the wall), fitted by a line and read at the base's top
  surface (``l0`` below the top face).

It is look-agnostic (``|I - background|``); the silhouette route
(:class:`osmobulge.imaging._facetrace.SilhouetteTracer`) finds the chamber with
it in the first frame (:class:`FlatMaps`: what its four orientations share,
computed once) and follows the walls with it frame by frame.  Tested on the
optics looks against their true well radius.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from osmobulge.imaging._chamber import ChamberNotFound

__all__ = ["FlatMaps", "SilhouetteWalls", "find_walls"]

#: largest row scatter (px) of a wall's silhouette edge about its line
MAX_WALL_RMS = 0.5


@dataclass(frozen=True)
class SilhouetteWalls:
    """Walls found by their silhouettes (px, stored frame, bulge-up).

    ``top_row``: the device's top face; ``base_row``: the base's top surface
    (``top_row + l0``); ``left``, ``right``: wall columns at ``base_row``;
    ``rim_radius`` and ``axis_col``; ``rms``: the walls' row scatter about their lines.
    """

    top_row: float
    base_row: float
    left: float
    right: float
    rms: float

    @property
    def rim_radius(self) -> float:
        return 0.5 * (self.right - self.left)

    @property
    def axis_col(self) -> float:
        return 0.5 * (self.right + self.left)


def _half_crossing(prof, peak, step, base=0.0):
    """Sub-pixel index where ``prof`` falls half-way from its peak to ``base``, walking from ``peak`` by
    ``step`` (+-1)."""
    half = 0.5 * (prof[peak] + base)
    if not prof[peak] > half:  # (no fall from the peak to the base)
        return np.nan
    k = peak
    while 0 <= k + step < prof.size and prof[k + step] > half:
        k += step
    j = k + step
    if not (0 <= j < prof.size):
        return np.nan
    return k + step * (prof[k] - half) / (prof[k] - prof[j])


class FlatMaps:
    """A flat frame's maps that :func:`find_walls` reads and a quarter turn only turns, computed once.

    The local light, the signed relative deviation from it (scaled by the
    99.5th percentile of its size, which no turn changes) and the row scores
    of the top-face search (:func:`_top_face`): those of a view turned by a
    half turn are the same rows reversed, so they are computed for two of the
    four views.  :meth:`view` gives find_walls' inputs for quarter turn ``k``
    (``np.rot90``'s).
    """

    def __init__(self, frame, light):
        self.values = np.asarray(frame, float)
        self.light = np.asarray(light, float)
        if self.light.shape != self.values.shape:
            raise ValueError(f"light has shape {self.light.shape}, the frame {self.values.shape}")
        self.deviation = _scaled_deviation(self.values, self.light)
        self.size = np.abs(self.deviation)
        self._scores = {}

    def view(self, k):
        """``(img, light, deviation)`` of the view turned by ``k`` quarter turns."""
        return tuple(np.rot90(a, k) for a in (self.values, self.light, self.deviation))

    def scores(self, k, l0_px):
        """The top-face search's row scores of view ``k``: the size's 15th percentile over the columns and the
        :func:`_line_score` of the frame."""
        key = (k % 2, float(l0_px))
        if key not in self._scores:
            k0 = k % 2
            self._scores[key] = (np.percentile(np.rot90(self.size, k0), 15, axis=1),
                                 _line_score(np.rot90(self.values, k0), l0_px))
        rows, line = self._scores[key]
        return (rows, line) if k % 4 < 2 else (rows[::-1], line[::-1])


def _scaled_deviation(img, bg):
    """(img - light) / light over the 99.5th percentile of its size (what the silhouettes are found on)."""
    sd = (img - bg) / np.maximum(bg, 1e-6 * max(float(bg.max()), 1e-30))
    scale = np.percentile(np.abs(sd), 99.5)
    if scale <= 1e-9:  # relative deviation: nothing but rounding
        raise ChamberNotFound("the frame is uniform: no top face or walls to find")
    return sd / scale


def find_walls(frame, l0_px, *, strip=(0.15, 0.6), depth_px=None, min_width=40, top_row=None,
               near=None, top_near=None, light=None, maps=None) -> SilhouetteWalls:
    """Find the top face and the two walls of the central well in a flat, bulge-up frame.

    Parameters
    ----------
    frame : ndarray of shape (M, N)
        The flat first frame, dome side up.
    l0_px : float
        Membrane thickness in px (the base's top surface lies this far below
        the top face).
    strip : (float, float)
        Rows of the base searched for walls, as fractions of ``depth_px``
        below the base's top surface.
    depth_px : float or None
        Well depth in px (default: 100 px).
    min_width : int
        Narrowest well (px).
    top_row : float, optional
        The top face's row when already known (a later frame of a series,
        registered against the first): not searched for.
    near : (float, float), optional
        Expected wall columns (left, right): the silhouettes are taken within
        ``min_width / 2`` px of them instead of the two strongest.
    top_near : float, optional
        Expected row of the top face (a given rim): it is searched within
        ``max(l0/2, 4)`` px of it instead of over the whole frame.
    light : ndarray of shape (M, N), optional
        The local light level when known (a later frame of a series: the flat
        frame's, moved by the drift); default the frame's Gaussian of 25 px.
    maps : (FlatMaps, int), optional
        The frame's maps and the quarter turn ``frame`` is of them (``frame``
        and ``light`` are then not read): the same walls, without computing
        again what the turns share.

    Raises
    ------
    ChamberNotFound
        No straight top face, or fewer than two wall silhouettes.
    """
    if not (np.isfinite(l0_px) and l0_px > 0):
        raise ValueError(f"l0_px must be > 0, got {l0_px!r}")
    scores = None
    if maps is not None:
        flat, k = maps
        img, _, sd = flat.view(k)
        d = np.rot90(flat.size, k)
        scores = None if top_row is not None else flat.scores(k, l0_px)
    else:
        img = np.asarray(frame, float)
        if img.ndim != 2:
            raise ValueError(f"frame must be 2-D, got shape {img.shape}")
        # relative deviation from the local light level (uneven illumination divides out)
        bg = ndimage.gaussian_filter(img, 25.0, mode="nearest") if light is None else np.asarray(light, float)
        if bg.shape != img.shape:
            raise ValueError(f"light has shape {bg.shape}, the frame {img.shape}")
        sd = _scaled_deviation(img, bg)
        d = np.abs(sd)
    if top_row is None:
        top_row = _top_face(d, l0_px, img, near=top_near, scores=scores)
    base_row = top_row + l0_px
    depth = 100.0 if depth_px is None else float(depth_px)
    r0 = int(np.ceil(base_row + strip[0] * depth))
    r1 = int(np.floor(base_row + strip[1] * depth))
    r1 = min(r1, img.shape[0] - 1)
    if r1 - r0 < 5:
        raise ChamberNotFound("too few base rows below the membrane to find the walls")
    band = ndimage.uniform_filter1d(d[r0:r1], 3, axis=1)
    col_score = np.median(band, axis=0)
    if near is not None:  # the silhouettes nearest the expected walls
        half = max(min_width // 2, 3)
        peaks = []
        for c in near:
            c0, c1 = max(int(round(c)) - half, 3), min(int(round(c)) + half + 1, img.shape[1] - 4)
            if c1 - c0 < 3 or col_score[c0:c1].max() < 0.1:
                raise ChamberNotFound(f"no wall silhouette within {half} px of column {c:.0f}")
            peaks.append(c0 + int(np.argmax(col_score[c0:c1])))
    else:
        peaks = _strongest(col_score, img.shape[1], min_width)
    return _fit_walls(sd, peaks, r0, r1, top_row, base_row)


#: line score (relative light) below which the top face's row is the deviation's own row score's peak
_LINE_FLOOR = 0.01


def _line_score(img, l0_px):
    """Per row, how far it stands out, in one direction, from the light both above and below it (15th
    percentile over the columns); the best of three film thicknesses, ``l0``, ``l0/2`` and ``l0/4``.

    A face is a thin line: its light departs from the level on either side and
    returns to it.  A change of medium across the whole frame (a turbid base
    below clear water) differs from one side only, and scores 0, however
    strong; against a Gaussian local light it would be a ramp tens of rows wide
    that can outscore a faint, blurred face.  Each side's level is the median
    of about ``0.4 l`` rows (an odd number: the score of the frame turned
    upside down is this one reversed) starting ``0.55 l`` away (past the
    film's other face's reach, short of its distance), on columns averaged in
    fours.  ``l0`` may be
    a guess: a film thinner than ``l0/2`` puts the level below its top face in
    the base, which a turbid base makes darker than the face, so thinner
    trials are scored too.
    """
    h, w = img.shape
    s = img[:, : w - w % 4].reshape(h, -1, 4).mean(axis=2)
    best = np.zeros(h)
    for thick in (l0_px, 0.5 * l0_px, 0.25 * l0_px):
        gap, win = max(int(round(0.55 * thick)), 2), max(int(round(0.4 * thick)), 3) | 1  # (odd: centred)
        off = gap + win // 2
        if off >= h:
            continue
        med = ndimage.median_filter(s, size=(win, 1), mode="nearest")
        up = np.r_[np.repeat(med[:1], off, axis=0), med[:-off]]  # the level above each row
        dn = np.r_[med[off:], np.repeat(med[-1:], off, axis=0)]  # and below it
        a = s / np.maximum(up, 1e-12) - 1.0
        b = s / np.maximum(dn, 1e-12) - 1.0
        r = np.where(a * b > 0, np.minimum(np.abs(a), np.abs(b)), 0.0)
        best = np.maximum(best, np.percentile(r, 15, axis=1))
    return best


def _top_face(d, l0_px, img=None, near=None, scores=None):
    """Row of the top face: the row that stands out as a line across nearly the whole frame.

    The row is the peak of :func:`_line_score` (of ``img``, when given), its
    centre and extent read on the |deviation|'s row score around it (its 15th
    percentile over the columns; the well's bottom face, as strong, spans only
    the well).  ``near``: only rows within ``max(l0/2, 4)`` px of it.
    ``scores``: the row score and line score when already computed
    (:meth:`FlatMaps.scores`; ``img`` is then not read).
    """
    row_score = np.percentile(d, 15, axis=1) if scores is None else scores[0]
    allowed = np.ones(row_score.size, bool)
    if near is not None:
        reach = max(0.5 * l0_px, 4.0)
        allowed = np.abs(np.arange(row_score.size) - float(near)) <= reach
        if not allowed.any():
            raise ChamberNotFound(f"the top face the given rim implies ({near:.0f} px into the bulge-up view) is "
                                  f"outside the frame")
    top = int(np.argmax(np.where(allowed, row_score, -np.inf)))
    if img is not None or scores is not None:  # a line, not a step: then the deviation's own peak within 2 rows
        score = np.where(allowed, _line_score(img, l0_px) if scores is None else scores[1], -np.inf)
        line = int(np.argmax(score))
        if score[line] >= _LINE_FLOOR:  # (else no row is a line: the deviation's peak it is)
            lo = max(line - 2, 0)
            window = np.where(allowed[lo : line + 3], row_score[lo : line + 3], -np.inf)
            top = lo + int(np.argmax(window))
    if row_score[top] < 0.02:
        where = "across the frame" if near is None else f"within {max(0.5 * l0_px, 4.0):.0f} px of the given rim"
        raise ChamberNotFound(f"no straight top face {where}")
    # its centre: half-level edges of the row score around the peak
    lo_e = _half_crossing(row_score, top, -1)
    hi_e = _half_crossing(row_score, top, +1)
    top_row = 0.5 * (lo_e + hi_e) if np.isfinite(lo_e + hi_e) else float(top)
    # a thick (absorbing) flat film: its top face is the band's upper edge
    if hi_e - lo_e > 0.6 * l0_px:
        top_row = lo_e
    return float(top_row)


def _strongest(col_score, width, min_width):
    """The two strongest silhouette columns at least ``min_width`` apart."""
    peaks = []
    order = np.argsort(col_score)[::-1]
    for c in order[: max(50, width // 4)]:
        if col_score[c] < 0.1:
            break
        if all(abs(c - p) > min_width for p in peaks):
            peaks.append(int(c))
        if len(peaks) == 2:
            break
    if len(peaks) < 2:
        raise ChamberNotFound("fewer than two wall silhouettes in the base below the membrane")
    return peaks


def _half_crossings(prof, pk, base=None):
    """:func:`_half_crossing` of each row of ``prof`` from its ``pk`` walking to higher indices (nan where none).

    ``base``: per row (default 0).
    """
    n, m = prof.shape
    rows = np.arange(n)
    top = prof[rows, pk]
    half = 0.5 * (top + (0.0 if base is None else base))
    k = np.arange(m)[None, :]
    below = (k > pk[:, None]) & ~(prof > half[:, None])  # (nan stops the walk, as in _half_crossing)
    j = np.argmax(below, axis=1)
    ok = (top > half) & below[rows, j]
    jm = np.maximum(j - 1, 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = jm + (prof[rows, jm] - half) / (prof[rows, jm] - prof[rows, j])
    return np.where(ok, e, np.nan)


def _wall_edges(sd, c):
    """Per row of ``sd`` (signed deviation, walking outwards to higher indices), the wall's outer half-level edge
    from its zone's extreme within 3 columns of ``c``: :func:`_fit_walls`' rule, on all the rows at once."""
    n, m = sd.shape
    rows = np.arange(n)
    lo = max(c - 3, 0)
    pk = lo + np.argmax(np.abs(sd[:, lo : c + 4]), axis=1)
    prof = np.sign(sd[rows, pk])[:, None] * sd
    e = _half_crossings(prof, pk)
    # the light just outside the wall: 4-12 px out
    idx = np.round(np.nan_to_num(e, nan=-100.0)).astype(int)[:, None] + np.arange(4, 13)[None, :]
    valid = (idx >= 0) & (idx < m) & np.isfinite(e)[:, None]
    outside = np.where(valid, prof[rows[:, None], np.clip(idx, 0, m - 1)], np.nan)
    enough = valid.sum(axis=1) >= 4
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (all-nan rows: no edge)
        base = np.nanmedian(outside, axis=1)
    e2 = _half_crossings(prof, pk, np.where(enough, base, 0.0))
    return np.where(enough & np.isfinite(e2), e2, e)


def _fit_walls(sd, peaks, r0, r1, top_row, base_row):
    """Each wall's outer half-level edge row by row, fitted by a line and read at ``base_row``.

    ``sd``: the signed relative deviation from the local light.  The level is
    half-way between the silhouette zone's extreme and the light just outside
    the wall (4-12 px out): the local light, a mean over the zone as well,
    lies between them, so the level is not half of the deviation's peak.
    """
    cl, cr = sorted(peaks)
    rows = np.arange(r0, r1)
    m = sd.shape[1]
    strip = sd[r0:r1]
    # the wall's zone lies inside the well: its outer edge is the wall (the left one walked in flipped columns)
    left = m - 1 - _wall_edges(strip[:, ::-1], m - 1 - cl)
    right = _wall_edges(strip, cr)
    fits, res = [], []
    for u in (left, right):
        ok = np.isfinite(u)
        if ok.sum() < 5:
            raise ChamberNotFound("a wall's silhouette edge could not be followed down the base")
        coef = np.polyfit(rows[ok], u[ok], 1)
        r = u[ok] - np.polyval(coef, rows[ok])
        keep = np.abs(r) <= max(3.0 * np.std(r), 0.3)
        coef = np.polyfit(rows[ok][keep], u[ok][keep], 1)
        fits.append(float(np.polyval(coef, base_row)))
        res.append(float(np.sqrt(np.mean((u[ok][keep] - np.polyval(coef, rows[ok][keep])) ** 2))))
    if max(res) > MAX_WALL_RMS:
        raise ChamberNotFound(f"the wall silhouettes are not straight lines (row scatter {max(res):.2f} px > "
                              f"{MAX_WALL_RMS} px): not walls, or a look this search cannot read")
    return SilhouetteWalls(float(top_row), float(base_row), fits[0], fits[1], max(res))
