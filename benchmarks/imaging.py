"""Benchmark: image extraction accuracy per nuisance, speed vs reading, memory vs series length (issue 4).

Run with ``python benchmarks/imaging.py [--quick] [--frames 500]``.

1. **Accuracy** on synthetic series of the paper's reference chamber
   (a = 200 um, h = 110 um, l0 = 20 um; 1 um/px, 1024 x 1024 frames, rim
   pre-stretch 1 + 0.01 Vtilde) over Vtilde = 0 .. 7, one row per nuisance and
   one with all of them: the largest profile RMS error (px, distance of the
   true midline from the traced curve), volume error (relative; a 0.5 px layer
   over the well counts as the floor -- the column "dV/tol" must stay <= 1),
   area-ratio error, rim-radius error (px), and frames flagged as rendered.
   Targets: RMS < 0.5 px, dV/tol <= 1, dA < 2 %, dR < 0.5 px, over the frames
   rendered without an event (a neighbour's bulge may touch in late frames:
   those must be flagged, their figures are not counted).  One more row
   renders delaminated, fractured (gap and collapsed) and touching frames and
   counts the flags that match.  The same figures follow for series that grow
   as filmed (40 frames), where almost every frame is tracked from the last two.
2. **Speed**: a multi-page 16-bit 1024 x 1024 TIFF of a series that grows as
   filmed (Vtilde 0 -> 5 over the ``--speed-frames`` frames, slow start, 1 %
   noise, 1 px drift per frame) read frame by frame with
   :func:`osmobulge.imaging.io.open_series` (page cache warm; median of 3
   passes) versus :func:`osmobulge.imaging.extract` on the same file (median
   of 3), single core; once more with the file evicted from the page cache
   before each pass (``posix_fadvise``), and for folders of TIFF and PNG
   files.  The first call in a process, which loads the numba kernels from
   their disk cache (compiling them takes about 45 s once on a new machine),
   is timed apart (on a 3-frame TIFF: a memory-mapped file's frames are
   read-only arrays, whose kernels are loaded apart), and so is how each
   frame was traced (``track``:
   from the prediction of the last two frames; ``guide``: wide search;
   ``global``: from scratch).  Target: extraction no slower than 5x reading
   (judged against osmobulge's reader; tifffile's own page-by-page read of
   the same file is printed for reference).
   ``--sweep N`` adds the worst figures over N seeds per nuisance (small chamber):
   seed-dependent failures (a speck of dust in the wrong place) show there.
   The same read-versus-extract figures follow for the silhouette route
   (``--look-frames`` frames of optics-rendered looks, :mod:`osmobulge.imaging.looks`,
   0.8 um/px, Vtilde 0 -> 4 with the flat frame first, written to a TIFF and
   extracted with the ``Chamber`` given, as ``benchmarks/looks.py`` does).
   Target there (issue 16): extraction no slower than 10x reading.  ``--day LOOK`` measures a day's
   series: 97 frames every 15 min (the reference chamber's growth scaled to Vtilde 4 at 24 h) of that
   look, read and extracted from each kind of file.
3. **Memory**: peak traced heap (tracemalloc, numpy buffers included) of
   ``extract`` on a 100- and a 500-frame TIFF cycling through 40 frames of that
   series.  Target: flat in the number of frames.

BLAS/OpenMP are pinned to one thread and the process to one CPU where allowed.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS",
             "VECLIB_MAXIMUM_THREADS", "BLIS_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import tifffile  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from osmobulge.imaging._chamber import FrameView  # noqa: E402
from osmobulge.imaging.extract import extract  # noqa: E402
from osmobulge.imaging.io import open_series, write_series  # noqa: E402
from osmobulge.imaging.looks import render_look  # noqa: E402
from osmobulge.imaging.synthetic import Nuisances, render_series  # noqa: E402
from osmobulge.imaging.trace import trace_series  # noqa: E402
from osmobulge.modeling import PreStretch  # noqa: E402
from osmobulge.modeling.transport import Chamber  # noqa: E402

REF = (200e-6, 110e-6, 20e-6)
PRE = PreStretch(0.01, 0.0)
VT = [0.0, 0.05, 0.3, 0.67, 1.5, 3.0, 5.0, 7.0]
NUISANCES = {
    "clean (16-bit, blur 1 px)": Nuisances(),
    "inverted contrast": Nuisances(polarity=-1),
    "low contrast (x0.3)": Nuisances(contrast=0.3, noise_sigma=0.01),
    "illumination gradient 0.4 + vignetting 0.3": Nuisances(illumination_gradient=0.4, vignetting=0.3),
    "8-bit": Nuisances(bit_depth=8),
    "noise 3 % + shot noise": Nuisances(noise_sigma=0.03, poisson_photons=2000),
    "blur 2.5 px": Nuisances(blur_sigma=2.5),
    "tilt -4 deg": Nuisances(tilt=-4.0),
    "drift 6 px/frame": Nuisances(drift_sigma=6.0),
    "dust 40 specks": Nuisances(dust_count=40, dust_opacity=0.5),
    "neighbours (2, one touching at Vtilde >= 5)": Nuisances(neighbours=((560e-6, 0.4), (-560e-6, 0.15))),
    "all of the above": Nuisances(polarity=-1, contrast=0.6, illumination_gradient=0.3, vignetting=0.2, bit_depth=8,
                                  noise_sigma=0.02, poisson_photons=3000, blur_sigma=1.5, tilt=3.0, drift_sigma=4.0,
                                  dust_count=30, neighbours=((560e-6, 0.4),)),
}


def _pin_one_cpu():
    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
        return "pinned to 1 CPU"
    except (AttributeError, OSError):
        return "not pinned"


def frame_errors(series, tracer, traces):
    """Profile RMS (px), dV/tol, |dA|/A, |dR| (px) per frame."""
    tr = series.truth
    p = tr.attrs["pixel_size"]
    a = tr.attrs["chamber_radius"] / p
    rows = []
    for i, r in enumerate(traces):
        t = tr.isel(time=i)
        if r.geometry is None or not len(r.u):
            rows.append((np.nan, np.nan, np.nan, np.nan))
            continue
        v = FrameView(series.frames[i], tracer.k)
        pts = r.geometry.line.point(r.u, r.z)
        rr, cc = v.to_frame(pts[:, 0], pts[:, 1])
        sd = np.r_[0, np.cumsum(np.hypot(np.diff(cc), np.diff(rr)))]
        si = np.arange(0, sd[-1], 0.05)
        d, _ = cKDTree(np.c_[np.interp(si, sd, cc), np.interp(si, sd, rr)]).query(
            np.c_[t.midline_col.values.ravel(), t.midline_row.values.ravel()])
        v_true = float(t.volume) / p**3
        tol = max(0.02 * v_true, 0.5 * np.pi * (float(t.rim_radius) / p) ** 2)
        rows.append((float(np.sqrt(np.mean(d**2))), abs(r.volume - v_true) / tol,
                     abs(r.area / (np.pi * a * a) / float(t.area_ratio) - 1), abs(r.geometry.rim_radius
                                                                              - float(t.rim_radius) / p)))
    return np.array(rows)


def accuracy(quick):
    print("\n## Accuracy per nuisance (reference chamber, 1 um/px, 1024 x 1024, Vtilde = 0 .. 7)\n")
    head = (f"| {'nuisance':44s} | RMS px | dV/tol | dA %  | dR px | flags ok | s/frame |\n"
            f"|{'-' * 46}|--------|--------|-------|-------|----------|---------|")
    print(head)
    vt = VT[::2] + [VT[-1]] if quick else VT
    for name, nu in NUISANCES.items():
        s = render_series(vt, chamber=REF, lambda_pre=PRE, nuisances=nu, seed=7)
        t0 = time.perf_counter()
        tracer, traces = trace_series(s.frames)
        dt = (time.perf_counter() - t0) / len(vt)
        e = frame_errors(s, tracer, traces)
        ok = sum(r.flag == f for r, f in zip(traces, s.truth.flag.values, strict=True))
        good = s.truth.flag.values == "ok"  # accuracy over the frames rendered without an event
        good_a = good & (np.asarray(vt) > 0)
        print(f"| {name:44s} | {np.nanmax(e[good, 0]):6.3f} | {np.nanmax(e[good, 1]):6.3f} |"
              f" {100 * np.nanmax(e[good_a, 2]):5.2f} | {np.nanmax(e[good, 3]):5.3f} | {ok:3d}/{len(vt):<4d} |"
              f" {dt:7.3f} |")
    # the same figures on series that grow as filmed (small steps: almost every frame is tracked)
    print("\n## Tracked series (40 frames, Vtilde 0 .. 5, slow start): worst frame, and how frames were traced\n")
    print(head.replace("s/frame |", "modes   |"))
    vt_f = np.linspace(0.0, 5.0, 20 if quick else 40) ** 1.5 / 5.0**0.5
    for name in ("clean (16-bit, blur 1 px)", "low contrast (x0.3)", "noise 3 % + shot noise", "drift 6 px/frame",
                 "dust 40 specks", "all of the above"):
        s = render_series(vt_f, chamber=REF, lambda_pre=PRE, nuisances=NUISANCES[name], seed=17)
        tracer, traces = trace_series(s.frames)
        e = frame_errors(s, tracer, traces)
        ok = sum(r.flag == f for r, f in zip(traces, s.truth.flag.values, strict=True))
        # figures over the frames both the truth and the tracer call ok (a dome within the 2.5 px touching
        # threshold of a neighbour's is flagged although the rendered bands do not overlap yet)
        good = (s.truth.flag.values == "ok") & np.array([r.flag == "ok" for r in traces])
        good_a = good & (vt_f > 0)
        n_track = sum(r.mode == "track" for r in traces)
        print(f"| {name:44s} | {np.nanmax(e[good, 0]):6.3f} | {np.nanmax(e[good, 1]):6.3f} |"
              f" {100 * np.nanmax(e[good_a, 2]):5.2f} | {np.nanmax(e[good, 3]):5.3f} | {ok:3d}/{len(vt_f):<4d} |"
              f" {n_track:2d} track |")
    nu = Nuisances(neighbours=((560e-6, 0.2),), delaminated_frames=(1, 5), fractured_frames=(2, 6),
                   touching_frames=(3, 7))
    v = [0.0, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.5]
    s = render_series(v, chamber=REF, lambda_pre=PRE, nuisances=nu, seed=8)
    _, traces = trace_series(s.frames)
    got = [r.flag for r in traces]
    want = list(s.truth.flag.values)
    s2 = render_series([0.0, 1.0, 2.0], chamber=REF, nuisances=Nuisances(fractured_frames=(1, 2),
                                                                          fracture_mode="collapsed"), seed=9)
    _, tr2 = trace_series(s2.frames)
    got += [r.flag for r in tr2]
    want += list(s2.truth.flag.values)
    n_ok = sum(a == b for a, b in zip(got, want, strict=True))
    print(f"\nEvent frames (delaminated, fractured gap/collapsed, touching): {n_ok}/{len(want)} flags right")
    print("  rendered: " + " ".join(want))
    print("  flagged:  " + " ".join(got))


def sweep(n_seeds):
    """Worst figures over many seeds (small chamber, a = 100 um, 16 frames as filmed): finds seed-dependent failures."""
    small = {"chamber": (100e-6, 50e-6, 10e-6), "shape": (420, 440), "pixel_size": 1e-6}
    vt = np.linspace(0.0, 3.0, 16) ** 1.5 / 3.0**0.5
    print(f"\n## Seed sweep: {n_seeds} seeds per nuisance, small chamber, 16 frames as filmed\n")
    print("| nuisance | worst RMS px | worst dV/tol | worst dA % | worst dR px | series failing |")
    print("|---|---|---|---|---|---|")
    for name, nu in NUISANCES.items():
        if nu.neighbours:  # the reference field's neighbours do not fit the small field
            if name != "all of the above":
                continue
            name, nu = "all of the above, no neighbour", replace(nu, neighbours=())
        worst, fails = np.zeros(4), []
        for seed in range(n_seeds):
            s = render_series(vt, chamber=small["chamber"], shape=small["shape"], pixel_size=1e-6,
                              lambda_pre=PreStretch(0.015, 0.0), nuisances=nu, seed=100 + seed)
            try:
                tracer, traces = trace_series(s.frames)
            except ValueError:  # the chamber not found in the first frame
                fails.append(100 + seed)
                continue
            flags_ok = [r.flag for r in traces] == list(s.truth.flag.values)
            if not all(r.geometry is not None and len(r.u) for r in traces):
                fails.append(100 + seed)
                continue
            e = frame_errors(s, tracer, traces)
            w = np.nanmax(e[s.truth.flag.values == "ok"], axis=0)
            worst = np.fmax(worst, w)
            if not (flags_ok and w[0] < 0.5 and w[1] <= 1 and w[2] < 0.02 and w[3] < 0.5):
                fails.append(100 + seed)
        print(f"| {name} | {worst[0]:.3f} | {worst[1]:.3f} | {100 * worst[2]:.2f} | {worst[3]:.3f} |"
              f" {len(fails)}/{n_seeds} {fails if fails else ''} |")


def _write_tiff(path, frames_iter, pixel_size, interval):
    import tifffile

    with tifffile.TiffWriter(path, bigtiff=True) as tw:
        for f in frames_iter:
            tw.write(f, contiguous=True, resolution=(1e-2 / pixel_size, 1e-2 / pixel_size),
                     resolutionunit="CENTIMETER", metadata=None)
    return path


def _drop_cache(path):
    """Evict a file from the page cache (its next read comes from the disk)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
        os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    finally:
        os.close(fd)


