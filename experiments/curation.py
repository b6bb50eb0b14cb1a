"""Curation: what a person decided about the frames of an experiment.

Kept beside the data in ``DIR/curation.json``, never inside the raw images:

- excluded frames, each with a reason (:data:`REASONS`), a free-text note, who and when;
- frames kept on purpose although the automatic extraction flagged them;
- manual profiles (points picked in the napari plugin, in metres, ``source = "manual"``);
- priors: points picked on some frames that guide the automatic tracer on
  the frames between (the semi-automatic mode; same coordinates);
- the time origin (when the chamber met the water), in seconds of the frame clock;
- chamber regions, when one field holds several chambers;
- the chamber's rim in the flat frame, when the automatic search does not find it.

Rules
-----
- Extraction never writes this file, so re-running it keeps every decision.
- Nothing a person entered is overwritten silently: changing an existing
  decision raises :class:`CurationConflict` unless ``force=True``; saving over a
  file that changed on disk since it was loaded raises too.
- Every save keeps the previous file in ``DIR/.curation-history/`` and appends
  to the ``history`` list inside the file; writes are atomic.

The edit functions (:func:`exclude_frame`, :func:`set_manual_profile`, ...)
take a :class:`Curation` and return a new one.  Given an experiment folder
instead, they load, edit and save in one call (what the napari plugin does).
"""

from __future__ import annotations

import copy
import datetime as _dt
import functools
import getpass
import hashlib
import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from osmobulge.experiments._io import atomic_write_text

__all__ = [
    "CURATION_FILE",
    "HISTORY_DIR",
    "REASONS",
    "Curation",
    "CurationConflict",
    "load_curation",
    "save_curation",
    "exclude_frame",
    "include_frame",
    "keep_flagged_frame",
    "set_manual_profile",
    "remove_manual_profile",
    "set_prior",
    "remove_prior",
    "set_time_origin",
    "set_chamber_regions",
    "set_rim",
    "apply_curation",
    "curation_fingerprint",
    "curation_summary",
]

CURATION_FILE = "curation.json"
HISTORY_DIR = ".curation-history"
#: reasons a frame can be excluded for
REASONS = ("delaminated", "fractured", "touching", "out_of_focus", "other")
SCHEMA = 1


class CurationConflict(RuntimeError):
    """A write would replace a decision a person made (pass ``force=True`` to do it anyway)."""


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _user() -> str:
    try:
        return getpass.getuser()
    except Exception:  # noqa: BLE001 - no user name in some containers
        return "unknown"


