"""Experiment folders and their ``experiment.toml`` (read, validate, template).

One folder per experiment: the frames (or a path to them), ``experiment.toml``
(what was measured, how), ``curation.json`` (what a person decided about the
frames, :mod:`osmobulge.experiments.curation`) and ``results/`` (what the
software computed, :mod:`osmobulge.experiments.runs`).

Every key is documented in ``docs/experiment-folder.md``.  The file is
validated on load: each error names the key, the value and the unit expected,
a value in the wrong unit (a radius in metres, a modulus in MPa) is caught by
range checks, an unknown key gets a "did you mean" suggestion, and a ``frames``
pattern that matches nothing is an error.  Lengths in the file are in
micrometres (``_um``), concentrations in mol/L (``_M``), times in minutes
(``_min``), material constants in Pa (``_Pa``); :class:`Experiment` holds SI.
"""

from __future__ import annotations

import datetime as _dt
import difflib
import glob
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from osmobulge.modeling.transport import Chamber

__all__ = [
    "EXPERIMENT_FILE",
    "FRAME_SUFFIXES",
    "MODELS",
    "BULGE_DIRECTIONS",
    "MetadataError",
    "ImagingSpec",
    "AnalysisSpec",
    "Experiment",
    "load_experiment",
    "validate_metadata",
    "is_experiment_dir",
    "find_experiments",
    "experiment_template",
    "write_template",
    "material_from_spec",
]

EXPERIMENT_FILE = "experiment.toml"
FRAME_SUFFIXES = (".tif", ".tiff", ".ome.tif", ".ome.tiff", ".png", ".jpg", ".jpeg", ".czi")
BULGE_DIRECTIONS = ("auto", "up", "down", "left", "right")
#: permeability models a ``fit`` step can run (``[analysis] models``)
MODELS = ("constant_linear", "constant_hyperelastic", "double_exponential")
_TIMESTAMP_SOURCES = ("files",)
_MATERIAL_LAWS = ("neo-hookean", "mooney-rivlin", "gent", "gent-gent", "linear")
_RATE_METHODS = ("bins", "savgol", "spline")


class MetadataError(ValueError):
    """An invalid ``experiment.toml``.

    Attributes
    ----------
    path : pathlib.Path or None
        The file.
    problems : list of str
        One message per problem, each naming the key, the value and what was expected.
    """

    def __init__(self, problems, path=None):
        self.problems = list(problems)
        self.path = None if path is None else Path(path)
        where = f"{self.path}: " if self.path is not None else ""
        if len(self.problems) == 1:
            msg = where + self.problems[0]
        else:
            msg = where + f"{len(self.problems)} problems:\n  - " + "\n  - ".join(self.problems)
        super().__init__(msg)


# ----------------------------------------------------------------------------------------------
# the schema: one declaration per key (type, unit, plausible range, default, documentation)
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Key:
    kind: str  # "str", "number", "int", "date", "bool", "str_or_list", "number_list", "material", "regions", "rim"
    required: bool = False
    default: Any = None
    unit: str = ""  # unit as written in the file, for messages
    lo: float | None = None  # plausible range (inclusive) in the file's unit
    hi: float | None = None
    si: float = 1.0  # multiply by this to get SI
    hints: tuple = ()  # (factor, unit name) pairs: value*factor in range -> "looks like <unit name>"
    choices: tuple = ()
    doc: str = ""


