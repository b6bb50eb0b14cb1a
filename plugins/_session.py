"""The curation session: one experiment folder open for review (Qt-free).

:class:`CurationSession` holds what the napari widgets show and forwards every
decision to :mod:`osmobulge.experiments.curation`, which saves it atomically
(``DIR/curation.json``).  It runs without Qt, so scripts and tests drive it
directly::

    s = CurationSession("my-experiment")
    s.set_picks(12, clicked_points_rc)       # snapped to the membrane, fitted live
    s.accept(12)                             # manual profile saved (source = "manual")
    s.exclude(20, "delaminated")
    s.set_picks(30, pts_30); s.set_picks(40, pts_40)
    s.trace_with_priors()                    # preview: frames between traced from the picks
    s.trace_with_priors(save=True)           # keep them as priors in curation.json and run process
    s.volume_series()                        # V/V0(t) with the decisions applied

See :mod:`osmobulge.plugins._logic` for the coordinate conventions.
"""

from __future__ import annotations

import contextlib
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from osmobulge.experiments import curation as cur_api
from osmobulge.experiments.metadata import load_experiment
from osmobulge.plugins._logic import (
    BULGE_DIRECTIONS,
    ChamberGeometry,
    ProfileFit,
    fit_picked_profile,
    order_along_curve,
    points_m_to_rc,
    points_rc_to_m,
    snap_points,
)

__all__ = ["CurationSession", "EXTRACTION_FILE", "open_frames"]

EXTRACTION_FILE = Path("results") / "extraction.nc"


# --------------------------------------------------------------------------- frames
def open_frames(exp):
    """The experiment's frames as a lazy ``(T, H, W)`` array, with pixel size and times.

    Parameters
    ----------
    exp : osmobulge.experiments.metadata.Experiment

    Returns
    -------
    frames : dask.array.Array of shape (T, H, W)
        One chunk per frame: a frame is read when napari shows it.
    pixel_size : float or None, m
        From ``experiment.toml`` or the files (:func:`osmobulge.imaging.io.open_series`
        checks that they agree).
    times : ndarray of shape (T,) or None, s
        From ``experiment.toml`` or the files.
    """
    import warnings

    import dask.array as da

    from osmobulge.imaging.io import open_series

    im = exp.imaging
    kw = {"pixel_size": im.pixel_size, "missing": "warn"}
    if not im.timestamps_from_files:
        if im.timestamps is not None:
            kw["timestamps"] = np.asarray(im.timestamps, float)
        elif im.frame_interval is not None:
            kw["frame_interval"] = im.frame_interval
    source = exp.frames_source()
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*not in the metadata.*", category=UserWarning)
        if isinstance(source, list | tuple):
            files = [Path(f) for f in source]
            folder = files[0].parent
            if all(f.parent == folder for f in files) and len(files) == len(_image_files(folder)):
                source = folder
            else:  # a glob picking some files of a folder: one series per file, stacked
                kw_file = {k: v for k, v in kw.items() if k not in ("timestamps", "frame_interval")}
                parts = [open_series(f, order="name", **kw_file) for f in files]
                frames = da.concatenate([p.to_dask() for p in parts])
                px = parts[0].pixel_size
                times = kw.get("timestamps")
                if times is None and "frame_interval" in kw:
                    times = np.arange(frames.shape[0]) * kw["frame_interval"]
                return frames, _finite_or_none(px), times
        series = open_series(source, order="name", **kw)
    times = np.asarray(series.timestamps, float)
    return series.to_dask(), _finite_or_none(series.pixel_size), times if np.all(np.isfinite(times)) else None


def _finite_or_none(v):
    return float(v) if v is not None and np.isfinite(v) else None


def _image_files(folder: Path) -> list[Path]:
    from osmobulge.imaging.io import IMAGE_EXTENSIONS

    return [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS]


