r"""From a micrograph series to a dataset of bulge profiles, volumes, areas and rim radii.

:func:`extract` runs the frame-by-frame tracer (:mod:`osmobulge.imaging.trace`)
over a series read lazily (one frame in memory at a time) and returns one
:class:`xarray.Dataset` in SI units with CF-style ``units``/``long_name``
attributes, the input of the permeability fits.  :func:`save_extraction` /
:func:`load_extraction` write and read it (netCDF via h5netcdf, or zarr v3)
without loss.

Volumes are the water added: the solid of revolution of the dome about the
chamber axis, above the membrane's own flat position (the midline of the band
on the base's top surface, measured in every frame), not relative to the first
frame (main text Sec. 2.3, 3.1).  With a chamber :math:`(a, h)`,
:math:`\tilde V = \Delta V/(\pi a^3)` and :math:`V/V_0 = 1 + \Delta V/(\pi a^2 h)`
(main text Eqn 4).
"""

from __future__ import annotations

import os
import tempfile
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import xarray as xr

from osmobulge import __version__
from osmobulge.imaging._chamber import ChamberNotFound, FrameView
from osmobulge.imaging._kernels import arc_resample, compiled_on_disk, ellipse_arc_volume, stored_profile_ellipse
from osmobulge.imaging.geometry import fit_ellipse
from osmobulge.imaging.trace import FLAGS, ChamberTracer, TraceSettings

__all__ = ["extract", "series_gates", "stack_chambers", "save_extraction", "load_extraction", "ERRORS", "FLAGS"]

ERRORS = ("flag", "raise")
_DIRECTIONS = ("auto", "up", "down", "left", "right")
_FIGURES = {
    "residual_rms": ("m", "RMS distance of the traced points from the profile spline"),
    "volume_disagreement": ("1", "|V_left - V_right| / max(V, 5 px layer over the well)"),
    "dome_contrast": ("1", "median band contrast along the dome / flat band contrast"),
    "gap_length": ("1", "longest run without membrane along the dome / membrane thickness"),
    "rim_contact": ("1", "membrane on the surface just outside the rims (1 = on it, 0 = lifted)"),
    "neighbour_gap": ("m", "gap between the dome and another (neighbour's) membrane"),
    "edge_jumps": ("1", "silhouette route: fraction of rays whose outer-face edge jumped from its neighbours'"),
    "edge_lost": ("1", "silhouette route: fraction of rays over the dome without an outer-face edge"),
    "least_bend": ("1", "silhouette route: the outer face's least bend over 10 % of its arc over its mean bend "
                          "(1: a circle; 0: a straight stretch, as a cap torn off leaves)"),
    "light_gain": ("1", "silhouette route: the base's mean light over the first frame's (the lamp, the exposure; "
                        "a frame more than 5 % off is divided by it before it is read)"),
    "clipped": ("m", "band route: how far the walls move (the larger) when the pixels at the camera's clip level "
                     "(its full scale, held by 3 or more of them) are read 1.25x brighter: the rim's dependence on "
                     "light the frame did not record (0: no clipped pixel at the walls)"),
    "clipped_share": ("1", "silhouette route: the share of the pixels within 3 px of a wall (the larger wall) the "
                           "camera clipped, in this frame or the first, in a frame with more of the walls' light "
                           "clipped than the first (its walls read on the rows no clipped pixel can have moved, or "
                           "with too few of those by matching the first frame's profile across them over the "
                           "pixels recorded); 0 in the others"),
    "wall_misfit": ("1", "silhouette route, walls matched to the first frame's profile (light clipped over most of "
                         "their rows): the misfit of the window read over the least of its two windows' (the wall's "
                         "neighbourhood, and 20 px either side), the larger wall's; over 1.25 the read is flagged "
                         "(poor_fit): the light inside the well changed and the wall's own window gave no straight "
                         "line; 1 when read by their half level"),
    "light_tilt": ("1", "silhouette route: how much the light changed across the view since the first frame (the "
                        "range of a plane through the water's change; divided out of a frame whose noise it raised "
                        "by over 25 %)"),
}

#: the quality figures that are lengths: a tracer gives them in px, the dataset in m (``flag_value`` too)
_LENGTH_FIGURES = frozenset(k for k, (unit, _) in _FIGURES.items() if unit == "m") | {
    "field_margin", "flat_lift", "flat_film", "low_dome", "wall_rms", "line_rms"}

#: how the chamber and dome are read: ``band`` (filled membrane band, grey step between well and base) or
#: ``silhouette`` (faces and walls seen by the light they bend away, any look; imaging._facetrace)
TRACERS = ("auto", "band", "silhouette")


# ------------------------------------------------------------------------------------ sources
class _ArraySource:
    """Frames already in memory (used only when :mod:`osmobulge.imaging.io` is unavailable)."""

    def __init__(self, frames, pixel_size, timestamps):
        self.frames = frames
        self.pixel_size = pixel_size
        self.timestamps = timestamps
        self.source = "array"
        self.bad_frames = []
        self.attrs = {}

    def __len__(self):
        return len(self.frames)

    def __getitem__(self, i):
        return np.asarray(self.frames[i])


def _open(source, pixel_size, frame_interval):
    """Open the series lazily: :func:`osmobulge.imaging.io.open_series` checks pixel size and times."""
    if pixel_size is not None and not (np.isfinite(pixel_size) and 1e-9 <= float(pixel_size) <= 1e-3):
        raise ValueError(f"pixel_size must be in [1e-9, 1e-3] m/px, got {pixel_size!r}")
    if frame_interval is not None and not (np.isfinite(frame_interval) and frame_interval > 0):
        raise ValueError(f"frame_interval must be > 0 s, got {frame_interval!r}")
    try:
        from osmobulge.imaging.io import open_series
    except ImportError:  # pragma: no cover - the readers are another module's
        open_series = None
    if open_series is not None:
        return open_series(source, pixel_size=pixel_size, frame_interval=frame_interval)
    if isinstance(source, str | os.PathLike):  # pragma: no cover
        raise NotImplementedError("reading files needs osmobulge.imaging.io")
    arr = np.asarray(source)
    if arr.ndim != 3:
        raise ValueError(f"source array must have shape (T, H, W), got {arr.shape}")
    if pixel_size is None:
        raise ValueError("pixel size unknown: the frames carry none, pass pixel_size= (m/px)")
    if frame_interval is None:
        raise ValueError("frame times unknown: the frames carry none, pass frame_interval= (s)")
    return _ArraySource(arr, float(pixel_size), np.arange(len(arr)) * float(frame_interval))


def _chamber_attrs(chamber):
    if chamber is None:
        return {}
    for k in ("radius", "depth", "thickness"):
        v = getattr(chamber, k, None)
        if v is None or not np.isfinite(float(v)) or float(v) <= 0:
            raise ValueError(f"chamber.{k} must be a positive length in m, got {v!r}")
        if float(v) >= 0.1:
            raise ValueError(f"chamber.{k}={v!r} is not a plausible length in m (give metres)")
    if hasattr(chamber, "to_attrs"):
        return {k: float(v) for k, v in chamber.to_attrs().items()}
    out = {"chamber_radius": float(chamber.radius), "chamber_depth": float(chamber.depth),
           "membrane_thickness": float(chamber.thickness)}
    for k in ("concentration", "feed_concentration", "temperature", "vant_hoff"):
        if getattr(chamber, k, None) is not None:
            out[k] = float(getattr(chamber, k))
    return out