@dataclass(frozen=True)
class Curation:
    """The curation of one experiment (immutable; edits return a new object).

    Attributes
    ----------
    excluded : dict of int -> dict
        Frame index -> ``{"reason", "note", "by", "at"}``.
    kept_flagged : dict of int -> dict
        Frames kept although the automatic extraction flagged them: ``{"note", "by", "at"}``.
    manual_profiles : dict of int -> dict
        Frame index -> ``{"points" (list of [x, y], m), "source": "manual", "chamber", "by", "at"}``.
    priors : dict of int -> dict
        Frame index -> ``{"points" (list of [x, y], m), "units": "m", "chamber", "by", "at"}``:
        points the tracer starts from on that frame and on the frames between
        (``priors=`` of :func:`osmobulge.imaging.extract.extract`).
    time_origin : float or None, s
        Time (frame clock) taken as t = 0 of the flux model.
    chamber_regions : tuple of dict or None
        ``{"name", "rows": [r0, r1], "cols": [c0, c1]}`` (pixels); None: as in experiment.toml.
    rim : tuple of 4 float or None
        ``(col0, row0, col1, row1)`` (pixels of the full frame): the flat
        membrane's mid-line ends at the two walls in the first (flat) frame,
        which locate the chamber for the silhouette route (``rim=`` of
        :func:`osmobulge.imaging.extract.extract`); None: as in experiment.toml
        (``[imaging] rim_px``).
    history : tuple of dict
        Every change: ``{"at", "by", "action", "frame", "detail"}``.
    revision : int
        Revision of the file this was loaded from (0: no file yet).
    """

    excluded: dict = field(default_factory=dict)
    kept_flagged: dict = field(default_factory=dict)
    manual_profiles: dict = field(default_factory=dict)
    priors: dict = field(default_factory=dict)
    time_origin: float | None = None
    chamber_regions: tuple | None = None
    rim: tuple | None = None
    history: tuple = ()
    revision: int = 0

    # ---- serialisation -------------------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-safe content (frame keys as strings)."""
        return {
            "schema": SCHEMA,
            "revision": self.revision,
            "excluded": {str(k): v for k, v in sorted(self.excluded.items())},
            "kept_flagged": {str(k): v for k, v in sorted(self.kept_flagged.items())},
            "manual_profiles": {str(k): v for k, v in sorted(self.manual_profiles.items())},
            "priors": {str(k): v for k, v in sorted(self.priors.items())},
            "time_origin": self.time_origin,
            "chamber_regions": None if self.chamber_regions is None else [dict(r) for r in self.chamber_regions],
            "rim": None if self.rim is None else list(self.rim),
            "history": list(self.history),
        }

    @classmethod
    def from_dict(cls, data: dict) -> Curation:
        """Inverse of :meth:`to_dict` (validates the content)."""
        if not isinstance(data, dict):
            raise ValueError("curation: expected a JSON object")
        schema = data.get("schema", SCHEMA)
        if schema != SCHEMA:
            raise ValueError(f"curation schema = {schema!r}: this version reads schema {SCHEMA}")
        frames = lambda d, what: {_frame_index(k, what): v for k, v in (d or {}).items()}  # noqa: E731
        excluded = frames(data.get("excluded"), "excluded")
        for k, v in excluded.items():
            if v.get("reason") not in REASONS:
                raise ValueError(f"curation excluded[{k}].reason = {v.get('reason')!r}: expected one of {REASONS}")
        manual = frames(data.get("manual_profiles"), "manual_profiles")
        for k, v in manual.items():
            _check_points(v.get("points"), f"manual_profiles[{k}].points")
        priors = frames(data.get("priors"), "priors")  # absent in files written before priors existed
        for k, v in priors.items():
            _check_points(v.get("points"), f"priors[{k}].points")
        regions = data.get("chamber_regions")
        return cls(
            excluded=excluded,
            kept_flagged=frames(data.get("kept_flagged"), "kept_flagged"),
            manual_profiles=manual,
            priors=priors,
            time_origin=None if data.get("time_origin") is None else float(data["time_origin"]),
            chamber_regions=None if regions is None else tuple(_check_regions(regions)),
            rim=None if data.get("rim") is None else _check_rim(data["rim"]),  # (absent in older files)
            history=tuple(data.get("history", ())),
            revision=int(data.get("revision", 0)),
        )

    # ---- views ---------------------------------------------------------------------------
    def decisions(self) -> dict:
        """The decisions without bookkeeping (history, revision, who/when)."""
        strip = lambda d: {k: {kk: vv for kk, vv in v.items() if kk not in ("by", "at")}  # noqa: E731
                           for k, v in sorted(d.items())}
        out = {
            "excluded": strip(self.excluded),
            "kept_flagged": strip(self.kept_flagged),
            "manual_profiles": strip(self.manual_profiles),
            "time_origin": self.time_origin,
            "chamber_regions": None if self.chamber_regions is None else [dict(r) for r in self.chamber_regions],
        }
        if self.priors:  # only when set: curations without priors keep the hashes they had before priors existed
            out["priors"] = strip(self.priors)
        if self.rim is not None:  # (likewise)
            out["rim"] = list(self.rim)
        return out

    def _log(self, action: str, frame=None, detail="", by=None) -> tuple:
        entry = {"at": _now(), "by": by or _user(), "action": action, "frame": frame, "detail": detail}
        return (*self.history, entry)


def _frame_index(key, what: str) -> int:
    try:
        idx = int(key)
    except (TypeError, ValueError):
        raise ValueError(f"curation {what}: frame key {key!r} is not an integer frame index") from None
    if idx < 0 or isinstance(key, bool):
        raise ValueError(f"curation {what}: frame index {key!r} must be >= 0")
    return idx


def _check_frame(frame) -> int:
    if isinstance(frame, bool) or not isinstance(frame, int | np.integer) or frame < 0:
        raise ValueError(f"frame = {frame!r}: expected a frame index (integer >= 0)")
    return int(frame)


