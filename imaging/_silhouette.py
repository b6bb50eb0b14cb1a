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

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import ndimage, signal

from osmobulge.imaging._chamber import ChamberNotFound
from osmobulge.imaging._kernels import _lerp, _masked_line, _rank

__all__ = ["FlatMaps", "SilhouetteWalls", "find_walls"]

#: largest row scatter (px) of a wall's silhouette edge about its line
MAX_WALL_RMS = 0.5
#: a later frame's wall row whose light just outside the wall (4-12 px out, the median) changed since the first
#: frame by more than this many times the noise off the rows' common change is left out of the wall's line
#: (:func:`_changed_rows`): a particle drifting past the wall.  Measured, in noise units: the presets and held-out
#: looks under 7 light changes, up to 3.0 but where the light was clipped (12 of 4114 walls, their frames read
#: no_membrane); drawn_20261207_59's particle against a wall 9.2
_CHANGED_ROW = 4.0
#: and a row across the wall that the first frame's row, shifted, leaves a misfit over this many times the rows'
#: median misfit (or the noise squared).  Measured, the largest ratio of a wall's rows: the presets and held-out
#: looks under 7 light changes, 2.2 median, 4.0 at the 99th percentile, 6.7 at most (ho_blind_1206n under a
#: ramp of stray light); a particle over coarse_2um's wall 13-34 (a faint one, 0.15 darker: 4)
_CHANGED_SHAPE = 8.0
#: rows either side of a changed row also left out (a particle's blurred rim: on coarse_2um a particle over the
#: wall's edge moved the rim 0.10 px with its rows over _CHANGED_SHAPE left out, 0.03 with these too)
_CHANGED_SPREAD = 2
#: the columns either side of a wall's edge its row is matched over, and the largest shift (px; the walls' lean
#: at Vtilde 4: 8.6 px at a wall's top on edge_dark)
_ALIGN_HALF = 12
_ALIGN_REACH = 12


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
        self.deviation, self.size = _scaled_deviation(self.values, self.light)
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
            self._scores[key] = (_percentile_rows(np.rot90(self.size, k0), 15),
                                 _line_score(np.rot90(self.values, k0), l0_px))
        rows, line = self._scores[key]
        return (rows, line) if k % 4 < 2 else (rows[::-1], line[::-1])


def _scaled_deviation(img, bg):
    """(img - light) / light over the 99.5th percentile of its size (what the silhouettes are found on), and its
    size (absolute value)."""
    floor, scale = _size_percentile(img, bg, *_rank(img.size, 99.5))
    if scale <= 1e-9:  # relative deviation: nothing but rounding
        raise ChamberNotFound("the frame is uniform: no top face or walls to find")
    sd, size = np.empty(img.shape), np.empty(img.shape)
    _scaled(img, bg, floor, scale, sd, size)
    return sd, size