# --------------------------------------------------------------------------- session
class CurationSession:
    """Review state of one experiment: frames, automatic profiles, picks, decisions.

    Parameters
    ----------
    folder : path
        Experiment folder (with ``experiment.toml``).
    chamber : int, optional
        Which chamber of a field holding several (index along the extraction's
        ``chamber`` dimension).

    Attributes
    ----------
    folder : pathlib.Path
    experiment : osmobulge.experiments.metadata.Experiment
    frames : array_like of shape (T, H, W)
        Lazy frame stack.
    pixel_size : float, m
    times : ndarray of shape (T,), s
        Frame clock (not shifted by the time origin).
    curation : osmobulge.experiments.curation.Curation
        As last saved.
    extraction : xarray.Dataset or None
        ``DIR/results/extraction.nc`` (loaded into memory), if processed.
    picks : dict of int to ndarray of shape (N, 2), px
        Points per frame, ``(row, col)``: the accepted manual profiles and the
        saved priors, then the user's edits (not saved until :meth:`accept` or
        :meth:`keep_as_priors`).
    """

    def __init__(self, folder, *, chamber: int = 0):
        self.folder = Path(folder)
        self.experiment = load_experiment(self.folder)
        self.frames, file_pixel, file_times = open_frames(self.experiment)
        im = self.experiment.imaging
        pixel = im.pixel_size if im.pixel_size is not None else file_pixel
        if pixel is None:
            raise ValueError(f"{self.folder}: no pixel size in experiment.toml ([imaging] pixel_size_um) "
                             "nor in the frame files")
        self.pixel_size = float(pixel)
        self.n_frames = int(self.frames.shape[0])
        self.times = self._frame_times(file_times)
        self.chamber = int(chamber)
        self.up = BULGE_DIRECTIONS.get(im.bulge_direction, BULGE_DIRECTIONS["up"])
        self.listeners: list[Callable[[str, int | None], None]] = []
        self.curation = cur_api.load_curation(self.folder)
        self.extraction = None
        self.reload_extraction()
        self.picks: dict[int, np.ndarray] = {}
        self._fits: dict[int, ProfileFit] = {}
        self._accepted: dict[int, ProfileFit] = {}
        for f, v in self.curation.priors.items():
            self.picks[int(f)] = points_m_to_rc(v["points"], self.pixel_size)
        for f, v in self.curation.manual_profiles.items():  # a frame's manual profile wins over its prior
            self.picks[int(f)] = points_m_to_rc(v["points"], self.pixel_size)

    # ------------------------------------------------------------------ basics
    def _frame_times(self, file_times) -> np.ndarray:
        im = self.experiment.imaging
        if im.timestamps is not None:
            t = np.asarray(im.timestamps, float)
        elif im.frame_interval is not None:
            t = np.arange(self.n_frames) * float(im.frame_interval)
        elif file_times is not None:
            t = np.asarray(file_times, float)
        else:
            t = np.arange(self.n_frames, dtype=float)
        if t.shape != (self.n_frames,):
            raise ValueError(f"{self.folder}: {t.size} frame times for {self.n_frames} frames")
        return t

    @property
    def shape(self) -> tuple[int, int]:
        """Frame shape ``(H, W)``, px."""
        return tuple(int(n) for n in self.frames.shape[1:])

    @property
    def chamber_volume(self) -> float:
        """Initial chamber volume :math:`V_0 = \\pi a^2 h`, m**3 (denominator of V/V0)."""
        return float(self.experiment.chamber.volume)

    def check_frame(self, frame) -> int:
        """Validate a frame index; returns it as int."""
        if isinstance(frame, bool) or not isinstance(frame, int | np.integer) or not 0 <= frame < self.n_frames:
            raise ValueError(f"frame = {frame!r}: expected an integer in [0, {self.n_frames - 1}]")
        return int(frame)

    def frame(self, frame: int) -> np.ndarray:
        """One frame as an in-memory array (H, W)."""
        return np.asarray(self.frames[self.check_frame(frame)])

    def _emit(self, what: str, frame: int | None = None) -> None:
        for cb in list(self.listeners):
            cb(what, frame)

    # ------------------------------------------------------------------ extraction
    def reload_extraction(self) -> None:
        """(Re)load ``results/extraction.nc`` if it exists."""
        path = self.folder / EXTRACTION_FILE
        if not path.is_file():
            self.extraction = None
            return
        import xarray as xr

        with xr.open_dataset(path, engine="h5netcdf") as ds:
            self.extraction = ds.load()
        self._emit("extraction")

    def _ds_frame(self, frame: int):
        """The extraction's entry for a frame (and chamber), or None."""
        ds = self.extraction
        if ds is None:
            return None
        if "frame" in ds.variables:
            pos = np.flatnonzero(np.asarray(ds["frame"].values).astype(int) == frame)
            if pos.size == 0:
                return None
            sub = ds.isel(time=int(pos[0]))
        elif frame < ds.sizes.get("time", 0):
            sub = ds.isel(time=frame)
        else:
            return None
        if "chamber" in sub.dims:
            sub = sub.isel(chamber=self.chamber)
        return sub

    def flag(self, frame: int) -> str | None:
        """The automatic quality flag of a frame (None before processing)."""
        sub = self._ds_frame(self.check_frame(frame))
        if sub is None or "flag" not in sub:
            return None
        return str(sub["flag"].values)

    def auto_profile_rc(self, frame: int) -> np.ndarray | None:
        """The extraction's traced profile of a frame, ``(row, col)`` px, ordered rim to rim."""
        sub = self._ds_frame(self.check_frame(frame))
        if sub is None:
            return None
        for xs, ys, scale in (("profile_col", "profile_row", 1.0), ("profile_x", "profile_y", 1.0 / self.pixel_size)):
            if xs in sub and ys in sub:
                x = np.asarray(sub[xs].values, float).ravel() * scale
                y = np.asarray(sub[ys].values, float).ravel() * scale
                ok = np.isfinite(x) & np.isfinite(y)
                return np.c_[y[ok], x[ok]] if ok.any() else None
        return None

    def geometry(self, frame: int) -> ChamberGeometry | None:
        """The chamber frame the extraction measured in a frame (None if unknown).

        The axis point is the extraction's ``axis_col``/``axis_row``; the directions
        of the flat membrane line and of the bulge come from the stored profile,
        which the extraction gives both in chamber coordinates (``profile_x``,
        ``profile_z``) and in pixels (``profile_col``, ``profile_row``): a least-squares
        fit of that rigid map, valid for any bulge direction and tilt.
        """
        sub = self._ds_frame(self.check_frame(frame))
        if sub is None or not {"axis_col", "axis_row"} <= set(sub.variables):
            return None
        ax, ay = float(sub["axis_col"].values), float(sub["axis_row"].values)
        if not (np.isfinite(ax) and np.isfinite(ay)):
            return None
        if {"profile_x", "profile_z", "profile_col", "profile_row"} <= set(sub.variables):
            x = np.asarray(sub["profile_x"].values, float) / self.pixel_size
            z = np.asarray(sub["profile_z"].values, float) / self.pixel_size
            col = np.asarray(sub["profile_col"].values, float)
            row = np.asarray(sub["profile_row"].values, float)
            ok = np.isfinite(x) & np.isfinite(z) & np.isfinite(col) & np.isfinite(row)
            if ok.sum() >= 3 and np.ptp(z[ok]) > 1.0 and np.ptp(x[ok]) > 1.0:
                design = np.column_stack([np.ones(ok.sum()), x[ok], z[ok]])
                coef, *_ = np.linalg.lstsq(design, np.column_stack([col[ok], row[ok]]), rcond=None)
                ex, ez = coef[1], coef[2]  # (dcol, drow) per unit x and per unit z
                up = tuple(float(v) for v in ez / np.linalg.norm(ez))
                return ChamberGeometry(axis_point=(ax, ay), angle=float(np.arctan2(ex[1], ex[0])), up=up,
                                       source="extraction")
        # no profile in this frame: the tilt of an upright view, in the stored frame
        up = BULGE_DIRECTIONS.get(str(self.extraction.attrs.get("bulge_direction", "")), self.up)
        tilt = float(sub["tilt"].values) if "tilt" in sub else 0.0
        theta = -np.deg2rad(tilt) if np.isfinite(tilt) else 0.0
        # rotate the view's line direction (cos, sin) by the quarter turns that make `up` upright
        base = np.arctan2(-up[0], up[1]) + np.pi  # angle of the line direction for this `up`, untilted
        return ChamberGeometry(axis_point=(ax, ay), angle=float(base + theta), up=up, source="extraction")

    # ------------------------------------------------------------------ picking
    def set_picks(self, frame: int, points_rc, *, snap: bool = True, search: float = 6.0) -> ProfileFit:
        """Replace a frame's picked points (optionally snapped to the membrane) and refit.

        Parameters
        ----------
        frame : int
        points_rc : array_like of shape (N, 2), px
            ``(row, col)``, any order.
        snap : bool
            Move the points onto the membrane band (:func:`osmobulge.plugins._logic.snap_points`).
        search : float, px
            Snapping search half-width.

        Returns
        -------
        ProfileFit
            The live ellipse and spline fits with volume and area.
        """
        frame = self.check_frame(frame)
        p = np.asarray(points_rc, float).reshape(-1, 2)
        if snap and len(p):
            p = snap_points(self.frame(frame), p, search=search, up=self.up).points_rc
        if len(p) >= 3:
            p = p[order_along_curve(p)]
        self.picks[frame] = p
        self._fits.pop(frame, None)
        fit = self.fit(frame)
        self._emit("picks", frame)
        return fit

    def clear_picks(self, frame: int) -> None:
        """Forget the picked points of a frame (the saved manual profile, if any, stays)."""
        frame = self.check_frame(frame)
        self.picks.pop(frame, None)
        self._fits.pop(frame, None)
        self._emit("picks", frame)

    def fit(self, frame: int) -> ProfileFit:
        """Ellipse and spline fits of the frame's picks (cached)."""
        frame = self.check_frame(frame)
        if frame not in self._fits:
            pts = self.picks.get(frame, np.empty((0, 2)))
            self._fits[frame] = fit_picked_profile(pts, pixel_size=self.pixel_size, geometry=self.geometry(frame),
                                                   up=self.up)
        return self._fits[frame]

    def accept(self, frame: int, *, by: str | None = None) -> ProfileFit:
        """Store the frame's picks as its manual profile (``source = "manual"``) and save.

        Parameters
        ----------
        frame : int
        by : str, optional
            Who (default: the login name).

        Returns
        -------
        ProfileFit
            The fit whose volume and area now stand for this frame.

        Raises
        ------
        ValueError
            The picks give no profile (fewer than 4 points, or not across the chamber axis).
        osmobulge.experiments.curation.CurationConflict
            Someone else saved the curation since this session loaded it.
        """
        frame = self.check_frame(frame)
        fit = self.fit(frame)
        if not fit:
            raise ValueError(f"frame {frame}: no profile to accept ({fit.message or 'pick more points'})")
        pts_m = points_rc_to_m(fit.points_rc, self.pixel_size)
        # the person replaces the profile they are looking at: an explicit decision (force);
        # save_curation still refuses if someone else saved in between
        new = cur_api.set_manual_profile(self.curation, frame, pts_m, by=by, force=True)
        self._save(new)
        self._accepted[frame] = fit
        self._emit("accepted", frame)
        return fit

    def remove_manual(self, frame: int, *, by: str | None = None) -> None:
        """Drop a frame's manual profile (the automatic trace counts again) and save."""
        frame = self.check_frame(frame)
        self._save(cur_api.remove_manual_profile(self.curation, frame, by=by))
        self._accepted.pop(frame, None)
        self.clear_picks(frame)
        self._emit("accepted", frame)

    def is_manual(self, frame: int) -> bool:
        """True when the saved curation holds a manual profile for the frame."""
        return self.check_frame(frame) in self.curation.manual_profiles

    def manual_fit(self, frame: int) -> ProfileFit | None:
        """The fit of the saved manual profile of a frame (None if it has none)."""
        frame = self.check_frame(frame)
        if frame not in self.curation.manual_profiles:
            return None
        if frame not in self._accepted:
            pts = points_m_to_rc(self.curation.manual_profiles[frame]["points"], self.pixel_size)
            self._accepted[frame] = fit_picked_profile(pts, pixel_size=self.pixel_size,
                                                       geometry=self.geometry(frame), up=self.up)
        return self._accepted[frame]

    # ------------------------------------------------------------------ decisions
    def _save(self, new) -> None:
        self.curation = cur_api.save_curation(self.folder, new)

    def exclude(self, frame: int, reason: str, note: str = "", *, by: str | None = None) -> None:
        """Exclude a frame from the fits with a reason (one of ``curation.REASONS``) and save."""
        frame = self.check_frame(frame)
        self._save(cur_api.exclude_frame(self.curation, frame, reason, note, by=by, force=True))
        self._emit("excluded", frame)

    def include(self, frame: int, *, by: str | None = None) -> None:
        """Undo a frame's exclusion and save."""
        frame = self.check_frame(frame)
        self._save(cur_api.include_frame(self.curation, frame, by=by))
        self._emit("excluded", frame)

    def keep_flagged(self, frame: int, note: str = "", *, by: str | None = None) -> None:
        """Keep a frame in the fits although the automatic extraction flagged it, and save."""
        frame = self.check_frame(frame)
        self._save(cur_api.keep_flagged_frame(self.curation, frame, note, by=by, force=True))
        self._emit("excluded", frame)

    def exclusion(self, frame: int) -> dict | None:
        """The exclusion record of a frame (reason, note, by, at), or None."""
        return self.curation.excluded.get(self.check_frame(frame))

    def set_time_origin(self, time: float, *, by: str | None = None) -> None:
        """Set t = 0 of the flux model (s of the frame clock) and save."""
        self._save(cur_api.set_time_origin(self.curation, float(time), by=by, force=True))
        self._emit("time_origin", None)

    def set_time_origin_frame(self, frame: int, *, by: str | None = None) -> None:
        """Set t = 0 at a frame's time and save."""
        self.set_time_origin(float(self.times[self.check_frame(frame)]), by=by)

    def set_chamber_regions(self, regions, *, by: str | None = None) -> None:
        """Set the chamber regions (``{"name", "rows", "cols"}``, px) and save."""
        self._save(cur_api.set_chamber_regions(self.curation, regions, by=by, force=True))
        self._emit("regions", None)

    def chamber_regions(self) -> list[dict]:
        """Regions in use: the curation's, else the ones of ``experiment.toml``."""
        regions = self.curation.chamber_regions
        if regions is None:
            regions = self.experiment.imaging.chamber_regions
        return [dict(r) for r in regions or ()]

    def rim(self) -> tuple | None:
        """The chamber's rim in use, ``(col0, row0, col1, row1)`` px of the full frame: the curation's, else
        experiment.toml's ``[imaging] rim_px`` (None: found automatically)."""
        if self.curation.rim is not None:
            return tuple(self.curation.rim)
        rim = self.experiment.imaging.rim
        return None if rim is None else tuple(float(v) for v in np.ravel(rim))

    def rim_from_picks(self, frame: int) -> tuple:
        """The rim a frame's picks give: the picked curve's two ends (the flat mid-line's ends at the walls),
        left to right, as ``(col0, row0, col1, row1)`` px."""
        frame = self.check_frame(frame)
        p = self.picks.get(frame, np.empty((0, 2)))
        if len(p) < 2:
            raise ValueError(f"frame {frame + 1}: pick the flat mid-line's two ends at the walls first "
                             f"({len(p)} point{'s' * (len(p) != 1)} picked)")
        (r0, c0), (r1, c1) = sorted([tuple(p[0]), tuple(p[-1])], key=lambda rc: rc[1])
        return float(c0), float(r0), float(c1), float(r1)

    def set_rim(self, rim, *, by: str | None = None) -> None:
        """Set the chamber's rim (``(col0, row0, col1, row1)`` px; None: back to experiment.toml's) and save;
        the next extraction (:meth:`reprocess`) locates the chamber by it."""
        self._save(cur_api.set_rim(self.curation, rim, by=by, force=True))
        self._emit("rim", None)

    # ------------------------------------------------------------------ V/V0(t)
    def live_dataset(self):
        """The extraction with the session's manual profiles in place of the automatic ones.

        Returns
        -------
        xarray.Dataset
            Over ``time`` (s, frame clock) with ``frame``, ``volume`` (m**3),
            ``volume_ratio``, ``flag`` and ``profile_source``; for frames with a
            saved manual profile the volume is that profile's (flag ``ok``,
            source ``manual``), as the next ``process`` step will compute it.
            Without an extraction, only the manual frames have volumes.
        """
        import xarray as xr

        n = self.n_frames
        vol = np.full(n, np.nan)
        flag = np.array(["ok"] * n, dtype=object)
        source = np.array(["auto"] * n, dtype=object)
        ds = self.extraction
        if ds is not None:
            pos = np.asarray(ds["frame"].values).astype(int) if "frame" in ds.variables else np.arange(ds.sizes["time"])
            keep = (pos >= 0) & (pos < n)
            for name, out in (("volume", vol), ("flag", flag), ("profile_source", source)):
                if name in ds:
                    values = ds[name]
                    if "chamber" in values.dims:
                        values = values.isel(chamber=self.chamber)
                    out[pos[keep]] = np.asarray(values.values)[keep]
        for f in self.curation.manual_profiles:
            if f < n:
                fit = self.manual_fit(f)
                vol[f] = fit.volume if fit is not None else np.nan
                flag[f], source[f] = "ok", "manual"
        ds = xr.Dataset(
            {
                "volume": ("time", vol, {"units": "m3", "long_name": "bulge volume"}),
                "volume_ratio": ("time", 1.0 + vol / self.chamber_volume, {"units": "1", "long_name": "V/V0"}),
                "flag": ("time", flag.astype(str)),
                "profile_source": ("time", source.astype(str)),
            },
            coords={"time": ("time", self.times, {"units": "s"}), "frame": ("time", np.arange(n))},
        )
        return ds

    def volume_series(self):
        """V/V0(t) with the curation applied (what the fits will use).

        Returns
        -------
        xarray.Dataset
            :meth:`live_dataset` after :func:`osmobulge.experiments.curation.apply_curation`:
            ``time`` shifted by the time origin, ``excluded``, ``exclusion_reason``, ``kept``.
        """
        return cur_api.apply_curation(self.live_dataset(), self.curation)

    def frame_status(self, frame: int) -> dict:
        """What the widgets show about a frame (JSON-safe)."""
        frame = self.check_frame(frame)
        exc = self.exclusion(frame)
        fit = self.fit(frame) if frame in self.picks else None
        t0 = self.curation.time_origin or 0.0
        live = self.live_dataset()
        return {
            "frame": frame,
            "n_frames": self.n_frames,
            "time_min": (float(self.times[frame]) - t0) / 60.0,
            "flag": self.flag(frame),
            "excluded": None if exc is None else exc["reason"],
            "kept_flagged": frame in self.curation.kept_flagged,
            "note": "" if exc is None else exc.get("note", ""),
            "manual": self.is_manual(frame),
            "n_picks": int(len(self.picks.get(frame, ()))),
            "volume_ratio": float(live["volume_ratio"].values[frame]),
            "pick_volume_ratio": None if not fit else 1.0 + fit.volume / self.chamber_volume,
            "pick_message": "" if fit is None else fit.message,
        }

    # ------------------------------------------------------------------ runs
    def reprocess(self, **extract_options):
        """Run the ``process`` step (extraction with the saved manual profiles) and reload it.

        Returns
        -------
        osmobulge.experiments.runs.ExperimentOutcome
        """
        from osmobulge.experiments.runs import run_experiment

        out = run_experiment(self.folder, ["process"], options={"extract": extract_options} if extract_options
                             else None, errors="raise")
        self.reload_extraction()
        self._accepted.clear()
        self._emit("extraction")
        return out

    def _prior_picks(self) -> dict:
        """The picks usable as priors: frame -> (N >= 4, 2) points (x, y), m."""
        return {int(f): points_rc_to_m(p, self.pixel_size) for f, p in self.picks.items() if len(p) >= 4}

    def trace_with_priors(self, frames=None, *, save: bool = False, by: str | None = None):
        """Semi-automatic mode: re-trace frames guided by the picked frames.

        The frames with picks (saved manual profiles, saved priors and unsaved
        picks, at least 4 points each) become priors of
        :func:`osmobulge.imaging.extract` (``priors=``): the tracer starts each
        frame between two picked frames from the nearest pick instead of the
        previous frame's trace.

        Parameters
        ----------
        frames : sequence of int, optional
            Frames to show the new traces of (default all).
        save : bool
            False (default): a preview, ``DIR/results`` and ``curation.json``
            are not touched.  True: the picks of frames without a manual profile
            are kept as priors in ``curation.json`` (:meth:`keep_as_priors`) and
            the ``process`` step runs (:meth:`reprocess`), so later runs of
            ``osmobulge process`` trace the same way.
        by : str, optional
            Who (with ``save``; default: the login name).

        Returns
        -------
        xarray.Dataset
            The new extraction; it replaces :attr:`extraction` in the session
            (overlays and V/V0 show it).
        """
        from osmobulge.experiments.runs import process_experiment

        priors = self._prior_picks()
        if not priors:
            raise ValueError("semi-automatic tracing needs picked points (at least 4) on at least one frame")
        if save:
            self.keep_as_priors(by=by)
            self.reprocess()
            return self.extraction
        with tempfile.TemporaryDirectory() as tmp:
            process_experiment(self.experiment, Path(tmp), priors=priors)
            import xarray as xr

            with xr.open_dataset(Path(tmp) / "extraction.nc", engine="h5netcdf") as ds:
                self.extraction = ds.load()
        self._fits.clear()
        self._accepted.clear()
        self._emit("extraction")
        return self.extraction

    def keep_as_priors(self, frames=None, *, by: str | None = None) -> list[int]:
        """Save picks as priors of the tracer in ``curation.json`` (the next ``process`` uses them).

        Parameters
        ----------
        frames : sequence of int, optional
            Frames whose picks to keep (default: every frame with at least 4
            picked points and no manual profile; a manual profile already
            stands for its frame and guides the next ones).
        by : str, optional
            Who (default: the login name).

        Returns
        -------
        list of int
            The frames whose priors were saved.

        Raises
        ------
        ValueError
            A frame named in ``frames`` has fewer than 4 picked points.
        osmobulge.experiments.curation.CurationConflict
            Someone else saved the curation since this session loaded it.
        """
        if frames is None:
            sel = [f for f, p in sorted(self.picks.items())
                   if len(p) >= 4 and f not in self.curation.manual_profiles]
        else:
            sel = sorted({self.check_frame(f) for f in frames})
            few = [f for f in sel if len(self.picks.get(f, ())) < 4]
            if few:
                raise ValueError(f"frames = {few}: fewer than 4 picked points (a prior needs N >= 4)")
        new = self.curation
        for f in sel:
            # the person replaces the prior they are looking at: an explicit decision (force)
            new = cur_api.set_prior(new, f, points_rc_to_m(self.picks[f], self.pixel_size), by=by, force=True)
        self._save(new)
        for f in sel:
            self._emit("priors", f)
        return sel

    def remove_prior(self, frame: int, *, by: str | None = None) -> None:
        """Drop a frame's saved prior (its picks stay in the session) and save."""
        frame = self.check_frame(frame)
        self._save(cur_api.remove_prior(self.curation, frame, by=by))
        self._emit("priors", frame)

    def is_prior(self, frame: int) -> bool:
        """True when the saved curation holds a prior for the frame."""
        return self.check_frame(frame) in self.curation.priors

    # ------------------------------------------------------------------ import / export
    def import_points(self, path, *, snap: bool = False, **kwargs) -> list[int]:
        """Load picked points from CSV or ImageJ ROI files into the session (not saved).

        Returns
        -------
        list of int
            The frames that received points.
        """
        from osmobulge.plugins.roi import read_points

        if Path(path).suffix.lower() == ".csv":
            kwargs.setdefault("pixel_size_um", self.pixel_size * 1e6)
        pts = read_points(path, **kwargs)
        for f, p in pts.items():
            self.set_picks(self.check_frame(f), p, snap=snap)
        return sorted(pts)

    def export_points(self, path, frames=None, **kwargs) -> Path:
        """Write the picked points (all frames, or ``frames``) to CSV or ImageJ ROI files."""
        from osmobulge.plugins.roi import write_points

        sel = {f: p for f, p in self.picks.items() if len(p) and (frames is None or f in frames)}
        if Path(path).suffix.lower() == ".csv":
            kwargs.setdefault("pixel_size_um", self.pixel_size * 1e6)
        return write_points(path, sel, **kwargs)

    def close(self) -> None:
        """Drop references (frames, extraction, listeners)."""
        self.listeners.clear()
        self.extraction = None
        with contextlib.suppress(Exception):
            del self.frames