def _safe_attrs(d, prefix=""):
    """Flatten a mapping into netCDF-safe attrs (no dicts, no None, no bools)."""
    out = {}
    for k, v in (d or {}).items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(_safe_attrs(v, key + "_"))
        elif v is None:
            out[key] = "none"
        elif isinstance(v, bool | np.bool_):
            out[key] = int(v)
        elif isinstance(v, str | int | float | np.integer | np.floating):
            out[key] = v
        elif isinstance(v, list | tuple | np.ndarray):
            arr = np.asarray(v)
            out[key] = arr if arr.dtype.kind in "iuf" else ", ".join(str(x) for x in np.ravel(arr))
        else:
            out[key] = str(v)
    return out


def _points_px(points_m, pixel_size, name):
    p = np.asarray(points_m, float)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 4:
        raise ValueError(f"{name} must be arrays of shape (N >= 4, 2) of (x, y) in m, got shape {p.shape}")
    return p / pixel_size  # (x=col, y=row) px


# ------------------------------------------------------------------------------------ extract
def extract(
    source,
    *,
    pixel_size=None,
    chamber=None,
    frame_interval=None,
    bulge_direction="auto",
    chamber_region=None,
    errors="flag",
    progress=True,
    priors=None,
    manual_profiles=None,
    metadata=None,
    settings=None,
    n_profile=201,
    fit_prestretch=True,
    reference_frame=None,
    tracer="auto",
    rim=None,
) -> xr.Dataset:
    r"""Extract bulge profiles, volumes, areas and rim radii from a micrograph series.

    Parameters
    ----------
    source : str, Path or ndarray of shape (T, H, W)
        A series file or folder (read lazily by :mod:`osmobulge.imaging.io`) or
        the frames themselves (8- or 16-bit or float).  The first frame must show
        the flat membrane (else see ``reference_frame``).
    pixel_size : float, m, optional
        Square pixel size; required when the source carries none; must agree
        with the file's value when both are given.
    chamber : Chamber, optional
        :class:`osmobulge.modeling.transport.Chamber` (or any object with
        ``radius``, ``depth``, ``thickness`` in m): gives :math:`a` and :math:`h`
        for ``vtilde``, ``volume_ratio`` and ``area_ratio`` (``lambda_pre`` is
        against the rim radius measured in the flat frame).
        Without it, :math:`a` is the rim radius and :math:`h` the well depth
        measured in the first frame.
    frame_interval : float, s, optional
        Time between frames when the source has no timestamps.
    bulge_direction : {"auto", "up", "down", "left", "right"}
        Direction the dome grows in the image.
    chamber_region : int, tuple of float or "all", optional
        Which well when several are in the field: index from the left in the
        bulge-up view, or ``(col0, col1)`` view columns holding its axis;
        default the most central well.  ``"all"``: every well whose two walls
        are in the field, traced side by side (each frame read once) and
        stacked along a ``chamber`` dimension (:func:`stack_chambers`); picked
        points go to the chamber they lie over (within 1.5 rim radii of its
        axis; points over no traced chamber are dropped with a warning).
    errors : {"flag", "raise"}
        A frame that cannot be measured is flagged ``no_membrane`` and kept
        ("flag"), or raises ("raise").
    progress : bool
        Show a progress bar (rich).
    priors : dict of int -> ndarray of shape (N, 2), optional
        Manual points ``(x, y)`` (m, image coordinates ``x = col * p``,
        ``y = row * p``) for some frames: the tracer starts from them in that
        frame and from the nearest one in frames where it has no good previous
        trace (the semi-automatic mode).
    manual_profiles : dict of int -> ndarray of shape (N, 2), optional
        Manual profiles (same coordinates, ordered along the curve from rim to
        rim) that replace the automatic trace of their frames
        (``profile_source = "manual"``); volume and area are computed from them.
    metadata : mapping, optional
        Experiment metadata stored in the attrs (flattened, netCDF-safe).
    settings : TraceSettings, optional
        Tracer tuning knobs (recorded in the attrs).
    n_profile : int
        Arc-length samples of the stored profile.
    fit_prestretch : bool
        Fit :math:`\lambda_{pre}(\tilde V)` (supplement Sec. 5.7) to the good frames.
    reference_frame : ndarray of shape (H, W), str or Path, optional
        The frame the chamber (flat line, rim, well) is found in, when the
        source's own first frame does not show the flat membrane: e.g. a later
        file of a series split into files, with the first file's first frame
        (an array, or an image or series file / folder whose first frame is
        used).  Same field of view (frame shape) and pixel size; the stage may
        have moved between the files by up to ``settings.max_drift`` px (the
        first frame is registered against it).  The rim radius and well depth
        of the reference (without ``chamber``) and the flat membrane's rim for
        :math:`\lambda_{pre}` come from it.
    tracer : {"auto", "band", "silhouette"}
        How the chamber and the dome are read.  ``"band"``: the membrane as a
        filled band and the well by its grey step against the base
        (:class:`~osmobulge.imaging.trace.ChamberTracer`).  ``"silhouette"``:
        the film and the walls by the light their faces bend away, whatever
        their look (edge-only faces of either sign, halos, defocus, well and
        base at one grey; :mod:`osmobulge.imaging._facetrace`): the outer face
        traced as the change since the flat first frame, the mid-surface half
        the film's thickness inside it; one upright chamber (no
        ``chamber_region``), thickness from ``chamber`` or measured from the
        flat film's two faces.  ``"auto"``: the band route, and the
        silhouette route when the band route finds no chamber, cannot read
        its own (flat) first frame, or (with ``chamber`` given) finds a rim
        more than ``ROUTE_RIM_TOL`` (10 %) off the chamber's radius while the
        silhouette route's is within it (a lightly dyed film's band is not
        the well).  The route taken is the ``tracer`` attr.
    rim : array_like of shape (2, 2), optional
        The chamber's rim in the flat (first or reference) frame when the
        automatic search fails: the flat membrane's mid-line ends at the two
        walls, ``(x, y)`` in m (``x = col * p``, ``y = row * p``; e.g. the
        ends of a flat profile picked in napari), within a few px.  The
        silhouette route then measures the top face and walls there instead
        of searching the frame (``tracer="auto"`` or ``"silhouette"``).

    Returns
    -------
    xarray.Dataset
        Over ``time`` (s; coordinate ``frame``), ``chamber`` (with
        ``chamber_region="all"``) and ``s`` (arc length along the
        profile, rim to rim, normalised to 1): ``profile_x``, ``profile_z`` (m,
        signed radial position and height above the flat membrane),
        ``profile_col``/``profile_row`` (px in the stored frame),
        ``profile_source``, ``bulge_height``, ``volume`` (m^3, water added),
        ``volume_left``/``volume_right``, ``volume_ellipse``, ``area``,
        ``area_ratio``, ``rim_radius`` (m), ``lambda_pre``, ``lambda_pre_fit``,
        ``vtilde`` and ``volume_ratio`` (with ``chamber``), ``flag``,
        ``flag_figure``, ``flag_value``, the quality figures, tilt and drift.
        Attrs: software version, every extraction parameter, the chamber
        (``chamber_radius``, ``chamber_depth``, ``membrane_thickness``, ...) and
        the experiment metadata.

    Notes
    -----
    Volume :math:`V = -\oint \pi r^2 dz` and area :math:`A = 2\pi\oint r\,ds` of
    each half of the dome about the axis (:mod:`osmobulge.imaging.geometry`);
    the reported values are the means of the two halves and their
    disagreement is a quality figure.  :math:`\tilde V = \Delta V/(\pi a^3)`,
    :math:`V/V_0 = 1 + \Delta V/(\pi a^2 h)` (main text Eqn 4), area ratio
    :math:`A/(\pi a^2)`, :math:`\lambda_{pre} = R/R_0` with :math:`R_0` the rim
    radius measured in the flat frame (supplement Sec. 5.7; attr
    ``lambda_pre_reference_radius``; a warning when it is more than 2 % off the
    chamber's ``a``, which Vtilde and V/V0 use).
    """
    if errors not in ERRORS:
        raise ValueError(f"errors must be one of {ERRORS}, got {errors!r}")
    if bulge_direction not in _DIRECTIONS:
        raise ValueError(f"bulge_direction must be one of {_DIRECTIONS}, got {bulge_direction!r}")
    if tracer not in TRACERS:
        raise ValueError(f"tracer must be one of {TRACERS}, got {tracer!r}")
    if tracer == "silhouette" and chamber_region is not None:
        raise ValueError("the silhouette tracer reads one chamber (the most central): chamber_region needs "
                         "tracer='band'")
    if rim is not None and (tracer == "band" or chamber_region is not None):
        raise ValueError("rim= locates the chamber for the silhouette route: not with tracer='band' or "
                         "chamber_region (the band route's way in)")
    if not (isinstance(n_profile, int | np.integer) and n_profile >= 11):
        raise ValueError(f"n_profile must be an int >= 11, got {n_profile!r}")
    settings = settings or TraceSettings()
    if not isinstance(settings, TraceSettings):
        raise TypeError(f"settings must be a TraceSettings, got {type(settings).__name__}")
    src = _open(source, pixel_size, frame_interval)
    n = len(src)
    if n == 0:
        raise ValueError("source holds no frames")
    p = float(src.pixel_size)
    times = np.asarray(src.timestamps, float)
    if not (np.isfinite(p) and p > 0) or times.shape != (n,) or not np.all(np.isfinite(times)):
        raise ValueError("pixel size or frame times unknown: pass pixel_size= (m/px) and frame_interval= (s)")
    chamber_attrs = _chamber_attrs(chamber)
    rim_px = None
    if rim is not None:
        rim_px = np.asarray(rim, float)
        if rim_px.shape != (2, 2) or not np.all(np.isfinite(rim_px)):
            raise ValueError(f"rim must be two finite (x, y) points in m, shape (2, 2); got {np.shape(rim)}")
        rim_px = rim_px / p  # (x=col, y=row) px
    priors_px = {int(k): _points_px(v, p, "priors") for k, v in (priors or {}).items()}
    manual_px = {int(k): _points_px(v, p, "manual_profiles") for k, v in (manual_profiles or {}).items()}
    for name, d in (("priors", priors_px), ("manual_profiles", manual_px)):
        bad = [k for k in d if not 0 <= k < n]
        if bad:
            raise ValueError(f"{name} has frame indices {bad} outside 0..{n - 1}")

    # -- the tracers: one per chamber ------------------------------------------------------------
    first = src[0]
    ref_frame, ref_name = _reference(reference_frame, first, p)
    try:
        tracers = _tracers(first if ref_frame is None else ref_frame, bulge_direction, chamber_region, settings,
                           "silhouette" if rim_px is not None else tracer, chamber, p, rim_px)
    except ChamberNotFound as err:  # (not a bad chamber_region: that error says so itself)
        if ref_frame is not None:
            raise ChamberNotFound(f"{err} -- in the reference frame ({ref_name}), which must show the flat "
                                  f"membrane") from err
        if "background is dark" in str(err):  # (its reason and way in are the whole story)
            raise
        # the ways in when the search ran (not when the rim was given, or one route asked for)
        hint = _LOOK_HINT if rim_px is None and tracer == "auto" else ""
        raise ChamberNotFound(f"{err} -- the chamber is found in the first frame, which must show the flat membrane "
                         f"(a series that starts with the dome already grown, e.g. the second file of a split "
                         f"series, needs reference_frame= a frame of the flat membrane){hint}") from err
    if ref_frame is not None:  # the reference must be flat itself: traced once (by a copy of each tracer)
        import copy

        for c, t in enumerate(tracers):
            _warn_if_bulged(copy.deepcopy(t).process(ref_frame, 0).height, t.ref.rim_radius, "reference frame",
                            f"chamber {c}: " if len(tracers) > 1 else "")
    view = FrameView(first, tracers[0].k)
    if len(tracers) == 1:
        parts_p, parts_m = [priors_px], [manual_px]
    else:  # picked points belong to the chamber over whose well their mean column lies
        axes = np.array([t.ref.line.x0 for t in tracers])
        reach = np.array([1.5 * t.ref.rim_radius for t in tracers])  # over the well or its overhanging dome

        def owner(pts):
            d = np.abs(axes - float(np.mean(view.from_frame(pts[:, 1], pts[:, 0])[0])))
            c = int(np.argmin(d))
            return c if d[c] <= reach[c] else -1

        orphans = sorted(i for d in (priors_px, manual_px) for i, v in d.items() if owner(v) < 0)
        if orphans:
            warnings.warn(f"picked points of frames {orphans} lie over no traced chamber: not used", UserWarning,
                          stacklevel=2)
        parts_p = [{i: v for i, v in priors_px.items() if owner(v) == c} for c in range(len(tracers))]
        parts_m = [{i: v for i, v in manual_px.items() if owner(v) == c} for c in range(len(tracers))]
    runs = [_Run(t, n, n_profile, pp, mm) for t, pp, mm in zip(tracers, parts_p, parts_m, strict=True)]

    bar = None
    if progress:
        from rich.progress import Progress

        bar = Progress(transient=True)
        first_note = "" if compiled_on_disk() else " (first run on this machine: compiling the tracer, about 45 s)"
        task = bar.add_task("extracting" + first_note, total=n)
        bar.start()
    read = getattr(src, "peek", src.__getitem__)  # no copy of a memory-mapped frame: its pages are read on use
    try:
        for i in range(n):
            try:
                frame = first if i == 0 else read(i)
            except Exception as err:  # noqa: BLE001 - an unreadable frame is flagged in every chamber
                if errors == "raise":
                    raise
                for run in runs:
                    run.failed(i, err)
            else:
                for run in runs:
                    run.step(i, frame, p, errors)
            if bar is not None:
                bar.update(task, advance=1, **({"description": "extracting"} if i == 0 else {}))  # compiled now
    finally:
        if bar is not None:
            bar.stop()
    for c, run in enumerate(runs if ref_frame is None else ()):
        # the chamber (flat line, rim, well) is found in the first frame: a dome already standing there can
        # bend it (measured: from Vtilde ~0.1 on the search fails, at 0.4 the rim came out 5 px narrow)
        _warn_if_bulged(run.scal["bulge_height"][0] / p, run.tracer.ref.rim_radius, "first frame",
                        f"chamber {c}: " if len(runs) > 1 else "",
                        " (a series that starts bulged needs reference_frame= a frame of the flat membrane)")

    for run in runs:
        series_gates(run.scal, run.flag, run.flag_figure, p, flat_first=ref_frame is None)
    if tracer == "auto" and chamber is None:
        for c, run in enumerate(runs):
            _warn_if_band_stays_flat(run, p, f"chamber {c}: " if len(runs) > 1 else "")
    parts = [_dataset(r, times, p, chamber_attrs, src, settings, bulge_direction, chamber_region, errors, metadata,
                      fit_prestretch) for r in runs]
    for ds in parts:
        ds.attrs["reference_frame"] = ref_name
        if ref_frame is not None and ds.attrs["reference_source"].startswith("image"):
            ds.attrs["reference_source"] = "image (reference frame)"
    if chamber_region != "all":
        return parts[0]
    return stack_chambers(parts, [f"chamber-{c}" for c in range(len(parts))])