_LEN_HINTS = ((1e6, "metres"), (1e3, "millimetres"), (1e-3, "nanometres"))
_SCHEMA: dict[str, dict[str, _Key]] = {
    "experiment": {
        "name": _Key("str", required=True, doc="Short unique name of the experiment (one chamber or one field)."),
        "condition": _Key("str", default="", doc="Free label of the condition, e.g. 'reference', 'small radius'."),
        "material": _Key("str", doc="Material preset (PDMS, PEO_PDMS); or give a [material] table instead."),
        "date": _Key("date", default="", doc="Date of the experiment (TOML date or 'YYYY-MM-DD')."),
        "operator": _Key("str", default="", doc="Who ran it."),
        "notes": _Key("str", default="", doc="Free text."),
    },
    "chamber": {
        "radius_um": _Key("number", required=True, unit="um", lo=5.0, hi=20000.0, si=1e-6, hints=_LEN_HINTS,
                          doc="Chamber (well) radius a."),
        "depth_um": _Key("number", required=True, unit="um", lo=1.0, hi=20000.0, si=1e-6, hints=_LEN_HINTS,
                         doc="Well depth h."),
        "membrane_thickness_um": _Key("number", required=True, unit="um", lo=0.1, hi=5000.0, si=1e-6,
                                      hints=_LEN_HINTS, doc="Unstretched membrane thickness l0."),
        "concentration_M": _Key("number", required=True, unit="mol/L (M)", lo=1e-4, hi=10.0, si=1e3,
                                hints=((1e-3, "mol/m^3 (mM)"),), doc="Initial salt concentration C0 in the chamber."),
        "feed_concentration_M": _Key("number", default=0.0, unit="mol/L (M)", lo=0.0, hi=10.0, si=1e3,
                                     hints=((1e-3, "mol/m^3 (mM)"),), doc="Salt concentration outside (0 = water)."),
        "temperature_K": _Key("number", default=298.15, unit="K", lo=250.0, hi=400.0, si=1.0,
                              hints=(), doc="Absolute temperature."),
        "vant_hoff": _Key("number", default=2.0, unit="", lo=1.0, hi=5.0, si=1.0,
                          doc="van 't Hoff factor of the salt (2 for NaCl)."),
    },
    "imaging": {
        "frames": _Key("str", required=True, doc="Frames: a glob ('frames/*.tif'), a file (multi-page TIFF, CZI) "
                       "or a folder, relative to the experiment folder."),
        "pixel_size_um": _Key("number", unit="um/px", lo=0.01, hi=200.0, si=1e-6, hints=_LEN_HINTS,
                              doc="Pixel size; omit when the files carry it."),
        "frame_interval_min": _Key("number", unit="min", lo=1e-3, hi=1440.0, si=60.0,
                                   hints=((1.0 / 60.0, "seconds"),), doc="Time between frames."),
        "timestamps": _Key("str", choices=_TIMESTAMP_SOURCES,
                           doc="'files': take the frame times from the files' metadata."),
        "timestamps_min": _Key("number_list", unit="min", si=60.0, doc="Explicit time of each frame."),
        "bulge_direction": _Key("str", default="auto", choices=BULGE_DIRECTIONS,
                                doc="Direction the dome rises in the image ('auto' detects it)."),
        "chamber_regions": _Key("regions", default=(), doc="Regions (pixels) when one field holds several "
                                "chambers: a list of tables {name, rows = [r0, r1], cols = [c0, c1]}."),
        "reference_frame": _Key("str", doc="When the frames start bulged (a later file of a split series): an "
                                "image or series file whose first frame shows the flat membrane in the same "
                                "field (e.g. the first file), relative to the experiment folder."),
        "rim_px": _Key("rim", unit="px", doc="When the chamber is not found automatically: its rim in the flat "
                       "frame, [col0, row0, col1, row1], the flat mid-line's ends at the two walls (e.g. the ends "
                       "of a flat profile picked in napari); the top face and walls are measured within a few px "
                       "of it (bright-field silhouette route; not with chamber_regions)."),
    },
    "material": {
        "law": _Key("str", required=True, choices=_MATERIAL_LAWS, doc="Constitutive law."),
        "c1_Pa": _Key("number", unit="Pa", lo=10.0, hi=1e10, hints=((1e6, "MPa"), (1e3, "kPa")),
                      doc="C1 (neo-Hookean, Mooney-Rivlin, Gent, Gent-Gent)."),
        "c2_Pa": _Key("number", unit="Pa", lo=0.0, hi=1e10, hints=((1e6, "MPa"), (1e3, "kPa")),
                      doc="C2 (Mooney-Rivlin, Gent-Gent)."),
        "jm": _Key("number", unit="", lo=0.1, hi=1e4, doc="Locking J_m (Gent, Gent-Gent)."),
        "E_Pa": _Key("number", unit="Pa", lo=10.0, hi=1e11, hints=((1e6, "MPa"), (1e3, "kPa")),
                     doc="Young's modulus (linear law)."),
        "reference_modulus_Pa": _Key("number", unit="Pa", lo=10.0, hi=1e11, hints=((1e6, "MPa"), (1e3, "kPa")),
                                     doc="Modulus E that nondimensionalises the turgor pressure (optional)."),
    },
    "analysis": {
        "models": _Key("str_or_list", default=MODELS, choices=MODELS, doc="Permeability models to fit."),
        "linear_window_volume_ratio": _Key("number", default=1.3, unit="", lo=1.0001, hi=100.0,
                                           doc="Largest V/V0 used by the constant, linear-elastic fit."),
        "instantaneous": _Key("bool", default=True, doc="Compute the instantaneous permeability (Eqn 25)."),
        "rate_method": _Key("str", default="spline", choices=_RATE_METHODS,
                            doc="Rates d(V/V0)/dt for the instantaneous permeability: 'bins' (the paper's "
                            "overlapping time bins), 'savgol' or 'spline'."),
        "bin_width_min": _Key("number", default=120.0, unit="min", lo=1.0, hi=1e5, si=60.0,
                              hints=((1.0 / 60.0, "seconds"),), doc="Width of the time bins of rate_method = 'bins'."),
    },
}
_SECTIONS = tuple(_SCHEMA)
_MATERIAL_KEYS = {
    "neo-hookean": ("c1_Pa",),
    "mooney-rivlin": ("c1_Pa", "c2_Pa"),
    "gent": ("c1_Pa", "jm"),
    "gent-gent": ("c1_Pa", "c2_Pa", "jm"),
    "linear": ("E_Pa",),
}