def _check_points(points, name="points") -> list:
    arr = np.asarray(points, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 4:
        raise ValueError(f"{name}: expected an array of shape (N, 2) with N >= 4 (x, y in m; the extraction fits "
                         f"a spline through them), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: points must be finite")
    if np.nanmax(np.abs(arr)) > 1.0:
        raise ValueError(f"{name}: coordinates up to {np.nanmax(np.abs(arr)):g} m: expected metres "
                         "(pixel coordinates must be multiplied by the pixel size)")
    return arr.tolist()


#: closest the rim's two ends may be (px; the silhouette route's narrowest well)
_RIM_MIN_PX = 40.0


def _check_rim(rim) -> tuple:
    arr = np.asarray(rim, dtype=float)
    if arr.size != 4:
        raise ValueError(f"rim = {rim!r}: expected the two ends of the flat mid-line, [col0, row0, col1, row1] "
                         f"(pixels)")
    arr = arr.ravel()
    if not np.all(np.isfinite(arr)) or np.any(arr < -0.5):
        raise ValueError(f"rim = {rim!r}: expected finite pixel coordinates inside the frame (>= -0.5, its edge)")
    gap = float(np.hypot(arr[2] - arr[0], arr[3] - arr[1]))
    if gap < _RIM_MIN_PX:
        raise ValueError(f"rim = {rim!r}: its two ends are {gap:.0f} px apart; they are the flat mid-line's ends at "
                         f"the two walls, at least {_RIM_MIN_PX:.0f} px apart")
    return tuple(float(v) for v in arr)


def _check_regions(regions) -> list:
    out = []
    for i, r in enumerate(regions):
        if not isinstance(r, dict) or not {"rows", "cols"} <= set(r):
            raise ValueError(f"chamber_regions[{i}] = {r!r}: expected {{name, rows: [r0, r1], cols: [c0, c1]}}")
        rows, cols = [int(v) for v in r["rows"]], [int(v) for v in r["cols"]]
        if len(rows) != 2 or len(cols) != 2 or rows[0] < 0 or cols[0] < 0 or rows[1] <= rows[0] or cols[1] <= cols[0]:
            raise ValueError(f"chamber_regions[{i}]: rows/cols must be [start, stop] with 0 <= start < stop")
        out.append({"name": str(r.get("name", f"chamber{i}")), "rows": rows, "cols": cols})
    return out


# ---- files --------------------------------------------------------------------------------------
def _curation_path(directory) -> Path:
    directory = Path(directory)
    return directory if directory.name == CURATION_FILE else directory / CURATION_FILE


def load_curation(directory) -> Curation:
    """Read ``DIR/curation.json`` (an empty :class:`Curation` when there is none).

    Parameters
    ----------
    directory : path
        The experiment folder (or the file itself).

    Returns
    -------
    Curation

    Raises
    ------
    ValueError
        The file is not valid JSON or not a curation (the file is left untouched).
    """
    path = _curation_path(directory)
    if not path.exists():
        return Curation()
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not valid JSON ({err}); restore it from {path.parent / HISTORY_DIR}") from None
    try:
        return Curation.from_dict(data)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None


def save_curation(directory, cur: Curation, *, force: bool = False) -> Curation:
    """Write the curation atomically, keeping the previous file in the history folder.

    Parameters
    ----------
    directory : path
        The experiment folder.
    cur : Curation
        Usually loaded with :func:`load_curation` and edited.
    force : bool
        Write even if the file on disk changed since ``cur`` was loaded.

    Returns
    -------
    Curation
        ``cur`` with the new revision number.

    Raises
    ------
    CurationConflict
        The file on disk has another revision than the one ``cur`` was loaded
        from (someone else saved in between) and ``force`` is false.
    """
    path = _curation_path(directory)
    on_disk = load_curation(path) if path.exists() else None
    disk_rev = on_disk.revision if on_disk is not None else 0
    if on_disk is not None and disk_rev != cur.revision and not force:
        raise CurationConflict(
            f"{path} is at revision {disk_rev} but these edits start from revision {cur.revision}: "
            "someone saved in between. Reload (load_curation), redo the edits, or save with force=True.")
    if on_disk is not None and on_disk.decisions() == cur.decisions() and not force:
        return on_disk  # nothing changed: no new revision
    if path.exists():
        hist = path.parent / HISTORY_DIR
        atomic_write_text(hist / f"curation.rev{disk_rev:05d}.json", path.read_text(encoding="utf-8"))
    new = replace(cur, revision=max(disk_rev, cur.revision) + 1)
    atomic_write_text(path, json.dumps(new.to_dict(), indent=1, sort_keys=False) + "\n")
    return new


def _path_or_curation(func):
    """Let an edit function take an experiment folder: load, edit, save (with ``force``)."""

    @functools.wraps(func)
    def wrapper(cur, *args, **kwargs):
        if isinstance(cur, Curation):
            return func(cur, *args, **kwargs)
        if isinstance(cur, str | Path):
            new = func(load_curation(cur), *args, **kwargs)
            return save_curation(cur, new)
        raise TypeError(f"expected a Curation or an experiment folder, got {type(cur).__name__}")

    return wrapper


# ---- edits --------------------------------------------------------------------------------------
@_path_or_curation
def exclude_frame(cur: Curation, frame: int, reason: str, note: str = "", *, by: str | None = None,
                  force: bool = False) -> Curation:
    """Exclude a frame from the fits.

    Parameters
    ----------
    cur : Curation or path
        A curation, or an experiment folder (load, edit, save).
    frame : int
        Frame index (0-based, in the experiment's frame order).
    reason : str
        One of :data:`REASONS`.
    note : str
        Free text.
    by : str, optional
        Who decided (default: the login name).
    force : bool
        Replace an existing, different exclusion of this frame.

    Returns
    -------
    Curation

    Raises
    ------
    CurationConflict
        The frame is already excluded with another reason or note.
    """
    frame = _check_frame(frame)
    if reason not in REASONS:
        raise ValueError(f"reason = {reason!r}: expected one of {', '.join(REASONS)}")
    if not isinstance(note, str):
        raise TypeError(f"note = {note!r}: expected a string")
    old = cur.excluded.get(frame)
    if old is not None and old["reason"] == reason and old.get("note", "") == note:
        return cur
    if old is not None and not force:
        raise CurationConflict(f"frame {frame} is already excluded (reason {old['reason']!r}, note "
                               f"{old.get('note', '')!r}, by {old.get('by')}); pass force=True to replace it")
    excluded = dict(cur.excluded)
    excluded[frame] = {"reason": reason, "note": note, "by": by or _user(), "at": _now()}
    kept = {k: v for k, v in cur.kept_flagged.items() if k != frame}
    return replace(cur, excluded=excluded, kept_flagged=kept,
                   history=cur._log("exclude", frame, f"{reason}: {note}" if note else reason, by))


@_path_or_curation
def include_frame(cur: Curation, frame: int, *, by: str | None = None) -> Curation:
    """Undo an exclusion (an explicit decision, recorded in the history).

    Parameters
    ----------
    cur : Curation or path
    frame : int

    Returns
    -------
    Curation
    """
    frame = _check_frame(frame)
    if frame not in cur.excluded:
        return cur
    old = cur.excluded[frame]
    excluded = {k: v for k, v in cur.excluded.items() if k != frame}
    return replace(cur, excluded=excluded, history=cur._log("include", frame, f"was {old['reason']}", by))


@_path_or_curation
def keep_flagged_frame(cur: Curation, frame: int, note: str = "", *, by: str | None = None,
                       force: bool = False) -> Curation:
    """Keep a frame in the fits although the automatic extraction flagged it.

    Parameters
    ----------
    cur : Curation or path
    frame : int
    note : str
    force : bool
        Needed when a person excluded the frame before.

    Returns
    -------
    Curation
    """
    frame = _check_frame(frame)
    if frame in cur.excluded and not force:
        raise CurationConflict(f"frame {frame} was excluded ({cur.excluded[frame]['reason']}); "
                               "pass force=True to keep it instead")
    excluded = {k: v for k, v in cur.excluded.items() if k != frame}
    kept = dict(cur.kept_flagged)
    kept[frame] = {"note": note, "by": by or _user(), "at": _now()}
    return replace(cur, excluded=excluded, kept_flagged=kept, history=cur._log("keep_flagged", frame, note, by))


def _set_points(cur, field_name, what, action, frame, points, *, chamber, by, force, extra=None):
    """Store picked points of one frame in ``cur.<field_name>`` (manual profiles, priors).

    An identical entry is a no-op; a different one raises :class:`CurationConflict`
    unless ``force``.  The change is logged in the history.
    """
    frame = _check_frame(frame)
    pts = _check_points(points)
    entries = getattr(cur, field_name)
    old = entries.get(frame)
    if old is not None and old["points"] == pts and old.get("chamber") == chamber:
        return cur
    if old is not None and not force:
        raise CurationConflict(f"frame {frame} already has a {what} ({len(old['points'])} points, by "
                               f"{old.get('by')} at {old.get('at')}); pass force=True to replace it")
    entries = dict(entries)
    entries[frame] = {"points": pts, "units": "m", **(extra or {}), "chamber": chamber,
                      "by": by or _user(), "at": _now()}
    return replace(cur, **{field_name: entries}, history=cur._log(action, frame, f"{len(pts)} points", by))


def _remove_points(cur, field_name, action, frame, by):
    """Drop the entry of one frame from ``cur.<field_name>`` (no-op when absent)."""
    frame = _check_frame(frame)
    entries = getattr(cur, field_name)
    if frame not in entries:
        return cur
    kept = {k: v for k, v in entries.items() if k != frame}
    return replace(cur, **{field_name: kept}, history=cur._log(action, frame, "", by))


@_path_or_curation
def set_manual_profile(cur: Curation, frame: int, points, *, chamber: str | None = None, by: str | None = None,
                       force: bool = False) -> Curation:
    """Store a hand-picked membrane profile for one frame (``source = "manual"``).

    Parameters
    ----------
    cur : Curation or path
    frame : int
    points : array_like of shape (N, 2), m
        Membrane midline points in image coordinates, metres: ``x`` = column *
        pixel size (right), ``y`` = row * pixel size (down), origin at the
        centre of pixel (0, 0), ordered along the membrane.  N >= 4.
    chamber : str, optional
        Region name when the field holds several chambers.
    force : bool
        Replace an existing, different manual profile of this frame.

    Returns
    -------
    Curation

    Raises
    ------
    CurationConflict
        A different manual profile exists for this frame.
    """
    return _set_points(cur, "manual_profiles", "manual profile", "manual_profile", frame, points,
                       chamber=chamber, by=by, force=force, extra={"source": "manual"})


@_path_or_curation
def remove_manual_profile(cur: Curation, frame: int, *, by: str | None = None) -> Curation:
    """Drop the manual profile of a frame (the automatic trace is used again).

    Parameters
    ----------
    cur : Curation or path
    frame : int

    Returns
    -------
    Curation
    """
    return _remove_points(cur, "manual_profiles", "remove_manual_profile", frame, by)


@_path_or_curation
def set_prior(cur: Curation, frame: int, points, *, chamber: str | None = None, by: str | None = None,
              force: bool = False) -> Curation:
    """Store points picked on one frame as a prior of the automatic tracer (semi-automatic mode).

    Unlike a manual profile, a prior does not replace the frame's trace: the
    ``process`` step passes the priors to :func:`osmobulge.imaging.extract.extract`
    (``priors=``), whose tracer starts from them on their frame and from the
    nearest one on frames where it has no good previous trace.

    Parameters
    ----------
    cur : Curation or path
    frame : int
    points : array_like of shape (N, 2), m
        Points on the membrane in image coordinates, metres: ``x`` = column *
        pixel size, ``y`` = row * pixel size (as :func:`set_manual_profile`).  N >= 4.
    chamber : str, optional
        Region name when the field holds several chambers.
    force : bool
        Replace an existing, different prior of this frame.

    Returns
    -------
    Curation

    Raises
    ------
    CurationConflict
        A different prior exists for this frame.
    """
    return _set_points(cur, "priors", "prior", "prior", frame, points, chamber=chamber, by=by, force=force)


@_path_or_curation
def remove_prior(cur: Curation, frame: int, *, by: str | None = None) -> Curation:
    """Drop the prior of a frame (the tracer no longer starts from it).

    Parameters
    ----------
    cur : Curation or path
    frame : int

    Returns
    -------
    Curation
    """
    return _remove_points(cur, "priors", "remove_prior", frame, by)


@_path_or_curation
def set_time_origin(cur: Curation, time: float, *, by: str | None = None, force: bool = False) -> Curation:
    """Set t = 0 of the flux model, in seconds of the frame clock.

    Parameters
    ----------
    cur : Curation or path
    time : float, s
        Frames before it are left out of the fits.
    force : bool
        Replace a different time origin set before.

    Returns
    -------
    Curation
    """
    if isinstance(time, bool) or not isinstance(time, int | float | np.floating | np.integer) or not np.isfinite(time):
        raise ValueError(f"time = {time!r}: expected a finite time in seconds")
    time = float(time)
    if cur.time_origin == time:
        return cur
    if cur.time_origin is not None and not force:
        raise CurationConflict(f"the time origin is already {cur.time_origin:g} s; pass force=True to change it")
    return replace(cur, time_origin=time, history=cur._log("time_origin", None, f"{time:g} s", by))


@_path_or_curation
def set_chamber_regions(cur: Curation, regions, *, by: str | None = None, force: bool = False) -> Curation:
    """Set the chamber regions (pixels) of a field holding several chambers.

    Parameters
    ----------
    cur : Curation or path
    regions : list of dict
        ``{"name", "rows": [r0, r1], "cols": [c0, c1]}``; these replace the
        ones of ``experiment.toml``.
    force : bool
        Replace different regions set before.

    Returns
    -------
    Curation
    """
    new = tuple(_check_regions(regions))
    if cur.chamber_regions is not None and [dict(r) for r in cur.chamber_regions] == list(new):
        return cur
    if cur.chamber_regions is not None and not force:
        raise CurationConflict("chamber regions were set before; pass force=True to replace them")
    return replace(cur, chamber_regions=new, history=cur._log("chamber_regions", None, f"{len(new)} regions", by))


@_path_or_curation
def set_rim(cur: Curation, rim, *, by: str | None = None, force: bool = False) -> Curation:
    """Set (or, with ``rim=None``, clear) the chamber's rim in the flat frame.

    Parameters
    ----------
    cur : Curation or path
    rim : array_like of 4 float (pixels) or None
        ``[col0, row0, col1, row1]`` of the full frame: the flat membrane's
        mid-line ends at the two walls in the first frame (e.g. the two ends
        of points picked in napari).  It replaces ``[imaging] rim_px`` of
        experiment.toml; the silhouette route then looks for the top face and
        walls within a few pixels of it.  None: back to experiment.toml's.
    force : bool
        Replace (or clear) a different rim set before.

    Returns
    -------
    Curation
    """
    new = None if rim is None else _check_rim(rim)
    if cur.rim == new:
        return cur
    if cur.rim is not None and not force:
        raise CurationConflict(f"the rim was set before ({', '.join(f'{v:.1f}' for v in cur.rim)} px); pass "
                               f"force=True to {'clear' if new is None else 'replace'} it")
    detail = "cleared" if new is None else ", ".join(f"{v:.1f}" for v in new) + " px"
    return replace(cur, rim=new, history=cur._log("rim", None, detail, by))


# ---- use ------------------------------------------------------------------------------------------
def curation_fingerprint(cur: Curation, part: str = "all") -> str:
    """Content hash of the decisions that matter for a step.

    Parameters
    ----------
    cur : Curation
    part : {"all", "extraction", "fit"}
        ``extraction``: manual profiles, priors, chamber regions and the rim; ``fit``: exclusions,
        kept flagged frames and the time origin.

    Returns
    -------
    str
        SHA-256 hex digest (bookkeeping such as who/when is left out).
    """
    parts = ("all", "extraction", "fit")
    if part not in parts:
        raise ValueError(f"part = {part!r}: expected one of {parts}")
    d = cur.decisions()
    if part == "extraction":
        d = {k: d[k] for k in ("manual_profiles", "priors", "chamber_regions", "rim") if k in d}
    elif part == "fit":
        d = {k: d[k] for k in ("excluded", "kept_flagged", "time_origin")}
    return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()


def curation_summary(cur: Curation) -> dict:
    """Counts and lists for reports and the catalog (JSON-safe)."""
    reasons: dict[str, int] = {}
    for v in cur.excluded.values():
        reasons[v["reason"]] = reasons.get(v["reason"], 0) + 1
    return {
        "n_excluded": len(cur.excluded),
        "excluded_by_reason": reasons,
        "excluded": {int(k): {"reason": v["reason"], "note": v.get("note", "")}
                     for k, v in sorted(cur.excluded.items())},
        "n_kept_flagged": len(cur.kept_flagged),
        "n_manual_profiles": len(cur.manual_profiles),
        "manual_frames": sorted(int(k) for k in cur.manual_profiles),
        "n_priors": len(cur.priors),
        "prior_frames": sorted(int(k) for k in cur.priors),
        "time_origin_s": cur.time_origin,
        "n_chamber_regions": 0 if cur.chamber_regions is None else len(cur.chamber_regions),
        "rim_px": None if cur.rim is None else list(cur.rim),
        "revision": cur.revision,
        "n_changes": len(cur.history),
    }


def _frame_numbers(ds) -> np.ndarray:
    if "frame" in ds.variables:
        return np.asarray(ds["frame"].values).astype(int)
    return np.arange(ds.sizes["time"])


def apply_curation(dataset, curation: Curation):
    """Attach the curation to an extraction dataset.

    Parameters
    ----------
    dataset : xarray.Dataset
        Output of :func:`osmobulge.imaging.extract` (dim ``time``; a ``frame``
        coordinate or variable maps entries to frame indices, else positions
        are frame indices; optional per-frame ``flag``).
    curation : Curation

    Returns
    -------
    xarray.Dataset
        A copy with ``time`` shifted by the time origin and new variables
        ``excluded`` (bool: a person excluded it), ``exclusion_reason`` (str),
        ``kept`` (bool: used by the fits = not excluded, automatic flag ``ok``
        or kept on purpose, and not before the time origin); attrs
        ``curation_revision``, ``curation_hash``, ``n_excluded``.

    Raises
    ------
    ValueError
        A manual profile in the curation was not used by this extraction
        (``profile_source`` is not ``manual`` for that frame): re-run the
        ``process`` step.
    """
    import xarray as xr

    if "time" not in dataset.dims:
        raise ValueError("dataset: expected a 'time' dimension (an extraction dataset)")
    ds = dataset.copy()
    frames = _frame_numbers(ds)
    n = frames.size
    excluded = np.array([int(f) in curation.excluded for f in frames])
    reason = np.array([curation.excluded.get(int(f), {}).get("reason", "") for f in frames], dtype=object)
    if "flag" in ds.variables:
        flag = np.asarray(ds["flag"].values).astype(str)
        if flag.ndim > 1:  # several chambers: a frame is fine when all its chambers are
            flag = np.where(np.all(flag == "ok", axis=tuple(range(1, flag.ndim))), "ok", "flagged")
        auto_ok = flag == "ok"
    else:
        auto_ok = np.ones(n, bool)
    kept_flagged = np.array([int(f) in curation.kept_flagged for f in frames])
    kept = ~excluded & (auto_ok | kept_flagged)
    # manual profiles must have been used by the extraction
    if curation.manual_profiles and "profile_source" in ds.variables:
        src = np.asarray(ds["profile_source"].values).astype(str)
        for f in curation.manual_profiles:
            pos = np.flatnonzero(frames == f)
            if pos.size and not np.any(src[pos[0]] == "manual"):
                raise ValueError(f"frame {f} has a manual profile in the curation but the dataset traced it "
                                 "automatically: re-run the process step (osmobulge process DIR)")
    if curation.time_origin is not None:
        t = ds["time"].values.astype(float) - curation.time_origin
        kept &= t >= 0
        ds = ds.assign_coords(time=xr.DataArray(t, dims="time", attrs=dict(ds["time"].attrs)))
        ds["time"].attrs["time_origin"] = curation.time_origin
    ds["excluded"] = xr.DataArray(excluded, dims="time", attrs={"long_name": "excluded by a person", "units": "1"})
    ds["exclusion_reason"] = xr.DataArray(reason.astype(str), dims="time",
                                          attrs={"long_name": "reason of the exclusion", "units": "1"})
    ds["kept"] = xr.DataArray(kept, dims="time", attrs={"long_name": "frame used by the fits", "units": "1"})
    ds.attrs = copy.deepcopy(dict(ds.attrs))
    ds.attrs["curation_revision"] = int(curation.revision)
    ds.attrs["curation_hash"] = curation_fingerprint(curation)
    ds.attrs["n_excluded"] = int(excluded.sum())
    return ds