#: a frame's volume tolerance: this fraction of its volume, or this many px of layer over the rim disc
GATE_VOLUME_FRACTION, GATE_LAYER_PX = 0.03, 0.5


def series_gates(scal, flag, flag_figure, p, *, flat_first=True):
    """Flag frames whose volume the rest of the series contradicts (in place).

    Two checks over the frames still flagged ``ok``, each a ``poor_fit`` with its
    figure (``flag_value``, in volume tolerances: ``max(3 %, a 0.5 px layer over
    the rim disc)``):

    * ``flat_volume``: the first frame, which must show the flat membrane, holds
      a volume above its tolerance (the trace follows a face or a halo, not the
      film, or the frame is not flat);
    * ``volume_outlier``: a frame's volume lies more than its tolerance outside
      the range of its nearest ok neighbours before and after.  A forward or
      reverse actuation changes the volume monotonically, so a frame that is
      not between its neighbours was traced on something else (a switched
      face, a lost film).

    Parameters
    ----------
    scal : dict of ndarray
        Per-frame scalars with ``volume_left``, ``volume_right`` (m3),
        ``rim_radius`` (m) and ``flag_value``.
    flag, flag_figure : ndarray of str
    p : float
        Pixel size (m).
    flat_first : bool
        The first frame is the series' own flat reference (no ``reference_frame``).
    """
    vol = 0.5 * (scal["volume_left"] + scal["volume_right"])
    rim = scal["rim_radius"]
    tol = np.maximum(GATE_VOLUME_FRACTION * np.abs(vol), GATE_LAYER_PX * p * np.pi * rim**2)
    ok = np.array([f == "ok" for f in flag]) & np.isfinite(vol) & np.isfinite(tol)
    hits = {}
    if flat_first and ok.size and ok[0] and abs(vol[0]) > tol[0]:
        hits[0] = ("flat_volume", abs(vol[0]) / tol[0])
    # worst offender first, then again without it: a frame that is off makes its neighbours look off too
    keep = ok.copy()
    while True:
        idx = np.flatnonzero(keep)
        if idx.size < 3:
            break
        mid, before, after = idx[1:-1], idx[:-2], idx[2:]
        lo, hi = np.minimum(vol[before], vol[after]), np.maximum(vol[before], vol[after])
        out = np.maximum(np.maximum(lo - vol[mid], vol[mid] - hi), 0.0)
        # the neighbours' own tolerances count too: one of them may be the bad frame
        excess = out / (tol[mid] + np.maximum(tol[before], tol[after]))
        if not np.any(excess > 1.0):
            break
        j = int(np.argmax(np.where(excess > 1.0, out / tol[mid], -1.0)))  # the one furthest out in its own tolerance
        i = int(mid[j])
        hits.setdefault(i, ("volume_outlier", out[j] / tol[i]))
        keep[i] = False
    for i, (fig, val) in hits.items():
        flag[i], flag_figure[i], scal["flag_value"][i] = "poor_fit", fig, val


