"""Compiled inner loops of the tracer (numba).

Transect sampling (with the view's rotation), the stations and normals of a
pass with their smoothed transects, band edges, step edges, clipped line fits
and the flat line's band fit, the dynamic-programming path, banded
least-squares cubic splines and the tracer's robust profile spline, station
cleaning and rim bridges, the coarse wall search, dusty wall rows, the
orientation's ridge filter and block means (and the light's interpolation
back from them), solids of revolution, the ellipse's scatter sums, point
distances and arc volume (and the stored profile's ellipse and arc-length
resampling in one call each), the rim contact figure, nan medians, percentiles
and run lengths (and numpy's median and percentile by one selection each,
in numpy itself).  A tracked frame takes a
handful of calls: its flat line (``line_band``), both walls
(``locate_walls``), its pass (``track_pass``) and the pass's end with the final
spline (``pass_tail``).

Each kernel does what a short numpy/scipy expression or a former numpy function
does (named in its docstring, and checked against it in
``tests/imaging/test_kernels.py``, or ``test_geometry.py`` for the ellipse;
``dusty_rows`` was written compiled and has its own tests in
``test_wall_dust.py``) without the temporary arrays and the per-call overhead
that dominate a frame's tracing time.  Compiled on first use (about 45 s once
per machine) and cached on disk (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["sample_transects", "change_transects", "outer_edges", "ends_noise", "band_edges_rows", "step_crossing_rows",
           "robust_line", "line_band",
           "viterbi_rows", "lsq_spline", "fill_rows_nanmedian", "nanmedian", "column_nanmedian", "longest_run",
           "running_percentile",
           "low_contrast_run", "ellipse_distance_folded", "robust_profile_spline", "pass_tail", "strongest_edge",
           "native_frame", "guide_transects", "revolution_halves", "clean_stations", "track_pass", "rim_bridge",
           "rim_zone", "rim_guide", "masked_nanmedian", "abs_percentile", "extrapolated_curve", "rim_contact",
           "curve_extent", "clear_of_curve",
           "ellipse_scatter", "conic_parameters", "direct_ellipse", "ellipse_arc_volume", "profile_ellipse",
           "arc_resample", "cubic_arc_table", "spline_points", "dusty_rows", "wall_rows", "locate_walls",
           "ridge_rows", "block_mean", "signed_profiles",
           "compiled_on_disk"]


@intrinsic
def _prefetch(typingctx, arr, idx):
    """Hint the CPU to fetch ``arr[idx]`` (1-D, in bounds) into its caches (``llvm.prefetch``: read, keep)."""
    sig = types.void(arr, idx)

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [args[1]], wraparound=False)
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]),
                                            "llvm.prefetch.p0i8")
        builder.call(fn, [builder.bitcast(ptr, i8p), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return sig, codegen


#: transects ahead whose pixels are prefetched while one is sampled: a new frame is not in the CPU's caches, and
#: a transect's rows are too far apart for the hardware prefetcher (a dome's cold sampling 0.17 -> 0.10 ms)
PREFETCH_AHEAD = 4


@njit(cache=True, nogil=True)
def _sample_transects(frame, k, px, py, dx, dy, offsets, out):
    h, w = frame.shape
    n, m = out.shape
    hm, wm = h - 1.0, w - 1.0
    flat = frame.ravel()
    omin = omax = offsets[0] if m else 0.0
    finite = True
    for j in range(m):
        if not np.isfinite(offsets[j]):
            finite = False
        omin = min(omin, offsets[j])
        omax = max(omax, offsets[j])
    span = omax - omin
    # the view's rotation as a linear map: stored (row, col) = start + offset * (drow, dcol); a transect whose
    # ends lie inside the last pixel square needs no bounds checks (most of them)
    rs_a, cs_a, dr_a, dc_a = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    inside = np.empty(n, np.bool_)
    for i in range(n):
        if k == 0:
            rs, cs, dr, dc = py[i], px[i], dy[i], dx[i]
        elif k == 1:
            rs, cs, dr, dc = px[i], wm - py[i], dx[i], -dy[i]
        elif k == 2:
            rs, cs, dr, dc = hm - py[i], wm - px[i], -dy[i], -dx[i]
        else:
            rs, cs, dr, dc = hm - px[i], py[i], -dx[i], dy[i]
        rs_a[i], cs_a[i], dr_a[i], dc_a[i] = rs, cs, dr, dc
        r_lo, r_hi = min(rs + omin * dr, rs + omax * dr), max(rs + omin * dr, rs + omax * dr)
        c_lo, c_hi = min(cs + omin * dc, cs + omax * dc), max(cs + omin * dc, cs + omax * dc)
        inside[i] = (finite and h > 1 and w > 1 and r_lo >= 1e-6 and c_lo >= 1e-6 and r_hi < hm - 1e-6
                     and c_hi < wm - 1e-6)
    for i in range(n):
        ia = i + PREFETCH_AHEAD
        if ia < n and inside[ia]:
            # points along the transect close enough that their two rows (a bilinear sample's) and their
            # cache lines (32 px of 16 bits) cover every pixel it samples
            n_pf = int(max(abs(dr_a[ia]) * span / 1.5, abs(dc_a[ia]) * span / 24.0)) + 2
            for q in range(n_pf):
                o = omin + span * q / (n_pf - 1)
                b0 = int(rs_a[ia] + o * dr_a[ia]) * w + int(cs_a[ia] + o * dc_a[ia])
                _prefetch(flat, b0)
                _prefetch(flat, b0 + w)
        rs, cs, dr, dc = rs_a[i], cs_a[i], dr_a[i], dc_a[i]
        if inside[i]:
            for j in range(m):
                r = rs + offsets[j] * dr
                c = cs + offsets[j] * dc
                r0 = int(r)
                c0 = int(c)
                fr = r - r0
                fc = c - c0
                b0 = r0 * w + c0
                a = flat[b0] * (1.0 - fc) + flat[b0 + 1] * fc
                b = flat[b0 + w] * (1.0 - fc) + flat[b0 + w + 1] * fc
                out[i, j] = a * (1.0 - fr) + b * fr
            continue
        for j in range(m):
            r = rs + offsets[j] * dr
            c = cs + offsets[j] * dc
            if not (r >= 0.0 and r <= hm and c >= 0.0 and c <= wm):
                out[i, j] = np.nan
                continue
            r0 = min(int(r), h - 2) if h > 1 else 0
            c0 = min(int(c), w - 2) if w > 1 else 0
            fr = r - r0
            fc = c - c0
            r1 = min(r0 + 1, h - 1)
            c1 = min(c0 + 1, w - 1)
            a = frame[r0, c0] * (1.0 - fc) + frame[r0, c1] * fc
            b = frame[r1, c0] * (1.0 - fc) + frame[r1, c1] * fc
            out[i, j] = a * (1.0 - fr) + b * fr


def native_frame(frame):
    """The frame as the kernels take it: C-contiguous, native byte order, not bool or half floats (no copy when it
    already is); a complex frame is refused."""
    frame = np.ascontiguousarray(frame)
    if frame.dtype == np.bool_:
        return frame.astype(np.uint8)
    if frame.dtype.kind == "c":
        raise TypeError(f"frame of complex dtype {frame.dtype}: an image is real")
    if frame.dtype == np.float16:
        return frame.astype(np.float32)
    if not frame.dtype.isnative:  # big-endian files (ImageJ's default TIFF byte order)
        return frame.astype(frame.dtype.newbyteorder("="))
    return frame


def sample_transects(frame, k, points, directions, offsets):
    """Bilinear samples of ``frame`` seen rotated by ``k`` quarter turns along transects.

    ``FrameView(frame, k).sample(points[:, None, :] + offsets[None, :, None] * directions[:, None, :])``:
    the view point ``points[i] + offsets[j] * directions[i]`` (``(x=col, y=row)``,
    px) sampled bilinearly, nan outside the frame.

    Returns
    -------
    ndarray of float64, shape (N, K)
    """
    frame = native_frame(frame)
    p = np.ascontiguousarray(points, np.float64).reshape(-1, 2)
    d = np.ascontiguousarray(directions, np.float64).reshape(-1, 2)
    o = np.ascontiguousarray(offsets, np.float64).ravel()
    out = np.empty((len(p), len(o)), np.float64)
    _sample_transects(frame, int(k) % 4, p[:, 0].copy(), p[:, 1].copy(), d[:, 0].copy(), d[:, 1].copy(), o, out)
    return out


@njit(cache=True, nogil=True)
def _change_transects(frame, k, flat, light, px, py, qx, qy, dx, dy, offsets, weights, out):
    n, m = out.shape
    ref = np.empty((n, m))
    bg = np.empty((n, m))
    _sample_transects(frame, k, px, py, dx, dy, offsets, out)
    _sample_transects(flat, k, qx, qy, dx, dy, offsets, ref)
    _sample_transects(light, 0, qx, qy, dx, dy, offsets, bg)
    r = (weights.size - 1) // 2
    row = np.empty(m + 2 * r)  # the ratio with its ends repeated r times (scipy's mode "nearest")
    for i in range(n):
        for j in range(m):
            v = (out[i, j] - ref[i, j]) / bg[i, j]
            row[r + j] = v if np.isfinite(v) else 0.0
        for j in range(r):
            row[j] = row[r]
            row[r + m + j] = row[r + m - 1]
        for j in range(m):  # a Gaussian along the transect
            acc = 0.0
            for q in range(2 * r + 1):
                acc += weights[q] * row[j + q]
            out[i, j] = acc


def change_transects(frame, k, flat, light, points, directions, offsets, shift, sigma):
    """The change of ``frame`` since ``flat`` over the ``light`` along transects, smoothed along them.

    ``(S(frame, k, p) - S(flat, k, p - shift)) / S(light, 0, p - shift)`` with
    ``S`` :func:`sample_transects` at the transects' points ``p`` (``shift``:
    the drift ``(dx, dy)`` px of ``frame`` from ``flat``; ``light`` is in the
    view already), 0 where not finite (outside the frame), then
    ``scipy.ndimage.gaussian_filter1d(., sigma, axis=1, mode="nearest")``
    (``sigma`` in samples).

    Returns
    -------
    ndarray of float64, shape (N, K)
    """
    frame, flat = native_frame(frame), native_frame(flat)
    light = np.ascontiguousarray(light, np.float32 if light.dtype == np.float32 else np.float64)
    p = np.ascontiguousarray(points, np.float64).reshape(-1, 2)
    d = np.ascontiguousarray(directions, np.float64).reshape(-1, 2)
    o = np.ascontiguousarray(offsets, np.float64).ravel()
    radius = int(4.0 * float(sigma) + 0.5)  # (gaussian_filter1d's truncate=4)
    x = np.arange(-radius, radius + 1)
    weights = np.exp(-0.5 / float(sigma) ** 2 * x**2)
    weights = weights / weights.sum()
    out = np.empty((len(p), len(o)), np.float64)
    _change_transects(frame, int(k) % 4, flat, light, p[:, 0].copy(), p[:, 1].copy(), p[:, 0] - float(shift[0]),
                      p[:, 1] - float(shift[1]), d[:, 0].copy(), d[:, 1].copy(), o, weights, out)
    return out


@njit(cache=True, nogil=True)
def _upsample(coarse, i_row, t_row, i_col, t_col, cols, out):
    for r in range(coarse.shape[0]):  # columns first (fewer rows), then rows
        for j in range(i_col.size):
            cols[r, j] = coarse[r, i_col[j]] * (1.0 - t_col[j]) + coarse[r, i_col[j] + 1] * t_col[j]
    for i in range(i_row.size):
        for j in range(cols.shape[1]):
            out[i, j] = cols[i_row[i], j] * (1.0 - t_row[i]) + cols[i_row[i] + 1, j] * t_row[i]


def _block_centres(n, m, block):
    """For each of ``n`` px, the block centre at or below it (of ``m``) and its weight on the next one."""
    x = np.clip((np.arange(n) - 0.5 * (block - 1)) / block, 0.0, m - 1.0)
    i0 = np.minimum(x.astype(np.int64), m - 2)
    return i0, x - i0


def upsample_linear(coarse, shape, block):
    """Linear interpolation of ``coarse`` (the centres of ``block`` x ``block`` px blocks) at every px of
    ``shape``, clamped at the ends: columns first, then rows (as two 1-D passes of ``coarse[i0] * (1 - t) +
    coarse[i0 + 1] * t`` with ``x = clip((px - (block - 1) / 2) / block, 0, m - 1)``, ``i0 = min(int(x), m - 2)``,
    ``t = x - i0``).  Each axis of ``coarse`` needs at least 2 blocks."""
    coarse = np.ascontiguousarray(coarse, np.float64)
    if coarse.ndim != 2 or min(coarse.shape) < 2:
        raise ValueError(f"coarse needs at least 2 blocks along each axis, got shape {coarse.shape}")
    i_row, t_row = _block_centres(int(shape[0]), coarse.shape[0], block)
    i_col, t_col = _block_centres(int(shape[1]), coarse.shape[1], block)
    cols, out = np.empty((coarse.shape[0], i_col.size)), np.empty((i_row.size, i_col.size))
    _upsample(coarse, i_row, t_row, i_col, t_col, cols, out)
    return out


@njit(cache=True, nogil=True)
def _grad(p, i, k, m):
    """``np.gradient(p[i])[k]`` (first-order one-sided at the ends)."""
    if k == 0:
        return p[i, 1] - p[i, 0]
    if k == m - 1:
        return p[i, m - 1] - p[i, m - 2]
    return (p[i, k + 1] - p[i, k - 1]) / 2.0


@njit(cache=True, nogil=True)
def outer_edges(prof, thr, window):
    """Sub-sample index of each row's outer edge (the rows of ``prof`` run from outside in), nan where none.

    On each row: the first sample above ``thr``, the feature's peak within
    ``window`` samples of it, and on its outer flank (from 8 samples before the
    first one to the peak) the steepest rise of ``np.gradient``, located by a
    parabola through the gradient's three values around it (the last one
    one-sided at the peak's next sample).  Rows need at least 2 samples.
    """
    n, m = prof.shape
    out = np.full(n, np.nan)
    for i in range(n):
        i0 = -1
        for j in range(m):
            if prof[i, j] > thr:
                i0 = j
                break
        if i0 < 0:
            continue
        pk, best = i0, prof[i, i0]
        for q in range(1, window):
            j = min(i0 + q, m - 1)
            if prof[i, j] > best:
                pk, best = j, prof[i, j]
        lo = max(i0 - 8, 1)
        end = min(pk + 1, m - 1)
        if pk <= lo:
            continue
        steep, top = lo, _grad(prof, i, lo, m)
        for k in range(lo + 1, pk + 1):
            g = _grad(prof, i, k, m)
            if g > top:
                steep, top = k, g
        if steep >= end:
            continue
        right = prof[i, end] - prof[i, end - 1] if steep + 1 == end else _grad(prof, i, min(steep + 1, m - 1), m)
        a = _grad(prof, i, max(steep - 1, 0), m)
        den = a - 2.0 * top + right
        off = 0.0
        if den < 0.0:
            off = min(max(0.5 * (a - right) / den, -0.5), 0.5)
        out[i] = steep + off
    return out


@njit(cache=True, nogil=True)
def _clip01(t):
    """``np.clip(t, 0, 1)``, nan kept."""
    if t < 0.0:
        return 0.0
    if t > 1.0:
        return 1.0
    return t


@njit(cache=True, nogil=True)
def _median_small(a, lo, hi, buf):
    """Median of ``a[lo:hi]`` (insertion sort in ``buf``: a few samples)."""
    m = hi - lo
    for i in range(m):
        v = a[lo + i]
        j = i
        while j > 0 and buf[j - 1] > v:
            buf[j] = buf[j - 1]
            j -= 1
        buf[j] = v
    if m % 2:
        return buf[m // 2]
    return 0.5 * (buf[m // 2 - 1] + buf[m // 2])


@njit(cache=True, nogil=True, error_model="numpy")
def _band_edges_rows(q, offsets, centre, search, side, out):
    n, k = q.shape
    buf = np.empty(max(side, 1), np.float64)
    for i in range(n):
        row = q[i]
        # peak in the window (first maximum, as np.argmax)
        c = centre[i]
        s = search[i]
        ipk = -1
        best = -np.inf
        for j in range(max(c - s, 0), min(c + s + 1, k)):
            if row[j] > best:
                best = row[j]
                ipk = j
        if ipk < 0:
            ipk = 0
        peak = row[ipk]
        left = _median_small(row, 0, side, buf)
        right = _median_small(row, k - side, k, buf)
        lev = 0.5 * (peak + left)
        lo = np.nan
        for j in range(ipk - 1, -1, -1):
            if row[j] < lev:
                j0 = j + 1
                t = (row[j0] - lev) / (row[j0] - row[j])
                t = _clip01(t)
                lo = offsets[j0] + t * (offsets[j] - offsets[j0])
                break
        lev = 0.5 * (peak + right)
        hi = np.nan
        for j in range(ipk + 1, k):
            if row[j] < lev:
                j0 = j - 1
                t = (row[j0] - lev) / (row[j0] - row[j])
                t = _clip01(t)
                hi = offsets[j0] + t * (offsets[j] - offsets[j0])
                break
        out[0, i] = 0.5 * (lo + hi)
        out[1, i] = lo
        out[2, i] = hi
        out[3, i] = peak - 0.5 * (left + right)
        out[4, i] = hi - lo


def band_edges_rows(q, offsets, centre, search, side):
    """Band edges of finite profiles ``q`` (band high): the loop of :func:`osmobulge.imaging._chamber.band_edges`.

    Returns
    -------
    ndarray of shape (5, N)
        Midline, lower and upper edge, contrast and width per row.
    """
    q = np.ascontiguousarray(q, np.float64)
    n, k = q.shape
    out = np.empty((5, n), np.float64)
    c = np.ascontiguousarray(np.broadcast_to(np.asarray(centre, np.int64), (n,)))
    s = np.ascontiguousarray(np.broadcast_to(np.asarray(search, np.int64), (n,)))
    _band_edges_rows(q, np.ascontiguousarray(offsets, np.float64), c, s, int(min(max(side, 1), k)), out)
    return out


@njit(cache=True, nogil=True)
def viterbi_rows(sc, m, penalty):
    """Best path through ``sc`` (N, K) with moves of at most ``m`` and a cost ``penalty`` per unit move.

    The loop of :func:`osmobulge.imaging._normals.viterbi_path` (same tie-breaking).
    """
    n, k = sc.shape
    back = np.zeros((n, k), np.int64)
    acc = sc[0].copy()
    new = np.empty(k, np.float64)
    for i in range(1, n):
        for q in range(k):
            best = -np.inf
            bj = 0
            for j in range(2 * m + 1):  # window index j <-> move d = m - j, source q - d
                src = q - m + j
                if src < 0 or src >= k:
                    v = -np.inf
                else:
                    v = acc[src] - penalty * abs(m - j)
                if v > best:
                    best = v
                    bj = j
            new[q] = best + sc[i, q]
            back[i, q] = m - bj
        acc[:] = new
    path = np.empty(n, np.int64)
    path[n - 1] = np.argmax(acc)
    for i in range(n - 1, 0, -1):
        path[i - 1] = path[i] - back[i, path[i]]
    return path


@njit(cache=True, nogil=True)
def _span(t, k, n, x):
    """Knot span l, k <= l <= n - 1, with t[l] <= x < t[l + 1] (the last point in the last span)."""
    lo, hi = k, n
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if t[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True)
def _next_span(t, k, n, x, l, x_prev):
    """:func:`_span` of ``x`` walking on from span ``l`` of ``x_prev`` (the same span; sorted x: no bisection)."""
    if not x >= x_prev:  # x went back (or nan): bisect
        return _span(t, k, n, x)
    while l + 1 <= n - 1 and t[l + 1] <= x:
        l += 1
    return l


@njit(cache=True, nogil=True)
def _basis(t, k, l, x, b, left, right):
    """de Boor-Cox: the k + 1 non-zero B-splines of degree k at x in span l, into ``b`` (work arrays left, right)."""
    b[0] = 1.0
    for j in range(1, k + 1):
        left[j] = x - t[l + 1 - j]
        right[j] = t[l + j] - x
        saved = 0.0
        for r in range(j):
            den = right[r + 1] + left[j - r]
            tmp = b[r] / den if den != 0.0 else 0.0
            b[r] = saved + right[r + 1] * tmp
            saved = left[j - r] * tmp
        b[j] = saved


@njit(cache=True, nogil=True)
def _cubic_table(t, x):
    """Spans and the 4 non-zero cubic B-splines at each x (sorted, inside the base interval): ``(spans, B)``.

    The same span walk and :func:`_basis` as :func:`_bspl_eval`, once for a
    fit (:func:`_lsq_normal_table`) and its residuals at the same points
    (:func:`_eval_table`).
    """
    nx = x.shape[0]
    n = t.shape[0] - 4
    spans = np.empty(nx, np.int64)
    B = np.empty((nx, 4))
    b = np.empty(4)
    left = np.empty(4)
    right = np.empty(4)
    l, x_prev = 3, -np.inf
    for i in range(nx):
        xi = x[i]
        l = _next_span(t, 3, n, xi, l, x_prev)
        x_prev = xi
        _basis(t, 3, l, xi, b, left, right)
        spans[i] = l
        for a in range(4):
            B[i, a] = b[a]
    return spans, B


@njit(cache=True, nogil=True)
def _lsq_normal_table(spans, B, y, w, ata, aty):
    """Banded normal equations of the cubic least-squares spline (weights multiply the residuals), accumulated
    into ``ata`` (upper bands in columns) and ``aty`` from a :func:`_cubic_table` of the points."""
    nd = y.shape[1]
    for i in range(spans.shape[0]):
        wi = w[i] * w[i]
        if wi == 0.0:
            continue
        l = spans[i]
        for a in range(4):
            ia = l - 3 + a
            for c in range(a, 4):
                ata[ia, c - a] += wi * B[i, a] * B[i, c]
            for d in range(nd):
                aty[ia, d] += wi * B[i, a] * y[i, d]


@njit(cache=True, nogil=True)
def _lsq_normal(x, y, t, w, ata, aty):
    """Banded normal equations of the cubic least-squares spline at parameters ``x`` (knots ``t``)."""
    spans, B = _cubic_table(t, x)
    _lsq_normal_table(spans, B, y, w, ata, aty)


@njit(cache=True, nogil=True)
def _eval_table(spans, B, c, out):
    """:func:`_bspl_eval` (cubic) from a :func:`_cubic_table` of the same knots."""
    nd = c.shape[1]
    for i in range(spans.shape[0]):
        l = spans[i]
        for d in range(nd):
            s = 0.0
            for a in range(4):
                s += B[i, a] * c[l - 3 + a, d]
            out[i, d] = s


@njit(cache=True, nogil=True)
def _band_cholesky_solve(ata, aty):
    """Solve the symmetric positive definite band system (upper bands in columns); False if not positive."""
    n, m = ata.shape
    nd = aty.shape[1]
    L = np.zeros((n, m))
    for i in range(n):
        for j in range(max(0, i - m + 1), i + 1):
            s = ata[j, i - j]
            for p in range(max(0, i - m + 1), j):
                if i - p < m and j - p < m:
                    s -= L[p, i - p] * L[p, j - p]
            if i == j:
                if not s > 0.0:
                    return False
                L[i, 0] = np.sqrt(s)
            else:
                L[j, i - j] = s / L[j, 0]
    for d in range(nd):  # forward, then back substitution
        for i in range(n):
            s = aty[i, d]
            for p in range(max(0, i - m + 1), i):
                s -= L[p, i - p] * aty[p, d]
            aty[i, d] = s / L[i, 0]
        for i in range(n - 1, -1, -1):
            s = aty[i, d]
            for p in range(i + 1, min(n, i + m)):
                s -= L[i, p - i] * aty[p, d]
            aty[i, d] = s / L[i, 0]
    return True


def lsq_spline(x, y, t, w=None):
    """Cubic least-squares spline: :func:`scipy.interpolate.make_lsq_spline` ``(x, y, t, k=3, w=w)``.

    Normal equations in band form with a Cholesky solve (the B-spline basis on
    knots at data quantiles is well conditioned).  When the system is not
    positive definite (B-splines without data in their support: a gap in the
    data wider than the knot spacing) the interior knots with no weighted data
    since the last kept one are dropped (the Schoenberg-Whitney condition) and
    the fit is repeated, with scipy's QR solver as the last resort; the
    returned spline's knots are then fewer than ``t``.

    Parameters
    ----------
    x : ndarray of shape (N,)
        Increasing abscissae inside ``[t[3], t[-4]]``.
    y : ndarray of shape (N,) or (N, D)
    t : ndarray
        Knots, 4-fold at both ends.
    w : ndarray of shape (N,), optional
        Weights multiplying the residuals (0 drops a point).

    Returns
    -------
    scipy.interpolate.BSpline
    """
    from scipy.interpolate import BSpline, make_lsq_spline

    x = np.ascontiguousarray(x, np.float64)
    y_in = np.asarray(y, np.float64)
    y2 = np.ascontiguousarray(y_in.reshape(len(x), -1))
    t = np.ascontiguousarray(t, np.float64)
    ww = np.ones(len(x)) if w is None else np.ascontiguousarray(w, np.float64)
    n = len(t) - 4
    ata = np.zeros((n, 4))
    aty = np.zeros((n, y2.shape[1]))
    _lsq_normal(x, y2, t, ww, ata, aty)
    xw = x[ww > 0]
    n_distinct = int(np.count_nonzero(np.diff(xw) > 0)) + 1 if len(xw) else 0
    # more coefficients than distinct points is singular, even when rounding lets the Cholesky factor through
    if n > n_distinct or not _band_cholesky_solve(ata, aty) or not np.all(np.isfinite(aty)):
        t = _supported_knots(x, ww, t)
        n = len(t) - 4
        ata = np.zeros((n, 4))
        aty = np.zeros((n, y2.shape[1]))
        _lsq_normal(x, y2, t, ww, ata, aty)
        if not _band_cholesky_solve(ata, aty) or not np.all(np.isfinite(aty)):
            return make_lsq_spline(x, y_in, t, k=3, w=w)
    # knots and coefficients are valid by construction: skip BSpline's checks (~40 us a call)
    return BSpline.construct_fast(t, aty.reshape((n, *y_in.shape[1:])), 3)


def _supported_knots(x, w, t):
    """Cubic knots ``t`` without the interior ones that have no weighted data since the last kept knot.

    Every knot span then holds data, and the last span too (knots are dropped
    from the end until it does): the B-splines all have data in their support.
    """
    xs = np.sort(x[w > 0])
    lo, hi = t[3], t[-4]
    keep = []
    prev = lo
    for kn in t[4:-4]:
        if np.any((xs > prev) & (xs < kn)):
            keep.append(kn)
            prev = kn
    while keep and not np.any((xs > keep[-1]) & (xs < hi)):
        keep.pop()
    # no more coefficients than distinct points: an even subset of the kept knots (none: one cubic)
    n_inner = max(len(np.unique(xs)) - 4, 0)
    if len(keep) > n_inner:
        keep = [keep[i] for i in np.unique(np.round(np.linspace(0, len(keep) - 1, n_inner)).astype(int))]
    return np.r_[[lo] * 4, keep, [hi] * 4]


@njit(cache=True, nogil=True)
def _fill_and_smooth(prof, sigma):
    """nan -> median of the finite samples, then a Gaussian along axis 0 (scipy's kernel, mode "nearest")."""
    n, m = prof.shape
    n_bad = 0
    for i in range(n):
        for j in range(m):
            if not np.isfinite(prof[i, j]):
                n_bad += 1
    if n_bad:
        good = np.empty(n * m - n_bad)
        c = 0
        for i in range(n):
            for j in range(m):
                if np.isfinite(prof[i, j]):
                    good[c] = prof[i, j]
                    c += 1
        fill = np.median(good) if c else np.nan
        for i in range(n):
            for j in range(m):
                if not np.isfinite(prof[i, j]):
                    prof[i, j] = fill
    if not sigma > 0:
        return prof
    radius = int(4.0 * sigma + 0.5)
    wts = np.empty(2 * radius + 1)
    tot = 0.0
    for r in range(-radius, radius + 1):
        wts[r + radius] = np.exp(-0.5 * r * r / (sigma * sigma))
        tot += wts[r + radius]
    wts /= tot
    out = np.zeros_like(prof)
    for i in range(n):
        for r in range(-radius, radius + 1):
            src = min(max(i + r, 0), n - 1)
            wr = wts[r + radius]
            for j in range(m):
                out[i, j] += wr * prof[src, j]
    return out


@njit(cache=True, nogil=True)
def ends_noise(prof):
    """Noise of one sample from the differences at both ends of each profile (4 samples each, as in trace)."""
    n, m = prof.shape
    e = min(4, m)
    d = np.empty(n * (2 * e - 1))
    c = 0
    row = np.empty(2 * e)
    for i in range(n):
        for j in range(e):
            row[j] = prof[i, j]
            row[e + j] = prof[i, m - e + j]
        for j in range(2 * e - 1):
            d[c] = abs(row[j + 1] - row[j])
            c += 1
    return 1.4826 * np.median(d) / np.sqrt(2.0)


@njit(cache=True, nogil=True, error_model="numpy")
def _step_crossing_rows(q, offsets, side, out, fit):
    n, k = q.shape
    buf = np.empty(max(side, 1))
    for i in range(n):
        row = q[i]
        fin_a = True
        fin_b = True
        for j in range(side):
            fin_a &= np.isfinite(row[j])
            fin_b &= np.isfinite(row[k - side + j])
        a = _median_small(row, 0, side, buf) if fin_a else np.nan
        b = _median_small(row, k - side, k, buf) if fin_b else np.nan
        lev = 0.5 * (a + b)
        best = np.inf
        jj = 0
        for j in range(k - 1):
            if (row[j] > lev) != (row[j + 1] > lev):
                d = abs(j + 0.5 - (k - 1) / 2.0)
                if d < best:
                    best = d
                    jj = j
        out[1, i] = b - a
        if best == np.inf:
            out[0, i] = np.nan
            continue
        t = _clip01((lev - row[jj]) / (row[jj + 1] - row[jj]))
        x_lin = offsets[jj] + t * (offsets[min(jj + 1, k - 1)] - offsets[jj])
        out[0, i] = x_lin
        if fit > 0:  # the crossing of a line through the 2 * fit samples around it
            j0, j1 = max(jj - fit + 1, 0), min(jj + fit, k - 1)
            sx = sy = sxx = sxy = 0.0
            cnt = 0
            for j in range(j0, j1 + 1):
                if np.isfinite(row[j]):
                    x = offsets[j] - x_lin
                    sx += x
                    sy += row[j]
                    sxx += x * x
                    sxy += x * row[j]
                    cnt += 1
            if cnt >= 3:
                den = cnt * sxx - sx * sx
                if den > 0:
                    c1 = (cnt * sxy - sx * sy) / den
                    c0 = (sy - c1 * sx) / cnt
                    # the line must rise the straddling pair's way, by a quarter of its rise at least
                    if (c1 > 0) == (row[jj + 1] > row[jj]) and abs(c1) * (offsets[j1] - offsets[j0]) >= 0.25 * abs(
                            row[jj + 1] - row[jj]) and c1 != 0.0:
                        dx = (lev - c0) / c1
                        if abs(dx) <= 0.5 * (offsets[j1] - offsets[j0]):
                            out[0, i] = x_lin + dx


def step_crossing_rows(q, offsets, side, fit=0):
    """Mid-level step crossing nearest the centre of each row (the loop of ``_chamber.step_crossing``).

    ``fit`` > 0: the crossing of the least-squares line through the ``2 fit``
    samples around it (finite ones, at least 3; kept only when that line rises
    the same way and crosses within the window), not of the two samples
    straddling it.

    Returns
    -------
    ndarray of shape (2, N)
        Crossing offset (nan if none) and step (last level - first level).
    """
    q = np.ascontiguousarray(q, np.float64)
    out = np.empty((2, q.shape[0]))
    _step_crossing_rows(q, np.ascontiguousarray(offsets, np.float64), int(min(max(side, 1), q.shape[1])), out,
                        int(fit))
    return out


@njit(cache=True, nogil=True)
def _masked_line(x, y, ok):
    """Least-squares line ``y = a + b x`` over the points in ``ok``: a, b and their count.

    ``b`` is nan when the points have no spread in x (``a`` is then their mean y).
    """
    m = 0
    sx = 0.0
    sy = 0.0
    for i in range(x.shape[0]):
        if ok[i]:
            m += 1
            sx += x[i]
            sy += y[i]
    if m == 0:
        return np.nan, np.nan, 0
    xm = sx / m
    ym = sy / m
    sxx = 0.0
    sxy = 0.0
    for i in range(x.shape[0]):
        if ok[i]:
            sxx += (x[i] - xm) * (x[i] - xm)
            sxy += (x[i] - xm) * (y[i] - ym)
    if not sxx > 0:
        return ym, np.nan, m
    b = sxy / sxx
    return ym - b * xm, b, m


@njit(cache=True, nogil=True)
def robust_line(x, y, iters, clip, floor):
    """Least-squares line ``y = a + b x`` with sigma clipping: the loop of ``_chamber._robust_line``.

    Returns a, b, rms and the inlier mask.
    """
    n = x.shape[0]
    ok = np.empty(n, np.bool_)
    for i in range(n):
        ok[i] = np.isfinite(x[i]) and np.isfinite(y[i])
    a = np.nan
    b = np.nan
    rms = np.nan
    res = np.empty(n)
    for _ in range(iters):
        a_new, b_new, m = _masked_line(x, y, ok)
        if m < 2 or not np.isfinite(b_new):
            break
        a, b = a_new, b_new
        r_ok = np.empty(m)
        c = 0
        ss = 0.0
        for i in range(n):
            res[i] = y[i] - (a + b * x[i])
            if ok[i]:
                r_ok[c] = res[i]
                ss += res[i] * res[i]
                c += 1
        med = np.median(r_ok)
        mad = 1.4826 * np.median(np.abs(r_ok - med))
        rms = np.sqrt(ss / m)
        lim = max(clip * mad, floor)
        same = True
        cnt = 0
        new = np.empty(n, np.bool_)
        for i in range(n):
            new[i] = np.isfinite(res[i]) and abs(res[i]) <= lim
            cnt += new[i]
            same &= new[i] == ok[i]
        if same or cnt < 2:
            break
        ok[:] = new
    return a, b, rms, ok


@njit(cache=True, nogil=True)
def line_band(frame, k, x0, y0, d0, d1, n0, n1, u, offsets, polarity, search, side):
    """The band centres across the flat line and their clipped line fit: ``_chamber.measure_line``'s arithmetic.

    Transects along the normal ``(n0, n1)`` at the line points
    ``(x0, y0) + u (d0, d1)`` (view rotated by ``k``), the band's edges
    (``band_edges`` with the centre sample and ``search``, ``side`` samples for
    the side levels), the rows with a finite midline and a contrast above a
    quarter of the median, and :func:`robust_line` (4 rounds, 3 sigma, 0.1 px
    floor) of their midlines over ``u``.  Returns ``a, b, rms, inliers`` and the
    nan medians of the inliers' band width and contrast.
    """
    n = u.shape[0]
    m = offsets.shape[0]
    px = np.empty(n)
    py = np.empty(n)
    dx = np.empty(n)
    dy = np.empty(n)
    for i in range(n):
        px[i] = x0 + u[i] * d0 + 0.0 * n0
        py[i] = y0 + u[i] * d1 + 0.0 * n1
        dx[i] = n0
        dy[i] = n1
    prof = np.empty((n, m))
    _sample_transects(frame, k, px, py, dx, dy, offsets, prof)
    q = signed_profiles(prof, polarity)
    out = np.empty((5, n))
    _band_edges_rows(q, offsets, np.full(n, m // 2, np.int64), np.full(n, search, np.int64), min(max(side, 1), m),
                     out)
    mid, con, width = out[0], out[3], out[4]
    cmed = _nanmedian_flat(con.copy())
    good = np.empty(n, np.bool_)
    ng = 0
    for i in range(n):
        good[i] = np.isfinite(mid[i]) and con[i] > 0.25 * cmed
        ng += good[i]
    xs = np.empty(ng)
    ys = np.empty(ng)
    gi = np.empty(ng, np.int64)
    j = 0
    for i in range(n):
        if good[i]:
            xs[j], ys[j], gi[j] = u[i], mid[i], i
            j += 1
    a, b, rms, ok = robust_line(xs, ys, 4, 3.0, 0.1)
    inl = np.zeros(n, np.bool_)
    for j in range(ng):
        if ok[j]:
            inl[gi[j]] = True
    ni = 0
    for i in range(n):
        ni += inl[i]
    wi = np.empty(ni)
    ci = np.empty(ni)
    j = 0
    for i in range(n):
        if inl[i]:
            wi[j], ci[j] = width[i], con[i]
            j += 1
    return a, b, rms, inl, _nanmedian_flat(wi), _nanmedian_flat(ci)


@njit(cache=True, nogil=True)
def longest_run(mask, weights):
    """Largest sum of ``weights`` over a run of True in ``mask``."""
    best = 0.0
    cur = 0.0
    for i in range(mask.shape[0]):
        cur = cur + weights[i] if mask[i] else 0.0
        if cur > best:
            best = cur
    return best


@njit(cache=True, nogil=True)
def running_percentile(x, q, size):
    """``scipy.ndimage.percentile_filter(x, q, size, mode="nearest")`` of a 1-D array without nan (odd ``size``).

    The window (the edge values repeated beyond the ends) slides along ``x``
    as counts per rank of ``x``'s sorted order in a Fenwick tree: each step
    removes one sample, adds one and finds the window's ``rank``-th smallest
    by descending the tree (``n log n``, not ``n size``).
    """
    if size < 1 or size % 2 == 0:
        raise ValueError("running_percentile needs an odd window size")
    n = x.shape[0]
    out = np.empty(n)
    if n == 0:
        return out
    half = size // 2
    rank = size - 1 if q == 100.0 else int(float(size) * q / 100.0)
    order = np.argsort(x)  # (ties in any order: the k-th smallest value of a window is the same)
    pos = np.empty(n, np.int64)  # 1-based rank of each sample
    for r in range(n):
        pos[order[r]] = r + 1
    tree = np.zeros(n + 1, np.int64)
    top = 1
    while top * 2 <= n:
        top *= 2
    for j in range(-half, half + 1):
        i = pos[min(max(j, 0), n - 1)]
        while i <= n:
            tree[i] += 1
            i += i & -i
    for i in range(n):
        p = 0  # the last rank whose prefix count is <= rank: the answer is the next one
        rem = rank
        b = top
        while b:
            if p + b <= n and tree[p + b] <= rem:
                p += b
                rem -= tree[p]
            b //= 2
        out[i] = x[order[p]]
        if i == n - 1:
            break
        old = pos[min(max(i - half, 0), n - 1)]
        new = pos[min(i + half + 1, n - 1)]
        if old != new:
            j = old
            while j <= n:
                tree[j] -= 1
                j += j & -j
            j = new
            while j <= n:
                tree[j] += 1
                j += j & -j
    return out


@njit(cache=True, nogil=True)
def low_contrast_run(contrast, mask, ds, noise, q=80.0, max_win=151):
    """Longest run (sum of ``ds``) of the masked stations whose contrast falls below their surroundings (gaps).

    The tracer's fracture figure: ``cd = nan_to_num(contrast[mask], nan=0)``;
    ``local = max(percentile_filter(cd, q, win, mode="nearest"), median(cd) / 2)``
    with ``win = min(max_win, 2 (len(cd) // 2) + 1)``; stations below
    ``max(0.3 local, 3 noise)``; :func:`longest_run` of them weighted by ``ds[mask]``.
    """
    idx = np.flatnonzero(mask)
    m = idx.shape[0]
    if m == 0 or np.isnan(noise):  # np.maximum's nan threshold: no station is low
        return 0.0
    cd = np.empty(m)
    w = np.empty(m)
    big = 1.7976931348623157e308
    for j in range(m):
        v = contrast[idx[j]]
        cd[j] = 0.0 if np.isnan(v) else (big if v == np.inf else (-big if v == -np.inf else v))
        w[j] = ds[idx[j]]
    win = min(max_win, 2 * (m // 2) + 1)
    local = running_percentile(cd, q, win)
    floor = 0.5 * np.median(cd)
    low = np.empty(m, np.bool_)
    for j in range(m):
        low[j] = cd[j] < max(0.3 * max(local[j], floor), 3.0 * noise)
    return longest_run(low, w)


@njit(cache=True, nogil=True)
def fill_rows_nanmedian(q):
    """Non-finite samples -> the median of the row's finite ones (0 for a row with none), in place."""
    n, k = q.shape
    buf = np.empty(k)
    for i in range(n):
        c = 0
        for j in range(k):
            if np.isfinite(q[i, j]):
                buf[c] = q[i, j]
                c += 1
        if c == k:
            continue
        fill = np.median(buf[:c]) if c else 0.0
        for j in range(k):
            if not np.isfinite(q[i, j]):
                q[i, j] = fill
    return q


@njit(cache=True, nogil=True)
def column_nanmedian(a):
    """``np.nanmedian(a, axis=0)`` of a 2-D array (nan for a column without a finite value)."""
    out = np.empty(a.shape[1])
    for j in range(a.shape[1]):
        out[j] = _nanmedian_flat(np.ascontiguousarray(a[:, j]))
    return out


@njit(cache=True, nogil=True)
def _nanmedian_flat(a):
    b = a[np.isfinite(a)]
    if b.size == 0:
        return np.nan
    return np.median(b)


def nanmedian(a):
    """``np.nanmedian`` of all the samples (nan when none is finite), without its per-call overhead."""
    return float(_nanmedian_flat(np.ascontiguousarray(a, np.float64).ravel()))


def _rank(n, q):
    """numpy's linear rule for the ``q``-th percentile of ``n`` values: the sorted values' index below it and the
    weight of the next one (``np.percentile``'s own arithmetic)."""
    v = (n - 1) * np.true_divide(q, 100)
    lo = np.floor(v)
    return int(min(lo, n - 1)), float(v - lo)


@njit(cache=True, nogil=True)
def _lerp(x0, x1, t):
    """numpy's ``_lerp``: ``x0`` interpolated by ``t`` towards ``x1``."""
    d = x1 - x0
    if t >= 0.5:
        return x1 - d * (1.0 - t)
    return x0 + d * t


def percentile(a, q):
    """``np.percentile(a, q)`` (method "linear") of all the samples (finite), the same to the bit, by one selection
    (numpy selects the two order statistics it interpolates between at once; see :func:`median`)."""
    x = np.asarray(a, np.float64).ravel()
    lo, t = _rank(x.size, q)
    if lo + 1 >= x.size:
        return float(x.max())
    p = np.partition(x, lo + 1)
    return float(_lerp(float(p[: lo + 1].max()), float(p[lo + 1]), t))


def median(a):
    """``np.median`` of all the samples (finite), the same to the bit, by one selection.

    For an even count numpy selects the two middle values at once (``np.partition``
    with two ``kth``), 4-5x slower on 25 000 samples than selecting the upper one,
    below which the lower one is the largest.
    """
    x = np.asarray(a, np.float64).ravel()
    k = x.size // 2
    p = np.partition(x, k)
    return float(p[k]) if x.size % 2 else float((p[:k].max() + p[k]) / 2)


@njit(cache=True, nogil=True, error_model="numpy")  # a zero axis gives nan (as numpy), not ZeroDivisionError
def ellipse_distance_folded(x, y, a, b, max_iter):
    """Distances of folded points (``x, y >= 0``, ``a >= b``) from the ellipse: Eberly's Newton in ``u = s + b^2``.

    The loop of :func:`osmobulge.imaging.geometry.ellipse_distance` point by
    point, each to its own convergence (there, all points iterate until the
    slowest has converged).
    """
    n = len(x)
    out = np.empty(n)
    d2 = a * a - b * b
    for i in range(n):
        xi = x[i]
        yi = max(y[i], 1e-12 * a)
        if (xi / a) ** 2 + (yi / b) ** 2 >= 1.0:
            u = b * b
        else:
            u = max(b * yi, a * xi - d2)
        for _ in range(max_iter):
            ra = a * xi / (u + d2)
            rb = b * yi / u
            f = ra * ra + rb * rb - 1.0
            df = -2.0 * (ra * ra / (u + d2) + rb * rb / u)
            step = f / df
            u = u - step
            if abs(step) <= 1e-14 * u:
                break
        out[i] = np.hypot(xi - a * a * xi / (u + d2), yi - b * b * yi / u)
    return out


# ---------------------------------------------------------------------------- robust profile spline
@njit(cache=True, nogil=True)
def _bspl_eval(t, c, k, x, out):
    """Degree-k spline (coefficients c, shape (n, D)) at x: ``BSpline(t, c, k)(x)`` (x inside the base interval)."""
    n = c.shape[0]
    nd = c.shape[1]
    b = np.empty(k + 1)
    left = np.empty(k + 1)
    right = np.empty(k + 1)
    l, x_prev = k, -np.inf
    for i in range(x.shape[0]):
        xi = x[i]
        l = _next_span(t, k, n, xi, l, x_prev)
        x_prev = xi
        _basis(t, k, l, xi, b, left, right)
        for d in range(nd):
            s = 0.0
            for a in range(k + 1):
                s += b[a] * c[l - k + a, d]
            out[i, d] = s


@njit(cache=True, nogil=True)
def cubic_arc_table(t, c):
    """Parameter and arc length of a cubic spline curve of 2-D points (knots ``t`` on [0, 1], coefficients ``c``
    of shape (n, 2), n = len(t) - 4) at ``min(max(8 (len(t) - 7), 1025), 4001)`` even steps of the parameter (8 per
    knot span): the trapezoid rule on the speed of its derivative spline (degree 2, knots ``t[1:-1]``)."""
    nc = c.shape[0]
    dc = np.empty((nc - 1, 2))
    for i in range(nc - 1):
        h = t[i + 4] - t[i + 1]
        for d in range(2):
            dc[i, d] = 3.0 * (c[i + 1, d] - c[i, d]) / h if h > 0.0 else 0.0
    nt = min(max(8 * (t.shape[0] - 7), 1025), 4001)
    uu = np.linspace(0.0, 1.0, nt)
    der = np.empty((nt, 2))
    _bspl_eval(t[1:-1], dc, 2, uu, der)
    ss = np.empty(nt)
    ss[0] = 0.0
    sp_prev = np.hypot(der[0, 0], der[0, 1])
    for i in range(1, nt):
        sp = np.hypot(der[i, 0], der[i, 1])
        ss[i] = ss[i - 1] + 0.5 * (sp + sp_prev) * (uu[i] - uu[i - 1])
        sp_prev = sp
    return uu, ss


def spline_points(t, c, k, u):
    """``BSpline(t, c, k)(u)`` of a spline of points (``c`` of shape (n, D) or with FITPACK's trailing zeros, n =
    len(t) - k - 1) at finite parameters ``u`` in its base interval (any order), shape (len(u), D): the compiled
    de Boor evaluation of :func:`_bspl_eval`, scipy's values within rounding, without scipy's per-call work."""
    n = len(t) - k - 1
    if np.asarray(c).shape[0] < n:
        raise ValueError(f"a spline of {len(t)} knots and degree {k} has {n} coefficients, got "
                         f"{np.asarray(c).shape[0]}")
    c = np.ascontiguousarray(np.asarray(c)[:n], np.float64)
    u = np.ascontiguousarray(u, np.float64)
    out = np.empty((u.shape[0], c.shape[1]))
    _bspl_eval(np.ascontiguousarray(t, np.float64), c, int(k), u, out)
    return out


@njit(cache=True, nogil=True)
def _quantile_knots(u, sel, spacing, chord, lo, hi):
    """Cubic knots on [lo, hi], interior ones at quantiles of u[sel] without its ends (``_lsq``'s rule)."""
    idx = np.flatnonzero(sel)
    m = idx.shape[0]
    n_int = int(np.floor(chord / spacing))
    n_int = min(max(n_int, 0), max(m - 4, 0))
    t = np.empty(n_int + 8)
    t[:4] = lo
    t[n_int + 4:] = hi
    if n_int:
        xs = u[idx[1:m - 1]]
        nx = xs.shape[0]
        for j in range(n_int):
            q = (j + 1) / (n_int + 1) * (nx - 1)  # np.interp(q (n - 1), arange(n), x)
            i0 = min(int(np.floor(q)), nx - 2) if nx > 1 else 0
            f = q - i0
            t[4 + j] = xs[i0] if nx == 1 else xs[i0] + f * (xs[i0 + 1] - xs[i0])
    return t


@njit(cache=True, nogil=True)
def _weighted_fit(spans, B, pts, w, t):
    """Least-squares cubic spline coefficients (n, 2) from a :func:`_cubic_table` of the points' parameters;
    ok False when the band system is not positive definite."""
    n = t.shape[0] - 4
    ata = np.zeros((n, 4))
    aty = np.zeros((n, 2))
    _lsq_normal_table(spans, B, pts, w, ata, aty)
    ok = _band_cholesky_solve(ata, aty)
    if ok:
        for i in range(n):
            if not (np.isfinite(aty[i, 0]) and np.isfinite(aty[i, 1])):
                ok = False
    return aty, ok


@njit(cache=True, nogil=True)
def robust_profile_spline(U, Z, ks, pinned, step):
    """The tracer's final robust profile spline (``ChamberTracer._robust_fit`` with ``final=True``), compiled.

    Stage 1: a stiff spline (knots ``max(15, 2.5 ks)`` apart) over the chord
    parameter, up to 3 rounds of rejecting points beyond ``max(3.5 MAD, 1 px)``;
    stage 2: one round with knots ``ks`` apart (floor 0.75 px); then
    :func:`osmobulge.imaging.geometry.smooth_profile` of the kept points with
    knots ``ks`` apart: the points re-parameterised by their own normalised
    chord, the least-squares spline, residuals of all points and the
    arc-length table (8 samples a knot span, 1025 to 4001).  The ends are
    pinned (weight 10, always kept) when ``pinned``.

    Returns ``status`` (0 ok; 1 a band system was not positive definite or
    fewer than 4 distinct points were kept: the caller falls back to scipy),
    ``keep``, final knots, coefficients (n, 2), residuals, the table
    ``(uu, ss)`` and the curve sampled every ``step`` of arc length.
    """
    n = U.shape[0]
    pts = np.empty((n, 2))
    pts[:, 0] = U
    pts[:, 1] = Z
    u = np.empty(n)
    u[0] = 0.0
    for i in range(1, n):
        u[i] = u[i - 1] + max(np.hypot(U[i] - U[i - 1], Z[i] - Z[i - 1]), 1e-9)
    wts = np.ones(n)
    inner = np.ones(n, np.bool_)
    if pinned:
        wts[0] = wts[n - 1] = 10.0
        inner[0] = inner[n - 1] = False
    keep = np.ones(n, np.bool_)
    empty_t = np.zeros(8)
    empty_c = np.zeros((4, 2))
    empty_v = np.zeros(1)
    fit = np.empty((n, 2))
    res = np.empty(n)
    n_stages = 2
    for stage in range(n_stages):
        spacing = max(15.0, 2.5 * ks) if stage == 0 else ks
        floor = 1.0 if stage == 0 else 0.75
        iters = 3 if stage == 0 else 1
        for _ in range(iters):
            w = np.where(keep, wts, 0.0)
            chord = 0.0
            prev = -1
            for i in range(n):
                if w[i] > 0.0:
                    if prev >= 0:
                        chord += np.hypot(U[i] - U[prev], Z[i] - Z[prev])
                    prev = i
            t = _quantile_knots(u, w > 0.0, spacing, chord, u[0], u[n - 1])
            spans, B = _cubic_table(t, u)
            c, ok = _weighted_fit(spans, B, pts, w, t)
            if not ok:
                return 1, keep, empty_t, empty_c, empty_v, empty_v, empty_v, empty_c
            _eval_table(spans, B, c, fit)
            cnt = 0
            for i in range(n):
                res[i] = np.hypot(fit[i, 0] - U[i], fit[i, 1] - Z[i])
                if keep[i] and inner[i]:
                    cnt += 1
            sel = np.empty(cnt)
            j = 0
            for i in range(n):
                if keep[i] and inner[i]:
                    sel[j] = res[i]
                    j += 1
            mad = 1.4826 * np.median(sel) if cnt > 0 else 0.0
            thr = max(3.5 * mad, floor)
            new = np.empty(n, np.bool_)
            same = True
            total = 0
            for i in range(n):
                new[i] = np.isfinite(res[i]) and res[i] <= thr
                if pinned and (i == 0 or i == n - 1):
                    new[i] = True
                if new[i] != keep[i]:
                    same = False
                if new[i]:
                    total += 1
            if same or total < 6:
                break
            keep = new
    # smooth_profile(pts, knot_spacing=ks, weights=where(keep, wts, 0)): kept, distinct points
    idx = np.flatnonzero(keep & np.isfinite(U) & np.isfinite(Z))
    if idx.shape[0] == 0:
        return 1, keep, empty_t, empty_c, empty_v, empty_v, empty_v, empty_c
    sub = pts[idx]
    span = sub.max() - sub.min()
    distinct = np.ones(idx.shape[0], np.bool_)
    for j in range(1, idx.shape[0]):
        distinct[j] = np.hypot(sub[j, 0] - sub[j - 1, 0], sub[j, 1] - sub[j - 1, 1]) > 1e-12 * (1.0 + span)
    idx = idx[distinct]
    m = idx.shape[0]
    if m < 4:
        return 1, keep, empty_t, empty_c, empty_v, empty_v, empty_v, empty_c
    p = pts[idx]
    ww = wts[idx]
    ch = np.empty(m)
    ch[0] = 0.0
    for j in range(1, m):
        ch[j] = ch[j - 1] + np.hypot(p[j, 0] - p[j - 1, 0], p[j, 1] - p[j - 1, 1])
    uf = ch / ch[m - 1]
    t = _quantile_knots(uf, np.ones(m, np.bool_), ks, ch[m - 1], 0.0, 1.0)
    spans, B = _cubic_table(t, uf)
    c, ok = _weighted_fit(spans, B, p, ww, t)
    if not ok:
        return 1, keep, empty_t, empty_c, empty_v, empty_v, empty_v, empty_c
    pf = np.empty((m, 2))
    _eval_table(spans, B, c, pf)
    resid = np.full(n, np.nan)
    for j in range(m):
        resid[idx[j]] = np.hypot(pf[j, 0] - p[j, 0], pf[j, 1] - p[j, 1])
    uu, ss = cubic_arc_table(t, c)
    nt = uu.shape[0]
    # the curve every `step` px of arc length (ProfileSpline.sample(step))
    length = ss[nt - 1]
    ns = max(int(np.ceil(length / step)) + 1, 2)
    us = np.empty(ns)
    j = 0
    dl = length / (ns - 1)
    for i in range(ns):  # np.interp(s, ss, uu)
        x = length if i == ns - 1 else i * dl
        if x <= ss[0]:
            us[i] = uu[0]
        elif x >= ss[nt - 1]:
            us[i] = uu[nt - 1]
        else:
            while ss[j + 1] <= x:
                j += 1
            us[i] = uu[j] + (x - ss[j]) * (uu[j + 1] - uu[j]) / (ss[j + 1] - ss[j])
    curve = np.empty((ns, 2))
    _bspl_eval(t, c, 3, us, curve)
    return 0, keep, t, c, resid, uu, ss, curve


@njit(cache=True, nogil=True)
def pass_tail(pu_all, pz_all, use, R, reach, ks, step, lo, hi, half):
    """The end of a pass (``ChamberTracer._passes``): rim bridges, the final robust spline and the pass figures.

    The used stations' band points, :func:`rim_bridge` to both rims (``reach``
    px), the points ``U, Z`` from rim to rim (pinned ends at ``(-R, 0)``,
    ``(R, 0)``), :func:`robust_profile_spline` of them (knots ``ks`` apart, the
    curve every ``step`` px), the RMS residual of the kept inner points, and
    the fraction of used stations with a band edge within 1 px of the
    window's end ``half``.  Returns ``status`` (that of the spline), ``U, Z``,
    the spline's ``keep, t, c, residuals, uu, ss, curve``, ``residual_rms``
    and ``edge_fraction``.
    """
    n = pu_all.shape[0]
    m = 0
    for i in range(n):
        m += use[i]
    pu = np.empty(m)
    pz = np.empty(m)
    j = 0
    n_edge = 0
    for i in range(n):
        if use[i]:
            pu[j], pz[j] = pu_all[i], pz_all[i]
            j += 1
            if abs(lo[i]) > half - 1.0 or abs(hi[i]) > half - 1.0:
                n_edge += 1
    bl = rim_bridge(pu, pz, R, -1.0, reach)
    br = rim_bridge(pu, pz, R, 1.0, reach)
    nl, nr = bl.shape[0], br.shape[0]
    N = 2 + nl + m + nr
    U = np.empty(N)
    Z = np.empty(N)
    U[0], Z[0] = -R, 0.0
    for i in range(nl):
        U[1 + i], Z[1 + i] = bl[i, 0], bl[i, 1]
    for i in range(m):
        U[1 + nl + i], Z[1 + nl + i] = pu[i], pz[i]
    for i in range(nr):
        U[1 + nl + m + i], Z[1 + nl + m + i] = br[nr - 1 - i, 0], br[nr - 1 - i, 1]
    U[N - 1], Z[N - 1] = R, 0.0
    status, keep, t, c, res, uu, ss, curve = robust_profile_spline(U, Z, ks, True, step)
    ss_in = 0.0
    n_in = 0
    if status == 0:
        for i in range(1, N - 1):
            if keep[i]:
                ss_in += res[i] * res[i]
                n_in += 1
    rms = np.sqrt(ss_in / n_in) if n_in else np.nan
    edge_fraction = n_edge / m if m else 1.0
    return status, U, Z, keep, t, c, res, uu, ss, curve, rms, edge_fraction


def strongest_edge(frame, k, px, py, dx, dy, offsets, sign):
    """:func:`_strongest_edge` of any frame (see there)."""
    return _strongest_edge(native_frame(frame), int(k) % 4, np.ascontiguousarray(px, np.float64),
                           np.ascontiguousarray(py, np.float64), np.ascontiguousarray(dx, np.float64),
                           np.ascontiguousarray(dy, np.float64), np.ascontiguousarray(offsets, np.float64),
                           float(sign))


@njit(cache=True, nogil=True)
def _strongest_edge(frame, k, px, py, dx, dy, offsets, sign):
    """Index of the strongest edge of one sign in the row-median of transects (-1 if any median is nan).

    ``argmax(sign * np.gradient(ndi.gaussian_filter1d(nanmedian(transects, axis=0), 1.0)))``
    (scipy's kernel: sigma 1, radius 4, mode "reflect"), as the tracer's coarse
    wall search does for each wall.
    """
    n, m = px.shape[0], offsets.shape[0]
    prof = np.empty((n, m))
    _sample_transects(frame, k, px, py, dx, dy, offsets, prof)
    med = np.empty(m)
    col = np.empty(n)
    buf = np.empty(n)
    for j in range(m):
        c = 0
        for i in range(n):
            v = prof[i, j]
            if np.isfinite(v):
                col[c] = v
                c += 1
        if c == 0:
            return -1
        med[j] = _median_small(col, 0, c, buf)  # a few rows: insertion sort, not np.median's allocations
    wts = np.empty(9)
    tot = 0.0
    for q in range(9):
        wts[q] = np.exp(-0.5 * (q - 4) ** 2)
        tot += wts[q]
    sm = np.empty(m)
    for j in range(m):
        s = 0.0
        for q in range(9):
            jj = j + q - 4
            # mode "reflect": d c b a | a b c d | d c b a
            while jj < 0 or jj >= m:
                jj = -jj - 1 if jj < 0 else 2 * m - 1 - jj
            s += wts[q] * med[jj]
        sm[j] = s / tot
    best, arg = -np.inf, 0
    for j in range(m):
        if m == 1:
            gr = 0.0
        elif j == 0:
            gr = sm[1] - sm[0]
        elif j == m - 1:
            gr = sm[m - 1] - sm[m - 2]
        else:
            gr = 0.5 * (sm[j + 1] - sm[j - 1])
        gr *= sign
        if gr > best:
            best, arg = gr, j
    return arg


@njit(cache=True, nogil=True)
def _guide_stations(gx, gy, step, smooth):
    """Stations every ``step`` px along a polyline and their smoothed normals.

    :func:`osmobulge.imaging._normals.resample_polyline` then
    :func:`~osmobulge.imaging._normals.polyline_normals` (``smooth``: Gaussian
    sigma of the tangents in stations, mode "nearest").
    """
    n = gx.shape[0]
    s = np.empty(n)
    s[0] = 0.0
    keep = np.empty(n, np.bool_)
    keep[0] = True
    for i in range(1, n):
        seg = np.hypot(gx[i] - gx[i - 1], gy[i] - gy[i - 1])
        s[i] = s[i - 1] + seg
        keep[i] = seg > 1e-9
    idx = np.flatnonzero(keep)
    xs, px, py = s[idx], gx[idx], gy[idx]
    total = s[n - 1]
    m = max(int(np.ceil(total / step)) + 1, 2)
    si = np.empty(m)
    dl = total / (m - 1)
    for i in range(m):
        si[i] = i * dl
    si[m - 1] = total
    pts = np.empty((m, 2))
    nk = xs.shape[0]
    j = 0
    for i in range(m):  # np.interp(si, xs, p)
        x = si[i]
        if x >= xs[nk - 1]:
            pts[i, 0], pts[i, 1] = px[nk - 1], py[nk - 1]
            continue
        if x <= xs[0]:
            pts[i, 0], pts[i, 1] = px[0], py[0]
            continue
        while xs[j + 1] <= x:
            j += 1
        f = (x - xs[j]) / (xs[j + 1] - xs[j])
        pts[i, 0] = px[j] + f * (px[j + 1] - px[j])
        pts[i, 1] = py[j] + f * (py[j + 1] - py[j])
    t = np.empty((m, 2))
    for d in range(2):
        t[0, d] = pts[1, d] - pts[0, d]
        t[m - 1, d] = pts[m - 1, d] - pts[m - 2, d]
        for i in range(1, m - 1):
            t[i, d] = 0.5 * (pts[i + 1, d] - pts[i - 1, d])
    if smooth > 0 and m > 5:
        t = _fill_and_smooth(t, smooth)
    nrm = np.empty((m, 2))
    for i in range(m):
        nn = max(np.hypot(t[i, 0], t[i, 1]), 1e-12)
        nrm[i, 0] = t[i, 1] / nn
        nrm[i, 1] = -t[i, 0] / nn
    return pts, si, nrm


def guide_transects(frame, k, guide, step, offsets, sigma):
    """Stations along a guide, their normals and the smoothed transects there, in one compiled pass.

    ``pts, s = resample_polyline(guide, step)``; ``nrm = polyline_normals(pts,
    smooth=2 / step)``; ``prof`` the transects there, nan filled with the median
    of the rest and smoothed along the stations (``ndi.gaussian_filter1d(...,
    sigma, axis=0, mode="nearest")``).  Returns ``pts, s, nrm, prof``.
    """
    g = np.asarray(guide, np.float64)
    pts, s, nrm = _guide_stations(np.ascontiguousarray(g[:, 0]), np.ascontiguousarray(g[:, 1]), float(step),
                                  2.0 / float(step))
    off = np.ascontiguousarray(offsets, np.float64)
    prof = np.empty((len(pts), len(off)))
    _sample_transects(native_frame(frame), int(k) % 4, pts[:, 0].copy(), pts[:, 1].copy(), nrm[:, 0].copy(),
                      nrm[:, 1].copy(), off, prof)
    return pts, s, nrm, _fill_and_smooth(prof, float(sigma))


@njit(cache=True, nogil=True)
def _half_measures(r, z, close):
    """Volume ``-sum(pi dz (r1^2 + r1 r2 + r2^2) / 3)`` (closed to z = 0) and area ``pi sum((r1 + r2) ds)``."""
    v = 0.0
    a = 0.0
    n = r.shape[0]
    for i in range(n - 1):
        r1, r2, dz = r[i], r[i + 1], z[i + 1] - z[i]
        v += dz * (r1 * r1 + r1 * r2 + r2 * r2) / 3.0
        a += (r1 + r2) * np.hypot(r2 - r1, dz)
    if close and n:
        r1 = r[n - 1]
        v += (0.0 - z[n - 1]) * (3.0 * r1 * r1) / 3.0
    return -np.pi * v, np.pi * a


@njit(cache=True, nogil=True)
def revolution_halves(x, z, close):
    """Both halves' volumes and areas about the axis, the apex height and the rim ends, in one pass.

    :func:`osmobulge.imaging.geometry.split_halves` (at the highest axis
    crossing), then :func:`~osmobulge.imaging.geometry.revolution_volume` and
    :func:`~osmobulge.imaging.geometry.revolution_area` of each half.  Returns
    ``ok`` (False: the curve does not cross the axis) and
    ``(v_left, v_right, a_left, a_right, height, rim_left, rim_right)``.
    """
    n = x.shape[0]
    if x[0] > x[n - 1]:
        x, z = x[::-1].copy(), z[::-1].copy()
    best_i, best_z = -1, -np.inf
    for i in range(n - 1):
        s0, s1 = np.sign(x[i]), np.sign(x[i + 1])
        if (s0 < 0 and s1 >= 0) or (s0 <= 0 and s1 > 0):
            t = -x[i] / (x[i + 1] - x[i]) if x[i + 1] != x[i] else 0.0
            zc = z[i] + t * (z[i + 1] - z[i])
            if zc > best_z or best_i < 0:
                best_i, best_z = i, zc
    if best_i < 0:
        return False, (np.nan, np.nan, np.nan, np.nan, np.nan, np.nan, np.nan)
    i = best_i
    skip_l = 1 if -x[i] <= 0 else 0
    nl = i + 1 - skip_l
    rl, zl = np.empty(nl + 1), np.empty(nl + 1)
    rl[0], zl[0] = 0.0, best_z
    for j in range(nl):
        src = i - skip_l - j
        rl[j + 1], zl[j + 1] = -x[src], z[src]
    skip_r = 1 if (i + 1 < n and x[i + 1] <= 0) else 0
    nr = n - (i + 1) - skip_r
    rr, zr = np.empty(nr + 1), np.empty(nr + 1)
    rr[0], zr[0] = 0.0, best_z
    for j in range(nr):
        src = i + 1 + skip_r + j
        rr[j + 1], zr[j + 1] = x[src], z[src]
    vl, al = _half_measures(rl, zl, close)
    vr, ar = _half_measures(rr, zr, close)
    return True, (vl, vr, al, ar, best_z, rl[nl], rr[nr])


@njit(cache=True, nogil=True)
def _excluded(u, z, R, zc, near):
    """The tracer's rim zones: at or beyond a rim and below ``zc``, or within ``near`` of a rim point."""
    return (abs(u) > R - 1.0 and z < zc) or np.hypot(abs(u) - R, z) < near


@njit(cache=True, nogil=True)
def rim_zone(u, z, R, zc, near):
    """:func:`_excluded` of each point ``(u[i], z[i])`` (chamber px), as a bool array."""
    out = np.empty(u.shape[0], np.bool_)
    for i in range(u.shape[0]):
        out[i] = _excluded(u[i], z[i], R, zc, near)
    return out


@njit(cache=True, nogil=True)
def rim_guide(guide, R, zc, near):
    """A dome guide from rim to rim: its points outside the rim zones, then the rim points at both ends.

    ``guide`` (N, 2) of ``(u, z)`` (chamber px): the points not in
    :func:`rim_zone`, in order from the left rim (reversed when the first
    kept point lies right of the last), between ``(-R, 0)`` and ``(R, 0)``.
    Returns ``(ok, out)``; ``ok`` False when fewer than 3 points are kept
    (``out`` is then empty: the caller starts from a straight guide).
    """
    n = guide.shape[0]
    keep = np.empty(n, np.bool_)
    m = 0
    for i in range(n):
        keep[i] = not _excluded(guide[i, 0], guide[i, 1], R, zc, near)
        m += keep[i]
    if m < 3:
        return False, np.empty((0, 2))
    idx = np.flatnonzero(keep)
    if guide[idx[0], 0] > guide[idx[m - 1], 0]:
        idx = idx[::-1]
    out = np.empty((m + 2, 2))
    out[0, 0], out[0, 1] = -R, 0.0
    for j in range(m):
        out[1 + j, 0], out[1 + j, 1] = guide[idx[j], 0], guide[idx[j], 1]
    out[m + 1, 0], out[m + 1, 1] = R, 0.0
    return True, out


@njit(cache=True, nogil=True)
def masked_nanmedian(x, exclude):
    """``np.nanmedian(x[~exclude])`` (nan when no finite value is left)."""
    return _nanmedian_flat(x[~exclude])


@njit(cache=True, nogil=True)
def clean_stations(mid, contrast, spx, spy, nx, ny, x0, y0, dirx, diry, nrmx, nrmy, R, zc, near, min_con, win):
    """Accepted stations of a pass (``ChamberTracer._clean``), compiled.

    Band points in line coordinates; ``good``: finite with contrast above
    ``min_con``; ``excl``: the band point or its station in a rim zone
    (:func:`_excluded`); ``use``: good, not excluded and (with more than 10)
    within ``max(4 MAD, 1 px)`` of the running median (``win`` stations,
    mode "nearest") of the offsets filled by interpolation.  ``sigma_d2``:
    robust sigma of the second differences of the used offsets (nan with 10
    or fewer).  Returns ``pu, pz, good, excl, use, sigma_d2``.
    """
    n = mid.shape[0]
    pu, pz = np.empty(n), np.empty(n)
    good = np.empty(n, np.bool_)
    excl = np.empty(n, np.bool_)
    use = np.empty(n, np.bool_)
    n_use = 0
    for i in range(n):
        m = mid[i] if np.isfinite(mid[i]) else 0.0
        px, py = spx[i] + m * nx[i] - x0, spy[i] + m * ny[i] - y0
        pu[i] = px * dirx + py * diry
        pz[i] = px * nrmx + py * nrmy
        qx, qy = spx[i] - x0, spy[i] - y0
        good[i] = np.isfinite(mid[i]) and contrast[i] > min_con
        excl[i] = _excluded(pu[i], pz[i], R, zc, near) or _excluded(qx * dirx + qy * diry, qx * nrmx + qy * nrmy,
                                                                   R, zc, near)
        use[i] = good[i] and not excl[i]
        if use[i]:
            n_use += 1
    if n_use > 10:
        idx = np.flatnonzero(use)
        filled = np.empty(n)
        j = 0
        for i in range(n):  # np.interp(arange(n), idx, mid[idx])
            if i <= idx[0]:
                filled[i] = mid[idx[0]]
            elif i >= idx[n_use - 1]:
                filled[i] = mid[idx[n_use - 1]]
            else:
                while idx[j + 1] <= i:
                    j += 1
                f = (i - idx[j]) / (idx[j + 1] - idx[j])
                filled[i] = mid[idx[j]] + f * (mid[idx[j + 1]] - mid[idx[j]])
        h = win // 2
        buf = np.empty(win)
        dev = np.empty(n)
        devu = np.empty(n_use)
        c = 0
        for i in range(n):  # ndi.median_filter(filled, win, mode="nearest"), win odd: a sorted sliding window
            if i == 0:
                for q in range(win):
                    v = filled[min(max(q - h, 0), n - 1)]
                    p = q
                    while p > 0 and buf[p - 1] > v:
                        buf[p] = buf[p - 1]
                        p -= 1
                    buf[p] = v
            else:  # the sample leaving the window out, the one entering in, the rest stays sorted
                v_out = filled[min(max(i - 1 - h, 0), n - 1)]
                v_in = filled[min(max(i + h, 0), n - 1)]
                p = 0
                while p < win - 1 and buf[p] != v_out:  # (finite: interpolated from finite midlines)
                    p += 1
                while p + 1 < win and buf[p + 1] < v_in:
                    buf[p] = buf[p + 1]
                    p += 1
                while p > 0 and buf[p - 1] > v_in:
                    buf[p] = buf[p - 1]
                    p -= 1
                buf[p] = v_in
            dev[i] = abs(mid[i] - buf[h])
            if use[i]:
                devu[c] = dev[i]
                c += 1
        thr = max(4.0 * 1.4826 * _nanmedian_flat(devu), 1.0)
        for i in range(n):
            use[i] = use[i] and dev[i] <= thr
    d2 = np.empty(max(n - 2, 0))
    c = 0
    for i in range(n - 2):
        if use[i] and use[i + 1] and use[i + 2]:
            d2[c] = abs(mid[i + 2] - 2.0 * mid[i + 1] + mid[i])
            c += 1
    sigma = 1.4826 * np.median(d2[:c]) / np.sqrt(6.0) if c > 10 else np.nan
    return pu, pz, good, excl, use, sigma


@njit(cache=True, nogil=True)
def track_pass(frame, k, gu, gz, x0, y0, d0, d1, n0, n1, step, offsets, polarity, search, side, R, zc, near,
               min_contrast, ref_con, win):
    """The tracking pass of ``ChamberTracer._passes`` up to its motion figure, in one call.

    The guide ``(gu, gz)`` (line coordinates) in the view
    (``Line.point``: ``(x0, y0) + u (d0, d1) + z (n0, n1)``), then
    :func:`guide_transects` (stations every ``step``, their smoothed
    transects at ``offsets``), ``band_edges`` about each transect's centre
    sample within ``search`` samples (``side`` samples for the side levels),
    :func:`ends_noise`, :func:`clean_stations` with the contrast floor
    ``max(min_contrast ref_con, 4 noise)`` (as Python's ``max``) and the 90th
    percentile of the used stations' ``|mid|`` (:func:`abs_percentile`).

    Returns ``pts, s, nrm, mid, lo, hi, contrast, width, noise, pu, pz, good,
    excl, use, sigma_d2, motion``.
    """
    n = gu.shape[0]
    gx = np.empty(n)
    gy = np.empty(n)
    for i in range(n):
        gx[i] = x0 + gu[i] * d0 + gz[i] * n0
        gy[i] = y0 + gu[i] * d1 + gz[i] * n1
    pts, s, nrm = _guide_stations(gx, gy, step, 2.0 / step)
    ns = pts.shape[0]
    m = offsets.shape[0]
    prof = np.empty((ns, m))
    _sample_transects(frame, k, pts[:, 0].copy(), pts[:, 1].copy(), nrm[:, 0].copy(), nrm[:, 1].copy(), offsets,
                      prof)
    prof = _fill_and_smooth(prof, 1.0 / step)
    noise = ends_noise(prof)
    _signed_into(prof, polarity, prof)  # signed_profiles in place (the smoothed transects are not needed after)
    out = np.empty((5, ns))
    _band_edges_rows(prof, offsets, np.full(ns, m // 2, np.int64), np.full(ns, search, np.int64),
                     min(max(side, 1), m), out)
    floor = min_contrast * ref_con
    if 4.0 * noise > floor:
        floor = 4.0 * noise
    mid = out[0].copy()
    con = out[3].copy()
    pu, pz, good, excl, use, sigma = clean_stations(mid, con, pts[:, 0].copy(), pts[:, 1].copy(), nrm[:, 0].copy(),
                                                    nrm[:, 1].copy(), x0, y0, d0, d1, n0, n1, R, zc, near, floor,
                                                    win)
    motion = abs_percentile(mid, use, 90.0)
    return (pts, s, nrm, mid, out[1].copy(), out[2].copy(), con, out[4].copy(), noise, pu, pz, good, excl, use,
            sigma, motion)


@njit(cache=True, nogil=True)
def rim_bridge(pu, pz, R, side, reach):
    """Points bridging the untraceable foot of the dome (merged with the flat band) to one rim.

    The direction ``theta(rho)`` of the traced points seen from the rim point
    ``(side R, 0)`` (``side`` -1 left, +1 right), least-squares linear in the
    distance ``rho`` (a curve leaving the rim at an angle with a curvature)
    over the nearest ``reach`` px of them (unwrapped; the angle measured from
    the outward direction, -u on the left and +u on the right, towards +z),
    filled every px from the rim out to the nearest point.  Returns an
    (M, 2) array of ``(u, z)`` (chamber px); used by :func:`pass_tail`.
    """
    n = pu.shape[0]
    if n == 0:
        return np.zeros((0, 2))
    rho = np.empty(n)
    rmin = np.inf
    for i in range(n):
        rho[i] = np.hypot(pu[i] - side * R, pz[i])
        rmin = min(rmin, rho[i])
    if rmin < 2.0:
        return np.zeros((0, 2))
    idx = np.flatnonzero(rho < rmin + reach)
    m = idx.shape[0]
    th = np.empty(m)
    for j in range(m):
        th[j] = np.arctan2(pz[idx[j]], side * (pu[idx[j]] - side * R))
    if m >= 4:
        y = th.copy()  # np.unwrap
        corr = 0.0
        for j in range(1, m):
            dd = th[j] - th[j - 1]
            ddmod = (dd + np.pi) - 2.0 * np.pi * np.floor((dd + np.pi) / (2.0 * np.pi)) - np.pi
            if ddmod == -np.pi and dd > 0:
                ddmod = np.pi
            if abs(dd) >= np.pi:
                corr += ddmod - dd
            y[j] = th[j] + corr
        xm, ym = 0.0, 0.0
        for j in range(m):
            xm += rho[idx[j]]
            ym += y[j]
        xm /= m
        ym /= m
        sxy, sxx = 0.0, 0.0
        for j in range(m):
            dx = rho[idx[j]] - xm
            sxy += dx * (y[j] - ym)
            sxx += dx * dx
        c1 = sxy / max(sxx, 1e-300)
        c0 = ym - c1 * xm
    else:
        c0, c1 = np.median(th), 0.0
    k = int(np.ceil(rmin - 1.0))  # np.arange(1.0, rmin, 1.0)
    out = np.empty((max(k, 0), 2))
    for j in range(k):
        rr = 1.0 + j
        tt = c0 + c1 * rr
        out[j, 0] = side * R + side * rr * np.cos(tt)
        out[j, 1] = rr * np.sin(tt)
    return out


@njit(cache=True, nogil=True)
def _arc_fractions(u, z):
    n = u.shape[0]
    f = np.empty(n)
    f[0] = 0.0
    for i in range(1, n):
        f[i] = f[i - 1] + np.hypot(u[i] - u[i - 1], z[i] - z[i - 1])
    return f


@njit(cache=True, nogil=True)
def extrapolated_curve(pu, pz, qu, qz):
    """The curve ``p`` moved on as it moved since ``q``: ``2 p - q`` at equal fractions of arc length (N, 2).

    ``fp, fq`` the cumulative arc lengths; ``2 p - interp(fp / fp[-1], fq / fq[-1], q)``
    (``np.interp``); ``p`` itself when either curve has no length.
    """
    n, m = pu.shape[0], qu.shape[0]
    out = np.empty((n, 2))
    out[:, 0] = pu
    out[:, 1] = pz
    if n == 0 or m == 0:
        return out
    fp, fq = _arc_fractions(pu, pz), _arc_fractions(qu, qz)
    if not (fp[n - 1] > 0.0 and fq[m - 1] > 0.0):
        return out
    lp, lq = fp[n - 1], fq[m - 1]
    for j in range(m):
        fq[j] /= lq
    j = 0
    for i in range(n):
        x = fp[i] / lp
        if x >= fq[m - 1]:
            iu, iz = qu[m - 1], qz[m - 1]
        elif x < fq[0]:
            iu, iz = qu[0], qz[0]
        else:
            while fq[j + 1] <= x:
                j += 1
            t = (x - fq[j]) / (fq[j + 1] - fq[j])
            iu = qu[j] + t * (qu[j + 1] - qu[j])
            iz = qz[j] + t * (qz[j + 1] - qz[j])
        out[i, 0] = 2.0 * pu[i] - iu
        out[i, 1] = 2.0 * pz[i] - iz
    return out


@njit(cache=True, nogil=True)
def abs_percentile(x, mask, q):
    """``np.percentile(np.abs(x[mask]), q)`` (linear interpolation; nan when the mask is empty)."""
    n = 0
    for i in range(x.shape[0]):
        if mask[i]:
            n += 1
    if n == 0:
        return np.nan
    v = np.empty(n)
    j = 0
    for i in range(x.shape[0]):
        if mask[i]:
            v[j] = abs(x[i])
            j += 1
    pos = q / 100.0 * (n - 1)
    lo = int(np.floor(pos))
    # the two order statistics the interpolation needs, by selection (as the sorted array's v[lo], v[lo + 1])
    v = np.partition(v, lo)
    v_lo = v[lo]
    v_hi = v_lo
    if lo + 1 < n:
        v_hi = v[lo + 1]
        for i in range(lo + 2, n):
            if v[i] < v_hi:
                v_hi = v[i]
    return v_lo + (pos - lo) * (v_hi - v_lo)


@njit(cache=True, nogil=True)
def rim_contact(frame, k, x0, y0, d0, d1, n0, n1, R, zw, fracs, far_left, far_right):
    """The tracer's rim contact figure (``ChamberTracer._figures``), one call for both sides.

    Per side ``sgn`` (-1 left, +1 right): bilinear samples (view rotated by
    ``k``) of the band at ``u = sgn (R + fracs R)``, ``z = 0``, of the band far
    out at ``u = far``, ``z = 0`` and of the water above it at ``z = zw`` (view
    point ``(x0, y0) + u (d0, d1) + z (n0, n1)``, as ``Line.point``); with the
    nan medians ``band``, ``band_far``, ``water`` the side's figure is
    ``(water - band) / (water - band_far)`` (nan when that denominator is 0 or
    not finite).  Returns ``min(left, right)`` as Python's ``min`` gives it
    (the left one unless the right one is smaller).
    """
    nb = fracs.shape[0]
    zero = np.zeros(1)
    out = np.empty(2)
    for side in range(2):
        sgn = -1.0 if side == 0 else 1.0
        far = far_left if side == 0 else far_right
        nf = far.shape[0]
        m = nb + 2 * nf
        px = np.empty(m)
        py = np.empty(m)
        for i in range(nb):
            u = sgn * (R + fracs[i] * R)
            px[i] = x0 + u * d0 + 0.0 * n0
            py[i] = y0 + u * d1 + 0.0 * n1
        for i in range(nf):
            px[nb + i] = x0 + far[i] * d0 + 0.0 * n0
            py[nb + i] = y0 + far[i] * d1 + 0.0 * n1
            px[nb + nf + i] = x0 + far[i] * d0 + zw * n0
            py[nb + nf + i] = y0 + far[i] * d1 + zw * n1
        zs = np.zeros(m)
        v = np.empty((m, 1))
        _sample_transects(frame, k, px, py, zs, zs, zero, v)
        band = _nanmedian_flat(v[:nb, 0].copy())
        band_far = _nanmedian_flat(v[nb:nb + nf, 0].copy())
        water = _nanmedian_flat(v[nb + nf:, 0].copy())
        den = water - band_far
        out[side] = (water - band) / den if np.isfinite(den) and abs(den) > 0 else np.nan
    return out[1] if out[1] < out[0] else out[0]


@njit(cache=True, nogil=True)
def clear_of_curve(us, u, z, zmax, gap):
    """Columns ``us`` farther than ``gap`` (along u) from every curve point below ``zmax``: a mask.

    The tracer's flat-line columns without the last dome's overhang
    (``ChamberTracer._geometry_at``): ``lu = sort(u[z < zmax])``, the nearest
    of ``lu`` to each column through ``searchsorted``; all True when no point
    is that low.
    """
    n = u.shape[0]
    m = 0
    for i in range(n):
        if z[i] < zmax:
            m += 1
    out = np.ones(us.shape[0], np.bool_)
    if m == 0:
        return out
    lu = np.empty(m)
    j = 0
    for i in range(n):
        if z[i] < zmax:
            lu[j] = u[i]
            j += 1
    lu.sort()
    for i in range(us.shape[0]):
        k = np.searchsorted(lu, us[i])
        d = np.inf
        if k > 0:
            d = abs(us[i] - lu[k - 1])
        if k < m:
            d = min(d, abs(us[i] - lu[k]))
        out[i] = d > gap
    return out


@njit(cache=True, nogil=True)
def curve_extent(u, z, x0, y0, d0, d1, n0, n1):
    """``max(|u|)`` and the view box of ``Line.point(u, z)``: ``(max|u|, x.min(), x.max(), y.min())``.

    The tracer's check whether another bulge could reach the dome
    (``ChamberTracer._neighbour_possible``); nan when ``u`` is empty.
    """
    n = u.shape[0]
    if n == 0:
        return np.nan, np.nan, np.nan, np.nan
    umax = abs(u[0])
    x = x0 + u[0] * d0 + z[0] * n0
    xmin = xmax = x
    ymin = y0 + u[0] * d1 + z[0] * n1
    for i in range(1, n):
        umax = max(umax, abs(u[i]))
        x = x0 + u[i] * d0 + z[i] * n0
        y = y0 + u[i] * d1 + z[i] * n1
        xmin = min(xmin, x)
        xmax = max(xmax, x)
        ymin = min(ymin, y)
    return umax, xmin, xmax, ymin


@njit(cache=True, nogil=True)
def ellipse_scatter(x, y):
    """Centroid, scale and the scatter matrices of Halir & Flusser's direct ellipse fit (normalised points).

    ``d = (p - mean) / std``; ``D1 = [x^2, x y, y^2]``, ``D2 = [x, y, 1]``;
    returns ``x0, y0, scale, D1'D1, D1'D2, D2'D2``.
    """
    n = x.shape[0]
    x0 = 0.0
    y0 = 0.0
    for i in range(n):
        x0 += x[i]
        y0 += y[i]
    x0 /= n
    y0 /= n
    var = 0.0
    for i in range(n):
        var += (x[i] - x0) ** 2 + (y[i] - y0) ** 2
    scale = np.sqrt(var / (2 * n))  # np.std of all 2n centred coordinates
    S1 = np.zeros((3, 3))
    S2 = np.zeros((3, 3))
    S3 = np.zeros((3, 3))
    if not scale > 0:
        return x0, y0, scale, S1, S2, S3
    d1 = np.empty(3)
    d2 = np.empty(3)
    for i in range(n):
        u = (x[i] - x0) / scale
        v = (y[i] - y0) / scale
        d1[0], d1[1], d1[2] = u * u, u * v, v * v
        d2[0], d2[1], d2[2] = u, v, 1.0
        for a in range(3):
            for b in range(3):
                S1[a, b] += d1[a] * d1[b]
                S2[a, b] += d1[a] * d2[b]
                S3[a, b] += d2[a] * d2[b]
    return x0, y0, scale, S1, S2, S3


@njit(cache=True, nogil=True)
def _solve3(A, B):
    """A X = B for a 3 x 3 A (Gaussian elimination, partial pivoting); ok False when A is singular."""
    a = A.copy()
    x = B.copy()
    m = x.shape[1]
    scale = 0.0
    for i in range(3):
        for j in range(3):
            scale = max(scale, abs(a[i, j]))
    if not scale > 0.0:
        return x, False
    for col in range(3):
        piv = col
        for r in range(col + 1, 3):
            if abs(a[r, col]) > abs(a[piv, col]):
                piv = r
        if not abs(a[piv, col]) > 1e-14 * scale:
            return x, False
        if piv != col:
            for j in range(3):
                a[col, j], a[piv, j] = a[piv, j], a[col, j]
            for j in range(m):
                x[col, j], x[piv, j] = x[piv, j], x[col, j]
        for r in range(col + 1, 3):
            f = a[r, col] / a[col, col]
            for j in range(col, 3):
                a[r, j] -= f * a[col, j]
            for j in range(m):
                x[r, j] -= f * x[col, j]
    for col in range(2, -1, -1):
        for j in range(m):
            v = x[col, j]
            for c in range(col + 1, 3):
                v -= a[col, c] * x[c, j]
            x[col, j] = v / a[col, col]
    return x, True


@njit(cache=True, nogil=True)
def _null_vector3(A):
    """Unit vector spanning the null space of a rank-2 3 x 3 matrix (the largest cross product of two rows)."""
    best = np.zeros(3)
    bn = 0.0
    for i, j in ((0, 1), (0, 2), (1, 2)):
        c0 = A[i, 1] * A[j, 2] - A[i, 2] * A[j, 1]
        c1 = A[i, 2] * A[j, 0] - A[i, 0] * A[j, 2]
        c2 = A[i, 0] * A[j, 1] - A[i, 1] * A[j, 0]
        nn = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        if nn > bn:
            bn = nn
            best[0], best[1], best[2] = c0 / nn, c1 / nn, c2 / nn
    return best, bn > 0.0


@njit(cache=True, nogil=True, error_model="numpy")  # divisions by zero give inf/nan, as numpy
def conic_parameters(a, b, c, d, f, g):
    """Centre, semi-axes (major first) and angle of the conic ``a x^2 + b x y + c y^2 + d x + f y + g = 0``.

    skimage's :class:`~skimage.measure.EllipseModel` conversion (Halir &
    Flusser's coefficient vector to ``xc, yc, width, height, phi``, ``phi``
    in ``[0, pi)``); nan for an axis whose square is negative (no ellipse),
    inf/nan where a denominator vanishes.  Shared by both routes of the
    direct ellipse fit.
    """
    b, d, f = b / 2.0, d / 2.0, f / 2.0
    den = b * b - a * c
    xc, yc = (c * d - b * f) / den, (a * f - b * d) / den
    num = a * f * f + c * d * d + g * b * b - 2.0 * b * d * f - a * c * g
    term = np.sqrt((a - c) ** 2 + 4.0 * b * b)
    w2 = 2.0 * num / (den * (term - (a + c)))
    h2 = 2.0 * num / (den * (-term - (a + c)))
    width = np.sqrt(w2) if w2 >= 0.0 else np.nan
    height = np.sqrt(h2) if h2 >= 0.0 else np.nan
    phi = 0.5 * np.arctan((2.0 * b) / (a - c))
    if a > c:
        phi += 0.5 * np.pi
    if width < height:
        width, height = height, width
        phi += np.pi / 2
    phi %= np.pi
    return xc, yc, width, height, phi


@njit(cache=True, nogil=True, error_model="numpy")  # a zero denominator -> inf/nan (a failed fit), no raise
def direct_ellipse(x, y):
    """Halir & Flusser's direct ellipse, all compiled: ``status, xc, yc, width, height, phi``.

    The algebra of :func:`osmobulge.imaging.geometry._direct_ellipse_numpy`
    (skimage's :class:`~skimage.measure.EllipseModel` estimate): the 3 x 3
    eigenproblem is solved through its characteristic cubic (three real roots,
    each polished by Newton steps) and null vectors, without LAPACK.  ``status``
    is 0 on success, 1 when no ellipse satisfies the constraint or the conic is
    degenerate (the fit failed), 2 when this route cannot decide (a singular
    scatter matrix, a cubic without three distinct real roots): the numpy
    algebra decides then.
    """
    x0, y0, scale, S1, S2, S3 = ellipse_scatter(x, y)
    if not scale >= 2.2250738585072014e-308:
        return 1, np.nan, np.nan, np.nan, np.nan, np.nan
    T, ok = _solve3(S3, S2.T.copy())
    if not ok:
        return 2, np.nan, np.nan, np.nan, np.nan, np.nan
    for i in range(3):
        for j in range(3):
            T[i, j] = -T[i, j]
    M0 = S1.copy()  # S1 + S2 T (loops: numba's matmul would compile BLAS bindings, seconds)
    for i in range(3):
        for j in range(3):
            for q in range(3):
                M0[i, j] += S2[i, q] * T[q, j]
    M = np.empty((3, 3))
    for j in range(3):
        M[0, j] = M0[2, j] / 2.0
        M[1, j] = -M0[1, j]
        M[2, j] = M0[0, j] / 2.0
    mnorm = 0.0
    for i in range(3):
        for j in range(3):
            mnorm += M[i, j] ** 2
    mnorm = np.sqrt(mnorm)
    # characteristic polynomial l^3 + A l^2 + B l + C
    A = -(M[0, 0] + M[1, 1] + M[2, 2])
    B = (M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0] + M[0, 0] * M[2, 2] - M[0, 2] * M[2, 0]
         + M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
    C = -(M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]) - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
          + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]))
    p = B - A * A / 3.0
    q = 2.0 * A * A * A / 27.0 - A * B / 3.0 + C
    if not p < 0.0:
        return 2, np.nan, np.nan, np.nan, np.nan, np.nan
    rad = 2.0 * np.sqrt(-p / 3.0)
    arg = 3.0 * q / (p * rad)
    if not abs(arg) < 1.0 - 1e-9:  # (nearly) repeated roots: numpy decides
        return 2, np.nan, np.nan, np.nan, np.nan, np.nan
    phi0 = np.arccos(arg) / 3.0
    found = 0
    vec = np.zeros(3)
    E = np.empty((3, 3))
    roots = np.empty(3)
    for kk in range(3):
        lam = rad * np.cos(phi0 - 2.0 * np.pi * kk / 3.0) - A / 3.0
        for _ in range(3):  # Newton polish on the cubic
            f = ((lam + A) * lam + B) * lam + C
            d = (3.0 * lam + 2.0 * A) * lam + B
            if d == 0.0:
                break
            lam -= f / d
        roots[kk] = lam
    for kk in range(3):
        lam = roots[kk]
        # the root's error from the coefficients' rounding (each ~ eps |M|^k: cancellation in the trace and
        # minors of a non-normal M), against its distance to the other roots: LAPACK decides when not tiny
        al = abs(lam)
        err = 1e-15 * (mnorm ** 3 + mnorm ** 2 * al + mnorm * al ** 2 + al ** 3) / abs(
            (3.0 * lam + 2.0 * A) * lam + B)
        gap = min(abs(lam - roots[(kk + 1) % 3]), abs(lam - roots[(kk + 2) % 3]))
        if not err <= 1e-9 * gap:
            return 2, np.nan, np.nan, np.nan, np.nan, np.nan
        for i in range(3):
            for j in range(3):
                E[i, j] = M[i, j] - (lam if i == j else 0.0)
        v, ok = _null_vector3(E)
        if not ok:
            return 2, np.nan, np.nan, np.nan, np.nan, np.nan
        if 4.0 * v[0] * v[2] - v[1] ** 2 > 0.0:
            found += 1
            vec[:] = v
    if found != 1:
        return 1, np.nan, np.nan, np.nan, np.nan, np.nan
    a, b, c = vec[0], vec[1], vec[2]
    d_ = T[0, 0] * a + T[0, 1] * b + T[0, 2] * c
    f = T[1, 0] * a + T[1, 1] * b + T[1, 2] * c
    g = T[2, 0] * a + T[2, 1] * b + T[2, 2] * c
    xc, yc, width, height, phi = conic_parameters(a, b, c, d_, f, g)
    if not (np.isfinite(xc) and np.isfinite(yc) and np.isfinite(phi)):  # (numpy maps nan/inf to numbers)
        return 2, np.nan, np.nan, np.nan, np.nan, np.nan
    if not (np.isfinite(width * height) and width > 0 and height > 0):
        return 1, np.nan, np.nan, np.nan, np.nan, np.nan
    return 0, xc * scale + x0, yc * scale + y0, width * scale, height * scale, phi


@njit(cache=True, nogil=True)
def ellipse_arc_volume(xc, yc, a, b, theta, n):
    """Volume of revolution of an ellipse's arc above z = 0, as a polygon (nan if the ellipse does not cross z = 0).

    ``n`` points ``t = linspace(0, 2 pi, n, endpoint=False)``; the one run of
    points at or above z = 0 (an ellipse meets a line in at most two points),
    closed on z = 0 by linear interpolation to the crossings at both ends, then
    :func:`revolution_halves` (mean of the two halves).
    """
    ct, st = np.cos(theta), np.sin(theta)
    ex = np.empty(n)
    ez = np.empty(n)
    above = np.empty(n, np.bool_)
    n_above = 0
    for i in range(n):
        t = 2.0 * np.pi * i / n
        ex[i] = xc + a * np.cos(t) * ct - b * np.sin(t) * st
        ez[i] = yc + a * np.cos(t) * st + b * np.sin(t) * ct
        above[i] = ez[i] >= 0
        if above[i]:
            n_above += 1
    if n_above == 0 or n_above == n:
        return np.nan
    start = 0
    for i in range(n):  # the first point of the run: below before it, above at it
        if not above[i] and above[(i + 1) % n]:
            start = (i + 1) % n
            break
    m = 0
    while m < n and above[(start + m) % n]:
        m += 1
    ax = np.empty(m + 2)
    az = np.empty(m + 2)
    for j in range(m):
        ax[j + 1] = ex[(start + j) % n]
        az[j + 1] = ez[(start + j) % n]
    for end in range(2):  # the crossings of z = 0: between the run's end point and its neighbour below
        i_in = start if end == 0 else (start + m - 1) % n
        i_out = (start - 1) % n if end == 0 else (start + m) % n
        w = ez[i_in] / (ez[i_in] - ez[i_out])
        k = 0 if end == 0 else m + 1
        ax[k] = ex[i_in] + w * (ex[i_out] - ex[i_in])
        az[k] = 0.0
    ok, meas = revolution_halves(ax, az, True)
    if not ok:
        return np.nan
    return 0.5 * (meas[0] + meas[1])


@njit(cache=True, nogil=True, error_model="numpy")
def profile_ellipse(x, y, n_arc):
    """The extraction's ellipse description of a profile in one call: ``status, a, b, rms, volume``.

    :func:`osmobulge.imaging.geometry.fit_ellipse` of the finite points (the
    compiled :func:`direct_ellipse`; its semi-axes ``a, b`` and the RMS of the
    exact geometric distances, :func:`ellipse_distance_folded`) and
    :func:`ellipse_arc_volume` of the arc above z = 0 (``n_arc`` points).
    ``status`` 0: done; else (fewer than 5 points, no ellipse, or a case the
    compiled route cannot decide) the caller asks ``fit_ellipse`` itself.
    """
    n = x.shape[0]
    m = 0
    for i in range(n):
        if np.isfinite(x[i]) and np.isfinite(y[i]):
            m += 1
    if m < 5:
        return 1, np.nan, np.nan, np.nan, np.nan
    xs = np.empty(m)
    ys = np.empty(m)
    j = 0
    for i in range(n):
        if np.isfinite(x[i]) and np.isfinite(y[i]):
            xs[j] = x[i]
            ys[j] = y[i]
            j += 1
    status, xc, yc, a, b, th = direct_ellipse(xs, ys)
    if status != 0:
        return status, np.nan, np.nan, np.nan, np.nan
    if not (np.isfinite(a) and np.isfinite(b) and a > 0 and b > 0):
        return 1, np.nan, np.nan, np.nan, np.nan
    # geometry.ellipse_distance: into the ellipse's frame, folded into the first quadrant, major axis first
    c, s_ = np.cos(th), np.sin(th)
    fx = np.empty(m)
    fy = np.empty(m)
    for i in range(m):
        dx, dy = xs[i] - xc, ys[i] - yc
        fx[i] = abs(dx * c + dy * s_)
        fy[i] = abs(-dx * s_ + dy * c)
    if a < b:
        res = ellipse_distance_folded(fy, fx, b, a, 60)
    else:
        res = ellipse_distance_folded(fx, fy, a, b, 60)
    rms = np.sqrt(np.mean(res * res))
    return 0, a, b, rms, ellipse_arc_volume(xc, yc, a, b, th, n_arc)


@njit(cache=True, nogil=True)
def stored_profile_ellipse(pu, pz, max_points, n_arc):
    """The extraction's ellipse of a profile's points: ``status, a, b, rms, volume`` (``_store``).

    Nothing (status 3) when the points span 1 px or less in z (``np.ptp``, nan
    included); else :func:`profile_ellipse` of at most ``max_points`` of them,
    ``np.linspace(0, n - 1, min(n, max_points)).astype(int)``.
    """
    n = pu.shape[0]
    if n == 0:
        return 3, np.nan, np.nan, np.nan, np.nan
    lo = hi = pz[0]
    for i in range(n):
        if np.isnan(pz[i]):
            return 3, np.nan, np.nan, np.nan, np.nan
        lo = min(lo, pz[i])
        hi = max(hi, pz[i])
    if not hi - lo > 1.0:
        return 3, np.nan, np.nan, np.nan, np.nan
    m = min(n, max_points)
    x = np.empty(m)
    y = np.empty(m)
    step = (n - 1) / (m - 1) if m > 1 else 0.0
    for i in range(m):
        j = int(i * step) if i < m - 1 else n - 1
        x[i], y[i] = pu[j], pz[j]
    return profile_ellipse(x, y, n_arc)


@njit(cache=True, nogil=True)
def arc_resample(u, z, n):
    """A polyline resampled at ``n`` points evenly spaced in arc length: ``length, uu, zz``.

    ``sc = concatenate(([0], cumsum(hypot(diff(u), diff(z)))))``;
    ``si = linspace(0, sc[-1], n)``; ``uu, zz = interp(si, sc, u), interp(si, sc, z)``
    (numpy's interpolation rule; ``u`` of at least 2 points with increasing ``sc``).
    """
    m = u.shape[0]
    sc = np.empty(m)
    sc[0] = 0.0
    for i in range(1, m):
        sc[i] = sc[i - 1] + np.hypot(u[i] - u[i - 1], z[i] - z[i - 1])
    length = sc[m - 1]
    uu = np.empty(n)
    zz = np.empty(n)
    step = length / (n - 1) if n > 1 else 0.0
    j = 0
    for i in range(n):
        x = i * step if step != 0.0 else i / (n - 1) * length
        if i == n - 1 and n > 1:
            x = length
        if x >= length:
            uu[i], zz[i] = u[m - 1], z[m - 1]
            continue
        while j < m - 2 and sc[j + 1] <= x:
            j += 1
        if sc[j] == x:
            uu[i], zz[i] = u[j], z[j]
            continue
        h = sc[j + 1] - sc[j]
        uu[i] = (u[j + 1] - u[j]) / h * (x - sc[j]) + u[j]
        zz[i] = (z[j + 1] - z[j]) / h * (x - sc[j]) + z[j]
    return length, uu, zz


@njit(cache=True, nogil=True)
def _upper_trend_ok(y, ok, clip, refits):
    """Rows of ``y`` within -clip .. +2 clip noise sigmas of its upper linear trend over the row index (in ``ok``).

    The noise ``sig = 1.4826 / sqrt(2) * median(|diff(y_finite)|)``, a
    constant trend at the upper quartile of ``y``, then ``refits`` least
    squares lines on the rows in the window about the last trend.  False
    (and no row in ``ok``) with fewer than 8 finite values.
    """
    n = y.shape[0]
    fy = np.empty(n)
    m = 0
    for i in range(n):
        if np.isfinite(y[i]):
            fy[m] = y[i]
            m += 1
        ok[i] = False
    if m < 8:
        return False
    d = np.empty(m - 1)
    for i in range(m - 1):
        d[i] = abs(fy[i + 1] - fy[i])
    srt = np.sort(fy[:m])
    sig = max(1.4826 / np.sqrt(2.0) * np.median(d), 1e-3 * abs(srt[m - 1]), 1e-12)
    a = srt[(3 * (m - 1)) // 4]
    b = 0.0
    rows = np.arange(n).astype(np.float64)
    for it in range(refits + 1):
        c = 0
        for i in range(n):
            r = y[i] - (a + b * i)
            ok[i] = np.isfinite(r) and -clip * sig < r < 2.0 * clip * sig
            c += ok[i]
        if it == refits or c < 4:
            break
        a, b, _ = _masked_line(rows, y, ok)
        b = b if np.isfinite(b) else 0.0  # no spread: the constant at the rows' mean
    return True


@njit(cache=True, nogil=True)
def dusty_rows(prof, offs, pos, gap, clip):
    """Rows darkened by dust on either side of a wall's edge, and those runs grown by half their length.

    See :func:`osmobulge.imaging._chamber._dusty_rows`.
    """
    n, k = prof.shape
    lev = np.empty((2, n))
    for i in range(n):
        s0 = 0.0
        s1 = 0.0
        c0 = 0
        c1 = 0
        if np.isfinite(pos[i]):
            for j in range(k):
                v = prof[i, j]
                if not np.isfinite(v):
                    continue
                r = offs[j] - pos[i]
                if r < -gap:
                    s0 += v
                    c0 += 1
                elif r > gap:
                    s1 += v
                    c1 += 1
        lev[0, i] = s0 / c0 if c0 else np.nan
        lev[1, i] = s1 / c1 if c1 else np.nan
    # detected: a finite side level below the trend; unknown: no level to check (a row without an edge, or
    # a side outside the view) -- dusty when it has an edge, but never a seed of the growth below
    detected = np.zeros(n, np.bool_)
    unknown = np.zeros(n, np.bool_)
    ok = np.empty(n, np.bool_)
    for side in range(2):
        trend = _upper_trend_ok(lev[side], ok, clip, 2)
        for i in range(n):
            if not np.isfinite(lev[side, i]):
                unknown[i] = True
            elif trend and not ok[i]:
                detected[i] = True
    # a speck's shadow fades out smoothly: beyond the rows where it is detected its fringe still bends
    # the crossings (most where it sits on the edge), so each run of detected rows grows by half its length
    dusty = detected | (unknown & np.isfinite(pos))
    grown = dusty.copy()
    i = 0
    while i < n:
        if not detected[i]:
            i += 1
            continue
        j = i
        while j < n and detected[j]:
            j += 1
        g = (j - i + 1) // 2
        for r in range(max(i - g, 0), min(j + g, n)):
            grown[r] = True
        i = j
    return dusty, grown



#: a wall row's side levels: the median of 8 samples (4 px) at each end of its +-11 px window (7 px and more
#: from the edge: no rim bias under a 2.5 px blur); its crossing from a line through the 4 samples (2 px)
#: around it, not the 2 straddling it (row scatter -26 %, locked to the pixels by 0.012 px at most at 1 px blur)
WALL_SIDE, WALL_FIT = 8, 2


@njit(cache=True, nogil=True)
def wall_rows(frame, k, x0, y0, d0, d1, n0, n1, u0, slope, zs, top, offs):
    """One wall's rows for its line fit: height above the surface and edge position ``(zz, uu)`` (nan: dropped).

    The first attempt of :func:`osmobulge.imaging._chamber.measure_walls`
    compiled: transects along the line direction ``(d0, d1)`` at the predicted
    wall ``u0 + slope (zs - top)`` of the line ``(x0, y0)`` with normal
    ``(n0, n1)``, their mid-level step crossings (:func:`step_crossing_rows`
    with ``side=WALL_SIDE, fit=WALL_FIT``),
    rows whose step is of the other sign or weaker than half the median
    dropped, then the rows :func:`dusty_rows` marks (the grown runs if that
    leaves 6 rows and either 30 % of them or half the rows' spread, else the
    runs themselves, else none).
    """
    n = zs.shape[0]
    m = offs.shape[0]
    px = np.empty(n)
    py = np.empty(n)
    dx = np.full(n, d0)
    dy = np.full(n, d1)
    uc = np.empty(n)
    for i in range(n):
        uc[i] = u0 + slope * (zs[i] - top)
        px[i] = x0 + uc[i] * d0 + zs[i] * n0
        py[i] = y0 + uc[i] * d1 + zs[i] * n1
    prof = np.empty((n, m))
    _sample_transects(frame, k, px, py, dx, dy, offs, prof)
    out = np.empty((2, n))
    _step_crossing_rows(prof, offs, min(WALL_SIDE, m), out, WALL_FIT)
    pos = out[0].copy()
    med = _nanmedian_flat(out[1])
    for i in range(n):
        st = out[1, i]
        if not (((st > 0 and med > 0) or (st < 0 and med < 0)) and abs(st) > 0.5 * abs(med)):
            pos[i] = np.nan
    dusty, grown = dusty_rows(prof, offs, pos, 2.0, 3.0)
    sd_all = np.std(zs)
    for c in range(2):
        cand = grown if c == 0 else dusty
        cnt = 0
        for i in range(n):
            if not cand[i] and np.isfinite(pos[i]):
                cnt += 1
        if cnt < 6:
            continue
        zk = np.empty(cnt)
        j2 = 0
        for i in range(n):
            if not cand[i] and np.isfinite(pos[i]):
                zk[j2] = zs[i]
                j2 += 1
        if cnt >= 0.3 * n or np.std(zk) >= 0.5 * sd_all:
            for i in range(n):
                if cand[i]:
                    pos[i] = np.nan
            break
    zz = np.empty(n)
    uu = np.empty(n)
    for i in range(n):
        zz[i] = zs[i] - top
        uu[i] = uc[i] + pos[i]
    return zz, uu

@njit(cache=True, nogil=True)
def locate_walls(frame, k, x0, y0, d0, d1, n0, n1, u_left, u_right, slope_left, slope_right, wall_sign, zs_coarse,
                 offs_coarse, zs, top, offs):
    """Both walls of a tracked frame in one call: the coarse search, then each wall's first clipped line fit.

    ``ChamberTracer._coarse_walls`` (the strongest edge of the wall's sign,
    ``wall_sign`` for the left wall and ``-wall_sign`` for the right, on the
    rows ``zs_coarse`` at offsets ``offs_coarse`` along the line; both walls
    keep their prediction when either search fails), then the first attempt of
    ``_chamber.measure_walls`` for each wall (:func:`wall_rows`,
    :func:`robust_line` with 4 rounds, 2.5 sigma, 0.1 px floor) and its
    combination of a weak wall's slope with the other's, mirrored.

    Returns ``status, coarse_left, coarse_right, a_left, b_left, a_right, b_right, rms``:
    status 0 done; 1 a wall has no fit (``measure_walls`` gives None); 2 a first
    fit is poor (RMS > 0.5 px): the caller runs ``measure_walls`` (with its
    robust second attempt) from the coarse walls.
    """
    nc = zs_coarse.shape[0]
    px = np.empty(nc)
    py = np.empty(nc)
    dx = np.full(nc, d0)
    dy = np.full(nc, d1)
    cl, cr = u_left, u_right
    for side in range(2):
        u0 = u_left if side == 0 else u_right
        slope = slope_left if side == 0 else slope_right
        for i in range(nc):
            u = u0 + slope * (zs_coarse[i] - top)
            px[i] = x0 + u * d0 + zs_coarse[i] * n0
            py[i] = y0 + u * d1 + zs_coarse[i] * n1
        j = _strongest_edge(frame, k, px, py, dx, dy, offs_coarse, wall_sign if side == 0 else -wall_sign)
        if j < 0:
            cl, cr = u_left, u_right
            break
        if side == 0:
            cl = u0 + offs_coarse[j]
        else:
            cr = u0 + offs_coarse[j]
    a = np.empty(2)
    b = np.empty(2)
    szz = np.empty(2)
    rms_max = -np.inf
    n_used = np.zeros(2, np.int64)
    zsum = np.zeros(2)
    usum = np.zeros(2)
    for side in range(2):
        u0 = cl if side == 0 else cr
        slope = slope_left if side == 0 else slope_right
        zz, uu = wall_rows(frame, k, x0, y0, d0, d1, n0, n1, u0, slope, zs, top, offs)
        aa, bb, rms, ok = robust_line(zz, uu, 4, 2.5, 0.1)
        m = 0
        for i in range(ok.shape[0]):
            m += ok[i]
        if not (np.isfinite(aa) and m >= 3):
            return 1, cl, cr, np.nan, np.nan, np.nan, np.nan, np.nan
        if not rms <= 0.5:
            return 2, cl, cr, np.nan, np.nan, np.nan, np.nan, np.nan
        a[side], b[side] = aa, bb
        rms_max = max(rms_max, rms)
        zr = np.empty(m)
        j = 0
        for i in range(ok.shape[0]):
            if ok[i]:
                zr[j] = zz[i]
                zsum[side] += zz[i]
                usum[side] += uu[i]
                j += 1
        mean = zr.mean()
        ss = 0.0
        for j in range(m):
            ss += (zr[j] - mean) ** 2
        szz[side] = ss
        n_used[side] = m
    # a weak wall (short spread of rows) takes the other's slope, mirrored, into its own (spread-weighted)
    weak = 1 if szz[1] < szz[0] else 0  # sorted() of the two keeps the left first on a tie
    strong = 1 - weak
    if szz[weak] < 0.5 * szz[strong] and n_used[weak] >= 3:
        bw = (szz[weak] * b[weak] - szz[strong] * b[strong]) / (szz[weak] + szz[strong])
        a[weak] = usum[weak] / n_used[weak] - bw * (zsum[weak] / n_used[weak])
        b[weak] = bw
    return 0, cl, cr, a[0], b[0], a[1], b[1], rms_max


@njit(cache=True, nogil=True)
def ridge_rows(img, w_max):
    """Per column: row and signed value of the strongest ridge (band) response over widths 1..w_max.

    :func:`osmobulge.imaging._chamber._ridge_rows` (the ``np.roll`` form) in
    one pass, in the image's float32: ``r = (up + dn) / 2 - img`` with ``up``,
    ``dn`` the pixels ``w`` rows above and below, kept where both differ from
    the pixel with the same sign, 0 within ``w`` rows of the ends.
    """
    h, w = img.shape
    half = np.float32(0.5)
    rows = np.zeros(w, np.int64)
    vals = np.zeros(w, np.float32)
    top_abs = np.full(w, np.float32(-1.0))
    best = np.empty(w, np.float32)
    zero = np.float32(0.0)
    for i in range(h):  # row by row, the widths in the middle loop and the columns innermost (contiguous)
        kmax = min(w_max, i, h - 1 - i)
        best[:] = zero
        x = img[i]
        for k in range(1, kmax + 1):
            up = img[i - k]
            dn = img[i + k]
            for j in range(w):
                du = up[j] - x[j]
                dd = dn[j] - x[j]
                same = ((du > 0) == (dd > 0)) and ((du < 0) == (dd < 0))  # np.sign(du) == np.sign(dd)
                r = half * (up[j] + dn[j]) - x[j]
                if same and abs(r) > abs(best[j]):
                    best[j] = r
        for j in range(w):
            if abs(best[j]) > top_abs[j]:
                top_abs[j] = abs(best[j])
                vals[j] = best[j]
                rows[j] = i
    return rows, vals


@njit(cache=True, nogil=True)
def block_mean(frame, f):
    """``frame[:h // f * f, :w // f * f]`` averaged over f x f blocks, as float32 (sums in float64)."""
    h, w = frame.shape[0] // f, frame.shape[1] // f
    out = np.zeros((h, w), np.float32)
    acc = np.zeros(w)
    inv = 1.0 / (f * f)
    for bi in range(h):
        acc[:] = 0.0
        for r in range(bi * f, bi * f + f):
            row = frame[r]
            # each row's f samples summed left to right, then added to the block's sum (the order of the
            # general loop; the unrolled f = 2 and 4, the usual factors, run 3-5x faster)
            if f == 2:
                for bj in range(w):
                    acc[bj] += np.float64(row[2 * bj]) + np.float64(row[2 * bj + 1])
            elif f == 4:
                for bj in range(w):
                    c = 4 * bj
                    acc[bj] += ((np.float64(row[c]) + np.float64(row[c + 1])) + np.float64(row[c + 2])
                                + np.float64(row[c + 3]))
            else:
                for bj in range(w):
                    s = 0.0
                    for c in range(bj * f, bj * f + f):
                        s += row[c]
                    acc[bj] += s
        for bj in range(w):
            out[bi, bj] = acc[bj] * inv
    return out


@njit(cache=True, nogil=True)
def _signed_into(prof, polarity, q):
    """``q = polarity * -prof``, each row's non-finite samples -> its finite median (0 if none); ``q`` may be prof."""
    n, k = prof.shape
    bad = False
    for i in range(n):
        for j in range(k):
            q[i, j] = -polarity * prof[i, j]
            if not np.isfinite(q[i, j]):
                bad = True
    if bad:
        fill_rows_nanmedian(q)
    return q


@njit(cache=True, nogil=True)
def signed_profiles(prof, polarity):
    """``polarity * -prof`` (the band high), each row's non-finite samples -> its finite median (0 if none)."""
    return _signed_into(prof, polarity, np.empty(prof.shape))



def compiled_on_disk():
    """Whether the tracer's largest kernels are in numba's disk cache (False: the first extraction compiles them).

    A heuristic on numba's cache index files (one per function); True when it
    cannot tell.
    """
    try:
        from pathlib import Path

        return all(Path(f._cache._cache_file._index_path).exists()
                   for f in (robust_profile_spline, clean_stations, _guide_stations, dusty_rows, revolution_halves))
    except Exception:  # noqa: BLE001 - numba internals: never fail an extraction over a progress message
        return True