def _suggest(name: str, options) -> str:
    close = difflib.get_close_matches(name, list(options), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else f"; valid keys: {', '.join(options)}"


def _fmt(value) -> str:
    return repr(value)


def _check_number(where: str, value, key: _Key, problems: list) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        unit = f" in {key.unit}" if key.unit else ""
        problems.append(f"{where} = {_fmt(value)}: expected a number{unit}, got {type(value).__name__}")
        return None
    value = float(value)
    if not math.isfinite(value):
        problems.append(f"{where} = {value!r}: expected a finite number")
        return None
    lo = -math.inf if key.lo is None else key.lo
    hi = math.inf if key.hi is None else key.hi
    if lo <= value <= hi:
        return value
    unit = f" {key.unit}" if key.unit else ""
    msg = f"{where} = {value!r}: expected a value in {key.unit or 'the range'} between {lo:g} and {hi:g}{unit}"
    for factor, unit_name in key.hints:
        if lo <= value * factor <= hi and value != 0:
            msg += f"; {value!r} looks like {unit_name} (did you mean {value * factor:g}{unit}?)"
            break
    problems.append(msg)
    return None


def _check_value(where: str, value, key: _Key, problems: list):
    """Validate one value against its declaration; return the file-unit value or None."""
    if key.kind == "str":
        if not isinstance(value, str):
            problems.append(f"{where} = {_fmt(value)}: expected a string, got {type(value).__name__}")
            return None
        if key.choices and value not in key.choices:
            problems.append(f"{where} = {value!r}: expected one of {', '.join(map(repr, key.choices))}")
            return None
        return value
    if key.kind == "number":
        return _check_number(where, value, key, problems)
    if key.kind == "bool":
        if not isinstance(value, bool):
            problems.append(f"{where} = {_fmt(value)}: expected true or false, got {type(value).__name__}")
            return None
        return value
    if key.kind == "date":
        if isinstance(value, _dt.datetime):
            return value.isoformat()
        if isinstance(value, _dt.date):
            return value.isoformat()
        if isinstance(value, str):
            if value == "":
                return ""
            try:
                return _dt.date.fromisoformat(value).isoformat()
            except ValueError:
                try:
                    return _dt.datetime.fromisoformat(value).isoformat()
                except ValueError:
                    pass
        problems.append(f"{where} = {_fmt(value)}: expected a date such as 2024-05-17 (TOML date or ISO string)")
        return None
    if key.kind == "str_or_list":
        items = [value] if isinstance(value, str) else value
        if not isinstance(items, list | tuple) or not all(isinstance(v, str) for v in items):
            problems.append(f"{where} = {_fmt(value)}: expected a string or a list of strings")
            return None
        bad = [v for v in items if key.choices and v not in key.choices]
        if bad:
            problems.append(f"{where} = {_fmt(value)}: unknown {', '.join(map(repr, bad))}; "
                            f"expected any of {', '.join(map(repr, key.choices))}")
            return None
        if not items:
            problems.append(f"{where} = []: give at least one of {', '.join(map(repr, key.choices))}")
            return None
        return tuple(dict.fromkeys(items))
    if key.kind == "number_list":
        if not isinstance(value, list) or not value:
            problems.append(f"{where} = {_fmt(value)}: expected a non-empty list of numbers in {key.unit}")
            return None
        if any(isinstance(v, bool) or not isinstance(v, int | float) for v in value):
            problems.append(f"{where} = {_fmt(value)}: expected a list of numbers in {key.unit}")
            return None
        arr = [float(v) for v in value]
        if any(not math.isfinite(v) for v in arr) or any(b <= a for a, b in zip(arr, arr[1:], strict=False)):
            problems.append(f"{where}: the times must be finite and strictly increasing")
            return None
        return tuple(arr)
    if key.kind == "rim":
        if (not isinstance(value, list) or len(value) != 4
                or any(isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) for v in value)):
            problems.append(f"{where} = {_fmt(value)}: expected four finite numbers [col0, row0, col1, row1] in "
                            f"{key.unit}")
            return None
        return tuple(float(v) for v in value)
    if key.kind == "regions":
        return _check_regions(where, value, problems)
    raise AssertionError(key.kind)  # pragma: no cover