def _reference(reference_frame, first, p):
    """The reference frame (an array, or the first frame of an image / series path) and its name for the attrs."""
    if reference_frame is None:
        return None, OWN_FIRST_FRAME
    if isinstance(reference_frame, str | os.PathLike):
        from osmobulge.imaging.io import read_first_frame

        frame, _ = read_first_frame(reference_frame, pixel_size=p)
        name = str(reference_frame)
    else:
        frame, name = np.asarray(reference_frame), "array"
    if frame.ndim != 2 or frame.shape != np.shape(first):
        raise ValueError(f"reference_frame must be one frame of the series' shape {np.shape(first)}, got shape "
                         f"{frame.shape}")
    if frame.dtype != np.asarray(first).dtype:  # the flat band's contrast sets every frame's thresholds
        raise ValueError(f"reference_frame is {frame.dtype}, the series {np.asarray(first).dtype}: it must come "
                         f"from the same camera and settings (the same grey scale)")
    return frame, name


def _silhouette_tracer(first, bulge_direction, settings, chamber, p, rim=None):
    from osmobulge.imaging._facetrace import SilhouetteTracer

    l0 = depth = radius = None
    if chamber is not None:
        l0, depth, radius = float(chamber.thickness) / p, float(chamber.depth) / p, float(chamber.radius) / p
    tracer = SilhouetteTracer(first, l0_px=l0, depth_px=depth, bulge_direction=bulge_direction, settings=settings,
                              rim=rim, radius_px=radius)
    off = _rim_off(tracer.ref.rim_radius, chamber, p)
    if rim is None and off > ROUTE_RIM_TOL:
        # (measured blind: three wells 40 um apart, their inner walls' zones too close to be told apart, read as
        # one well from the first's left wall to the third's right one, 3.3x the chamber's radius; the flat frame
        # ok with that rim, every later frame flagged)
        w = tracer.walls0
        raise ChamberNotFound(
            f"the walls found (view columns {w.left:.0f} and {w.right:.0f}, rim radius "
            f"{tracer.ref.rim_radius * p * 1e6:.1f} um) are not this chamber's (radius "
            f"{float(chamber.radius) * 1e6:.1f} um, more than {100 * ROUTE_RIM_TOL:.0f} % off): several wells "
            f"side by side, or the wrong chamber; give its rim (rim=, the flat mid-line's ends at its walls) or "
            f"crop to it")
    return tracer


