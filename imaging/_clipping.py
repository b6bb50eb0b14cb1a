"""Light the camera clipped: pixels at its full scale, where the light read is a bound, not a value.

A camera records at most its full scale (``2**bits - 1``).  Brighter light,
an exposure turned up or stray light added over the day, reads as that value:
a level read from such pixels is too low by an amount the frame does not tell,
and a half-level crossing between it and a darker side moves towards the
darker side.

The band route reads each wall as the half-level crossing of a step between
the well's and the base's levels.  Measured on painted_band with its light
1.6x from the series' middle (the well's liquid, 0.8 of full scale, clipped):
the rim read 1.1-1.2 px off with every frame ``ok``.  :func:`wall_clipping`
tells a frame whose walls are read in clipped light; the band route then reads
them again with the clipped pixels :data:`BRIGHTER` and flags the frame
``clipped`` when they move more than :data:`MOVED_FLAG` px.

The silhouette route reads the walls of a frame with more clipped light than
its first frame on the rows whose half-level read no clipped pixel can have
moved (``osmobulge.imaging._silhouette._moved_by_clip``: clipping keeps the
pixels' order), or with too few of those by matching the first frame's
profile across them over the pixels recorded
(``SilhouetteTracer._shifted_walls``; both use :func:`clip_mask`): the
re-read above does not tell its right frames from its wrong ones there (it
moves both 0.2-0.5 px).

Only the top is a clip: a dark pixel at 0 is light near none, which a level
read from it does not miss by more than the noise.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FULL_SCALES", "BRIGHTER", "MOVED_FLAG", "clip_level", "clip_mask", "clip_message", "clipped_share",
           "raised", "wall_clipping"]

#: the values a camera's or a file's full scale takes: 8, 10, 12, 14 and 16 bits, and 1.0 (floats scaled to 1)
FULL_SCALES = (1.0, 255.0, 1023.0, 4095.0, 16383.0, 65535.0)

#: fewest pixels at the top value that make it a clip (one or two are the brightest of a smooth distribution)
MIN_PILE = 3

#: how much brighter than the clip level the clipped pixels are read to see whether the walls depend on them
BRIGHTER = 1.25

#: a frame whose walls move more than this (px) when its clipped pixels are read :data:`BRIGHTER` is flagged
#: ``clipped`` (half issue 16's 0.5 px tolerance of the rim radius)
MOVED_FLAG = 0.25

#: the rows of the walls read, as fractions of the well's depth below the base's top surface
WALL_ROWS = (0.06, 0.92)

#: the columns each side of a wall read, px from it (the levels either side of its edge)
WALL_REACH = (2.0, 12.0)


def clip_level(values):
    """The camera's clip level in ``values``: their largest value when it is a full scale (:data:`FULL_SCALES`
    or the integer dtype's largest) held by at least :data:`MIN_PILE` of them, else None."""
    v = np.asarray(values)
    if v.size == 0:
        return None
    top = np.nanmax(v) if v.dtype.kind == "f" else v.max()
    full = float(np.iinfo(v.dtype).max) if v.dtype.kind in "ui" else np.nan
    if not (float(top) in FULL_SCALES or float(top) == full):
        return None
    return top if np.count_nonzero(v == top) >= MIN_PILE else None


def clip_mask(values):
    """Boolean mask of ``values`` at the camera's clip level (see :func:`clipped_share`), or None when none is."""
    v = np.asarray(values)
    top = clip_level(v)
    return None if top is None else v == top


def raised(values, mask, factor=BRIGHTER):
    """``values`` as float32 with the ``mask``'s pixels ``factor`` times brighter (a copy)."""
    out = np.array(values, np.float32)
    out[mask] *= factor
    return out


def clip_message(moved):
    """The message of a frame flagged ``clipped`` (``moved``: how far its walls moved, px)."""
    how = "were not found" if not np.isfinite(moved) else f"moved {moved:.2f} px"
    return (f"the walls are read in light the camera clipped (pixels at its full scale): read {BRIGHTER:g}x "
            f"brighter, they {how}, so the rim radius depends on light the frame did not record; lower the "
            f"exposure or the lamp, or keep the frame if its volume is all you need (curation: keep flagged)")


def clipped_share(values) -> float:
    """Share of ``values`` at the camera's clip level: their largest value when it is a full scale
    (:data:`FULL_SCALES`, or the integer dtype's largest) held by at least :data:`MIN_PILE` of them; else 0.

    >>> clipped_share(np.array([10, 4095, 4095, 4095, 200], np.uint16))
    0.6
    >>> clipped_share(np.array([10, 4000, 4000, 4000, 200], np.uint16))
    0.0
    """
    v = np.asarray(values)
    v = v[np.isfinite(v)] if v.dtype.kind == "f" else v.ravel()
    mask = clip_mask(v)
    return 0.0 if mask is None else float(np.count_nonzero(mask)) / v.size


def wall_clipping(view, geometry) -> float:
    """The largest share, over each wall's two sides, of the pixels the wall's levels are read from that lie at
    the camera's clip level (:func:`clipped_share`; nan without walls).

    ``view``: the frame (:class:`~osmobulge.imaging._chamber.FrameView`, as
    stored: no gain divided out); ``geometry``: its
    :class:`~osmobulge.imaging._chamber.ChamberGeometry`.  Each side is the
    pixels :data:`WALL_REACH` px from the wall, on its rows :data:`WALL_ROWS`
    of the well's depth below the base's top surface, nearest pixels (a
    bilinear sample would mix a clipped pixel with its neighbours).
    """
    g = geometry
    well = g.well
    depth = well.depth if np.isfinite(well.depth) else 4.0 * g.thickness
    top = -0.5 * g.thickness  # (the base's top surface; z up from the film's mid-line)
    z = top - np.linspace(*WALL_ROWS, max(int(0.86 * depth), 8)) * depth
    reach = np.arange(WALL_REACH[0], WALL_REACH[1] + 0.5)
    shares = []
    for u0, slope, outward in ((well.u_left, well.slope_left, -1.0), (well.u_right, well.slope_right, 1.0)):
        u_wall = u0 + slope * (z - top)
        for sign in (-1.0, 1.0):  # (inside the well, then outside it)
            u = u_wall[:, None] + sign * outward * reach[None, :]
            xy = g.line.point(u, z[:, None].repeat(reach.size, axis=1))
            r, c = view.to_frame(np.rint(xy[..., 0]), np.rint(xy[..., 1]))
            r, c = r.astype(int).ravel(), c.astype(int).ravel()
            inside = (r >= 0) & (r < view.frame.shape[0]) & (c >= 0) & (c < view.frame.shape[1])
            if np.count_nonzero(inside) < 10:
                continue
            shares.append(clipped_share(view.frame[r[inside], c[inside]]))
    return float(max(shares)) if shares else np.nan
