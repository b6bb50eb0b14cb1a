r"""Trace the membrane dome of one chamber through a micrograph series, frame by frame.

For every frame (:class:`ChamberTracer`):

1. **drift**: while tracking (the last frame was good) the chamber is looked
   for where the last frame put it; otherwise, and whenever the tracked
   geometry is implausible, phase correlation
   (:func:`skimage.registration.phase_cross_correlation`) of a patch of the
   base under the membrane (walls and well bottom; it excludes the dome)
   against the first frame predicts where the chamber is;
2. **flat membrane line and tilt**: sub-pixel centres of the membrane band
   where it lies flat on the base's top surface, away from every well, with a
   clipped least-squares line (its angle is the tilt);
3. **rim and axis**: sub-pixel wall edges, wall lines extrapolated to the
   base's top surface; the rim radius is half the distance between the wall
   tops, the axis halfway between them;
4. **dome**: a guide curve (the previous frame's dome, a manual prior, or a
   minimum-cost path from rim to rim on a coarse background-flattened image)
   is refined: grey levels are sampled bilinearly along the guide's normals,
   the band is found near the guide -- within the last frame-to-frame motion
   when tracking, else along a smooth path through a wide window chosen by
   dynamic programming (robust to dust and gaps) -- and its two edges are
   located at the half-levels of each side (sub-pixel, either contrast sign,
   any band width); narrow passes repeat until the curve stops moving, and a
   smoothing spline with clipped outliers gives the profile.  A tracked result
   that is not trustworthy (weak or incomplete band, large residuals, no
   convergence) is redone with the wide search, then from the global guide
   (``FrameTrace.mode`` says which gave the result);
5. **measures and flags**: volume and area of both halves as solids of
   revolution (:mod:`osmobulge.imaging.geometry`), and the quality figures.

The inner loops (sampling, band edges, the dynamic-programming path, the
least-squares splines) are compiled (:mod:`osmobulge.imaging._kernels`).
Everything is in pixels of the bulge-up view (see :mod:`osmobulge.imaging._chamber`);
:func:`osmobulge.imaging.extract` converts to SI.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np
from scipy import interpolate
from scipy import ndimage as ndi
from skimage.graph import route_through_array
from skimage.registration import phase_cross_correlation

from osmobulge.imaging._chamber import (
    ROTATIONS,
    WALL_WINDOW,
    ChamberGeometry,
    FrameView,
    Line,
    Well,
    _nanmedian,
    band_edges,
    detect_orientation,
    find_chambers,
    measure_line,
    measure_walls,
    smoothed_coarse,
)
from osmobulge.imaging._clipping import MOVED_FLAG, clip_mask, clip_message, raised, wall_clipping
from osmobulge.imaging._kernels import (
    abs_percentile,
    block_mean,
    clean_stations,
    clear_of_curve,
    curve_extent,
    ends_noise,
    extrapolated_curve,
    guide_transects,
    locate_walls,
    low_contrast_run,
    lsq_spline,
    masked_nanmedian,
    native_frame,
    pass_tail,
    rim_contact,
    rim_guide,
    robust_profile_spline,
    track_pass,
)
from osmobulge.imaging._normals import resample_polyline, viterbi_path
from osmobulge.imaging.geometry import ProfileSpline, revolution_measures, smooth_profile, sorted_quantile

__all__ = ["TraceSettings", "FrameTrace", "ChamberTracer", "FLAGS", "trace_series"]

#: quality flags, in order of precedence
FLAGS = ("ok", "no_membrane", "delaminated", "fractured", "touching", "poor_fit")

_BRIDGE_REACH = 40.0  # px of trusted points nearest a rim that set its bridge (_kernels.rim_bridge)
_RIM_FRACTIONS = np.linspace(0.02, 0.1, 9)  # rim contact: the band just outside the rim, R (1 + f) from the axis


@dataclass(frozen=True)
class TraceSettings:
    """Tuning knobs of the tracer (pixels unless stated).

    Parameters
    ----------
    search : float
        Half-width of the wide (dynamic-programming) band search along the
        guide's normals (plus half the band thickness).
    track_search : float
        Smallest half-width of the tracking pass from the dome predicted by the
        last two frames (no dynamic programming; widened to 1.5x the last
        prediction error plus 4 px and two blur sigmas).  Beyond twice this the
        frame is traced with the wide search instead, and so is a frame whose
        band comes within 2 px and two blur sigmas of the window's ends; a
        tracking pass that finds the band where predicted (within 1 px) is final.
        An unreliable tracked result falls back to the wide search, then to the
        global guide.
    refine : float
        Half-width of the final sub-pixel pass.
    station_step : float
        Spacing of the normals along the curve.
    sample_step : float
        Spacing of the samples along each normal.
    smoothing : float
        Expected scatter of the traced points (sets the spline smoothing).
    min_contrast : float
        Band contrast, as a fraction of the flat band's, below which a station
        is not used (nor above 4 noise sigmas) and below which the dome's median
        contrast means ``no_membrane``.
    gap_flag : float
        Longest run without membrane, in band thicknesses, that flags ``fractured``.
    delamination_flag : float
        Rim contact (1 = membrane on the surface at the rim, 0 = lifted) below which
        a frame is ``delaminated``.
    touching_flag : float
        Sustained gap (px) between the dome and another membrane below which a
        frame is ``touching``.
    residual_flag : float
        RMS residual (px) of the traced points about the spline that flags ``poor_fit``.
    asymmetry_flag : float
        Left/right volume disagreement that flags ``poor_fit``.
    max_drift : float
        Largest drift (px) searched by the phase correlation: frame to frame on
        the band route, from the first frame on the silhouette route (a frame
        past it is ``no_membrane``, saying so; raise it when the stage was moved).
    well_membrane_flag : float
        Fraction of the well's interior with membrane contrast above which a frame
        without a dome is ``fractured`` (torn flaps in the well) rather than ``no_membrane``.
    """

    search: float = 20.0
    track_search: float = 5.0
    refine: float = 5.0
    station_step: float = 2.0
    sample_step: float = 0.5
    smoothing: float = 0.35
    min_contrast: float = 0.08
    gap_flag: float = 1.5
    delamination_flag: float = 0.5
    touching_flag: float = 2.5
    residual_flag: float = 1.0
    asymmetry_flag: float = 0.08
    max_drift: float = 40.0
    well_membrane_flag: float = 0.01

    def __post_init__(self):
        for k, v in self.__dict__.items():
            if not (isinstance(v, int | float) and np.isfinite(v) and v > 0):
                raise ValueError(f"TraceSettings.{k} must be a positive number (px or fraction), got {v!r}")
        if self.sample_step > 1.0 or self.station_step > 4.0:
            raise ValueError(f"sample_step must be <= 1 px and station_step <= 4 px, got {self.sample_step!r}, "
                             f"{self.station_step!r}")

    def to_attrs(self) -> dict:
        """netCDF-safe attrs, prefixed ``trace_``."""
        return {f"trace_{k}": float(v) for k, v in self.__dict__.items()}


@dataclass
class FrameTrace:
    """Everything measured in one frame (pixels of the bulge-up view).

    ``u``/``z`` are the dome midline in chamber coordinates (px) from the left
    rim to the right rim (spline samples); ``flag`` is one of :data:`FLAGS`
    and ``figures`` holds every quality figure (the one that triggered the
    flag is named in ``flag_figure``).
    """

    index: int
    ok: bool = False
    geometry: ChamberGeometry | None = None
    u: np.ndarray = field(default_factory=lambda: np.zeros(0))
    z: np.ndarray = field(default_factory=lambda: np.zeros(0))
    points_u: np.ndarray = field(default_factory=lambda: np.zeros(0))  # accepted raw points
    points_z: np.ndarray = field(default_factory=lambda: np.zeros(0))
    source: str = "auto"
    mode: str = ""  # how the dome was found: "track", "guide", "global" (or "" for manual / none)
    volume_left: float = np.nan
    volume_right: float = np.nan
    area_left: float = np.nan
    area_right: float = np.nan
    height: float = np.nan
    residual_rms: float = np.nan
    drift: tuple = (np.nan, np.nan)
    flag: str = "no_membrane"
    flag_figure: str = ""
    flag_value: float = np.nan
    figures: dict = field(default_factory=dict)
    message: str = ""

    @property
    def volume(self):
        return 0.5 * (self.volume_left + self.volume_right)

    @property
    def area(self):
        return 0.5 * (self.area_left + self.area_right)


# ---------------------------------------------------------------------------------- helpers
#: closest approach (px) of the dome to the field's edge below which a frame is poor_fit (``field_margin``): part
#: of the dome may lie outside the frame (measured on a dome growing out of the top of the field, both routes:
#: the stretch outside was read as a tear, ``fractured``, and once the dome was mostly out as ``no_membrane``)
FIELD_MARGIN_PX = 3.0


def field_edge_message(margin, index=None):
    """What a frame flagged by ``field_margin`` says (``index``: the frame whose dome reached the edge, when an
    earlier one)."""
    whose, verb = ("the traced dome", "comes") if index is None else (f"frame {index}'s traced dome", "came")
    where = (f"{verb} within {margin:.1f} px of the field's edge" if margin >= 0.0 else
             f"{'runs' if index is None else 'ran'} {-margin:.0f} px past the field's edge")
    return (f"{whose} {where}: the dome may have grown out of the field, not measured there (keep it in view: a "
            "larger field of view or lower magnification, the chamber nearer the field's centre), or the trace "
            "is not the dome's")


#: a flat band fitted with more scatter than this (px), or this fraction off the first frame's width, is not the
#: film's band (a stretch of it cut by the search window's edge, or another edge)
_BAND_RMS, _BAND_WIDTH = 1.0, 0.25


def first_flag(checks, fig):
    """``(flag, figure, value)`` of the first ``(flag, figure, hit)`` check that hits, else ``("ok", "", nan)``."""
    for name, key, hit in checks:
        if hit:
            return name, key, float(fig[key])
    return "ok", "", np.nan


# ---------------------------------------------------------------------------------- tracer
class ChamberTracer:
    """Follows one chamber through a series, one frame at a time (constant memory).

    Parameters
    ----------
    first_frame : ndarray of shape (H, W)
        A frame with a flat membrane (normally the first of the series).
    bulge_direction : {"auto", "up", "down", "left", "right"}
        Direction the dome grows in the image.
    chamber_region : int or tuple of float, optional
        Which well: index from the left in the bulge-up view or ``(col0, col1)``
        of the view holding its axis; default the most central complete well.
    thickness : float, optional, px
        Membrane thickness (else measured).
    settings : TraceSettings
    """

    route = "band"

    def __init__(self, first_frame, *, bulge_direction="auto", chamber_region=None, thickness=None,
                 settings=None):
        valid = ("auto", *ROTATIONS)
        if bulge_direction not in valid:
            raise ValueError(f"bulge_direction must be one of {valid}, got {bulge_direction!r}")
        frame = np.asarray(first_frame)
        if frame.ndim != 2:
            raise ValueError(f"frames must be 2-D (H, W), got shape {frame.shape}")
        self.settings = settings or TraceSettings()
        coarse = None
        if bulge_direction == "auto":
            coarse = smoothed_coarse(frame)
            bulge_direction, _ = detect_orientation(frame, coarse=coarse)
        self.bulge_direction = bulge_direction
        self.k = ROTATIONS[bulge_direction]
        view = FrameView(frame, self.k)
        # the band search sees the bulge-up view: the orientation's coarse image is that view when unrotated
        self.ref = find_chambers(view, thickness=thickness, chamber=chamber_region,
                                 coarse=coarse if self.k == 0 else None)
        self.shape = frame.shape
        g = self.ref
        # registration patch: the base under the membrane around the well (no dome)
        top = -0.5 * g.thickness - 3.0
        depth = g.well.depth if np.isfinite(g.well.depth) else 4 * g.thickness
        corners = np.array([g.line.point(u, z) for u in (-1.6 * g.rim_radius, 1.6 * g.rim_radius)
                            for z in (0.5 * g.thickness + 6.0, top - depth - 12.0)])
        c0, r0 = np.floor(corners.min(axis=0)).astype(int)
        c1, r1 = np.ceil(corners.max(axis=0)).astype(int) + 1
        self._patch_box = (r0, r1, c0, c1)
        ref_patch, _ = view.patch(r0, r1, c0, c1)
        self._ref_raw = ref_patch.copy()  # the first frame itself is registered without a correlation (a copy:
        # view.patch is a view of a float32 frame, which a caller may reuse for the next frame)
        self._ref_patch = self._highpass(ref_patch)
        # sign of (liquid - base) grey levels: the left wall steps by this sign going right
        zmid = top - 0.4 * depth
        pl = g.line.point(np.array([-0.5 * g.rim_radius, -g.rim_radius - 3 * g.thickness]), zmid)
        liq, bas = view.sample(pl[:, 0], pl[:, 1])
        self._wall_sign = 1.0 if liq >= bas else -1.0
        self.blur = self._estimate_blur(view)
        self._drift = np.zeros(2)  # (dx, dy) of the current frame w.r.t. the first, view px
        self.prev = None  # last good FrameTrace
        self._prev2 = None  # the good one before it (for the motion prediction)
        self._edge_reached = (None, np.inf)  # the last traced frame and its dome's margin to the field's edge, px
        self._motion = self.settings.search  # px, last frame-to-frame motion of the dome
        self._band = np.nan  # px, the last good dome's band width (90th percentile over its stations)
        self._tracking = False  # the last frame processed was good: start from its geometry
        self.priors = {}  # frame index -> (u, z) guide in chamber px
        # flat-line columns: away from every well's rim
        self._flat_u = self._flat_columns(view)
        # the flat band's width as the line fit reads it in this frame (what a later frame's fit is held to;
        # the chamber search's own estimate is another reading); nan, none held to, when the fit is not a band's
        # (a first frame that is not flat: extract says so)
        _, width, _, rms0, _ = measure_line(view, g.line, self._flat_u, polarity=g.polarity, thickness=g.thickness,
                                            window=0.5 * g.thickness + 8.0)
        self._band_width0 = width if np.isfinite(width) and width > 0 and rms0 < _BAND_RMS else np.nan
        self._rim_contact_u = self._rim_contact_columns()
        self._wall_grid = {}  # well depth -> the wall rows and offsets (_wall_rows_at)

    def _rim_contact_columns(self):
        """The 15 flat columns nearest the axis on each side (left, right), where the rim contact is referred to."""
        fars = []
        for sgn in (-1.0, 1.0):
            side = self._flat_u[np.sign(self._flat_u) == sgn]
            if side.size < 5:  # no flat surface on this side in the field: use the other side's
                side = self._flat_u
            fars.append(side[np.argsort(np.abs(side))[:15]])
        return fars

    # ---------------------------------------------------------------------- geometry
    def _estimate_blur(self, view):
        """Gaussian blur (px) of the optics from the 10-90 % rise of the band's upper edge."""
        from osmobulge.imaging._chamber import _transects

        g = self.ref
        us = np.r_[np.linspace(-g.line.x0 + 10, g.well.u_left - 0.6 * g.rim_radius, 15),
                   np.linspace(g.well.u_right + 0.6 * g.rim_radius, view.shape[1] - g.line.x0 - 10, 15)]
        prof, offs = _transects(view, g.line, us, 0.0, 0.5 * g.thickness + 15.0, step=0.25)
        q = g.polarity * -_nanmedian(prof, axis=0)  # band high at offset 0 .. water low
        if not np.all(np.isfinite(q)):
            return 1.0
        hi_, lo_ = q[0], np.median(q[-8:])
        f = (q - lo_) / max(hi_ - lo_, 1e-12)
        i90 = np.flatnonzero(f < 0.9)
        i10 = np.flatnonzero(f < 0.1)
        if not i90.size or not i10.size:
            return 1.0
        d = offs[i10[0]] - offs[i90[0]]
        return float(np.clip(np.sqrt(max((d / 2.563) ** 2 - 1.0 / 12.0, 0.0)), 0.3, 20.0))

    def _flat_columns(self, view):
        g = self.ref
        h, w = view.shape
        x0 = g.line.x0
        us = np.arange(-x0 + 6, w - x0 - 6, 3.0)
        keep = np.ones(us.shape, bool)
        wells = sorted((g.well, *g.others), key=lambda wl: wl.u_left)
        for k, wl in enumerate(wells):
            # keep clear of the rims (domes' feet, delaminated flaps), but never more than 30 % of the
            # surface between two wells (close neighbours); later frames also drop the columns under
            # the last dome's overhang (measure_geometry)
            gl = wl.u_left - wells[k - 1].u_right if k > 0 else np.inf
            gr = wells[k + 1].u_left - wl.u_right if k + 1 < len(wells) else np.inf
            ml = min(0.45 * g.rim_radius + g.thickness, 0.3 * gl)
            mr = min(0.45 * g.rim_radius + g.thickness, 0.3 * gr)
            keep &= ~((us > wl.u_left - ml) & (us < wl.u_right + mr))
        if keep.sum() < 12:  # narrow field: use what lies outside our own well at least
            keep = (us < g.well.u_left - g.thickness) | (us > g.well.u_right + g.thickness)
        return us[keep]

    def _register(self, view):
        """Drift of the frame from phase correlation of the base patch (high-passed: no illumination)."""
        r0, r1, c0, c1 = self._patch_box
        dx, dy = np.round(self._drift).astype(int)
        cur, _ = view.patch(r0 + dy, r1 + dy, c0 + dx, c1 + dx)
        if (cur.shape[0] // 2, cur.shape[1] // 2) != self._ref_patch.shape:
            return self._drift.copy()
        if cur.shape == self._ref_raw.shape and np.array_equal(cur, self._ref_raw):
            return np.array([dx, dy], float)  # the reference patch itself (the first frame): no shift
        cur = self._highpass(cur)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # an empty (black) frame: no RMS error estimate
            shift, _, _ = phase_cross_correlation(self._ref_patch, cur, upsample_factor=1, normalization=None)
        # the shift registers the current patch onto the reference one (2x downsampled)
        return np.array([dx - 2 * shift[1], dy - 2 * shift[0]], float)

    @staticmethod
    def _highpass(patch):
        """2x block mean minus a smooth background (removes uneven illumination)."""
        p = block_mean(np.ascontiguousarray(patch, np.float32), 2)
        return p - ndi.uniform_filter(p, 9, mode="nearest")

    def _coarse_line(self, view, line):
        """Move the predicted line onto the band with a wide box-filter search (robust to bad drift)."""
        g0 = self.ref
        us = self._flat_u[:: max(1, len(self._flat_u) // 60)]
        half = 0.5 * g0.thickness + self.settings.max_drift
        from osmobulge.imaging._chamber import _transects

        prof, offs = _transects(view, line, us, -half, half, step=1.0)
        prof = np.where(np.isfinite(prof), prof, _nanmedian(prof))
        q = g0.polarity * -_nanmedian(prof, axis=0)  # median over columns: dust-free band profile
        if not np.all(np.isfinite(q)):
            return line
        w = max(1, int(round(g0.thickness)))
        fl = max(2, int(round(0.25 * g0.thickness)) + 2)
        c = np.convolve(q, np.ones(w) / w, mode="same")
        left = np.convolve(q, np.ones(fl) / fl, mode="same")
        side = 0.5 * (np.roll(left, (w + fl) // 2 + 1) + np.roll(left, -((w + fl) // 2 + 1)))
        score = c - side
        score[: w + fl] = -np.inf
        score[-(w + fl):] = -np.inf
        return line.shifted(0.0, float(offs[int(np.argmax(score))]))

    def _wall_rows_at(self, depth):
        """Rows and offsets of the coarse wall search and of the wall fits (cached: the same every frame)."""
        key = float(depth) if np.isfinite(depth) else None  # (nan keys never match: one entry a call)
        cache = self._wall_grid
        if key not in cache:
            g0 = self.ref
            top = -0.5 * g0.thickness
            d = depth if np.isfinite(depth) else 4.0 * g0.thickness
            span = self.settings.max_drift
            cache[key] = (top - np.linspace(0.2, 0.7, 9) * d, np.arange(-span, span + 1e-9, 1.0),
                          top - np.linspace(0.06, 0.92, int(np.clip(0.86 * d, 8, 250))) * d,
                          np.arange(-WALL_WINDOW, WALL_WINDOW + 1e-9, 0.5))
        return cache[key]

    def _walls(self, view, line, well):
        """Both walls of a frame near their prediction: the refined :class:`Well` and the wall RMS (None, nan: lost).

        First the predicted walls move onto the strongest edges of the right
        sign within ``max_drift`` (median over 9 rows), then
        :func:`~osmobulge.imaging._chamber.measure_walls` fits them: both
        compiled in one call (:func:`~osmobulge.imaging._kernels.locate_walls`);
        ``measure_walls`` itself runs when a first fit is poor (its robust second
        attempt).
        """
        g0 = self.ref
        zs_c, offs_c, zs, offs = self._wall_rows_at(well.depth)
        status, cl, cr, al, bl, ar, br, rms = locate_walls(
            view.frame, view.k, float(line.x0), float(line.y0), *line._dn,
            float(well.u_left), float(well.u_right), float(well.slope_left), float(well.slope_right),
            float(self._wall_sign), zs_c, offs_c, zs, -0.5 * g0.thickness, offs)
        if status == 1:
            return None, np.nan
        if status == 2:
            well = replace(well, u_left=float(cl), u_right=float(cr))
            return measure_walls(view, line, well, thickness=g0.thickness, window=WALL_WINDOW)
        return Well(float(al), float(ar), float(bl), float(br), well.depth), float(rms)

    def measure_geometry(self, view):
        """Drift, flat line, walls and rim of the chamber in one frame (a :class:`ChamberGeometry`).

        While tracking (the last frame was good) the chamber is looked for where
        the last frame put it: first with the fine line fit alone (a vertical
        drift of a few px), then with the wide line search before it (up to
        ``max_drift``; the walls always get their wide search).  Otherwise, and
        again when the tracked geometry is implausible (walls lost, or the rim
        radius jumped), the phase correlation of the base runs first.
        """
        if self._tracking and self.prev is not None and self.prev.geometry is not None:
            geom, drift = self._geometry_at(view, self._drift.copy(), coarse=False)
            if geom is None:  # moved beyond the fine windows: the wide searches from the same place
                geom, drift = self._geometry_at(view, self._drift.copy())
            gp = self.prev.geometry
            if geom is not None and abs(geom.rim_radius - gp.rim_radius) <= 2.0 + 0.02 * gp.rim_radius:
                return geom, drift
        drift = self._register(view)
        if not np.all(np.isfinite(drift)) or np.hypot(*(drift - self._drift)) > self.settings.max_drift:
            drift = self._drift.copy()
        return self._geometry_at(view, drift)

    def _geometry_at(self, view, drift, *, coarse=True):
        """Geometry near the predicted position; ``coarse=False``: no wide line search (None when it was needed)."""
        g0 = self.ref
        angle, well = g0.line.angle, g0.well
        if self.prev is not None and self.prev.geometry is not None:
            angle = self.prev.geometry.line.angle
            w = self.prev.geometry.well
            well = Well(w.u_left, w.u_right, w.slope_left, w.slope_right, g0.well.depth)
        line = Line(g0.line.x0 + drift[0], g0.line.y0 + drift[1], angle)
        if coarse:
            line = self._coarse_line(view, line)
        win = 0.5 * g0.thickness + 8.0
        us = self._flat_u
        if self.prev is not None and len(self.prev.u):
            # skip columns where the last dome (its overhang) comes down into the search window
            clear = clear_of_curve(us, np.ascontiguousarray(self.prev.u, np.float64),
                                   np.ascontiguousarray(self.prev.z, np.float64), 0.5 * g0.thickness + win + 6.0, 6.0)
            if np.count_nonzero(clear) >= 12:
                us = us[clear]
        predicted = line
        line, thick, con, rms, inl = measure_line(view, line, us, polarity=g0.polarity,
                                                  thickness=g0.thickness, window=win)
        if not coarse:
            # the fine window holds the band only when it moved less than a few px: else its contrast drops, and
            # a band cut by the window's edge reads thin and scattered (below: the stage moved 12 px between
            # frames, the line fitted 4.5 px from where it was, the band 9.7 px for 24.9, scatter 1.9 px for 0.03,
            # its contrast 0.52 of the first frame's; the frame read 5x its volume tolerance off, ok)
            _, _, n0, n1 = line._dn
            dz = abs((line.x0 - predicted.x0) * n0 + (line.y0 - predicted.y0) * n1)
            if not (dz < 6.0 and abs(con) > 0.5 * abs(g0.contrast)):
                return None, drift
        # (a nan width held to compares False: not checked)
        if (np.isfinite(rms) and rms >= _BAND_RMS) or abs(thick - self._band_width0) >= _BAND_WIDTH * self._band_width0:
            # not the film's band (the wide search, after the stage moved further than the drift read: a band
            # 1.9 px wide, scattered 9.3 px, read 8x the volume tolerance off, ok): no chamber here
            return None, drift
        well, wall_rms = self._walls(view, line, well)
        if well is None:
            return None, drift
        ax = well.centre
        line = line.shifted(ax, 0.0)
        well = Well(well.u_left - ax, well.u_right - ax, well.slope_left, well.slope_right, well.depth)
        if not (np.isfinite(con) and abs(con) > 0.3 * abs(g0.contrast)):
            con = g0.contrast  # too few clean flat columns in this frame: keep the first frame's
        # (direct constructors, not dataclasses.replace: this runs every frame)
        geom = ChamberGeometry(line=line, thickness=g0.thickness, polarity=g0.polarity, rim_radius=well.half_width,
                               well=well, others=g0.others, contrast=con, line_rms=rms, wall_rms=wall_rms)
        return geom, drift

    # ---------------------------------------------------------------------- guides
    def _global_guide(self, view, g):
        """Minimum-cost path rim to rim on a coarse, background-flattened image (chamber px)."""
        R = g.rim_radius
        f = max(1, int(round(R / 50.0)))
        umax = 2.1 * R
        zmax = 3.3 * R
        corners = np.array([g.line.point(u, z) for u in (-umax, umax) for z in (-g.thickness, zmax)])
        c0, r0 = np.floor(corners.min(axis=0)).astype(int)
        c1, r1 = np.ceil(corners.max(axis=0)).astype(int) + 1
        coarse, (pr0, pc0) = view.block_mean(r0, r1, c0, c1, f)  # f x f block means of the patch (compiled)
        hh, ww = coarse.shape[0] * f, coarse.shape[1] * f
        if hh < 4 * f or ww < 4 * f:
            return None
        bg = ndi.gaussian_filter(coarse, 8.0, mode="nearest")
        con = g.polarity * (bg - coarse) / np.maximum(np.abs(bg), 1e-9)
        if np.isfinite(g.contrast):
            ref = abs(g.contrast) / max(np.median(np.abs(bg)), 1e-9)
        else:
            ref = np.percentile(con, 99.5)
        c = np.clip(con / max(ref, 1e-9), 0.0, 1.0)
        cost = 1.0 / (0.04 + c) ** 2
        # coarse pixel centres in view coordinates -> chamber (u, z)
        nr, nc = coarse.shape
        pts = np.empty((nr, nc, 2))
        pts[..., 0] = pc0 + f * np.arange(nc) + (f - 1) / 2.0
        pts[..., 1] = (pr0 + f * np.arange(nr) + (f - 1) / 2.0)[:, None]
        u, z = g.line.coords(pts.reshape(-1, 2))
        u = u.reshape(nr, nc)
        z = z.reshape(nr, nc)
        cost[z < -0.5 * f - 1.0] = 1e6  # never below the flat membrane (the well)
        cost[np.abs(u) > umax] = 1e6

        def node(uu):
            p = g.line.point(uu, 0.0)
            j = int(np.clip(round((p[0] - pc0 - (f - 1) / 2.0) / f), 0, ww // f - 1))
            i = int(np.clip(round((p[1] - pr0 - (f - 1) / 2.0) / f), 0, hh // f - 1))
            return i, j

        path, _ = route_through_array(cost, node(-R), node(R), fully_connected=True, geometric=True)
        path = np.asarray(path)
        pu, pz = u[path[:, 0], path[:, 1]], z[path[:, 0], path[:, 1]]
        if len(pu) >= 5:
            pu = ndi.uniform_filter1d(pu, 3, mode="nearest")
            pz = ndi.uniform_filter1d(pz, 3, mode="nearest")
        return np.c_[pu, pz], 1.5 * f + 2.0

    # ---------------------------------------------------------------------- refinement
    def _refine(self, view, g, guide_uz, half, *, dp=True, width=None, band=None):
        """One pass along the guide's normals: band midline offsets and station data.

        ``dp``: wide pass choosing a smooth path through the band by dynamic
        programming; else the peak is looked for within ``half`` of the guide
        (or, with ``width``, within the band's half-width).  The window reaches
        ``half`` beyond half of ``band`` (px; default the flat band's thickness).
        """
        st = self.settings
        guide = g.line.point(guide_uz[:, 0], guide_uz[:, 1])
        # the wide dynamic-programming pass samples twice as coarsely as the final ones
        step, sstep = (2.0 * st.station_step, 2.0 * st.sample_step) if dp else (st.station_step, st.sample_step)
        # stations every `step` along the guide, their normals (to the left of travel; travel is left rim ->
        # right rim, so "left" is outward, up) and the transects there, nan-filled and smoothed along the curve
        band = g.thickness if band is None else band
        w = half + 0.5 * band
        offs = np.arange(-w, w + 1e-9, sstep)
        pts, s, nrm, prof = guide_transects(view.frame, view.k, guide, step, offs, 1.0 / step)
        if dp:
            q = g.polarity * (np.median(prof, axis=1, keepdims=True) - prof)
            dec = max(1, int(round(3.0 / step)))
            sub = max(1, int(round(1.0 / sstep)))
            # cap the score at the membrane's typical contrast: a dark speck (dust) can then
            # score no more than the membrane, and the smooth path does not detour to it
            # (a running median along the curve, so a faint thin pole is capped at its own level)
            cap = ndi.median_filter(q.max(axis=1), 41, mode="nearest")
            cap = np.maximum(cap, 1e-12 + 0.05 * float(np.median(cap)))
            sc = (q / cap[:, None])[::dec, ::sub]
            path = viterbi_path(np.clip(sc, -0.5, 1.0), max_step=max(1, int(round(dec * step))), penalty=0.3)
            centre = np.interp(np.arange(len(q)), np.arange(0, len(q), dec)[: len(path)], path * sub)
            centre = centre.round().astype(int)
            # the path lies inside the band (thick or thin): look for the peak only close to it
            search = int(round((2.0 + 1.5 * self.blur) / sstep))
        else:
            centre = np.full(len(prof), len(offs) // 2)
            if width is None:
                search = int(round((0.5 * band + half) / sstep))
            else:  # the peak lies within the band's own half-width of the guide (never on a nearby speck)
                wi = np.interp(s, width[0], width[1])
                search = np.round((0.5 * wi + 2.0 + 1.5 * self.blur) / sstep).astype(int)
        mid, lo, hi, con, width = band_edges(prof, offs, g.polarity, centre=centre, search=search,
                                             side=max(2, int(1.5 / sstep)))
        # noise of a single sample, from differences at the window ends (away from the band)
        noise = float(ends_noise(prof))
        return {"mid": mid, "lo": lo, "hi": hi, "contrast": con, "width": width, "stations": s, "noise": noise,
                "station_pts": pts, "normals": nrm, "half": w}

    def _track_pass(self, view, g, guide_uz, half, ref_con):
        """:meth:`_refine` (a narrow pass, no dynamic programming), :meth:`_clean` and the pass's motion, compiled.

        One call of :func:`~osmobulge.imaging._kernels.track_pass` (tested
        equal to the three steps): the tracked frame's pass.  Its window reaches
        ``half`` beyond half the last good dome's band width (the 90th percentile
        over its stations, never more than the flat band's thickness): the band
        thins as the dome stretches (to a quarter of the flat band's width at
        Vtilde 5), and so does the window, with the same margin about it.
        """
        st = self.settings
        band = self._track_band(g)
        w = half + 0.5 * band
        offs = np.arange(-w, w + 1e-9, st.sample_step)
        line = g.line
        zc, near = self._exclusion_zone(g)
        (pts, s, nrm, mid, lo, hi, con, width, noise, pu, pz, good, excl, use, sigma, motion) = track_pass(
            view.frame, view.k, np.ascontiguousarray(guide_uz[:, 0], np.float64),
            np.ascontiguousarray(guide_uz[:, 1], np.float64), float(line.x0), float(line.y0), *line._dn,
            float(st.station_step), offs, float(g.polarity),
            int(round((0.5 * band + half) / st.sample_step)), max(2, int(1.5 / st.sample_step)),
            float(g.rim_radius), float(zc), float(near), float(st.min_contrast), float(ref_con), 15)
        sigma = st.smoothing if not np.isfinite(sigma) else sigma
        return {"mid": mid, "lo": lo, "hi": hi, "contrast": con, "width": width, "stations": s, "noise": float(noise),
                "station_pts": pts, "normals": nrm, "half": w, "pu": pu, "pz": pz, "good": good, "excluded": excl,
                "use": use, "sigma": min(max(float(sigma), 0.01), 3.0), "motion": float(motion)}

    def _track_band(self, g):
        """Band width (px) the tracking window is sized from: the last good dome's, at most the flat band's."""
        return min(g.thickness, self._band) if np.isfinite(self._band) else g.thickness

    def _exclusion_zone(self, g):
        """Height below which the band beyond a rim is flat, and the radius of the corner blob at a rim point.

        Points there (``_kernels.rim_zone``) are merged with the flat band and not trusted: within half a
        band thickness, 2 px and two blur sigmas of the rim point the dome's band and the flat band's
        corner are one blob, also just inside the rim; a station there is pulled off the dome and bends
        the bridge to the rim.
        """
        return g.thickness + 3.0, 0.5 * g.thickness + 2.0 + 2.0 * self.blur  # half a band and the blur round the rim

    def trace_dome(self, view, g, guide=None, *, track=False):
        """Trace the dome given the frame geometry; returns a dict of results (chamber px).

        Escalates until a result is trustworthy: a narrow tracking pass from
        ``guide`` (``track``: the previous frame's dome), the wide dynamic-programming
        search from ``guide``, then the global guide.
        """
        st = self.settings
        R = g.rim_radius
        # tracking only while the prediction is good: a wider window needs the robust wide search
        # (wide enough that the band's far edge stays 2 px + 2 blur sigmas inside the window)
        half_track = max(st.track_search, 1.5 * self._motion + 4.0 + 2.0 * self.blur)
        if guide is None:
            attempts = ["global"]
        else:
            attempts = (["track"] if track and half_track <= 2.0 * st.track_search else []) + ["guide", "global"]
        out = None
        for mode in attempts:
            if mode == "global":
                res = self._global_guide(view, g)
                if res is None:
                    break
                gu, half = res
            else:
                gu = guide
                half = st.search if mode == "guide" else half_track
            # guide from rim to rim through the current rim points (its points in the rim zones dropped)
            ok, gu = rim_guide(np.ascontiguousarray(gu, np.float64), float(R), *self._exclusion_zone(g))
            if not ok:
                gu = np.concatenate([[[-R, 0.0]], np.c_[np.linspace(-R, R, 20), np.zeros(20)], [[R, 0.0]]])
            res = self._passes(view, g, gu, half, track=mode == "track")
            if res is not None:
                res["mode"] = mode
            if mode == "track":
                if res is not None and self._trustworthy(res):
                    return res
                continue
            out = res
            if out is not None and (mode == "global" or self._trustworthy(out)):
                break
        return out

    def _predicted_guide(self, index):
        """The dome expected in frame ``index``: the last one moved as it moved since the one before.

        Points at equal fractions of the arc length correspond; without a good
        frame just before the last, the last dome itself.
        """
        p, q = self.prev, self._prev2
        if (q is None or q.index != p.index - 1 or p.index != index - 1 or len(q.u) < 4 or p.source != "auto"
                or q.source != "auto"):
            return np.column_stack((p.u, p.z))
        c = np.ascontiguousarray
        return extrapolated_curve(c(p.u, np.float64), c(p.z, np.float64), c(q.u, np.float64), c(q.z, np.float64))

    def _trustworthy(self, tr):
        """A tracked (not global) result good enough to keep: strong band along the whole dome.

        Strong: median band contrast above half the flat band's or, tracking from
        the last frame, above 0.8x the last dome's (a thinning membrane fades
        slowly; a lost track drops at once).
        """
        dome = ~tr["excluded"]
        n_dome = np.count_nonzero(dome)
        if not n_dome:
            return False
        con = self._dome_median(tr)
        strong = con > 0.5 * tr["ref_contrast"]
        if tr.get("mode") == "track" and self.prev is not None:
            strong = strong or con > 0.8 * self.prev.figures.get("dome_contrast", np.inf) * tr["ref_contrast"]
        # the fraction of good dome stations (as np.mean of the booleans: an exact count over an exact count)
        return bool(np.count_nonzero(tr["good"] & dome) / n_dome > 0.9 and strong
                    and tr["residual_rms"] < self.settings.residual_flag and tr["converged"]
                    and tr["edge_fraction"] < 0.05)

    @staticmethod
    def _dome_median(tr):
        """Median band contrast of a pass's dome stations (not excluded; once per pass, kept in ``tr``)."""
        if "dome_median" not in tr:
            con = np.ascontiguousarray(tr["contrast"], np.float64)
            tr["dome_median"] = float(masked_nanmedian(con, tr["excluded"]))
        return tr["dome_median"]

    def _clean(self, g, r, ref_con):
        """Accepted stations of a pass: finite, enough contrast, outside the rim zones, not outliers.

        A station sees the membrane when its band stands out of the flat band's
        scale and the noise; outliers are far from a running median (15
        stations) of the offsets along the curve.  Compiled
        (:func:`~osmobulge.imaging._kernels.clean_stations`).
        """
        st = self.settings
        line = g.line
        sp, nrm = r["station_pts"], r["normals"]
        d, nv = line.direction, line.normal
        pu, pz, good, excl, use, sigma = clean_stations(
            np.ascontiguousarray(r["mid"], np.float64), np.ascontiguousarray(r["contrast"], np.float64),
            np.ascontiguousarray(sp[:, 0]), np.ascontiguousarray(sp[:, 1]), np.ascontiguousarray(nrm[:, 0]),
            np.ascontiguousarray(nrm[:, 1]), float(line.x0), float(line.y0), float(d[0]), float(d[1]), float(nv[0]),
            float(nv[1]), float(g.rim_radius), *self._exclusion_zone(g),
            float(max(st.min_contrast * ref_con, 4.0 * r.get("noise", 0.0))), 15)
        sigma = st.smoothing if not np.isfinite(sigma) else sigma
        r.update(pu=pu, pz=pz, good=good, excluded=excl, use=use, sigma=min(max(float(sigma), 0.01), 3.0))
        return r

    @staticmethod
    def _lsq(u, pts, w, spacing):
        """Least-squares cubic spline of pts (N, 2) over parameter u with knots at data quantiles."""
        sel = w > 0
        chord = float(np.sum(np.hypot(*np.diff(pts[sel], axis=0).T)))
        n_int = int(np.clip(np.floor(chord / spacing), 0, max(int(sel.sum()) - 4, 0)))
        inner = sorted_quantile(u[sel][1:-1], np.linspace(0.0, 1.0, n_int + 2)[1:-1]) if n_int else np.zeros(0)
        t = np.concatenate(([u[0]] * 4, inner, [u[-1]] * 4))
        return lsq_spline(u, pts, t, w)

    @classmethod
    def _final_fit(cls, U, Z, ks, *, pinned=True, step=1.0):
        """The final :meth:`_robust_fit`, compiled, and its curve sampled every ``step`` px of arc length (N, 2).

        :func:`~osmobulge.imaging._kernels.robust_profile_spline` does the same
        arithmetic as :meth:`_robust_fit` (tested equal); scipy's solver takes
        over when a band system is singular.
        """
        U, Z = np.ascontiguousarray(U, np.float64), np.ascontiguousarray(Z, np.float64)
        status, keep, t, c, res, uu, ss, curve = robust_profile_spline(U, Z, float(ks), bool(pinned), float(step))
        if status == 0:
            spl = interpolate.BSpline.construct_fast(t, c, 3, axis=1)
            return ProfileSpline(spline=spl, length=float(ss[-1]), residuals=res,
                                 _u_of_s=partial(np.interp, xp=ss, fp=uu)), keep, curve
        spl, keep = cls._robust_fit(U, Z, ks, pinned=pinned)
        return spl, keep, spl.sample(step=step)[1]

    @classmethod
    def _robust_fit(cls, U, Z, ks, *, pinned=True, final=True):
        """Spline through (U, Z) rejecting outliers (dust bumps) against a stiff spline first (numpy/scipy).

        The ends are pinned (weight 10) when ``pinned``.  Returns the final
        :class:`~osmobulge.imaging.geometry.ProfileSpline` (knots ``ks`` apart; or
        the stiff spline sampled every pixel when ``final`` is False) and the
        mask of kept points.  Used for the guide's stiff curve and as the
        fallback of :meth:`_final_fit`, the compiled final fit.
        """
        pts = np.column_stack((U, Z))
        n = len(U)
        seg = np.hypot(*np.diff(pts, axis=0).T)
        u = np.concatenate(([0.0], np.cumsum(np.maximum(seg, 1e-9))))
        wts = np.ones(n)
        inner = np.ones(n, bool)
        if pinned:
            wts[[0, -1]] = 10.0
            inner[[0, -1]] = False
        keep = np.ones(n, bool)
        stages = ((max(15.0, 2.5 * ks), 1.0, 3),) + (((ks, 0.75, 1),) if final else ())
        for spacing, floor, iters in stages:
            for _ in range(iters):
                spl = cls._lsq(u, pts, np.where(keep, wts, 0.0), spacing)
                res = np.hypot(*(spl(u) - pts).T)
                sel = keep & inner
                mad = 1.4826 * _nanmedian(res[sel]) if sel.any() else 0.0
                new = np.isfinite(res) & (res <= max(3.5 * mad, floor))
                if pinned:
                    new[[0, -1]] = True
                if np.array_equal(new, keep) or new.sum() < 6:
                    break
                keep = new
        if not final:
            return spl(np.linspace(u[0], u[-1], max(int(u[-1]), 2))), keep
        return smooth_profile(pts, knot_spacing=ks, weights=np.where(keep, wts, 0.0)), keep

    def _guide_from(self, g, r, ks):
        R = g.rim_radius
        use = r["use"]
        U = np.concatenate(([-R], r["pu"][use], [R]))
        Z = np.concatenate(([0.0], r["pz"][use], [0.0]))
        curve, _ = self._robust_fit(U, Z, max(ks, 8.0), final=False)
        return curve

    @staticmethod
    def _offset_guide(g, r):
        """Next guide of a tracking pass: the stations moved by their smoothed band offsets (chamber px)."""
        use = r["use"]
        mid = np.interp(np.arange(len(use)), np.flatnonzero(use), r["mid"][use])
        mid = ndi.gaussian_filter1d(ndi.median_filter(mid, 9, mode="nearest"), 2.0, mode="nearest")
        pu, pz = g.line.coords(r["station_pts"] + mid[:, None] * r["normals"])
        return np.column_stack((pu, pz))

    def _passes(self, view, g, guide_uz, half, *, track=False):
        st = self.settings
        R = g.rim_radius
        ref_con = abs(g.contrast) if np.isfinite(g.contrast) else None
        # pass 1: wide search with dynamic programming and a robust stiff spline for the next guide, or
        # (tracking from the last frame) a narrow search and the stations moved by their smoothed offsets
        if track and ref_con is not None:  # the narrow pass, cleaned, and its motion: one compiled call
            r = self._track_pass(view, g, guide_uz, half, ref_con)
        else:
            r = self._refine(view, g, guide_uz, half, dp=not track)
            if ref_con is None:
                ref_con = float(np.nanpercentile(r["contrast"], 90))
            r = self._clean(g, r, ref_con)
        use = r["use"]
        if np.count_nonzero(use) < 6:
            return None
        motion = moved = r["motion"] if "motion" in r else float(abs_percentile(r["mid"], use, 90.0))
        if track and motion > half - 2.0 - 2.0 * self.blur:
            # the band came close to the window's end (the prediction was off): its edges and width are
            # not to be trusted -- the wide search takes over
            return None
        ks = min(max(4.0 + 10.0 * r["sigma"], 4.0), 15.0)
        # a fine tracking pass that found the band where predicted is final; else narrow passes around
        # the last curve, repeated until it stops moving
        n_more = 0 if (track and motion < 1.0) else 3
        if n_more:
            uz = self._offset_guide(g, r) if track else self._guide_from(g, r, ks)
            wd = np.where(use, r["width"], np.nan)
            ok_w = np.isfinite(wd)
            wmed = ndi.median_filter(np.interp(np.arange(len(wd)), np.flatnonzero(ok_w), wd[ok_w]), 31,
                                     mode="nearest")
        for _ in range(n_more):
            sw = resample_polyline(g.line.point(uz[:, 0], uz[:, 1]), st.station_step)[1]
            width = (np.linspace(0.0, sw[-1], len(wmed)), wmed)
            r = self._refine(view, g, uz, st.refine, dp=False, width=width)
            r = self._clean(g, r, ref_con)
            use = r["use"]
            if use.sum() < 6:
                return None
            moved = float(abs_percentile(r["mid"], use, 90.0))
            if moved < 1.0:
                break
            uz = self._offset_guide(g, r) if track else self._guide_from(g, r, ks)
        r["converged"] = moved < 1.0
        r["motion"] = motion
        ks = min(max(4.0 + 10.0 * r["sigma"], 4.0), 15.0)
        # bridges to the rims, the final robust spline and the pass figures: one compiled call
        # (the scipy solver takes over when a band system is singular, as in _final_fit)
        status, U, Z, keep, _, _, res, _, _, puz, rms, edge_fraction = pass_tail(
            np.ascontiguousarray(r["pu"], np.float64), np.ascontiguousarray(r["pz"], np.float64), use, float(R),
            _BRIDGE_REACH, ks, 1.0, np.ascontiguousarray(r["lo"], np.float64),
            np.ascontiguousarray(r["hi"], np.float64), float(r["half"]))
        if status != 0:
            spl, keep, puz = self._final_fit(U, Z, ks)
            res = spl.residuals
        inner = keep.copy()
        inner[0] = inner[-1] = False
        if status != 0:
            rms = float(np.sqrt(np.mean(res[inner] ** 2))) if inner.any() else np.nan
        r.update(
            u=np.ascontiguousarray(puz[:, 0]),  # contiguous once here (the next kernels take them as they are)
            z=np.ascontiguousarray(puz[:, 1]),
            points_u=U[inner],
            points_z=Z[inner],
            residual_rms=float(rms),
            edge_fraction=float(edge_fraction),
            ref_contrast=ref_con,
        )
        return r

    # ---------------------------------------------------------------------- quality figures
    def _figures(self, view, g, tr):
        R = g.rim_radius
        fig = {}
        con, excl = tr["contrast"], tr["excluded"]
        ds = np.diff(tr["stations"], prepend=tr["stations"][0])  # station spacing, 0 for the first
        dome = ~excl
        ref = tr["ref_contrast"]
        fig["dome_contrast"] = float(self._dome_median(tr) / ref) if dome.any() and ref > 0 else 0.0
        # the dome reaching the field's edge (part of it outside the frame)
        fig["field_margin"] = self._field_margin(view, g, tr)
        # gaps: stations whose band contrast drops well below the dome's own (a running 80th percentile
        # along the curve: the thin pole is fainter than the rims) and into the noise
        fig["gap_length"] = float(low_contrast_run(np.ascontiguousarray(con, np.float64), dome, ds,
                                                   float(tr.get("noise", 0.0))) / max(g.thickness, 1.0))
        # rim contact: membrane on the flat line just outside each rim, as a fraction of the
        # band's contrast against the water on the nearest flat columns (1 = on the surface, 0 = lifted)
        # (compiled: the band at the rim, the band far out and the water above it, both sides in one call)
        fig["rim_contact"] = float(rim_contact(
            view.frame, view.k, float(g.line.x0), float(g.line.y0), *g.line._dn, float(R),
            0.5 * g.thickness + 3.0 * self.blur + 4.0, _RIM_FRACTIONS,
            *self._rim_contact_u))
        # sustained gap to another membrane beyond the band, both sides of the dome
        fig["neighbour_gap"] = self._neighbour_gap(view, g, tr) if self._neighbour_possible(view, g, tr) else np.inf
        fig["residual_rms"] = tr["residual_rms"]
        return fig

    @staticmethod
    def _extent(g, tr):
        """The traced curve's largest distance from the axis (px) and its least and greatest column and least row
        (view)."""
        return curve_extent(np.ascontiguousarray(tr["u"], np.float64), np.ascontiguousarray(tr["z"], np.float64),
                            float(g.line.x0), float(g.line.y0), *g.line._dn)

    def _field_margin(self, view, g, tr):
        """The traced curve's closest approach (px) to the field's edge (< 0: beyond it)."""
        _, xmin, xmax, ymin = self._extent(g, tr)
        return float(min(xmin, view.shape[1] - 1 - xmax, ymin))

    def _neighbour_possible(self, view, g, tr):
        """Could another bulge reach the dome?  A well within reach, or the dome near the field's edge."""
        umax, xmin, xmax, ymin = self._extent(g, tr)
        reach = umax + 2.5 * g.rim_radius
        if any(min(abs(wl.u_left), abs(wl.u_right)) < reach for wl in g.others):
            return True
        h, w = view.shape
        margin = 0.5 * g.rim_radius
        return bool(xmin < margin or xmax > w - margin or ymin < margin)

    def _neighbour_gap(self, view, g, tr):
        """Gap (px) between the dome's band and the nearest *other* long membrane (a neighbour's bulge).

        Membrane-like pixels around the dome (background-flattened contrast above
        half the dome's own), minus the dome's band, the flat band and the base,
        are grouped into connected pieces; pieces shorter than twice the membrane
        thickness (dust) are ignored.  The figure is the smallest distance from
        the dome's midline to a remaining piece, less the dome's half-width.
        """
        from scipy.spatial import cKDTree

        f = 2

        u, z = tr["u"], tr["z"]
        pts = g.line.point(u, z)
        reach = 2.0 * g.thickness + 4.0 * self.blur + 10.0
        (c0, r0), (c1, r1) = np.floor(pts.min(axis=0) - reach), np.ceil(pts.max(axis=0) + reach)
        patch, (pr0, pc0) = view.patch(r0, r1, c0, c1)
        hh, ww = patch.shape[0] // f * f, patch.shape[1] // f * f
        if hh < 8 or ww < 8:
            return np.inf
        img = patch[:hh, :ww].reshape(hh // f, f, ww // f, f).mean(axis=(1, 3))
        bg = ndi.gaussian_filter(img, 12.0, mode="nearest")
        con = g.polarity * (bg - img) / max(abs(g.contrast), 1e-9)
        dome_con = float(_nanmedian(tr["contrast"][~tr["excluded"]])) / max(abs(g.contrast), 1e-9)
        mask = con > max(0.5 * dome_con, 0.1)
        yy, xx = np.nonzero(mask)
        if yy.size == 0:
            return np.inf
        vx = pc0 + f * xx + (f - 1) / 2.0
        vy = pr0 + f * yy + (f - 1) / 2.0
        pu, pz = g.line.coords(np.c_[vx, vy])
        tree = cKDTree(pts)
        dist, idx = tree.query(np.c_[vx, vy])
        half = np.interp(
            np.arange(len(u)),
            np.linspace(0, len(u) - 1, len(tr["width"])),
            np.nan_to_num(ndi.median_filter(np.nan_to_num(tr["width"], nan=0.0), 21), nan=0.0),
        )
        excl_r = 0.5 * half[idx] + 1.5 * self.blur + 2.0 + f
        own = dist <= excl_r
        flat = pz < g.thickness + 2.0 * self.blur + 2.0
        keep = ~own & ~flat & (dist <= reach)
        if not keep.any():
            return np.inf
        lab = np.zeros(mask.shape, np.int32)
        sub = np.zeros(mask.shape, bool)
        sub[yy[keep], xx[keep]] = True
        lab, n = ndi.label(sub, structure=np.ones((3, 3)))
        if n == 0:
            return np.inf
        objs = ndi.find_objects(lab)
        long_ = np.zeros(n + 1, bool)
        min_len = max(2.0 * g.thickness, 30.0) / f
        for k, sl in enumerate(objs, start=1):
            if sl is not None and np.hypot(sl[0].stop - sl[0].start, sl[1].stop - sl[1].start) >= min_len:
                long_[k] = True
        sel = keep & long_[lab[yy, xx]]
        if not sel.any():
            return np.inf
        # 0 when a foreign membrane reaches the edge of the dome's own band
        return float(max(np.min(dist[sel] - excl_r[sel]), 0.0))

    def _well_membrane(self, view, g):
        """Fraction of the well's interior showing membrane contrast (torn flaps hanging into it)."""
        R = g.rim_radius
        depth = g.well.depth if np.isfinite(g.well.depth) else 4.0 * g.thickness
        top = -0.5 * g.thickness
        uu = np.arange(-0.9 * R, 0.9 * R, 2.0)
        zz = np.arange(top - 3.0 * self.blur - 2.0, top - depth + 3.0 * self.blur + 2.0, -2.0)
        if uu.size == 0 or zz.size == 0:
            return 0.0
        pts = g.line.point(uu[None, :], zz[:, None])
        vals = view.sample(pts[..., 0], pts[..., 1])
        liquid = _nanmedian(vals)
        q = g.polarity * (liquid - vals) / max(abs(g.contrast), 1e-9)
        return float(np.mean(q > 0.5))

    def _flag(self, fig):
        st = self.settings
        checks = [
            ("no_membrane", "dome_contrast", fig["dome_contrast"] < st.min_contrast),
            ("poor_fit", "field_margin", fig.get("field_margin", np.inf) < FIELD_MARGIN_PX),
            # (the rim read in light the camera clipped)
            ("poor_fit", "clipped", fig.get("clipped", 0.0) > MOVED_FLAG),
            ("delaminated", "rim_contact", fig["rim_contact"] < st.delamination_flag),
            ("fractured", "gap_length", fig["gap_length"] > st.gap_flag),
            ("touching", "neighbour_gap", fig["neighbour_gap"] < st.touching_flag),
            ("poor_fit", "residual_rms", not fig["residual_rms"] <= st.residual_flag),
            ("poor_fit", "volume_disagreement", fig.get("volume_disagreement", 0.0) > st.asymmetry_flag),
        ]
        return first_flag(checks, fig)

    # ---------------------------------------------------------------------- one frame
    def process(self, frame, index=0, *, guide=None, manual=None):
        """Measure one frame.

        Parameters
        ----------
        frame : ndarray of shape (H, W)
        index : int
            Frame index (for priors and bookkeeping).
        guide : ndarray of shape (N, 2), optional
            Prior dome points ``(x=col, y=row)`` of the stored frame (px), used as the guide.
        manual : ndarray of shape (N, 2), optional
            Manual dome points ``(x=col, y=row)`` of the stored frame (px): replace the trace.

        Returns
        -------
        FrameTrace
        """
        frame = native_frame(np.asarray(frame))  # once here, not in every kernel (big-endian files, bool masks)
        if frame.shape != self.shape:
            raise ValueError(f"frame {index} has shape {frame.shape}, expected {self.shape}")
        view = FrameView(frame, self.k)
        out = FrameTrace(index=index)
        g, drift = self.measure_geometry(view)
        self._tracking = False  # until this frame proves good
        out.drift = (float(drift[0]), float(drift[1]))
        if g is None:
            out.message = "chamber walls not found"
            out.flag, out.flag_figure, out.flag_value = "no_membrane", "wall_rms", np.nan
            return out
        # the measured axis is the best drift estimate (reported, and the next frame's prediction)
        self._drift = np.array([g.line.x0 - self.ref.line.x0, g.line.y0 - self.ref.line.y0])
        out.drift = (float(self._drift[0]), float(self._drift[1]))
        out.geometry = g
        clipped = out.figures["clipped"] = self._clip_shift(view, g)
        if manual is not None:
            return self._from_points(view, g, out, manual)
        guide_uz = None
        track = False
        if guide is not None:
            gx, gy = view.from_frame(np.asarray(guide)[:, 1], np.asarray(guide)[:, 0])
            guide_uz = np.c_[g.line.coords(np.c_[gx, gy])]
        elif self.prev is not None and self.prev.flag == "ok" and len(self.prev.u):
            guide_uz = self._predicted_guide(index)
            track = True
        tr = self.trace_dome(view, g, guide_uz, track=track)
        if tr is not None:
            self._finish(view, g, out, tr)
            if tr["mode"] == "track" and out.flag != "ok":
                # a tracked frame failing a check is traced again as without tracking (an event, a lost track)
                out = FrameTrace(index=index, geometry=g, drift=out.drift, figures={"clipped": clipped})
                tr = self.trace_dome(view, g, guide_uz, track=False)
                if tr is not None:
                    self._finish(view, g, out, tr)
        if tr is None:
            out.message = "no dome traced"
            out.figures = {"dome_contrast": 0.0, "well_membrane": self._well_membrane(view, g), "clipped": clipped}
            last, margin = self._edge_reached
            if margin < FIELD_MARGIN_PX:  # (a dome does not shrink: it grew on out of the field)
                out.message = f"no dome traced: {field_edge_message(margin, last)}"
                out.figures["field_margin"] = margin
                out.flag, out.flag_figure, out.flag_value = "poor_fit", "field_margin", margin
            elif out.figures["well_membrane"] > self.settings.well_membrane_flag:
                out.flag, out.flag_figure = "fractured", "well_membrane"
                out.flag_value = out.figures["well_membrane"]
            else:
                out.flag, out.flag_figure, out.flag_value = "no_membrane", "dome_contrast", 0.0
            return out
        if out.flag_figure == "clipped":
            out.message = clip_message(out.flag_value)
        if out.flag == "ok":
            self._prev2, self.prev = self.prev, out
            # the first pass's offsets from the predicted dome are the prediction error (after a global
            # trace unknown: the next frame tries tracking, its window's edges guard it)
            self._motion = tr["motion"] if tr["mode"] != "global" else 0.0
            wd = tr["width"]
            self._band = float(abs_percentile(wd, tr["use"] & np.isfinite(wd), 90.0))  # nan when none
            self._tracking = True
        return out

    def _clip_shift(self, view, g):
        """How far the walls move (px, the larger) when the frame's pixels at the camera's clip level are read
        :data:`~osmobulge.imaging._clipping.BRIGHTER`: 0 when none is where the walls are read, inf when the
        walls are not found then.  Their light is a bound: a wall's level read from it is too low by an amount
        the frame does not tell (measured: painted_band with its light 1.6x, rim 1.1 px off)."""
        if not wall_clipping(view, g) > 0.0:
            return 0.0
        mask = clip_mask(view.frame)
        if mask is None:
            return 0.0
        well, _ = self._walls(FrameView(raised(view.frame, mask), view.k), g.line, g.well)
        if well is None:
            return np.inf
        return float(max(abs(well.u_left - g.well.u_left), abs(well.u_right - g.well.u_right)))

    def _finish(self, view, g, out, tr):
        """Measures, quality figures and flag of a traced dome, into ``out``."""
        out.u, out.z = tr["u"], tr["z"]
        out.points_u, out.points_z = tr["points_u"], tr["points_z"]
        out.residual_rms = tr["residual_rms"]
        self._measure(out)
        fig = self._figures(view, g, tr)
        fig["volume_disagreement"] = out.figures.get("volume_disagreement", np.nan)
        out.figures.update(fig)
        out.flag, out.flag_figure, out.flag_value = self._flag(out.figures)
        if out.flag_figure == "field_margin":
            out.message = field_edge_message(out.flag_value)
        self._edge_reached = (out.index, out.figures["field_margin"])
        out.ok = True
        out.mode = tr["mode"]

    def _measure(self, out):
        try:
            m = revolution_measures(out.u, out.z)
        except ValueError as err:
            out.message = str(err)
            return
        out.volume_left, out.volume_right = m.volume_left, m.volume_right
        out.area_left, out.area_right = m.area_left, m.area_right
        out.height = m.height
        # relative to the volume, but never to less than a 5 px layer over the well (a flat membrane)
        g = out.geometry
        floor = 5.0 * np.pi * g.rim_radius**2 if g is not None else 0.0
        out.figures["volume_disagreement"] = float(abs(m.volume_left - m.volume_right) / max(abs(m.volume), floor,
                                                                                            1e-300))

    def _from_points(self, view, g, out, manual):
        out.points_u, out.points_z, out.u, out.z = manual_curve(view, g.line, manual)
        out.source = "manual"
        out.residual_rms = 0.0
        self._measure(out)
        out.figures.update({"residual_rms": 0.0})
        out.flag, out.flag_figure, out.flag_value = "ok", "", np.nan
        out.ok = True
        self._prev2, self.prev = None, out  # a person's profile guides the trace of the next frames
        self._band = np.nan  # its band width is unknown: the next tracking window is the flat band's again
        self._tracking = True
        return out


def manual_curve(view, line, manual):
    """A manual profile in the ``(u, z)`` px of the flat ``line``: the picked points and the curve through them.

    ``manual`` holds stored-frame ``(x=col, y=row)`` px points picked in order
    along the membrane (an overhang is not monotone in ``u``); ``view`` is the
    :class:`~osmobulge.imaging._chamber.FrameView` of the traced orientation.
    Returns the points' ``u, z`` (left rim first) and a smoothing spline
    through them sampled every px.
    """
    pts = np.asarray(manual, float)
    vx, vy = view.from_frame(pts[:, 1], pts[:, 0])
    u, z = line.coords(np.c_[vx, vy])
    if u[0] > u[-1]:
        u, z = u[::-1], z[::-1]
    _, puz = smooth_profile(np.c_[u, z]).sample(step=1.0)
    return u, z, puz[:, 0], puz[:, 1]


def trace_series(frames, **kwargs):
    """Trace every frame of an in-memory series (convenience for tests); returns a list of :class:`FrameTrace`."""
    frames = list(frames)
    tracer = ChamberTracer(frames[0], **kwargs)
    return tracer, [tracer.process(f, i) for i, f in enumerate(frames)]