def _tracers(first, bulge_direction, chamber_region, settings, route="band", chamber=None, p=None, rim=None):
    """The tracer of the chosen chamber, or (``"all"``) of every chamber whose two walls are in the field."""
    if route == "silhouette":
        return [_silhouette_tracer(first, bulge_direction, settings, chamber, p, rim)]
    if chamber_region != "all":
        try:
            band = ChamberTracer(first, bulge_direction=bulge_direction, chamber_region=chamber_region,
                                 thickness=None, settings=settings)
        except ChamberNotFound as err:
            if route != "auto" or chamber_region is not None:
                raise
            try:
                return [_silhouette_tracer(first, bulge_direction, settings, chamber, p)]
            except ChamberNotFound as err2:
                raise ChamberNotFound(f"{err}; and by the walls' and film's silhouettes: {err2}") from err2
        if route == "auto" and chamber_region is None:
            # a band found in a look it does not fit (measured: an inverted bright-field film) does not read
            # its own flat frame; the silhouette route then, when it finds the chamber.  Nor is a band whose rim
            # lies more than ROUTE_RIM_TOL off the given chamber's radius this chamber's (measured: a lightly dyed
            # film, ho_dyed_film, a band 88 px wide of rim over a well of 160 px, read flat in every frame while
            # the dome rose, flagged ok): the silhouette route then, when its rim (the well's walls) is within it
            import copy

            own = copy.deepcopy(band).process(first, 0)
            off = _rim_off(band.ref.rim_radius, chamber, p)
            # without the chamber, the band's rim is checked against the walls' (measured on the 100 cached looks
            # read without the chamber: the band route took a band not the well's film on 8, its rim 10-72 % off
            # and frames ok and wrong, 3-9 of 9; the silhouette route's rims within 0.3 px of the truth on all 10
            # tried, the painted looks' too)
            unchecked = chamber is None and own.flag == "ok"
            if own.flag != "ok" or off > ROUTE_RIM_TOL or unchecked:
                try:
                    sil = _silhouette_tracer(first, bulge_direction, settings, chamber, p)
                except ChamberNotFound as err:  # the band route it is: its frames are flagged (and a bulged
                    # frame the chamber was found in is warned about below); not on a dark background, which
                    # neither route reads unless asked (a band found there does not read its own flat frame),
                    # nor when its rim is not this chamber's (measured blind on ho_blind_1206c, a neighbouring
                    # well in the field: a band rim 80 % off the chamber's radius, 6 of 25 frames ok and wrong)
                    from osmobulge.imaging._facetrace import dark_background

                    if own.flag != "ok" and dark_background(first)[1]:
                        raise ChamberNotFound(f"the band route cannot read its own first frame ({own.flag}), "
                                              f"and {err}") from err
                    if off > ROUTE_RIM_TOL:
                        raise ChamberNotFound(
                            f"the band route's well (rim radius {band.ref.rim_radius * p * 1e6:.1f} um) is not this "
                            f"chamber's (radius {float(chamber.radius) * 1e6:.1f} um, more than "
                            f"{100 * ROUTE_RIM_TOL:.0f} % off), and the silhouette route: {err}") from err
                else:
                    if unchecked:
                        apart = abs(band.ref.rim_radius / sil.ref.rim_radius - 1.0)
                        if apart > ROUTE_RIM_TOL:
                            warnings.warn(f"the band route's rim ({band.ref.rim_radius:.1f} px) lies "
                                          f"{100 * apart:.0f} % off the walls' ({sil.ref.rim_radius:.1f} px): its "
                                          f"band is not this well's film; the silhouette route is taken (pass the "
                                          f"chamber to check either against it)", UserWarning, stacklevel=3)
                            return [sil]
                    elif own.flag != "ok" or _rim_off(sil.ref.rim_radius, chamber, p) <= ROUTE_RIM_TOL:
                        return [sil]
        return [band]
    central = ChamberTracer(first, bulge_direction=bulge_direction, settings=settings)
    g = central.ref
    w = FrameView(first, central.k).shape[1]
    found = [(g.line.x0, central)]
    margin = 12.0  # the wall fits' windows (8 px) and their side samples inside the field
    for wl in g.others:
        c0, c1 = g.line.x0 + wl.u_left, g.line.x0 + wl.u_right  # view columns of the wall tops (line ~level)
        if c0 > margin and c1 < w - 1.0 - margin:  # complete: both walls inside the field
            try:
                t = ChamberTracer(first, bulge_direction=central.bulge_direction,
                                  chamber_region=(c0 + 0.25 * (c1 - c0), c1 - 0.25 * (c1 - c0)), settings=settings)
            except ValueError as err:  # a well the tracer cannot measure is left out, with a warning
                warnings.warn(f"chamber at view columns {c0:.0f}-{c1:.0f} left out: {err}", UserWarning,
                              stacklevel=3)
                continue
            found.append((t.ref.line.x0, t))
    return [t for _, t in sorted(found, key=lambda x: x[0])]


#: relative difference between the flat frame's measured rim radius and the chamber's radius a above which
#: extract warns (Vtilde uses a, lambda_pre the measured radius)
RIM_MISMATCH = 0.02
#: relative difference between a route's rim radius in the flat frame and the given chamber's radius a above which
#: the route has found something else than this chamber's well (``tracer="auto"``: the band route's rim is checked,
#: the silhouette route's taken when it is within this; the silhouette route's rims lie within 0.3 px of the
#: truth on every look, 0.2 % at 160 px; a well made 10 % off its drawing is not this chamber)
ROUTE_RIM_TOL = 0.10


def _rim_off(rim_px, chamber, p):
    """How far (relative) a rim radius of ``rim_px`` px lies off the chamber's radius (0 without a chamber)."""
    if chamber is None or p is None or not np.isfinite(rim_px):
        return 0.0 if chamber is None or p is None else np.inf
    return abs(float(rim_px) * float(p) / float(chamber.radius) - 1.0)


#: first-frame dome height, as a fraction of the rim radius, above which extract warns (the first frame
#: must show the flat membrane; a first frame at Vtilde 0.05, height 0.1 a, still measures within 0.2 %)
FIRST_FRAME_HEIGHT = 0.2
#: what a failed chamber search adds: the looks the tracer cannot read yet, and the ways in
_LOOK_HINT = (". Both searches failed: the band route needs a filled membrane band and a grey step between the "
              "well's liquid and the base; the silhouette route needs an upright view with the two walls' "
              "silhouettes in the base below a straight top face. Ways in: crop to one chamber with "
              "chamber_region=(col0, col1) (bulge-up view) when several wells confuse the search, give the rim "
              "(rim=((x_left, y_left), (x_right, y_right)) in m: the flat mid-line's ends at the walls; in an "
              "experiment folder [imaging] rim_px, or napari's Profile picker: Rim = ends of this frame's "
              "picks), pass the chamber (its membrane thickness and depth), or pick the profiles by hand in "
              "napari (python -m osmobulge.plugins EXPERIMENT, Profile picker)")

#: the ``reference_frame`` attr of an extraction whose chamber was found in the source's own first frame
OWN_FIRST_FRAME = "first frame"


def _warn_if_bulged(height, rim_radius, which, where, hint=""):
    """Warn when the frame the chamber was found in (``which``) shows a dome above FIRST_FRAME_HEIGHT (px)."""
    if np.isfinite(height) and height > FIRST_FRAME_HEIGHT * rim_radius:
        warnings.warn(f"{where}the {which}'s dome already stands {height:.0f} px ({height / rim_radius:.2f} of the "
                      f"rim radius) above the flat membrane; the chamber is found in the {which}, which must show "
                      f"the flat membrane: rim radius, volumes and lambda_pre may be wrong{hint}", UserWarning,
                      stacklevel=3)


#: largest dome (px above the flat membrane) over a series' later ok frames below which an unchecked band route
#: (``tracer="auto"`` without a chamber) warns that its band may not be the membrane
FLAT_SERIES_PX = 1.0


def _warn_if_band_stays_flat(run, p, where):
    """Warn when the band route, taken without a chamber to check its rim against (:data:`ROUTE_RIM_TOL`), reads
    every later ok frame (two at least) within FLAT_SERIES_PX of the flat membrane: a band that is not the
    membrane reads so (measured: a lightly dyed film's flat band, 0.02 px while the dome stood 150-270 px)."""
    if not isinstance(run.tracer, ChamberTracer):
        return
    later = np.array([f == "ok" for f in run.flag])
    later[:1] = False
    height = run.scal["bulge_height"][later] / p
    if later.sum() >= 2 and np.all(np.abs(height) < FLAT_SERIES_PX):
        warnings.warn(f"{where}the band route read no dome in any of {int(later.sum())} later frames flagged ok (all "
                      f"within {FLAT_SERIES_PX:.0f} px of the flat membrane): if a dome is seen, the band followed is "
                      f"not the membrane (a lightly dyed film's flat band reads so); pass the chamber (auto then "
                      f"checks the band's rim against its radius) or tracer='silhouette'", UserWarning, stacklevel=3)