def _check_regions(where: str, value, problems: list):
    if not isinstance(value, list):
        problems.append(f"{where} = {_fmt(value)}: expected a list of tables "
                        "{name, rows = [r0, r1], cols = [c0, c1]}")
        return None
    out = []
    for i, reg in enumerate(value):
        w = f"{where}[{i}]"
        if not isinstance(reg, dict):
            problems.append(f"{w} = {_fmt(reg)}: expected a table {{name, rows = [r0, r1], cols = [c0, c1]}}")
            continue
        unknown = set(reg) - {"name", "rows", "cols"}
        for k in sorted(unknown):
            problems.append(f"{w}: unknown key {k!r}" + _suggest(k, ("name", "rows", "cols")))
        name = reg.get("name", f"chamber{i}")
        if not isinstance(name, str):
            problems.append(f"{w}.name = {_fmt(name)}: expected a string")
            continue
        ok = True
        bounds = {}
        for k in ("rows", "cols"):
            v = reg.get(k)
            if (not isinstance(v, list) or len(v) != 2 or any(isinstance(x, bool) or not isinstance(x, int)
                                                                for x in v) or v[0] < 0 or v[1] <= v[0]):
                problems.append(f"{w}.{k} = {_fmt(v)}: expected [start, stop] pixel indices, 0 <= start < stop")
                ok = False
            else:
                bounds[k] = (int(v[0]), int(v[1]))
        if ok:
            out.append({"name": name, "rows": bounds["rows"], "cols": bounds["cols"]})
    names = [r["name"] for r in out]
    if len(set(names)) != len(names):
        problems.append(f"{where}: region names must be unique, got {names}")
    return tuple(out)


# ----------------------------------------------------------------------------------------------
# the validated experiment
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ImagingSpec:
    """How the frames were taken (SI).

    Attributes
    ----------
    frames : str
        The pattern, file or folder as written in the file.
    pixel_size : float or None, m
    frame_interval : float or None, s
    timestamps : tuple of float or None, s
        Explicit frame times (``timestamps_min``).
    timestamps_from_files : bool
    bulge_direction : str
    chamber_regions : tuple of dict
        ``{"name", "rows": (r0, r1), "cols": (c0, c1)}`` in pixels.
    reference_frame : str or None
        The file (as written) whose first frame shows the flat membrane, when the frames start bulged.
    rim : tuple of 4 float or None
        ``(col0, row0, col1, row1)`` px: the chamber's rim in the flat frame, when it is not found automatically.
    """

    frames: str
    pixel_size: float | None = None
    frame_interval: float | None = None
    timestamps: tuple | None = None
    timestamps_from_files: bool = False
    bulge_direction: str = "auto"
    chamber_regions: tuple = ()
    reference_frame: str | None = None
    rim: tuple | None = None


@dataclass(frozen=True)
class AnalysisSpec:
    """What the ``fit`` step computes (``[analysis]``).

    Attributes
    ----------
    models : tuple of str
        Any of :data:`MODELS`.
    linear_window_volume_ratio : float
        Largest V/V0 of the constant, linear-elastic fit (paper: 1.3).
    instantaneous : bool
    rate_method : str
        ``bins``, ``savgol`` or ``spline`` (:func:`osmobulge.modeling.instantaneous.volume_rates`).
    bin_width : float, s
        Time-bin width of ``rate_method = "bins"``.
    """

    models: tuple = MODELS
    linear_window_volume_ratio: float = 1.3
    instantaneous: bool = True
    rate_method: str = "spline"
    bin_width: float = 7200.0


