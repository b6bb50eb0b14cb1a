"""Low-level ridge tracing along the normals of a guide curve (sub-pixel, robust).

Pure numerics on float images in the bulge-up frame (row 0 at the top, the
pixel ``(row, col)`` centred on ``(x=col, y=row)``).  Used by
:mod:`osmobulge.imaging.trace`.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from osmobulge.imaging._kernels import viterbi_rows

__all__ = ["sample_normals", "viterbi_path", "band_centres", "resample_polyline", "polyline_normals"]


def resample_polyline(points, step):
    """Resample an open polyline (N, 2) at even arc-length ``step``; returns (M, 2) and arc lengths (M,)."""
    p = np.asarray(points, float)
    seg = np.hypot(*np.diff(p, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    keep = np.concatenate([[True], seg > 1e-9])
    p, s = p[keep], s[keep]
    n = max(int(np.ceil(s[-1] / step)) + 1, 2)
    si = np.linspace(0.0, s[-1], n)
    return np.c_[np.interp(si, s, p[:, 0]), np.interp(si, s, p[:, 1])], si


def polyline_normals(points, *, smooth=2.0):
    """Unit normals (N, 2) of a polyline, the tangent rotated by +90 deg (to the left of travel).

    With (x=col, y=row) and rows growing downwards, a curve travelled left to
    right over a dome gets normals pointing up-and-out of the dome (row 0).
    """
    p = np.asarray(points, float)
    t = np.gradient(p, axis=0)
    if smooth and len(p) > 5:
        t = ndi.gaussian_filter1d(t, smooth, axis=0, mode="nearest")
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    return np.c_[t[:, 1], -t[:, 0]]


def sample_normals(image, points, normals, offsets, *, order=1):
    """Image values along normals: ``image`` at ``points + offsets * normals``.

    Parameters
    ----------
    image : ndarray of shape (H, W)
        Float image.
    points, normals : ndarray of shape (N, 2)
        Curve points and unit normals in (x=col, y=row) pixels.
    offsets : ndarray of shape (K,)
        Signed distances along the normals (px).
    order : int
        Spline order of :func:`scipy.ndimage.map_coordinates` (1: bilinear).

    Returns
    -------
    ndarray of shape (N, K)
        Samples (nan outside the image).
    """
    x = points[:, 0:1] + offsets[None, :] * normals[:, 0:1]
    y = points[:, 1:2] + offsets[None, :] * normals[:, 1:2]
    out = ndi.map_coordinates(image, [y.ravel(), x.ravel()], order=order, mode="constant", cval=np.nan,
                              prefilter=False)
    return out.reshape(x.shape)


def viterbi_path(score, max_step=1, penalty=0.0):
    """Path through a score table maximising the summed score with bounded jumps.

    Parameters
    ----------
    score : ndarray of shape (N, K)
        Score of offset index k at station i (higher is better; nan counts as 0).
    max_step : int
        Largest change of k between neighbouring stations.
    penalty : float
        Cost per unit change of k (smoothness).

    Returns
    -------
    ndarray of int, shape (N,)
        The best offset index per station.
    """
    sc = np.ascontiguousarray(np.nan_to_num(np.asarray(score, float), nan=0.0))
    if sc.ndim != 2 or not sc.shape[0] or not sc.shape[1]:
        raise ValueError(f"score must be a non-empty 2-D table, got shape {sc.shape}")
    return viterbi_rows(sc, int(max_step), float(penalty))


def band_centres(contrast, offsets, centre_index, *, half_window, level=0.5):
    """Sub-pixel midline of a bright band in each normal profile (centroid above a level).

    Parameters
    ----------
    contrast : ndarray of shape (N, K)
        Background-corrected membrane contrast (membrane positive) along N normals.
    offsets : ndarray of shape (K,)
        Offsets of the samples (px), evenly spaced.
    centre_index : ndarray of int, shape (N,)
        Approximate band position per profile (e.g. from :func:`viterbi_path`).
    half_window : int
        Samples either side of ``centre_index`` considered.
    level : float
        Fraction of the local peak contrast above which samples contribute
        (0.5: centroid of the band above half its height, unbiased by symmetric
        blur and insensitive to the band width).

    Returns
    -------
    offset : ndarray of shape (N,)
        Sub-pixel band centre (px along the normal); nan where no band.
    peak : ndarray of shape (N,)
        Peak contrast in the window.
    width : ndarray of shape (N,)
        Width of the contiguous region above ``level`` (px).
    """
    c = np.asarray(contrast, float)
    n, k = c.shape
    w = int(half_window)
    j = np.clip(np.asarray(centre_index)[:, None] + np.arange(-w, w + 1)[None, :], 0, k - 1)
    win = np.take_along_axis(c, j, axis=1)
    win = np.nan_to_num(win, nan=0.0)
    off = offsets[j]
    # local baseline: a line through the medians of the window's outer quarters
    q = max(w // 3, 1)
    b0 = np.median(win[:, :q], axis=1)
    b1 = np.median(win[:, -q:], axis=1)
    t = np.linspace(0.0, 1.0, win.shape[1])[None, :]
    win = win - (b0[:, None] * (1 - t) + b1[:, None] * t)
    ipk = np.argmax(win, axis=1)
    peak = win[np.arange(n), ipk]
    thr = level * peak
    above = win > thr[:, None]
    # contiguous run of `above` containing the peak
    cols = np.arange(win.shape[1])[None, :]
    breaks_left = np.where(~above & (cols < ipk[:, None]), cols, -1).max(axis=1)
    breaks_right = np.where(~above & (cols > ipk[:, None]), cols, win.shape[1]).min(axis=1)
    run = (cols > breaks_left[:, None]) & (cols < breaks_right[:, None])
    wgt = np.where(run, win - thr[:, None], 0.0)
    tot = wgt.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        centre = (wgt * off).sum(axis=1) / tot
    # width of the run with linear interpolation of the crossings
    step = float(offsets[1] - offsets[0])
    width = (breaks_right - breaks_left - 1) * step
    bad = ~(tot > 0) | ~(peak > 0)
    centre[bad] = np.nan
    return centre, peak, width