#: share of a flagged frame's pixels at its most common value, beyond the first frame's, that names it a blank or
#: partial frame in its message (a transfer cut short, the shutter, the lamp)
BLANK_SHARE = 0.2


def _mode_share(frame):
    """The most common value of a frame and the share of its pixels at it."""
    f = np.asarray(frame).ravel()
    if f.dtype.kind == "u" and f.dtype.itemsize <= 2:
        counts = np.bincount(f)
        k = int(np.argmax(counts))
        return k, counts[k] / f.size
    values, counts = np.unique(f, return_counts=True)
    k = int(np.argmax(counts))
    return values[k].item(), counts[k] / f.size


def _blank_note(frame, first_share):
    """What a flagged frame's message starts with when most of it is one value, more than the first frame was
    (measured: a black frame, a white one and a frame black in its top half read as chamber walls not found or
    as a dome past the field's edge); else ''."""
    value, share = _mode_share(frame)
    if share - first_share <= BLANK_SHARE:
        return ""
    what = (f"blank (every pixel is {value})" if share == 1.0 else
            f"partly blank ({100 * share:.0f} % of its pixels are {value}; the first frame's most common value, "
            f"{100 * first_share:.0f} %)")
    return f"the frame is {what}: a transfer cut short, the shutter or the lamp? "


class _Run:
    """One chamber's tracer and per-frame storage (memory flat in T: scalars and fixed-length profiles)."""

    def __init__(self, tracer, n, n_profile, priors, manual):
        self.tracer, self.n_profile, self.priors, self.manual = tracer, n_profile, priors, manual
        self.scal = {k: np.full(n, np.nan) for k in (
            "bulge_height", "volume_left", "volume_right", "area_left", "area_right", "rim_radius", "tilt", "drift_x",
            "drift_y", "axis_col", "axis_row", "volume_ellipse", "ellipse_a", "ellipse_b", "ellipse_rms",
            "flag_value", "well_depth", "band_thickness", "wall_rms", "line_rms", *_FIGURES)}
        self.flag = np.array(["no_membrane"] * n, dtype=object)
        self.flag_figure = np.array([""] * n, dtype=object)
        self.source_kind = np.array(["auto"] * n, dtype=object)
        self.message = np.array([""] * n, dtype=object)
        self.px, self.pz, self.pcol, self.prow = (np.full((n, n_profile), np.nan) for _ in range(4))
        self.plen = np.full(n, np.nan)
        self.prior_frames = np.array(sorted(priors), int)
        self.first_share = None  # (the first frame's pixels' share at its most common value: _blank_note)

    def guide_for(self, i):
        if i in self.priors:
            return self.priors[i]
        if self.tracer.prev is not None and self.tracer.prev.flag == "ok":
            return None  # tracking from the previous frame
        if self.prior_frames.size:
            return self.priors[int(self.prior_frames[np.argmin(np.abs(self.prior_frames - i))])]
        return None

    def failed(self, i, err):
        self.message[i] = f"{type(err).__name__}: {err}"
        self.flag[i] = "no_membrane"
        self.flag_figure[i] = "exception"

    def step(self, i, frame, p, errors):
        try:
            man = self.manual.get(i)
            res = self.tracer.process(frame, i, guide=None if man is not None else self.guide_for(i), manual=man)
            if self.first_share is None:
                self.first_share = _mode_share(frame)[1]
            if res.flag != "ok":
                res.message = _blank_note(frame, self.first_share) + res.message
            if res.geometry is None and errors == "raise":
                raise RuntimeError(f"frame {i} cannot be measured: {res.message}")
        except Exception as err:  # noqa: BLE001 - batch runs record failures as data
            if errors == "raise":
                raise
            self.failed(i, err)
            return
        try:
            _store(i, res, self, frame, p)
        except Exception as err:  # noqa: BLE001 - a frame that cannot be stored is flagged, the series goes on
            if errors == "raise":
                raise
            self.failed(i, err)


#: per-chamber attributes that become variables over ``chamber`` when chambers are stacked
_PER_CHAMBER = {  # name: (units or None, long name)
    "prestretch_c1": ("1", "pre-stretch c1 of lambda_pre = 1 + c1 Vtilde + c2 Vtilde^2 (supplement Sec. 5.7)"),
    "prestretch_c2": ("1", "pre-stretch c2 of lambda_pre = 1 + c1 Vtilde + c2 Vtilde^2 (supplement Sec. 5.7)"),
    "prestretch_frames": (None, "frames in the pre-stretch fit"),
    "reference_radius": ("m", "chamber radius a used for Vtilde, V/V0 and A/A0"),
    "lambda_pre_reference_radius": ("m", "rim radius R0 measured in the flat frame: lambda_pre = R/R0"),
    "lambda_pre_reference_source": (None, "where R0 comes from"),
    "polarity": (None, "membrane contrast: +1 dark, -1 bright"),
    "blur_sigma_px": ("px", "Gaussian blur of the optics measured in the first frame"),
    "bulge_direction": (None, "direction the dome grows in the image"),
}


def stack_chambers(parts, names):
    """Stack per-chamber extractions along a ``chamber`` dimension (dims ``time, chamber, ...``).

    Attributes that differ between chambers (:data:`_PER_CHAMBER`: pre-stretch
    fit, reference radius, polarity, blur, bulge direction) become variables
    over ``chamber``; the others are those of the first part.
    """
    per = {key: [d.attrs.get(key, np.nan) for d in parts] for key in _PER_CHAMBER}
    ds = xr.concat(parts, dim="chamber", combine_attrs="override", coords="minimal", compat="override")
    ds = ds.assign_coords(chamber=("chamber", list(names), {"long_name": "chamber"}))
    for key, vals in per.items():
        units, long_name = _PER_CHAMBER[key]
        ds[key] = ("chamber", np.asarray(vals), {"long_name": long_name} | ({"units": units} if units else {}))
        ds.attrs.pop(key, None)
    return ds.transpose("time", "chamber", ...)