@dataclass(frozen=True)
class Experiment:
    """A validated experiment folder.

    Attributes
    ----------
    path : pathlib.Path
        The folder.
    name, condition, date, operator, notes : str
    material_spec : str or dict
        The preset name, or the ``[material]`` table as written.
    chamber : osmobulge.modeling.Chamber
    imaging : ImagingSpec
    analysis : AnalysisSpec
    raw : dict
        The parsed TOML (JSON-safe: dates as ISO strings).
    """

    path: Path
    name: str
    material_spec: Any
    chamber: Chamber
    imaging: ImagingSpec
    analysis: AnalysisSpec = field(default_factory=AnalysisSpec)
    condition: str = ""
    date: str = ""
    operator: str = ""
    notes: str = ""
    raw: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def toml_path(self) -> Path:
        return self.path / EXPERIMENT_FILE

    @property
    def results_dir(self) -> Path:
        return self.path / "results"

    @property
    def reference_path(self) -> Path | None:
        """``[imaging] reference_frame`` as a path (relative to the folder, ``~`` expanded), or None."""
        ref = self.imaging.reference_frame
        return None if not ref else self.path / Path(ref).expanduser()

    @property
    def material(self):
        """The constitutive law (a :mod:`osmobulge.modeling.materials` object)."""
        return material_from_spec(self.material_spec)

    @property
    def material_name(self) -> str:
        if isinstance(self.material_spec, str):
            return self.material_spec.upper().replace("-", "_")
        consts = ", ".join(f"{k}={v:g}" for k, v in self.material_spec.items() if k != "law")
        return f"{self.material_spec['law']}({consts})"

    def frame_files(self) -> list[Path]:
        """The frame files, in natural order (validated to exist on load)."""
        return resolve_frames(self.path, self.imaging.frames)

    def frames_source(self) -> Path | list[Path]:
        """What to hand to the reader: the single file or folder, else the list of files."""
        files = self.frame_files()
        target = _frames_target(self.path, self.imaging.frames)
        if target.is_dir() or (len(files) == 1 and not _has_glob(self.imaging.frames)):
            return target
        return files

    def groups(self) -> dict[str, str]:
        """Condition keys for grouping: ``geometry``, ``loading``, ``material``."""
        c = self.chamber
        return {
            "geometry": f"a={c.radius * 1e6:g}um h={c.depth * 1e6:g}um l0={c.thickness * 1e6:g}um",
            "loading": f"C0={c.concentration / 1e3:g}M feed={c.feed_concentration / 1e3:g}M T={c.temperature:g}K",
            "material": self.material_name,
        }

    def summary(self) -> dict:
        """JSON-safe metadata (file units, as in the catalog)."""
        c, im = self.chamber, self.imaging
        r = lambda x: float(f"{x:.12g}")  # noqa: E731 - undo the SI round trip (100e-6 * 1e6 = 99.99999999999999)
        return {
            "name": self.name, "condition": self.condition, "material": self.material_name,
            "date": self.date, "operator": self.operator, "notes": self.notes,
            "radius_um": r(c.radius * 1e6), "depth_um": r(c.depth * 1e6), "membrane_thickness_um": r(c.thickness * 1e6),
            "concentration_M": r(c.concentration / 1e3), "feed_concentration_M": r(c.feed_concentration / 1e3),
            "temperature_K": c.temperature,
            "pixel_size_um": None if im.pixel_size is None else r(im.pixel_size * 1e6),
            "frame_interval_min": None if im.frame_interval is None else r(im.frame_interval / 60.0),
            "frame_times": self._timing(),
            "bulge_direction": im.bulge_direction,
        }

    def _timing(self) -> str:
        im = self.imaging
        if im.timestamps_from_files:
            return "from the files' metadata"
        if im.timestamps is not None:
            t = im.timestamps
            return f"{len(t)} times from timestamps_min, {t[0] / 60:g} to {t[-1] / 60:g} min"
        if im.frame_interval is not None:
            return f"every {im.frame_interval / 60:g} min"
        return ""


def material_from_spec(spec):
    """Material object from a preset name or a validated ``[material]`` table.

    Parameters
    ----------
    spec : str or dict
        ``"PDMS"``, ``"PEO_PDMS"``, or ``{"law": ..., "c1_Pa": ..., ...}``.

    Returns
    -------
    material
        An :mod:`osmobulge.modeling.materials` law.
    """
    from osmobulge.modeling import materials as m

    if isinstance(spec, str):
        return m.get_material(spec)
    law = spec["law"]
    ref = spec.get("reference_modulus_Pa")
    if law == "neo-hookean":
        return m.NeoHookean(spec["c1_Pa"], reference_modulus=ref)
    if law == "mooney-rivlin":
        return m.MooneyRivlin(spec["c1_Pa"], spec["c2_Pa"], reference_modulus=ref)
    if law == "gent":
        return m.Gent(spec["c1_Pa"], spec["jm"], reference_modulus=ref)
    if law == "gent-gent":
        return m.GentGent(spec["c1_Pa"], spec["c2_Pa"], spec["jm"], reference_modulus=ref)
    if law == "linear":
        return m.LinearElastic(spec["E_Pa"])
    raise ValueError(f"[material] law = {law!r}: expected one of {_MATERIAL_LAWS}")


def _has_glob(pattern: str) -> bool:
    return any(ch in pattern for ch in "*?[")


def _frames_target(base: Path, pattern: str) -> Path:
    p = Path(pattern).expanduser()
    return p if p.is_absolute() else Path(base) / p


def _is_frame_file(p: Path) -> bool:
    name = p.name.lower()
    return p.is_file() and not name.startswith(".") and name.endswith(FRAME_SUFFIXES)