def _series_file(folder, n, base):
    """A TIFF of n 1024x1024 16-bit frames cycling through the rendered base frames (growth then repeat)."""
    path = Path(folder) / f"series_{n}.tif"
    return _write_tiff(path, (base[i % len(base)] for i in range(n)), 1e-6, 600.0)


def _frame_copy(frames):
    """Median over 3 passes of the time (ms per frame) to copy every frame of ``frames`` (an array in memory) into
    a fresh array, and its bandwidth (GB/s): the least a read of the frames from the page cache costs (the series
    is larger than the caches, so this is the memory's bandwidth)."""
    frames = np.asarray(frames)
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        for f in frames:
            np.array(f)
        times.append((time.perf_counter() - t0) / len(frames))
    t = float(np.median(times))
    return 1e3 * t, frames[0].nbytes / t / 1e9


def _median_pass(fn, n, before=None):
    """Median over 3 passes of ``fn()``'s time per frame (s, over ``n`` frames), and its last result;
    ``before()`` (untimed) runs ahead of each pass."""
    times = []
    for _ in range(3):
        if before is not None:
            before()
        t0 = time.perf_counter()
        out = fn()
        times.append((time.perf_counter() - t0) / n)
    return float(np.median(times)), out


def _read_all(path):
    """Every frame of the series at ``path`` read once with osmobulge's reader."""
    ser = open_series(path, frame_interval=600.0)
    for i in range(len(ser)):
        ser[i]
    ser.close()