def _store(i, res, run, frame, p):
    """One frame's trace into the chamber's storage (SI), with the paper's ellipse description."""
    scal, flag, flag_figure, source_kind, message = run.scal, run.flag, run.flag_figure, run.source_kind, run.message
    px, pz, pcol, prow, plen, n_profile = run.px, run.pz, run.pcol, run.prow, run.plen, run.n_profile
    g = res.geometry
    flag[i] = res.flag
    flag_figure[i] = res.flag_figure
    source_kind[i] = res.source
    message[i] = res.message
    # (in the units of the figure's own variable: px -> m for a length)
    scal["flag_value"][i] = res.flag_value * (p if res.flag_figure in _LENGTH_FIGURES else 1.0)
    scal["drift_x"][i], scal["drift_y"][i] = res.drift
    for k in _FIGURES:  # (the tracers' quality figures)
        v = res.figures.get(k, np.nan)
        scal[k][i] = v if np.isfinite(v) else (np.inf if v == np.inf else np.nan)
    scal["clipped"][i] *= p  # (px -> m; inf stays)
    if g is None:
        return
    view = FrameView(frame, run.tracer.k)
    r, c = view.to_frame(g.line.x0, g.line.y0)
    scal["axis_col"][i], scal["axis_row"][i] = c, r
    # tilt of the device from its upright (bulge-up) view, counter-clockwise as displayed
    scal["tilt"][i] = -np.degrees(g.line.angle)
    scal["rim_radius"][i] = g.rim_radius * p
    scal["well_depth"][i] = g.well.depth * p
    scal["band_thickness"][i] = g.thickness * p
    scal["wall_rms"][i] = g.wall_rms * p
    scal["line_rms"][i] = g.line_rms * p
    if not len(res.u):
        return
    scal["volume_left"][i] = res.volume_left * p**3
    scal["volume_right"][i] = res.volume_right * p**3
    scal["area_left"][i] = res.area_left * p**2
    scal["area_right"][i] = res.area_right * p**2
    scal["bulge_height"][i] = res.height * p
    scal["residual_rms"][i] = res.residual_rms * p
    if np.isfinite(scal["neighbour_gap"][i]):
        scal["neighbour_gap"][i] *= p
    # the profile on an even arc-length grid
    length, uu, zz = arc_resample(np.ascontiguousarray(res.u, np.float64), np.ascontiguousarray(res.z, np.float64),
                                  int(n_profile))
    plen[i] = length * p
    px[i], pz[i] = uu * p, zz * p
    vp = g.line.point(uu, zz)
    rr, cc = view.to_frame(vp[:, 0], vp[:, 1])
    pcol[i], prow[i] = cc, rr
    # the paper's description: an ellipse through the traced points, integrated the same way
    pts_u = res.points_u if len(res.points_u) >= 5 else res.u
    pts_z = res.points_z if len(res.points_z) >= 5 else res.z
    # (at most 200 of the points, when they span more than 1 px in z; compiled: fit_ellipse and _ellipse_volume)
    pts_u, pts_z = np.ascontiguousarray(pts_u, np.float64), np.ascontiguousarray(pts_z, np.float64)
    status, a, b, rms, vol = stored_profile_ellipse(pts_u, pts_z, 200, 721)
    if status in (1, 2):  # too few points, no ellipse, or a case only the numpy algebra decides
        sel = np.linspace(0, len(pts_u) - 1, min(len(pts_u), 200)).astype(int)
        ell = fit_ellipse(np.column_stack((pts_u[sel], pts_z[sel])))
        if ell:
            (a, b), rms, vol, status = ell.semi_axes, ell.rms, _ellipse_volume(ell), 0
    if status == 0:
        scal["ellipse_a"][i], scal["ellipse_b"][i] = a * p, b * p
        scal["ellipse_rms"][i] = rms * p
        scal["volume_ellipse"][i] = vol * p**3


def _ellipse_volume(ell):
    """Volume of the solid of revolution of the ellipse arc above z = 0 (nan if it does not cross z = 0).

    A 721-point polygon (error ~ (2 pi / 720)^2 / 12 = 6e-6 of the volume),
    integrated like a traced profile (compiled:
    :func:`~osmobulge.imaging._kernels.ellipse_arc_volume`).
    """
    (xc, yc), (a, b) = ell.center, ell.semi_axes
    return float(ellipse_arc_volume(float(xc), float(yc), float(a), float(b), float(ell.angle), 721))