def resolve_frames(base, pattern: str) -> list[Path]:
    """Frame files of a ``frames`` entry, in natural order.

    Parameters
    ----------
    base : path
        The experiment folder (relative patterns are relative to it).
    pattern : str
        A glob, a file or a folder.

    Returns
    -------
    list of pathlib.Path
        Empty when nothing matches.
    """
    from natsort import natsorted

    target = _frames_target(Path(base), pattern)
    if _has_glob(pattern):
        files = [Path(f) for f in glob.glob(str(target), recursive=True)]
        files = [f for f in files if f.is_file()]
    elif target.is_dir():
        files = [f for f in target.iterdir() if _is_frame_file(f)]
    elif target.is_file():
        files = [target]
    else:
        files = []
    return [Path(f) for f in natsorted(files, key=str)]


def validate_metadata(data: dict, base=None, *, check_frames: bool = True, path=None) -> Experiment:
    """Validate parsed ``experiment.toml`` content.

    Parameters
    ----------
    data : dict
        The parsed TOML.
    base : path, optional
        The experiment folder (for the frames); default the current folder.
    check_frames : bool
        Require that ``[imaging] frames`` matches at least one file.
    path : path, optional
        The file, for messages.

    Returns
    -------
    Experiment

    Raises
    ------
    MetadataError
        Listing every problem: missing keys, wrong types, values out of their
        plausible range (with the likely unit mistake), unknown keys with a
        suggestion, frames that match nothing.
    """
    base = Path(base if base is not None else ".")
    problems: list[str] = []
    if not isinstance(data, dict):
        raise MetadataError(["expected a TOML document"], path)
    for sec in data:
        if sec not in _SCHEMA:
            problems.append(f"unknown section [{sec}]" + _suggest(sec, _SECTIONS).replace("keys", "sections"))
        elif not isinstance(data[sec], dict):
            problems.append(f"{sec} = {_fmt(data[sec])}: expected a table [{sec}]")
    values: dict[str, dict[str, Any]] = {}
    for sec, keys in _SCHEMA.items():
        table = data.get(sec, {})
        if not isinstance(table, dict):
            table = {}
        if sec == "material" and sec not in data:
            continue
        vals: dict[str, Any] = {}
        for k in table:
            if k not in keys:
                problems.append(f"[{sec}] unknown key {k!r}" + _suggest(k, keys))
        for k, key in keys.items():
            where = f"[{sec}] {k}"
            if k in table:
                v = _check_value(where, table[k], key, problems)
                if v is not None:
                    vals[k] = v
            elif key.required:
                unit = f" in {key.unit}" if key.unit else ""
                problems.append(f"{where}: missing (required{unit}: {key.doc})")
            elif key.default is not None:
                vals[k] = key.default
        values[sec] = vals

    # material: a preset or a [material] table, not both
    exp = values.get("experiment", {})
    mat_table = values.get("material")
    material_spec: Any = None
    if "material" in exp and mat_table is not None:
        problems.append("[experiment] material and a [material] table are both given: keep one")
    elif "material" in exp:
        from osmobulge.modeling.materials import get_material

        try:
            get_material(exp["material"])
            material_spec = exp["material"]
        except ValueError as err:
            problems.append(f"[experiment] material = {exp['material']!r}: {err}; or describe it in a [material] table")
    elif mat_table is not None:
        law = mat_table.get("law")
        if law is not None:
            raw_mat = data["material"]
            for k in _MATERIAL_KEYS[law]:
                if k not in raw_mat:
                    problems.append(f"[material] {k}: missing (required by law = {law!r})")
            extra = set(raw_mat) & set(_SCHEMA["material"]) - set(_MATERIAL_KEYS[law]) - {"law", "reference_modulus_Pa"}
            for k in sorted(extra):
                problems.append(f"[material] {k} = {raw_mat[k]!r}: not a constant of law = {law!r} "
                                f"(which takes {', '.join(_MATERIAL_KEYS[law])})")
            material_spec = dict(mat_table)
            if not problems:
                try:
                    material_from_spec(material_spec)
                except (TypeError, ValueError) as err:
                    problems.append(f"[material]: {err}")
    elif "experiment" in data:
        problems.append("[experiment] material: missing (a preset such as 'PDMS' or 'PEO_PDMS', "
                        "or a [material] table with law and constants in Pa)")

    # timing: exactly one source
    im = values.get("imaging", {})
    raw_im = data.get("imaging")
    if isinstance(raw_im, dict):
        given = [k for k in ("frame_interval_min", "timestamps", "timestamps_min") if k in raw_im]
        if not given:
            problems.append("[imaging]: no frame times: set frame_interval_min (minutes), timestamps_min (a list "
                            "in minutes) or timestamps = \"files\" (from the files' metadata)")
        elif len(given) > 1:
            problems.append(f"[imaging]: give only one of {', '.join(given)}")

    # frames exist
    files: list[Path] = []
    if check_frames and "frames" in im:
        files = resolve_frames(base, im["frames"])
        if not files:
            target = _frames_target(base, im["frames"])
            problems.append(f"[imaging] frames = {im['frames']!r}: no frame file found ({target}); "
                            f"expected a glob, a file or a folder of {', '.join(FRAME_SUFFIXES)} images")
        elif "timestamps_min" in im and len(files) > 1 and len(im["timestamps_min"]) != len(files):
            problems.append(f"[imaging] timestamps_min: {len(im['timestamps_min'])} times for {len(files)} frame files")
    if im.get("rim_px") is not None and im.get("chamber_regions"):
        problems.append("[imaging] rim_px and chamber_regions: the rim locates one chamber in the whole field; "
                        "give one or the other")
    if "reference_frame" in im and not str(im["reference_frame"]).strip():
        problems.append("[imaging] reference_frame is empty: give a file, or delete the key")
    elif check_frames and "reference_frame" in im:
        target = base / Path(im["reference_frame"]).expanduser()
        if not target.is_file():
            problems.append(f"[imaging] reference_frame = {im['reference_frame']!r}: no such file ({target}); "
                            f"give the image or series file whose first frame shows the flat membrane")

    if problems:
        raise MetadataError(problems, path)

    s = lambda sec, k: values[sec][k] * _SCHEMA[sec][k].si  # noqa: E731
    try:
        chamber = Chamber(
            radius=s("chamber", "radius_um"), depth=s("chamber", "depth_um"),
            thickness=s("chamber", "membrane_thickness_um"), concentration=s("chamber", "concentration_M"),
            feed_concentration=s("chamber", "feed_concentration_M"), temperature=s("chamber", "temperature_K"),
            vant_hoff=s("chamber", "vant_hoff"),
        )
    except ValueError as err:  # e.g. a membrane thicker than the chamber radius
        raise MetadataError([f"[chamber]: {err}"], path) from None
    imaging = ImagingSpec(
        frames=im["frames"],
        pixel_size=s("imaging", "pixel_size_um") if "pixel_size_um" in im else None,
        frame_interval=s("imaging", "frame_interval_min") if "frame_interval_min" in im else None,
        timestamps=tuple(t * 60.0 for t in im["timestamps_min"]) if "timestamps_min" in im else None,
        timestamps_from_files=im.get("timestamps") == "files",
        bulge_direction=im["bulge_direction"],
        chamber_regions=im["chamber_regions"],
        reference_frame=im.get("reference_frame"),
        rim=im.get("rim_px"),
    )
    an = values["analysis"]
    analysis = AnalysisSpec(
        models=tuple(an["models"]), linear_window_volume_ratio=an["linear_window_volume_ratio"],
        instantaneous=an["instantaneous"], rate_method=an["rate_method"], bin_width=an["bin_width_min"] * 60.0,
    )
    return Experiment(
        path=base, name=exp["name"], material_spec=material_spec, chamber=chamber, imaging=imaging,
        analysis=analysis, condition=exp["condition"], date=exp["date"], operator=exp["operator"],
        notes=exp["notes"], raw=_json_safe(data),
    )