def speed_and_memory(n_speed, n_mem, quick):
    print("\n## Speed (1024 x 1024 16-bit, one core) and memory\n")
    # the speed series grows as filmed (Vtilde 0 -> 5 over n_speed frames, e.g. every 15 min over a day);
    # the memory series cycles through 40 frames of it
    vt = np.linspace(0.0, 5.0, n_speed) ** 1.5 / 5.0**0.5  # slow start, as V/V0(t) of a real actuation
    base = render_series(vt, chamber=REF, lambda_pre=PRE, nuisances=Nuisances(noise_sigma=0.01, drift_sigma=1.0),
                         seed=3).frames
    with tempfile.TemporaryDirectory() as tmp:
        # the first call in a process loads (or compiles) the numba kernels: timed apart, on a 3-frame TIFF
        # (a memory-mapped file's frames are read-only arrays: kernels of their own, loaded on first use)
        first = _series_file(tmp, 3, base)
        t0 = time.perf_counter()
        extract(first, frame_interval=600.0, progress=False)
        t_first = time.perf_counter() - t0
        sources = {"multi-page TIFF (uncompressed, memory-mapped)": _series_file(tmp, n_speed, base)}
        if not quick:
            for fmt, label in (("tiff-folder", "folder of TIFF files"), ("png", "folder of 16-bit PNG files")):
                sources[label] = write_series(base, Path(tmp) / fmt, fmt=fmt, pixel_size=1e-6,
                                              timestamps=600.0 * np.arange(n_speed))
        print("| series | read ms/frame | extract ms/frame (incl. reading) | frames/s | extract / read | frames ok |")
        print("|---|---|---|---|---|---|")
        ratios, t_exts = {}, {}
        tiff = sources["multi-page TIFF (uncompressed, memory-mapped)"]
        if hasattr(os, "posix_fadvise"):
            sources["same TIFF, page cache dropped before each pass"] = tiff
        for label, path in sources.items():
            before = (lambda p=path: _drop_cache(p)) if label.startswith("same TIFF") else None
            t_read, _ = _median_pass(lambda p=path: _read_all(p), n_speed, before)
            t_ext, ds = _median_pass(lambda p=path: extract(p, frame_interval=600.0, progress=False), n_speed,
                                     before)
            ratios[label] = t_ext / t_read
            t_exts[label] = t_ext
            print(f"| {label} | {1e3 * t_read:.2f} | {1e3 * t_ext:.2f} | {1 / t_ext:.0f} | {t_ext / t_read:.1f}x |"
                  f" {int((ds.flag == 'ok').sum())}/{n_speed} |")
        # for reference: the same file read page by page with tifffile's own decoder (what a script would do)
        def tifffile_read():
            with tifffile.TiffFile(tiff) as tf:
                for page in tf.pages:
                    page.asarray()

        t_tf, _ = _median_pass(tifffile_read, n_speed)
        t_mp = t_exts["multi-page TIFF (uncompressed, memory-mapped)"]
        modes = {}
        _, traces = trace_series(base)
        for r in traces:
            modes[r.mode or "-"] = modes.get(r.mode or "-", 0) + 1
        print(f"\nreads: median of 3 passes, page cache warm (except the dropped row: posix_fadvise DONTNEED before"
              f" each pass; on a VM whose disk the host caches that is not a real disk figure); extractions: median"
              f" of 3 passes as well.  A read copies every frame; the extraction samples a memory-mapped"
              f" TIFF in place (FrameSeries.peek) and touches only the pages it samples.\n"
              f"first extract call in a process (numba kernels loaded from cache or compiled): {t_first:.2f} s; "
              f"how frames were traced: {modes}")
        print(f"for reference, tifffile reading the multi-page TIFF page by page (TiffFile.pages[i].asarray()): "
              f"{1e3 * t_tf:.2f} ms/frame; the TIFF extraction is {t_mp / t_tf:.1f}x that"
              f" (the target is judged against osmobulge's own, faster reader above)")
        print("target: extraction no slower than 5x reading -- "
              + "; ".join(f"{k}: {'met' if v <= 5 else 'NOT met'} ({v:.1f}x)" for k, v in ratios.items()))
        rows = []
        for n in (100, n_mem):
            p = _series_file(tmp, n, base[:: max(1, len(base) // 40)])
            tracemalloc.start()
            t0 = time.perf_counter()
            extract(p, frame_interval=600.0, progress=False)
            el = time.perf_counter() - t0
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
            rows.append((n, peak / 2**20, el))
            os.remove(p)
        print("\n| frames | peak traced heap MiB | time s |\n|---|---|---|")
        for n, mib, el in rows:
            print(f"| {n} | {mib:.1f} | {el:.1f} |")
        print(f"\npeak({n_mem}) / peak(100) = {rows[1][1] / rows[0][1]:.2f} (target: ~1, flat in the frames; "
              f"the frames alone would be {n_mem * 2:.0f} MiB)")


def _tracer_times(frames, chamber, px):
    """The silhouette tracer alone on in-memory frames, best of 3 passes: its setup on the first frame (s), and
    per frame the time (s) and whether its dome was searched for (not tracked)."""
    from osmobulge.imaging._facetrace import SilhouetteTracer

    l0_px, depth_px = chamber.thickness / px, chamber.depth / px
    setup, per_frame, searched = np.inf, None, None
    for _ in range(3):
        t0 = time.perf_counter()
        tr = SilhouetteTracer(frames[0], l0_px=l0_px, depth_px=depth_px)
        setup = min(setup, time.perf_counter() - t0)
        ts, ss = [], []
        for i, f in enumerate(frames):
            n = tr.searches
            t0 = time.perf_counter()
            tr.process(f, i)
            ts.append(time.perf_counter() - t0)
            ss.append(tr.searches > n)
        per_frame = np.array(ts) if per_frame is None else np.minimum(per_frame, ts)
        searched = np.array(ss)
    return setup, per_frame, searched


def _write_czi(path, frames, pixel_size, compression=None):
    """The frames as a CZI file (pylibCZIrw; None when it is not installed), one T plane each."""
    try:
        from pylibCZIrw import czi as pyczi
    except ImportError:
        return None
    kw = {} if compression is None else {"compression_options": compression}
    with pyczi.create_czi(str(path), exist_ok=True, **kw) as w:
        for t, f in enumerate(frames):
            w.write(data=np.asarray(f)[..., None], plane={"T": t, "Z": 0, "C": 0})
        w.write_metadata(scale_x=pixel_size, scale_y=pixel_size)
    return path


#: the CZI files the silhouette route's speed is also measured against: what the microscope (AxioObserver, ZEN)
#: writes, uncompressed or with ZEN's lossless zstd
CZI_KINDS = {"raw": None, "zstd": "zstd1:ExplicitLevel=1;PreProcess=HiLoByteUnpack"}


def silhouette_speed(n_frames, looks=("edge_dark", "defocus", "halo")):
    """Read vs extract per frame on optics-rendered looks written to a TIFF and to CZI files (the silhouette
    route)."""
    print(f"\n## Speed of the silhouette route (optics looks, {n_frames} frames, 1024 x 1024 16-bit, one core)\n")
    print("| look | route | TIFF read ms/frame (warm / dropped) | extract ms/frame (warm / dropped) |"
          " extract / read (warm / dropped) | CZI read ms/frame (raw / zstd) | extract from CZI / CZI read"
          " (raw / zstd) | frames ok | tracer setup s | tracked ms (median, max) | searched ms (median, n) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    vt = np.linspace(0.0, 4.0, n_frames) ** 1.5 / 2.0
    ratios = {}
    drop = hasattr(os, "posix_fadvise")
    with tempfile.TemporaryDirectory() as tmp:
        for name in looks:
            s = render_look(name, vt, lambda_pre=PRE)
            px = s.truth.attrs["pixel_size"]
            chamber = Chamber(*(s.truth.attrs[k] for k in ("chamber_radius", "chamber_depth",
                                                              "membrane_thickness")),
                              concentration=3000.0)  # mol/m**3 (3 M NaCl, as benchmarks/looks.py)
            path = _write_tiff(Path(tmp) / f"{name}.tif", list(s.frames), px, 600.0)

            def run(p=path, ch=chamber):
                return extract(p, chamber=ch, frame_interval=600.0, progress=False)

            run()  # (kernels loaded)
            t_read, _ = _median_pass(lambda p=path: _read_all(p), n_frames)
            t_ext, ds = _median_pass(run, n_frames)
            cold = ("", "", "")
            if drop:
                t_read_c, _ = _median_pass(lambda p=path: _read_all(p), n_frames, lambda p=path: _drop_cache(p))
                t_ext_c, _ = _median_pass(run, n_frames, lambda p=path: _drop_cache(p))
                cold = f" / {1e3 * t_read_c:.2f}", f" / {1e3 * t_ext_c:.2f}", f" / {t_ext_c / t_read_c:.1f}x"
            czi_read, czi_ratio = [], []
            for kind, comp in CZI_KINDS.items():
                czi = _write_czi(Path(tmp) / f"{name}_{kind}.czi", s.frames, px, comp)
                if czi is None:
                    continue
                t_cr, _ = _median_pass(lambda c=czi: _read_all(c), n_frames)
                t_ce, _ = _median_pass(lambda c=czi: run(c), n_frames)
                czi_read.append(f"{1e3 * t_cr:.2f}")
                czi_ratio.append(f"{t_ce / t_cr:.1f}x")
                ratios[f"{name}, CZI {kind}"] = t_ce / t_cr
            setup, per, searched = _tracer_times([np.asarray(f) for f in s.frames], chamber, px)
            tracked = per[~searched] if (~searched).any() else np.array([np.nan])
            sought = per[searched] if searched.any() else np.array([np.nan])
            ratios[f"{name}, warm TIFF"] = t_ext / t_read
            if drop:
                ratios[f"{name}, cold TIFF"] = t_ext_c / t_read_c
            print(f"| {name} | {ds.attrs['tracer']} | {1e3 * t_read:.2f}{cold[0]} | {1e3 * t_ext:.2f}{cold[1]} |"
                  f" {t_ext / t_read:.1f}x{cold[2]} | {' / '.join(czi_read) or '-'} | {' / '.join(czi_ratio) or '-'} |"
                  f" {int((ds.flag == 'ok').sum())}/{n_frames} | {setup:.2f} |"
                  f" {1e3 * np.median(tracked):.1f}, {1e3 * tracked.max():.1f} |"
                  f" {1e3 * np.median(sought):.1f}, {int(searched.sum())} |",
                  flush=True)
    print("\ndropped: the TIFF evicted from the page cache before each pass (posix_fadvise DONTNEED; on a VM whose"
          " host caches the disk that is not a real disk figure). CZI: the same frames written by pylibCZIrw,"
          " uncompressed and zstd (ZEN's lossless option), read and extracted with osmobulge's CZI reader"
          " (aicspylibczi); the extraction includes the reading. Tracer columns: SilhouetteTracer alone on the"
          " frames in memory (best of 3 passes). A day's series is measured by --day LOOK (97 frames; an"
          " estimate from these columns would leave out the reading and extract's own work per frame, and the"
          " tracked frames' cost grows with the dome)")
    print("target (issue 16): extraction no slower than 10x reading -- "
          + "; ".join(f"{k}: {'met' if v <= 10 else 'NOT met'} ({v:.1f}x)" for k, v in ratios.items()))


def day_vtilde(n_day=97, interval=900.0):
    """Vtilde of a day's series filmed every ``interval`` s: the paper's reference PDMS chamber's growth
    (:func:`osmobulge.modeling.simulate`), scaled to reach the issue's Vtilde 4 at its last frame (a chamber a
    little slower than the reference, which passes 4 at 17.5 h)."""
    from osmobulge.modeling import DoubleExponential, paper_chamber, simulate
    from osmobulge.modeling.materials import PDMS

    t = np.arange(n_day) * interval
    v = simulate(paper_chamber("reference"), PDMS, DoubleExponential.PDMS, t).vtilde.values
    return t, 4.0 * v / v[-1]


def silhouette_day(name="edge_dark", n_day=97, series=None):
    """A day's series measured, not derived: ``n_day`` frames every 15 min (:func:`day_vtilde`) of one optics look,
    read and extracted from a TIFF (warm and dropped page cache) and from raw and zstd CZI files, with its
    accuracy against the truth (rendering takes about 6 s a frame; ``series``: an already rendered one)."""
    from osmobulge.imaging.looks import score

    t, vt = day_vtilde(n_day)
    s = render_look(name, vt, lambda_pre=PRE, times=t) if series is None else series
    px = s.truth.attrs["pixel_size"]
    chamber = Chamber(*(s.truth.attrs[k] for k in ("chamber_radius", "chamber_depth", "membrane_thickness")),
                      concentration=3000.0)
    n = len(s.frames)
    print(f"\n## A day's series measured ({name}, {n} frames every 15 min, Vtilde 0 -> 4, 1024 x 1024 16-bit,"
          f" one core)\n")
    print("| read from | read ms/frame | extract ms/frame | extract / read |")
    print("|---|---|---|---|")
    ratios = {}
    with tempfile.TemporaryDirectory() as tmp:
        sources = {"TIFF, warm": _write_tiff(Path(tmp) / f"{name}.tif", list(s.frames), px, 900.0)}
        for kind, comp in CZI_KINDS.items():
            czi = _write_czi(Path(tmp) / f"{name}_{kind}.czi", s.frames, px, comp)
            if czi is not None:
                sources[f"CZI, {kind}"] = czi

        def run(p):
            return extract(p, chamber=chamber, frame_interval=900.0, progress=False)

        ds = run(sources["TIFF, warm"])  # (kernels loaded)
        passes = [(k, p, None) for k, p in sources.items()]
        if hasattr(os, "posix_fadvise"):
            tiff = sources["TIFF, warm"]
            passes.insert(1, ("TIFF, dropped", tiff, lambda p=tiff: _drop_cache(p)))
        for label, path, before in passes:
            t_read, _ = _median_pass(lambda p=path: _read_all(p), n, before)
            t_ext, _ = _median_pass(lambda p=path: run(p), n, before)
            ratios[label] = t_ext / t_read
            print(f"| {label} | {1e3 * t_read:.2f} | {1e3 * t_ext:.2f} | {t_ext / t_read:.1f}x |", flush=True)
    copy_ms, gbs = _frame_copy(s.frames)
    print(f"\na warm TIFF read is a copy of each frame out of the page cache: copying the frames from memory alone"
          f" takes {copy_ms:.2f} ms a frame here ({gbs:.1f} GB/s), so the warm ratio follows this machine's memory"
          f" bandwidth (docs/architecture.md: the same code 12x on a machine whose warm read took 0.50 ms)")
    sc = score(s.truth, ds)
    print(f"\nfrom the TIFF: {int((ds.flag == 'ok').sum())}/{n} frames ok, {sc['n_silent']} silent, worst volume"
          f" error {sc['worst_dv_tol']:.2f} of the tolerance, worst rim bias"
          f" {np.nanmax(np.abs(sc['rim_bias_px'])):.2f} px")
    print("target (issue 16): extraction no slower than 10x reading -- "
          + "; ".join(f"{k}: {'met' if v <= 10 else 'NOT met'} ({v:.1f}x)" for k, v in ratios.items()))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer volumes and frames")
    ap.add_argument("--frames", type=int, default=500, help="frames of the long series of the memory test")
    ap.add_argument("--speed-frames", type=int, default=100, help="frames of the speed test")
    ap.add_argument("--look-frames", type=int, default=25,
                    help="frames of each optics look of the silhouette route's speed test (0: skip it)")
    ap.add_argument("--day", metavar="LOOK", default=None,
                    help="also a day's series of this optics look measured (97 frames, about 10 min to render)")
    ap.add_argument("--skip-accuracy", action="store_true")
    ap.add_argument("--skip-speed", action="store_true", help="skip the speed and memory part")
    ap.add_argument("--sweep", type=int, default=0, metavar="N",
                    help="also the worst figures over N seeds per nuisance (small chamber; about 1.5 s a series)")
    args = ap.parse_args()
    print(f"# osmobulge imaging benchmark ({_pin_one_cpu()}; load average {os.getloadavg()[0]:.2f})")
    if not args.skip_accuracy:
        accuracy(args.quick)
    if args.sweep:
        sweep(args.sweep)
    if not args.skip_speed:
        speed_and_memory(args.speed_frames, 200 if args.quick else args.frames, args.quick)
        if args.look_frames:
            silhouette_speed(args.look_frames)
        if args.day:
            silhouette_day(args.day)


if __name__ == "__main__":
    main()