def _dataset(run, times, p, chamber_attrs, src, settings, bulge_direction, chamber_region, errors, metadata, do_fit):
    """One chamber's storage -> its Dataset (SI, CF attributes), with the pre-stretch fit."""
    tracer, scal, flag, flag_figure, source_kind, message = (run.tracer, run.scal, run.flag, run.flag_figure,
                                                             run.source_kind, run.message)
    px, pz, pcol, prow, plen, n_profile = run.px, run.pz, run.pcol, run.prow, run.plen, run.n_profile
    priors_px, manual_px = run.priors, run.manual
    n = len(times)
    ok = np.array([f == "ok" for f in flag])
    volume = 0.5 * (scal["volume_left"] + scal["volume_right"])
    area = 0.5 * (scal["area_left"] + scal["area_right"])
    # reference radius and depth: the chamber's, else measured in the first frame
    if chamber_attrs:
        a, h, ref_src = chamber_attrs["chamber_radius"], chamber_attrs["chamber_depth"], "chamber"
    else:
        a, h, ref_src = tracer.ref.rim_radius * p, tracer.ref.well.depth * p, "image (first frame)"
    vtilde = volume / (np.pi * a**3)
    volume_ratio = 1.0 + volume / (np.pi * a * a * h) if np.isfinite(h) else np.full(n, np.nan)
    # lambda_pre = R(Vtilde) / R0, R0 the rim radius measured in the flat frame (supplement Sec. 5.7), not the
    # chamber's nominal a: a well made 2 % wider than drawn would otherwise start at lambda_pre 1.02
    r0, r0_src = float(tracer.ref.rim_radius) * p, "measured (flat frame)"
    if not (np.isfinite(r0) and r0 > 0):
        r0, r0_src = float(a), "chamber radius a (the flat frame's rim not measured)"
        warnings.warn("the flat frame's rim radius is not measured: lambda_pre is R/a, against the chamber's "
                      "radius", UserWarning, stacklevel=3)
    lam = scal["rim_radius"] / r0
    if ref_src == "chamber" and abs(r0 / a - 1.0) > RIM_MISMATCH:
        warnings.warn(f"the rim radius measured in the flat frame, {1e6 * r0:.1f} um, differs from the chamber's "
                      f"radius a = {1e6 * a:.1f} um by {100 * (r0 / a - 1):+.1f} %: lambda_pre is R/R0 with the "
                      f"measured R0, but Vtilde = dV/(pi a^3), V/V0 and A/A0 use a (pass the chamber's true "
                      f"radius, or check the pixel size)", UserWarning, stacklevel=3)

    def var(data, units, long_name, dims=("time",), **extra):
        attrs = {"units": units, "long_name": long_name} if units is not None else {"long_name": long_name}
        attrs.update(extra)
        return (dims, data, attrs)

    data = {
        "profile_x": var(px, "m", "signed radial position of the membrane midline from the chamber axis",
                         ("time", "s")),
        "profile_z": var(pz, "m", "height of the membrane midline above the flat membrane", ("time", "s")),
        "profile_col": var(pcol, "px", "membrane midline column in the stored frame", ("time", "s")),
        "profile_row": var(prow, "px", "membrane midline row in the stored frame", ("time", "s")),
        "profile_length": var(plen, "m", "arc length of the membrane midline, rim to rim"),
        "profile_source": var(source_kind.astype(str), None, "origin of the profile: auto (traced) or manual"),
        "bulge_height": var(scal["bulge_height"], "m", "dome height on the chamber axis above the flat membrane"),
        "volume": var(volume, "m3", "water added: bulge volume above the flat membrane (mean of the halves)"),
        "volume_left": var(scal["volume_left"], "m3", "bulge volume from the left half of the profile"),
        "volume_right": var(scal["volume_right"], "m3", "bulge volume from the right half of the profile"),
        "volume_ellipse": var(scal["volume_ellipse"], "m3", "bulge volume of the fitted ellipse arc (paper Sec. 2.3)"),
        "ellipse_a": var(scal["ellipse_a"], "m", "ellipse semi-axis a"),
        "ellipse_b": var(scal["ellipse_b"], "m", "ellipse semi-axis b"),
        "ellipse_rms": var(scal["ellipse_rms"], "m", "RMS distance of the traced points from the ellipse"),
        "area": var(area, "m2", "membrane area of the dome (mean of the halves)"),
        "area_left": var(scal["area_left"], "m2", "membrane area from the left half"),
        "area_right": var(scal["area_right"], "m2", "membrane area from the right half"),
        "area_ratio": var(area / (np.pi * a * a), "1", "membrane area ratio A/A0, A0 = pi a^2"),
        "vtilde": var(vtilde, "1", "dimensionless bulge volume dV/(pi a^3) (Eqn 4)"),
        "volume_ratio": var(volume_ratio, "1", "chamber volume ratio V/V0 = 1 + dV/(pi a^2 h) (Eqn 4)"),
        "rim_radius": var(scal["rim_radius"], "m", "rim radius: half the distance between the wall tops"),
        "lambda_pre": var(lam, "1", "rim pre-stretch R/R0, R0 the flat frame's rim radius (supplement Sec. 5.7)"),
        "flag": var(flag.astype(str), None, "frame quality: " + "|".join(FLAGS)),
        "flag_figure": var(flag_figure.astype(str), None, "quality figure that set the flag"),
        "flag_value": var(scal["flag_value"], "m or 1", "value of the figure that set the flag, in that figure's "
                          "units: m for a length (" + ", ".join(sorted(_LENGTH_FIGURES)) + "), else 1"),
        "message": var(message.astype(str), None, "why a frame could not be measured"),
        "tilt": var(scal["tilt"], "deg", "tilt of the flat membrane, counter-clockwise as displayed"),
        "drift_x": var(scal["drift_x"], "px", "drift of the chamber along the view columns since frame 0 "
                       "(or the reference frame)"),
        "drift_y": var(scal["drift_y"], "px", "drift of the chamber along the view rows since frame 0 "
                       "(or the reference frame)"),
        "axis_col": var(scal["axis_col"], "px", "column where the chamber axis meets the flat membrane"),
        "axis_row": var(scal["axis_row"], "px", "row where the chamber axis meets the flat membrane"),
        "well_depth": var(scal["well_depth"], "m", "well depth measured in the first frame"),
        "band_thickness": var(scal["band_thickness"], "m", "membrane band thickness on the surface (image)"),
        "wall_rms": var(scal["wall_rms"], "m", "scatter of the wall edge points about the wall lines"),
        "line_rms": var(scal["line_rms"], "m", "scatter of the flat band centres about the flat line"),
    }
    for k, (u, ln) in _FIGURES.items():
        data[k] = var(scal[k], u, ln)
    coords = {
        "time": ("time", np.asarray(times, float), {"units": "s", "long_name": "time since the first frame"}),
        "frame": ("time", np.arange(n), {"long_name": "frame index"}),
        "s": ("s", np.linspace(0.0, 1.0, n_profile),
              {"units": "1", "long_name": "arc length from the left rim / length"}),
    }
    attrs = {
        "title": "bulge profiles extracted from a micrograph series",
        "software": "osmobulge",
        "osmobulge_version": __version__,
        "source": str(getattr(src, "source", "array")),
        "bad_frames": "; ".join(f"{a}: {b}" for a, b in getattr(src, "bad_frames", [])) or "none",
        "pixel_size": p,
        "frame_interval": float(np.median(np.diff(times))) if n > 1 else 0.0,
        "bulge_direction": tracer.bulge_direction,
        "bulge_direction_requested": bulge_direction,
        "tracer": getattr(tracer, "route", "band"),
        "chamber_region": "auto" if chamber_region is None else str(chamber_region),
        "errors": errors,
        "n_profile": int(n_profile),
        "polarity": int(tracer.ref.polarity),
        "blur_sigma_px": float(tracer.blur),
        "reference_radius": float(a),
        "lambda_pre_reference_radius": float(r0),
        "lambda_pre_reference_source": r0_src,
        "reference_depth": float(h),
        "reference_source": ref_src,
        "prior_frames": np.array(sorted(priors_px), np.int64) if priors_px else "none",
        "manual_frames": np.array(sorted(manual_px), np.int64) if manual_px else "none",
        "Conventions": "CF-1.8",
    }
    attrs.update(settings.to_attrs())
    attrs.update(chamber_attrs)
    attrs.update(_safe_attrs(metadata, "meta_"))
    # lambda_pre(Vtilde): second-order polynomial through (0, 1) (supplement Sec. 5.7)
    fit_ok = ok & np.isfinite(vtilde) & np.isfinite(lam) & (vtilde >= 0)
    if do_fit and fit_ok.sum() >= 3 and np.ptp(vtilde[fit_ok]) > 0:
        from osmobulge.modeling.prestretch import fit_prestretch as _fit

        pre = _fit(vtilde[fit_ok], lam[fit_ok])
        data["lambda_pre_fit"] = var(pre(np.clip(vtilde, 0, None)), "1",
                                     "fitted rim pre-stretch 1 + c1 Vtilde + c2 Vtilde^2 (supplement Sec. 5.7)")
        attrs["prestretch_c1"] = float(pre.c1)
        attrs["prestretch_c2"] = float(pre.c2)
    else:
        data["lambda_pre_fit"] = var(np.full(n, np.nan), "1", "fitted rim pre-stretch (not enough good frames)")
        attrs["prestretch_c1"] = np.nan
        attrs["prestretch_c2"] = np.nan
    attrs["prestretch_frames"] = int(fit_ok.sum())
    return xr.Dataset(data, coords=coords, attrs=attrs)


# ------------------------------------------------------------------------------------ save / load
_FORMATS = ("netcdf", "zarr")


def _fmt(path, fmt):
    if fmt is None:
        fmt = "zarr" if str(path).rstrip("/").endswith(".zarr") else "netcdf"
    if fmt not in _FORMATS:
        raise ValueError(f"fmt must be one of {_FORMATS}, got {fmt!r}")
    return fmt


def save_extraction(ds, path, *, fmt=None):
    """Write an extraction dataset without loss (netCDF via h5netcdf, or zarr v3), atomically.

    Parameters
    ----------
    ds : xarray.Dataset
    path : str or Path
        ``*.nc`` (netCDF) or ``*.zarr`` (a zarr v3 store, a folder).
    fmt : {"netcdf", "zarr"}, optional
        Default from the suffix.

    Returns
    -------
    pathlib.Path
    """
    path = Path(path)
    fmt = _fmt(path, fmt)
    path.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "netcdf":
        fd, tmp = tempfile.mkstemp(suffix=".nc.part", dir=path.parent)
        os.close(fd)
        try:
            ds.to_netcdf(tmp, engine="h5netcdf")
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)
        return path
    tmp = Path(tempfile.mkdtemp(suffix=".zarr.part", dir=path.parent))
    import shutil

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # zarr v3 notes on string dtypes
            ds.to_zarr(tmp, mode="w", zarr_format=3, consolidated=False)
        if path.exists():
            shutil.rmtree(path)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    return path


def load_extraction(path, *, fmt=None):
    """Read a dataset written by :func:`save_extraction` (fully loaded into memory).

    Parameters
    ----------
    path : str or Path
    fmt : {"netcdf", "zarr"}, optional

    Returns
    -------
    xarray.Dataset
    """
    path = Path(path)
    fmt = _fmt(path, fmt)
    if not path.exists():
        raise FileNotFoundError(f"{str(path)!r} does not exist")
    if fmt == "netcdf":
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            return ds.load()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return xr.open_zarr(path, zarr_format=3, consolidated=False).load()