def _json_safe(obj):
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, _dt.date | _dt.time):
        return obj.isoformat()
    return obj


def load_experiment(path, *, check_frames: bool = True) -> Experiment:
    """Read and validate an experiment folder.

    Parameters
    ----------
    path : path
        The folder, or its ``experiment.toml``.
    check_frames : bool
        Require the frames to exist (off for catalogs of moved data).

    Returns
    -------
    Experiment

    Raises
    ------
    FileNotFoundError
        No ``experiment.toml`` (run ``osmobulge init DIR``).
    MetadataError
        Invalid TOML or invalid content (every problem listed).
    """
    path = Path(path)
    toml = path if path.name == EXPERIMENT_FILE or path.suffix == ".toml" else path / EXPERIMENT_FILE
    if not toml.is_file():
        raise FileNotFoundError(f"{toml}: no {EXPERIMENT_FILE} (write a template with `osmobulge init {toml.parent}`)")
    try:
        data = tomllib.loads(toml.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as err:
        raise MetadataError([f"not valid TOML: {err}"], toml) from None
    return validate_metadata(data, toml.parent, check_frames=check_frames, path=toml)


def is_experiment_dir(path) -> bool:
    """True when ``path`` is a folder holding an ``experiment.toml``."""
    return (Path(path) / EXPERIMENT_FILE).is_file()


def find_experiments(root) -> list[Path]:
    """Every experiment folder at or under ``root``, in natural order.

    ``results/`` folders and hidden folders are not searched.
    """
    import os

    from natsort import natsorted

    root = Path(root)
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = [d for d in dirnames if not d.startswith(".") and d != "results"]
        if EXPERIMENT_FILE in filenames:
            found.append(Path(dirpath))
    return [Path(p) for p in natsorted(found, key=str)]


# ----------------------------------------------------------------------------------------------
# template
# ----------------------------------------------------------------------------------------------
_TEMPLATE = '''\
# osmobulge experiment description.  Every key: docs/experiment-folder.md
# Units are in the key names: _um micrometres, _M mol/L, _min minutes, _K kelvin, _Pa pascal.

[experiment]
name = "{name}"                  # short unique name
condition = "{condition}"        # free label used to group experiments ("reference", "small radius", ...)
material = "{material}"          # preset: "PDMS" or "PEO_PDMS"; or delete this line and fill [material] below
date = {date}
operator = ""
notes = ""

[chamber]
radius_um = 200.0                # well radius a
depth_um = 110.0                 # well depth h
membrane_thickness_um = 20.0     # unstretched membrane thickness l0
concentration_M = 3.0            # salt in the chamber at t = 0
feed_concentration_M = 0.0       # salt outside (0 = pure water)
temperature_K = 298.15
# vant_hoff = 2.0                # van 't Hoff factor (2 for NaCl)

[imaging]
frames = "{frames}"              # a glob, a multi-page TIFF/OME-TIFF/CZI file, or a folder of images
pixel_size_um = 2.0              # delete if the files carry the pixel size
frame_interval_min = 15.0        # or: timestamps = "files"  or: timestamps_min = [0, 15, 30, ...]
bulge_direction = "auto"         # "auto", "up", "down", "left" or "right"
# reference_frame = "../day-1/frames.tif"  # frames that start bulged (a later file of a split series):
#                                          # a file whose first frame shows the flat membrane
# Several chambers in one field: one region each (pixel index ranges, [start, stop)).
# chamber_regions = [
#   {{ name = "left", rows = [0, 512], cols = [0, 400] }},
#   {{ name = "right", rows = [0, 512], cols = [400, 800] }},
# ]

# [material]                     # instead of a preset: law and constants in Pa
# law = "gent-gent"              # "neo-hookean", "mooney-rivlin", "gent", "gent-gent" or "linear"
# c1_Pa = 31600.0
# c2_Pa = 29700.0
# jm = 26.0
# reference_modulus_Pa = 370000.0   # E used for P_t / E (optional)

[analysis]
models = ["constant_linear", "constant_hyperelastic", "double_exponential"]
linear_window_volume_ratio = 1.3 # largest V/V0 of the constant, linear-elastic fit
instantaneous = true             # instantaneous permeability (main text Eqn 25)
rate_method = "spline"           # d(V/V0)/dt: "bins" (paper, supplement Sec 7.3), "savgol" or "spline"
bin_width_min = 120.0            # width of the time bins of rate_method = "bins"
'''


def experiment_template(name: str = "experiment", *, material: str = "PDMS", frames: str = "frames/*.tif",
                        condition: str = "", date: str | None = None) -> str:
    """The commented ``experiment.toml`` template written by ``osmobulge init``.

    Parameters
    ----------
    name, material, frames, condition : str
        Filled in; everything else holds the paper's reference chamber.
    date : str, optional
        ISO date; default today.

    Returns
    -------
    str
        TOML text that :func:`validate_metadata` accepts once the frames exist.
    """
    date = date or _dt.date.today().isoformat()
    esc = lambda s: str(s).replace("\\", "\\\\").replace('"', '\\"')  # noqa: E731
    return _TEMPLATE.format(name=esc(name), condition=esc(condition), material=esc(material),
                            frames=esc(frames), date=_dt.date.fromisoformat(date).isoformat())


def write_template(directory, *, name: str | None = None, material: str = "PDMS", frames: str = "frames/*.tif",
                   condition: str = "", force: bool = False) -> Path:
    """Write ``DIR/experiment.toml`` from :func:`experiment_template` (atomically).

    Parameters
    ----------
    directory : path
        Created if missing.
    name : str, optional
        Default: the folder name.
    force : bool
        Overwrite an existing file (it is kept as ``experiment.toml.bak``).

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    FileExistsError
        The file exists and ``force`` is false.
    """
    from osmobulge.experiments._io import atomic_write_text

    directory = Path(directory)
    target = directory / EXPERIMENT_FILE
    if target.exists():
        if not force:
            raise FileExistsError(f"{target} exists; pass force=True (--force) to replace it (a .bak is kept)")
        atomic_write_text(target.with_name(EXPERIMENT_FILE + ".bak"), target.read_text(encoding="utf-8"))
    text = experiment_template(name or directory.resolve().name, material=material, frames=frames,
                               condition=condition)
    tomllib.loads(text)  # the template must stay valid TOML
    return atomic_write_text(target, text)