def find_walls(frame, l0_px, *, strip=(0.15, 0.6), depth_px=None, min_width=40, top_row=None,
               near=None, top_near=None, light=None, maps=None, radius_px=None,
               reference=None, clipped=None) -> SilhouetteWalls:
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
    radius_px : float, optional
        The chamber's radius (px) when known: the walls are a pair of zones
        about that far from their middle (:func:`_wall_pair`).
    reference : ndarray of shape (M, N), optional
        For a later frame, the first frame in this frame's light (its light's
        change put on): the rows of a wall where this frame differs from it
        beyond the wall's own shift are left out of the wall's line
        (:func:`_changed_rows`: a particle drifting past).  Not read with
        ``maps`` (a first frame).
    clipped : ndarray of bool, shape (M, N), optional
        The pixels the camera clipped: a wall's rows whose read a clipped
        pixel may have moved are left out (:func:`_moved_by_clip`).  Not read
        with ``maps``.

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
        sd, d = _scaled_deviation(img, bg)
    if top_row is None:
        top_row = _top_face(d, l0_px, img, near=top_near, scores=scores)
    base_row = top_row + l0_px
    depth = 100.0 if depth_px is None else float(depth_px)
    r0, r1, col_score = _zone_scores(d, base_row, depth, strip)
    if col_score is None:
        raise ChamberNotFound("too few base rows below the membrane to find the walls")
    if near is not None:  # the silhouettes nearest the expected walls
        half = max(min_width // 2, 3)
        peaks = []
        for c in near:
            c0, c1 = max(int(round(c)) - half, 3), min(int(round(c)) + half + 1, img.shape[1] - 4)
            if c1 - c0 < 3 or col_score[c0:c1].max() < 0.1:
                raise ChamberNotFound(f"no wall silhouette within {half} px of column {c:.0f}")
            peaks.append(c0 + int(np.argmax(col_score[c0:c1])))
    else:
        peaks = _wall_pair(col_score, img.shape[1], min_width, radius_px)
    pair = None
    if reference is not None and maps is None:
        ref = np.asarray(reference, float)
        if ref.shape != img.shape:
            raise ValueError(f"reference has shape {ref.shape}, the frame {img.shape}")
        lit = np.maximum(bg, 1e-9)
        pair = (img / lit - 1.0, ref / lit - 1.0)
    if clipped is not None and maps is None:
        clipped = np.asarray(clipped, bool)
        if clipped.shape != img.shape:
            raise ValueError(f"clipped has shape {clipped.shape}, the frame {img.shape}")
    else:
        clipped = None
    return _fit_walls(sd, peaks, r0, r1, top_row, base_row, pair, clipped)


def _zone_scores(d, base_row, depth, strip):
    """The base's rows where the walls are read (``strip``: fractions of the well ``depth`` px below
    ``base_row``), ``(r0, r1)``, and each column's silhouette score there: the median over those rows of the
    deviation's size ``d`` averaged over 3 columns (None when fewer than 5 rows are in the frame)."""
    r0 = int(np.ceil(base_row + strip[0] * depth))
    r1 = min(int(np.floor(base_row + strip[1] * depth)), d.shape[0] - 1)
    if r1 - r0 < 5:
        return r0, r1, None
    return r0, r1, _column_medians(ndimage.uniform_filter1d(d[r0:r1], 3, axis=1))  # (np.median(., axis=0))


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
    s = np.empty((h, w // 4))
    _column_means(img, s, abs(img.strides[1]) <= abs(img.strides[0]))
    best = np.zeros(h)
    finite = bool(np.isfinite(s).all())
    med = np.empty_like(s)
    lo, t = _rank(s.shape[1], 15)
    for thick in (l0_px, 0.5 * l0_px, 0.25 * l0_px):
        gap, win = max(int(round(0.55 * thick)), 2), max(int(round(0.4 * thick)), 3) | 1  # (odd: centred)
        off = gap + win // 2
        if off >= h:
            continue
        if finite:  # (the window's median is one of its values: the same whatever computes it)
            _running_median(s, win, med)
        else:
            med = ndimage.median_filter(s, size=(win, 1), mode="nearest")
        _line_rows(s, med, off, lo, t, best)
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


def _strongest(col_score, width, min_width, most=2):
    """The ``most`` strongest silhouette columns at least ``min_width`` apart, strongest first."""
    peaks = []
    order = np.argsort(col_score)[::-1]
    for c in order[: max(50, width // 4)]:
        if col_score[c] < 0.1:
            break
        if all(abs(c - p) > min_width for p in peaks):
            peaks.append(int(c))
        if len(peaks) == most:
            break
    if len(peaks) < 2:
        raise ChamberNotFound("fewer than two wall silhouettes in the base below the membrane")
    return peaks


def _wall_side(col_score, c):
    """Which wall the silhouette zone peaking at column ``c`` belongs to: -1 a left wall, +1 a right one, 0 unknown.

    A wall's zone lies inside its well and its outer edge is the wall
    (:mod:`osmobulge.imaging.optics`): the zone falls to half its peak
    sharply on the wall's side and gradually into the well, when the look
    shows it so (a flat-topped, saturated zone may fall alike on both).  The
    side whose half-level crossing lies less than ``_SIDE_RATIO`` times as
    far from the zone's top (the columns within 5 % of its peak) as the
    other's is the wall's.
    """
    top, lo, hi = 0.95 * col_score[c], c, c  # (a flat-topped zone: its flanks from the ends of its top)
    while lo > 0 and col_score[lo - 1] >= top:
        lo -= 1
    while hi < col_score.size - 1 and col_score[hi + 1] >= top:
        hi += 1
    dl = lo - _half_crossing(col_score, c, -1)
    dr = _half_crossing(col_score, c, +1) - hi
    dl, dr = (x if np.isfinite(x) else np.inf for x in (dl, dr))
    if dl < _SIDE_RATIO * dr:
        return -1
    if dr < _SIDE_RATIO * dl:
        return 1
    return 0


#: a zone's flank that reaches half its peak in less than this fraction of the other flank's distance is its wall's
#: (measured, the flanks' distance ratio, left / right: the looks' left walls 0.10-1.44, right walls 0.77-9.98, of
#: which 0.6 decides only the clear ones, e.g. 0.26 and 3.86 on ho_blind_1206c; the two strongest zones of every
#: look are never of contrary sides)
_SIDE_RATIO = 0.6
#: silhouette zones weighed when the two strongest are not one well's (neighbouring wells in the field), and the
#: share of the strongest zone's score they must reach (walls of one device show alike; a well's inner features,
#: its zones' shoulders, score 0.15 of them on ho_blind_1206c)
_WALL_CANDIDATES, _WALL_SHARE = 6, 0.5
#: with the chamber's radius known, a pair of wall zones whose half-distance lies more than _RADIUS_TOL off it is not
#: the chamber's well: the neighbouring zones (down to _RADIUS_GAP px apart: the walls of wells 40 um apart at 1.6
#: um/px lie 30 px apart, below find_walls' min_width) are paired again (:func:`_wall_pair`)
_RADIUS_TOL, _RADIUS_GAP = 0.15, 8
#: zones this near a wall's (a tenth of the radius, at most 2 _RADIUS_GAP) are its own when it is paired: a second
#: line of the wall's silhouette (drawn_20261207_72, inverted, absorbing: every wall's zone doubled 9-15 px
#: apart, 11 um at 0.85 um/px; neighbouring wells' walls 34 px apart and more)
_OWN_ZONE = 0.1


def _central_pair(cols, sides, width, fits=lambda cl, cr: True):
    """Of the zones at columns ``cols`` (left to right, their sides ``sides``: :func:`_wall_side`), the two next to
    each other, not of contrary sides, for which ``fits(cl, cr)``, whose middle is nearest the field's centre, as
    ``[left, right]``; None if there are none."""
    pairs = [(cl, cr) for cl, sl, cr, sr in zip(cols[:-1], sides[:-1], cols[1:], sides[1:], strict=True)
             if sl != 1 and sr != -1 and fits(cl, cr)]
    return list(min(pairs, key=lambda p: abs(0.5 * (p[0] + p[1]) - 0.5 * (width - 1)))) if pairs else None


def _wall_pair(col_score, width, min_width, radius_px=None):
    """The columns of the two walls of the well nearest the field's centre (of the chamber's radius, when
    ``radius_px`` is given and the pair :func:`_zone_pair` finds is not of it).

    With ``radius_px``, when that pair's half-distance lies more than :data:`_RADIUS_TOL` off it or another zone
    lies between them (but not within :data:`_OWN_ZONE` of the radius of either: the wall's own; measured on
    drawn_20261207_23 in a 460 x 860 px field: wells 36 um apart, every zone alike on both sides, the chamber's
    left wall and the neighbour's left one were paired, 14 % over the radius, and the route refused the view): of
    the zones (:func:`_zone_peaks`), the two next to each other,
    not of contrary sides, whose half-distance lies within
    :data:`_RADIUS_TOL` of the radius, nearest the field's centre (measured
    blind: three wells 40 um apart at 1.6 um/px, whose inner walls' zones lie
    30 px apart, read as one well from the first's left wall to the third's
    right one, 3.3x the radius); :func:`_zone_pair`'s pair when there is none.
    """
    try:
        pair, err = _zone_pair(col_score, width, min_width), None
    except ChamberNotFound as e:
        pair, err = None, e
    peaks = _zone_peaks(col_score)
    own = _RADIUS_GAP if radius_px is None else max(_RADIUS_GAP, min(_OWN_ZONE * radius_px, 2 * _RADIUS_GAP))
    if radius_px is None or (pair is not None and abs(0.5 * (pair[1] - pair[0]) / radius_px - 1.0) <= _RADIUS_TOL
                             and not any(pair[0] + own < c < pair[1] - own for c in peaks)):
        if pair is None:
            raise err
        return pair
    fit = _central_pair(peaks, [_wall_side(col_score, c) for c in peaks], width,
                        lambda cl, cr: abs(0.5 * (cr - cl) / radius_px - 1.0) <= _RADIUS_TOL)
    if fit is not None:
        return fit
    outside = _partner_outside(col_score, peaks, width, radius_px)
    if outside:
        raise ChamberNotFound(outside)
    if pair is None:
        raise err
    return pair


def _partner_outside(col_score, peaks, width, radius_px):
    """Why the strongest zone (of ``peaks``) is one wall of a well whose other wall lies outside the frame's
    ``width`` columns, at twice the chamber's radius on its well's side ("" when it is not so): measured blind,
    a well with one wall outside the field was refused as walls that are not straight lines."""
    c = max(peaks, key=lambda q: col_score[q], default=None)
    if c is None:
        return ""
    side = _wall_side(col_score, c)
    others = [c + 2.0 * radius_px * s for s in ((-side,) if side else (-1, 1))]  # (a left wall's, -1, is right)
    if not all(o < 0 or o > width - 1 for o in others):
        return ""
    where = " or ".join(f"{o:.0f}" for o in others)
    return (f"one wall silhouette of a well of the chamber's radius ({radius_px:.0f} px) only, at column {c}: its "
            f"other wall would lie at column {where}, outside the frame's {width} columns (this route needs the "
            f"whole well in the field, its walls give the rim and register the drift, or the chamber's radius is "
            f"not this well's)")


def _zone_pair(col_score, width, min_width):
    """The columns of the two walls of the well nearest the field's centre, from the zones alone.

    The two strongest zones (:func:`_strongest`) unless they are not one
    well's left and right wall (:func:`_wall_side`: both of one side, or a
    right wall left of a left wall: the base between two neighbouring wells);
    then, of the strongest :data:`_WALL_CANDIDATES` zones at least
    :data:`_WALL_SHARE` of the strongest, the two next to each other (no such
    zone between them), not of contrary sides, whose middle is nearest the
    field's centre.  Measured on ho_blind_1206c (a neighbour's well beside the
    chamber, three zones of one strength): the two strongest were the
    chamber's right wall and the neighbour's left one, which the wall fit
    refused.  Nor are they when other wells lie between them
    (:func:`_wells_between`).
    """
    peaks = _strongest(col_score, width, min_width, _WALL_CANDIDATES)
    first = sorted(peaks[:2])
    peaks = [c for c in peaks if col_score[c] >= _WALL_SHARE * col_score[peaks[0]]]  # (not a well's inner features)
    sides = {c: _wall_side(col_score, c) for c in {*peaks, *first}}
    if not (sides[first[0]] == 1 or sides[first[1]] == -1):  # (unknown sides: the two strongest, as always)
        inner = _wells_between(col_score, width, min_width, first)
        return first if inner is None else inner
    cols = sorted(peaks)
    pair = _central_pair(cols, [sides[c] for c in cols], width)
    if pair is None:
        raise ChamberNotFound(f"no left and right wall silhouette of one well side by side in the base below the "
                              f"membrane (zones at columns {', '.join(map(str, cols))})")
    return pair


def _zone_peaks(col_score):
    """The zones' peaks (local maxima of the column score at least :data:`_RADIUS_GAP` px apart and at least
    :data:`_WALL_SHARE` of the strongest), left to right: each wall's once, however close the walls (a zone's
    fading side is not a zone of its own, as the strongest columns :data:`_RADIUS_GAP` apart would take it)."""
    top = float(np.max(col_score)) if col_score.size else 0.0
    if top < 0.1:
        return []
    peaks, _ = signal.find_peaks(col_score, height=_WALL_SHARE * top, distance=_RADIUS_GAP)
    return [int(c) for c in peaks]


def _wells_between(col_score, width, min_width, outer):
    """When a right wall's zone and, after it, a left wall's lie between the two walls ``outer`` (the base
    between two wells: several wells side by side, read as one), the two walls of the well nearest the field's
    centre; else None.

    The zones :func:`_zone_peaks`; the wells are the pairs next to each
    other, not of contrary sides, at least ``min_width`` apart
    (measured blind: three wells 40 um apart at 1.6 um/px, whose inner walls'
    zones lie 30 px apart, within find_walls' ``min_width``, were read as one
    well from the first's left wall to the third's right one; the flat frame
    ok with that rim).
    """
    cols = _zone_peaks(col_score)
    sides = [_wall_side(col_score, c) for c in cols]
    inside = [s for c, s in zip(cols, sides, strict=True) if outer[0] + _RADIUS_GAP < c < outer[1] - _RADIUS_GAP]
    base_between = any(a == 1 and -1 in inside[i + 1:] for i, a in enumerate(inside))
    # (or two zones or more between them whose sides are not known: a wall's zone alike on both sides, as
    # drawn_20261207_23's, is any wall's; one well has none between its walls)
    if not base_between and not (len(inside) >= 2 and 0 in inside):
        return None
    return _central_pair(cols, sides, width, lambda cl, cr: cr - cl >= min_width)


def neighbour_walls(maps, k, w, depth_px, strip=(0.15, 0.6), min_width=40):
    """The nearest walls of other wells beside the well of walls ``w`` (view of quarter turn ``k`` of the flat
    frame's :class:`FlatMaps`): ``(left, right)`` columns at the base's top surface, nan where there is none.

    A neighbour on the right shows its left wall: a silhouette zone (as
    :func:`find_walls` reads them, in the same rows of the base) at least
    ``min_width`` px right of the right wall, not of a right wall's side
    (:func:`_wall_side`; a zone whose flanks fall alike is taken), at least :data:`_WALL_SHARE` of the weaker of the
    well's own two zones, whose edge follows a straight line down the base
    (:data:`MAX_WALL_RMS`); the nearest such one; when there is none, the same
    of the zones' peaks (:func:`_zone_peaks`) from :data:`_RADIUS_GAP` px off the wall
    (measured blind: wells 40 um apart at 1.6 um/px, whose walls' zones lie
    30 px apart, were not seen, and the three domes were searched as one).
    The same mirrored on the left.
    """
    _, _, sd = maps.view(k)
    r0, r1, col_score = _zone_scores(np.rot90(maps.size, k), w.base_row, depth_px, strip)
    out = [np.nan, np.nan]
    if col_score is None:
        return tuple(out)
    m = col_score.size
    lo, hi = int(np.clip(w.left, 0, m - 1)), int(np.clip(w.right, 0, m - 1))
    own = min(col_score[lo : lo + 12].max(), col_score[max(hi - 11, 0) : hi + 1].max())  # (the zones inside the walls)
    rows = np.arange(r0, r1).astype(float)
    strip_sd = sd[r0:r1]
    for gap in (min_width, _RADIUS_GAP):
        if np.isfinite(out).all():
            break
        if gap == min_width:
            try:
                peaks = _strongest(col_score, m, gap, 2 * _WALL_CANDIDATES)
            except ChamberNotFound:  # (fewer than two zones: the well's own at most)
                return tuple(out)
        else:
            peaks = _zone_peaks(col_score)
        for c in sorted(peaks, key=lambda c: min(abs(c - w.left), abs(c - w.right))):
            right = c > w.right + gap
            if not (right or c < w.left - gap) or col_score[c] < _WALL_SHARE * own:
                continue
            # (a zone whose flanks fall alike, side 0, is taken: measured on drawn_20261207_23, wells 36 um apart
            # at 1.27 um/px, their near walls' zones 33 px apart and alike on both sides; the neighbours were not
            # seen and the three touching domes were traced as one, flagged fractured)
            if _wall_side(col_score, c) == (1 if right else -1) or np.isfinite(out[int(right)]):
                continue
            u = _wall_edges(strip_sd, c) if not right else m - 1 - _wall_edges(strip_sd[:, ::-1], m - 1 - c)
            at, rms, n = _clipped_line(rows, u, float(w.base_row))
            if n >= 5 and rms <= MAX_WALL_RMS:
                out[int(right)] = float(at)
    return tuple(out)


def _fit_walls(sd, peaks, r0, r1, top_row, base_row, pair=None, clipped=None):
    """Each wall's outer half-level edge row by row, fitted by a line and read at ``base_row``.

    ``sd``: the signed relative deviation from the local light.  The level is
    half-way between the silhouette zone's extreme and the light just outside
    the wall (4-12 px out): the local light, a mean over the zone as well,
    lies between them, so the level is not half of the deviation's peak.
    ``pair``: a later frame's and its first frame's light over this frame's,
    less 1 (:func:`find_walls`' ``reference``): the rows :func:`_changed_rows`
    finds are left out of the lines; ``clipped``: the pixels the camera
    clipped (the rows :func:`_moved_by_clip` finds are left out).
    """
    cl, cr = sorted(peaks)
    rows = np.arange(r0, r1)
    m = sd.shape[1]
    strip = sd[r0:r1]
    # the wall's zone lies inside the well: its outer edge is the wall (the left one walked in flipped columns)
    left = m - 1 - _wall_edges(strip[:, ::-1], m - 1 - cl)
    right = _wall_edges(strip, cr)
    if pair is not None:
        gone = _changed_rows(pair[0][r0:r1], pair[1][r0:r1], left, right)
        left, right = (np.where(g, np.nan, u) for u, g in zip((left, right), gone, strict=True))
    if clipped is not None:  # (the left wall walked in flipped columns, as its edges were found)
        cut = clipped[r0:r1]
        left = np.where(_moved_by_clip(cut[:, ::-1], m - 1 - left, m - 1 - cl), np.nan, left)
        right = np.where(_moved_by_clip(cut, right, cr), np.nan, right)
    fits, res = [], []
    for u in (left, right):
        at, rms, n = _clipped_line(rows.astype(float), u, float(base_row))
        if clipped is not None and n < max(5, (r1 - r0) / 3):
            raise ChamberNotFound(f"the camera clipped a wall's silhouette on all but {n} of its {r1 - r0} rows")
        if n < 5:
            raise ChamberNotFound("a wall's silhouette edge could not be followed down the base")
        fits.append(float(at))
        res.append(float(rms))
    if max(res) > MAX_WALL_RMS:
        raise ChamberNotFound(f"the wall silhouettes are not straight lines (row scatter {max(res):.2f} px > "
                              f"{MAX_WALL_RMS} px): not walls, or a look this search cannot read")
    return SilhouetteWalls(float(top_row), float(base_row), fits[0], fits[1], max(res))


def _moved_by_clip(clipped, edge, c):
    """The rows whose :func:`_wall_edges` read a clipped pixel may have moved (``clipped``: the strip's rows,
    walking outwards to higher columns as ``edge`` was found from the zone at ``c``).

    The half level lies half-way between the zone's extreme (within 3 px
    of ``c``) and the median of the light 4-12 px beyond the edge; the
    edge is where the light crosses it between two pixels.  Clipping only
    lowers the brightest pixels and keeps their order, so the read is
    exact unless a clipped pixel is the zone's extreme (any within 3 px of
    ``c``), one of the two the crossing lies between, or the median beyond
    (half or more of those pixels clipped; the pixels beyond are counted
    from the first crossing, half-way to the light, which may lie a pixel
    off the edge: each of the three windows a pixel apart is checked).
    """
    n, m = clipped.shape
    out = np.ones(n, bool)
    for i in range(n):
        e = edge[i]
        if not np.isfinite(e):
            continue
        j = int(np.floor(e))
        zone = clipped[i, max(c - 3, 0) : min(c + 4, m)]
        cross = clipped[i, max(j, 0) : min(j + 2, m)]
        k = int(np.rint(e))
        beyond = [clipped[i, min(max(k + o + 4, 0), m) : min(max(k + o + 13, 0), m)] for o in (-1, 0, 1)]
        out[i] = zone.any() or cross.any() or any(b.size > 0 and 2 * np.count_nonzero(b) >= b.size for b in beyond)
    return out


def _changed_rows(now, then, left, right):
    """The rows of each wall (``left``, ``right``: its edges, :func:`_wall_edges`) where this frame changed since the
    first beyond the light and the wall's own shift: ``now`` and ``then``, this frame and the first frame (in this
    frame's light) over this frame's light, less 1, in the strip's rows.  Two tests, either suffices:

    * the light just outside the wall (the median of ``now - then`` over 4-12
      px out, at least 4 samples) lies more than :data:`_CHANGED_ROW` times
      the noise off the median over both walls' rows (a change they share:
      the walls' halos moved with their lean, light not quite taken off); the
      noise, of one sample, from the differences of neighbouring samples
      (their mean absolute value: a smooth particle's own slope barely counts);
    * the row across the wall (``_ALIGN_HALF`` px either side of its edge)
      matched by the first frame's row shifted (within ``_ALIGN_REACH`` px:
      the wall's lean, the drift's fraction of a px; :func:`_aligned_misfits`)
      leaves a mean square more than :data:`_CHANGED_SHAPE` times the median
      over both walls' rows, or the noise squared when that is larger: a
      particle over the wall's edge, which a shift does not explain.

    The rows found and those within :data:`_CHANGED_SPREAD` of them (a particle's
    blurred rim) are left out; a wall keeps its rows when fewer than 5, or than a
    third of them, would be left.
    """
    change = now - then
    levels, diffs, count = [], 0.0, 0
    for edges, outward in ((left, -1), (right, 1)):
        level, d, k = _outside_levels(change, edges, outward)
        levels.append(level)
        diffs, count = diffs + d, count + k
    if count == 0:
        return [np.zeros(left.shape, bool), np.zeros(right.shape, bool)]
    noise = max(np.sqrt(np.pi / 2) * diffs / count / np.sqrt(2), 1e-3)  # (relative light)
    both = np.concatenate(levels)
    common = np.nanmedian(both) if np.isfinite(both).any() else 0.0
    now, then = np.ascontiguousarray(now), np.ascontiguousarray(then)
    misfits = [_aligned_misfits(now, then, u, _ALIGN_REACH, _ALIGN_HALF) for u in (left, right)]
    every = np.concatenate(misfits)
    typical = max(np.nanmedian(every), noise**2) if np.isfinite(every).any() else np.inf
    gone = []
    for u, level, misfit in zip((left, right), levels, misfits, strict=True):
        g = (np.abs(level - common) > _CHANGED_ROW * noise) | (misfit > _CHANGED_SHAPE * typical)  # (False at nan)
        if g.any():
            g = ndimage.binary_dilation(g, iterations=_CHANGED_SPREAD)
        kept = np.count_nonzero(np.isfinite(u) & ~g)
        gone.append(g if kept >= max(5, np.count_nonzero(np.isfinite(u)) / 3) else np.zeros(u.shape, bool))
    return gone


@njit(cache=True, nogil=True)
def _clipped_line(x, y, at):
    """:func:`_fit_walls`' line of one wall through the finite ``(x, y)``: the least-squares line, fitted again
    without the points more than ``max(3 std, 0.3)`` px off it (std of the residuals, numpy's ``ddof=0``); its
    value at ``at``, the rms of the kept points' residuals from it, and the number of finite points (the
    values are nan below 2)."""
    keep = np.isfinite(y)
    n = int(keep.sum())
    if n < 2:
        return np.nan, np.nan, n
    a, b, _ = _masked_line(x, y, keep)  # (the rows are distinct: b is finite)
    r = np.empty(n)
    c = 0
    for i in range(x.size):
        if keep[i]:
            r[c] = y[i] - (a + b * x[i])
            c += 1
    lim = max(3.0 * np.std(r), 0.3)
    c = 0
    for i in range(x.size):
        if keep[i]:
            keep[i] = abs(r[c]) <= lim
            c += 1
    a, b, m = _masked_line(x, y, keep)
    ss = 0.0
    for i in range(x.size):
        if keep[i]:
            d = y[i] - (a + b * x[i])
            ss += d * d
    return a + b * at, np.sqrt(ss / m), n


@njit(cache=True, nogil=True)
def _outside_levels(change, edges, outward):
    """:func:`_changed_rows`' samples of ``change`` 4-12 px outside each row's edge ``edges`` (``outward``: +1 to
    higher columns, -1 to lower; the edge rounded to the pixel): per row their median (``np.nanmedian``; nan with
    fewer than 4 finite samples inside the row, or no edge), and the sum of the absolute differences of
    neighbouring finite samples and their number."""
    n, m = change.shape
    level = np.full(n, np.nan)
    vals = np.empty(9)
    diffs, count = 0.0, 0
    for i in range(n):
        e = edges[i]
        if not np.isfinite(e):
            continue
        k0 = int(np.rint(e))
        cnt = 0
        last = np.nan
        for o in range(4, 13):
            k = k0 + outward * o
            v = change[i, k] if 0 <= k < m else np.nan
            if np.isfinite(v) and np.isfinite(last):
                diffs += abs(v - last)
                count += 1
            last = v
            if np.isfinite(v):
                vals[cnt] = v
                cnt += 1
        if cnt >= 4:
            srt = np.sort(vals[:cnt])
            level[i] = 0.5 * (srt[(cnt - 1) // 2] + srt[cnt // 2])
    return level, diffs, count


@njit(cache=True, nogil=True)
def _aligned_misfits(now, then, edges, reach, half):
    """:func:`_changed_rows`' misfit of each row: over the columns ``j`` within ``half`` of the row's rounded edge,
    the least mean of ``(now[j] - then[j - f])**2`` over the shifts ``f`` in whole px within ``reach`` (the first
    least), then in tenths of a px within 1 px of the best whole one (``then`` linearly interpolated; a tenth
    reaching past the row is skipped); nan where there is no edge or the window or a whole shift's leaves the row
    (those shifts are skipped)."""
    n, m = now.shape
    out = np.full(n, np.nan)
    for i in range(n):
        e = edges[i]
        if not np.isfinite(e):
            continue
        c = int(np.rint(e))
        j0, j1 = c - half, c + half + 1
        if j0 < 0 or j1 > m:
            continue
        best, bs = np.inf, 0
        for s in range(-reach, reach + 1):
            if j0 - s < 0 or j1 - s > m:
                continue
            ss = 0.0
            for j in range(j0, j1):
                d = now[i, j] - then[i, j - s]
                ss += d * d
            if ss < best:
                best, bs = ss, s
        if not np.isfinite(best):
            continue
        for t in range(-10, 11):
            f = bs + 0.1 * t
            ss = 0.0
            ok = True
            for j in range(j0, j1):
                x = j - f
                k = int(np.floor(x))
                if k < 0 or k + 1 >= m:
                    ok = False
                    break
                w = x - k
                d = now[i, j] - ((1.0 - w) * then[i, k] + w * then[i, k + 1])
                ss += d * d
            if ok and ss < best:
                best = ss
        out[i] = best / (j1 - j0)
    return out


# ---------------------------------------------------------------------- compiled inner loops
# Each does what the numpy/scipy expression in its docstring does, with the same result to the bit (checked in
# tests/imaging/test_silhouette.py), without its sorts, copies and temporary arrays; those that divide take
# numpy's error model (x / 0 is inf or nan, not ZeroDivisionError).


def _percentile_rows(a, q):
    """``np.percentile(a, q, axis=1)`` of a 2-D array (of a turned view: read along its stored rows)."""
    if abs(a.strides[0]) < abs(a.strides[1]):
        return _column_percentiles(a.T, *_rank(a.shape[1], q))
    return _row_percentiles(a, *_rank(a.shape[1], q))


@njit(cache=True, nogil=True)
def _select2(a, n, k, b):
    """The ``k``-th and ``k + 1``-th smallest values of ``a[:n]`` (no nan, ``k + 1 < n``; ``a`` and ``b``, of at
    least ``n``, are overwritten): quickselect, each pass splitting without branches."""
    smp = np.empty(9)
    while n > 16:
        if n < 64:
            x0, x1, x2 = a[0], a[n >> 1], a[n - 1]
            p = max(min(x0, x1), min(max(x0, x1), x2))  # (median of three)
        else:  # of nine evenly spaced (sorted), the one just past the k-th's expected place towards the middle
            for i in range(9):
                x = a[(2 * i + 1) * n // 18]
                j = i - 1
                while j >= 0 and smp[j] > x:
                    smp[j + 1] = smp[j]
                    j -= 1
                smp[j + 1] = x
            f = 10.0 * (k + 0.5) / n - 1.0
            p = smp[min(max(int(f + 1.5) if f < 4.0 else int(f - 0.5), 0), 8)]
        n_lt = n_gt = 0
        for j in range(n):  # below the pivot to the front of a, above it to b
            x = a[j]
            a[n_lt] = x
            b[n_gt] = x
            n_lt += x < p
            n_gt += x > p
        n_le = n - n_gt
        if k + 1 < n_lt:
            n = n_lt
        elif k + 1 == n_lt:
            m = a[0]
            for j in range(1, n_lt):
                m = max(m, a[j])
            return m, p
        elif k + 1 < n_le:
            return p, p
        elif k + 1 == n_le:
            m = b[0]
            for j in range(1, n_gt):
                m = min(m, b[j])
            return p, m
        else:
            k -= n_le
            n = n_gt
            a, b = b, a
    for i in range(1, n):  # (insertion sort)
        x = a[i]
        j = i - 1
        while j >= 0 and a[j] > x:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = x
    return a[k], a[k + 1]


@njit(cache=True, nogil=True)
def _column_medians(a):
    """``np.median(a, axis=0)`` of a 2-D array."""
    m, n = a.shape
    out = np.empty(n)
    cols = np.empty((n, max(m, 1)))
    for i in range(m):
        for j in range(n):
            cols[j, i] = a[i, j]
    b = np.empty(max(m, 1))
    for j in range(n):
        v = cols[j]
        nan = m == 0
        for i in range(m):
            nan |= np.isnan(v[i])
        if nan:
            out[j] = np.nan
        elif m == 1:
            out[j] = v[0]
        elif m % 2:
            out[j] = _select2(v, m, m // 2, b)[0]
        else:
            x0, x1 = _select2(v, m, m // 2 - 1, b)
            out[j] = (x0 + x1) / 2.0
    return out


@njit(cache=True, nogil=True)
def _percentile_of(a, n, lo, t, b):
    """The percentile of rank ``lo`` and weight ``t`` (:func:`_rank`) of ``a[:n]`` (no nan; ``a`` and ``b``
    overwritten), interpolated as numpy's ``_lerp``."""
    if lo + 1 < n:
        x0, x1 = _select2(a, n, lo, b)
    else:  # (the largest)
        x0 = a[0]
        for j in range(1, n):
            x0 = max(x0, a[j])
        x1 = x0
    return _lerp(x0, x1, t)


@njit(cache=True, nogil=True)
def _row_percentiles(a, lo, t):
    """Each row's percentile of rank ``lo`` and weight ``t`` (:func:`_rank`): ``np.percentile(a, q, axis=1)``."""
    m, n = a.shape
    out = np.empty(m)
    v = np.empty(max(n, 1))
    b = np.empty(max(n, 1))
    for i in range(m):
        nan = n == 0
        for j in range(n):
            v[j] = a[i, j]
            nan |= np.isnan(v[j])
        out[i] = np.nan if nan else _percentile_of(v, n, lo, t, b)
    return out


@njit(cache=True, nogil=True)
def _column_percentiles(a, lo, t):
    """:func:`_row_percentiles` of ``a.T`` (``np.percentile(a, q, axis=0)``), ``a`` read along its rows: its
    columns copied 32 at a time (down a column, a power-of-two stride would make the cache forget them)."""
    m, n = a.shape
    out = np.empty(n)
    cols = np.empty((32, m + 8))  # (rows 8 apart from a power of two)
    b = np.empty(max(m, 1))
    for j0 in range(0, n, 32):
        nj = min(32, n - j0)
        for i in range(m):
            for q in range(nj):
                cols[q, i] = a[i, j0 + q]
        for q in range(nj):
            v = cols[q]
            nan = m == 0
            for i in range(m):
                nan |= np.isnan(v[i])
            out[j0 + q] = np.nan if nan else _percentile_of(v, m, lo, t, b)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _size_percentile(img, bg, lo, t):
    """:func:`_scaled_deviation`'s floor of the light, ``1e-6 * max(bg.max(), 1e-30)``, and percentile (rank
    ``lo``, weight ``t``) of ``np.abs((img - bg) / np.maximum(bg, floor))``.

    One pass over the frame when no light is below the floor (as
    ``_relative``'s): only the sizes between two order statistics of a
    sample of them that bound the two it needs (checked by their counts)
    are kept to select from.
    """
    m, n = img.shape
    size = m * n
    if size == 0:
        return np.nan, np.nan
    hi = min(lo + 1, size - 1)
    below, above = -np.inf, np.inf
    step = size // 4096
    if step >= 4:
        ns = size // step
        smp = np.empty(ns)
        nan = False
        for s in range(ns):
            i, j = divmod(s * step, n)
            smp[s] = abs((img[i, j] - bg[i, j]) / bg[i, j])
            nan |= np.isnan(smp[s])
        if not nan:
            margin = int(4.0 * np.sqrt(ns)) + 8
            r0, r1 = lo * ns // size - margin, hi * ns // size + margin
            scratch = np.empty(ns)
            below = -np.inf if r0 < 0 else _select2(smp, ns, r0, scratch)[0]
            above = np.inf if r1 >= ns - 1 else _select2(smp, ns, r1, scratch)[0]
    keep = np.empty(size)
    k = n_lt = n_gt = 0
    top, low, nan = -np.inf, np.inf, False
    for i in range(m):
        for j in range(n):
            b = bg[i, j]
            if b > top:
                top = b
            if b < low:
                low = b
            nan |= np.isnan(b)
            x = abs((img[i, j] - b) / b)
            if x < below:
                n_lt += 1
            elif x > above:
                n_gt += 1
            else:  # (and nan)
                keep[k] = x
                k += 1
    floor = np.nan if nan else 1e-6 * (1e-30 if top < 1e-30 else top)
    if nan or low < floor or not (n_lt <= lo and hi <= size - 1 - n_gt):  # all of them, with the floor
        k = n_lt = 0
        for i in range(m):
            for j in range(n):
                b = bg[i, j]
                if b < floor or nan:
                    b = floor
                keep[k] = abs((img[i, j] - bg[i, j]) / b)
                k += 1
    for i in range(k):
        if np.isnan(keep[i]):
            return floor, np.nan
    return floor, _percentile_of(keep, k, lo - n_lt, t, np.empty(k))


@njit(cache=True, nogil=True, error_model="numpy")
def _scaled(img, bg, floor, scale, sd, size):
    """``sd = (img - bg) / np.maximum(bg, floor) / scale`` and ``size = np.abs(sd)``."""
    m, n = img.shape
    nan = np.isnan(floor)
    for i in range(m):
        for j in range(n):
            b = bg[i, j]
            if b < floor or nan:  # (np.maximum: nan if either is)
                b = floor
            x = (img[i, j] - bg[i, j]) / b / scale
            sd[i, j] = x
            size[i, j] = abs(x)


@njit(cache=True, nogil=True, error_model="numpy")
def _column_means(img, s, by_rows):
    """``s = img[:, :4 * w].reshape(h, w, 4).mean(axis=2)`` (numpy's order of the sum), ``s`` of shape (h, w);
    ``img`` read along its rows (``by_rows``) or its columns."""
    h, w = s.shape
    if by_rows:
        for i in range(h):
            for c in range(w):
                s[i, c] = (((img[i, 4 * c] + img[i, 4 * c + 1]) + img[i, 4 * c + 2]) + img[i, 4 * c + 3]) / 4.0
    else:
        for c in range(w):
            for i in range(h):
                s[i, c] = (((img[i, 4 * c] + img[i, 4 * c + 1]) + img[i, 4 * c + 2]) + img[i, 4 * c + 3]) / 4.0


@njit(cache=True, nogil=True)
def _running_median(s, win, out):
    """``out = ndimage.median_filter(s, size=(win, 1), mode="nearest")`` of a finite 2-D array, odd ``win``.

    Each column's window is kept sorted (``a[:, c]``) as it slides down, one
    value out and one in, by the same operations for all the columns (no
    branches: the compiler vectorises them).  Windows of 3 and 5: their
    medians by comparisons.
    """
    h, w = s.shape
    if win == 3 or win == 5:
        for i in range(h):
            s0, s1, s2 = s[max(i - 1, 0)], s[i], s[min(i + 1, h - 1)]
            s3, s4 = s[max(i - 2, 0)], s[min(i + 2, h - 1)]
            o = out[i]
            for c in range(w):
                x, y, z = s0[c], s1[c], s2[c]
                if win == 5:  # the least and the greatest of the four around y are not the median: dropped
                    lo, hi = min(s3[c], s4[c]), max(s3[c], s4[c])
                    x, z = max(lo, min(x, z)), min(hi, max(x, z))
                o[c] = max(min(x, y), min(max(x, y), z))  # (median of three)
        return
    half = win // 2
    a = np.empty((win, w))
    b = np.empty((win, w))
    pos = np.empty(w, np.int64)
    for c in range(w):
        for j in range(win):
            v = s[min(max(j - half, 0), h - 1), c]
            p = j
            while p > 0 and a[p - 1, c] > v:
                a[p, c] = a[p - 1, c]
                p -= 1
            a[p, c] = v
        out[0, c] = a[half, c]
    for i in range(1, h):
        old, new = s[max(i - 1 - half, 0)], s[min(i + half, h - 1)]
        pos[:] = 0  # the old value's place: how many are below it
        for p in range(win):
            ap = a[p]
            for c in range(w):
                pos[c] += ap[c] < old[c]
        # b[p] = max(t[p - 1], min(t[p], new)) with t: a without the old value (-inf, +inf past its ends)
        a0, a1, bp = a[0], a[1], b[0]
        for c in range(w):
            x0, x1, y = a0[c], a1[c], new[c]
            hi = x0 if pos[c] > 0 else x1
            bp[c] = hi if hi < y else y
        for p in range(1, win - 1):
            a0, a1, a2, bp = a[p - 1], a[p], a[p + 1], b[p]
            for c in range(w):
                q, x0, x1, x2, y = pos[c], a0[c], a1[c], a2[c], new[c]
                lo = x0 if p - 1 < q else x1
                hi = x1 if p < q else x2
                hi = hi if hi < y else y
                bp[c] = hi if hi > lo else lo
        a0, a1, bp = a[win - 2], a[win - 1], b[win - 1]
        for c in range(w):
            x0, x1, y = a0[c], a1[c], new[c]
            lo = x0 if win - 2 < pos[c] else x1
            bp[c] = y if y > lo else lo
        a, b = b, a
        for c in range(w):
            out[i, c] = a[half, c]


@njit(cache=True, nogil=True, error_model="numpy")
def _line_rows(s, med, off, lo, t, best):
    """:func:`_line_score`'s row score of one thickness, into ``best`` where larger: with ``up`` and ``dn`` the
    median ``med`` ``off`` rows above and below (edge rows repeated), ``a = s / np.maximum(up, 1e-12) - 1``
    and ``b`` likewise, ``r = np.where(a * b > 0, np.minimum(|a|, |b|), 0)``; its rows' percentile of rank
    ``lo`` and weight ``t``."""
    h, w = s.shape
    hi = min(lo + 1, w - 1)
    full = np.empty(max(w, 1))
    r = np.empty(max(w, 1))
    b = np.empty(max(w, 1))
    for i in range(h):
        si, up, dn = s[i], med[max(i - off, 0)], med[min(i + off, h - 1)]
        for j in range(w):
            u, d, x = up[j], dn[j], si[j]
            ra = x / (1e-12 if u < 1e-12 else u) - 1.0
            rb = x / (1e-12 if d < 1e-12 else d) - 1.0
            m = abs(ra) if abs(ra) <= abs(rb) else abs(rb)
            full[j] = m if ra * rb > 0 else 0.0
        k = 0  # the positive r, to the front (the others are 0, below them)
        for j in range(w):
            r[k] = full[j]
            k += full[j] > 0
        zeros = w - k
        if w == 0:
            p = np.nan
        elif zeros > hi:
            p = 0.0
        elif zeros > lo:  # (0 and the smallest positive)
            m = r[0]
            for j in range(1, k):
                m = min(m, r[j])
            p = _lerp(0.0, m, t)
        else:
            p = _percentile_of(r, k, lo - zeros, t, b)
        if np.isnan(p) or p > best[i]:
            best[i] = p


@njit(cache=True, nogil=True, error_model="numpy")
def _crossing(sd, i, pk, sign, base):
    """:func:`_half_crossing` of row ``i`` of ``sign * sd`` from ``pk`` walking to higher indices (nan where it
    does not fall to the level; a nan stops the walk)."""
    m = sd.shape[1]
    top = sign * sd[i, pk]
    half = 0.5 * (top + base)
    if not top > half:
        return np.nan
    j = pk + 1
    while j < m and sign * sd[i, j] > half:
        j += 1
    if j == m:
        return np.nan
    p = sign * sd[i, j - 1]
    return (j - 1) + (p - half) / (p - sign * sd[i, j])


@njit(cache=True, nogil=True, error_model="numpy")
def _wall_edges(sd, c):
    """Per row of ``sd`` (signed deviation, walking outwards to higher indices), the wall's outer half-level edge
    from its zone's extreme within 3 columns of ``c``: :func:`_fit_walls`' rule, on all the rows at once.

    The zone's extreme is the first largest ``|sd|`` in the row's columns
    ``c - 3 .. c + 3``; the edge, the first crossing (:func:`_half_crossing`) of
    the level half-way from it to 0 and then, with the median of the light
    just outside the wall (4-12 px past that crossing, at least 4 of them
    inside the row) as the base, half-way from it to that base (the first
    crossing when there is none); nan where there is no crossing.
    """
    n, m = sd.shape
    lo, hi = max(c - 3, 0), min(c + 4, m)
    out = np.full(n, np.nan)
    vals = np.empty(9)
    for i in range(n):
        if hi <= lo:
            continue
        pk = lo  # (np.argmax: the first largest, or the first nan)
        top = abs(sd[i, lo])
        if not np.isnan(top):
            for j in range(lo + 1, hi):
                x = abs(sd[i, j])
                if np.isnan(x):
                    pk = j
                    break
                if x > top:
                    top, pk = x, j
        x = sd[i, pk]
        sign = 1.0 if x > 0 else (-1.0 if x < 0 else (0.0 if x == 0 else np.nan))  # (np.sign)
        e = _crossing(sd, i, pk, sign, 0.0)
        out[i] = e
        if not np.isfinite(e):
            continue
        # the light just outside the wall: the median of 4-12 px out (nan ignored)
        k0 = int(np.rint(e))
        valid = cnt = 0
        for o in range(4, 13):
            if 0 <= k0 + o < m:
                valid += 1
                v = sign * sd[i, k0 + o]
                if not np.isnan(v):
                    vals[cnt] = v
                    cnt += 1
        if valid < 4 or cnt == 0:
            continue
        v = np.sort(vals[:cnt])
        e2 = _crossing(sd, i, pk, sign, (v[(cnt - 1) // 2] + v[cnt // 2]) / 2.0)
        if np.isfinite(e2):
            out[i] = e2
    return out
