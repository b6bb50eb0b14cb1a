"""Self-contained HTML reports (figures embedded as base64 PNG; open offline).

- :func:`write_experiment_report`: one experiment (metadata, curation summary,
  frame strip with traced profiles, V/V0(t) with every fitted model and
  residuals, lambda_pre(Vtilde), instantaneous P_w(lambda_bar) with the fitted
  law, parameter table with uncertainties, quality warnings, software version
  and parameters).
- :func:`write_campaign_report`: a group of experiments fitted simultaneously
  (the paper's Table 2, Table 3, Fig. 6 and Fig. 7 from the user's data).

Plots use matplotlib's Agg backend and never touch the screen.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import json
import math
from pathlib import Path

import numpy as np

from osmobulge.experiments._io import atomic_write_text

__all__ = ["HtmlReport", "figure_png", "write_experiment_report", "write_campaign_report", "extraction_warnings",
           "plot_volume_ratio", "plot_instantaneous", "plot_prestretch", "plot_frame_strip"]

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;max-width:1100px;
color:#222;line-height:1.4;padding:0 1em}
h1{font-size:1.6em;border-bottom:2px solid #2a7;padding-bottom:.2em}h2{font-size:1.25em;margin-top:1.6em;color:#155}
table{border-collapse:collapse;margin:.6em 0;font-size:.92em}td,th{border:1px solid #ccc;padding:.25em .6em;
text-align:left;vertical-align:top}th{background:#eef5f2}td.num{text-align:right;font-variant-numeric:tabular-nums}
.warn{background:#fff4e0;border-left:4px solid #e90;padding:.4em .8em;margin:.3em 0}
.ok{background:#eaf7ee;border-left:4px solid #2a7;padding:.4em .8em;margin:.3em 0}
.err{background:#fde8e8;border-left:4px solid #c22;padding:.4em .8em;margin:.3em 0}
figure{margin:1em 0}figcaption{font-size:.9em;color:#555}img{max-width:100%}
code,pre{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:.88em}pre{background:#f6f6f6;padding:.6em;
overflow-x:auto}.small{font-size:.85em;color:#666}
"""


def figure_png(fig, *, dpi: int = 110) -> str:
    """A matplotlib figure as a base64 PNG string (the figure is closed)."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _fmt(v, spec=".4g") -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int | float | np.floating | np.integer):
        if isinstance(v, float | np.floating) and not math.isfinite(float(v)):
            return ""
        return format(v, spec)
    return str(v)


class HtmlReport:
    """A minimal builder of one self-contained HTML page.

    Parameters
    ----------
    title : str
    """

    def __init__(self, title: str):
        self.title = title
        self.parts: list[str] = []

    def h2(self, text: str) -> None:
        self.parts.append(f"<h2>{html.escape(text)}</h2>")

    def p(self, text: str, cls: str | None = None) -> None:
        c = f' class="{cls}"' if cls else ""
        self.parts.append(f"<p{c}>{html.escape(text)}</p>")

    def note(self, text: str, kind: str = "warn") -> None:
        """A coloured box: ``kind`` in warn, ok, err."""
        self.parts.append(f'<div class="{kind}">{html.escape(text)}</div>')

    def pre(self, text: str) -> None:
        self.parts.append(f"<pre>{html.escape(text)}</pre>")

    def table(self, rows, columns=None, *, formats=None) -> None:
        """A table from a list of dicts (or a dict of key -> value as two columns)."""
        formats = formats or {}
        if isinstance(rows, dict):
            rows = [{"key": k, "value": v} for k, v in rows.items()]
            columns = columns or ["key", "value"]
        rows = list(rows)
        if not rows:
            self.parts.append('<p class="small">(none)</p>')
            return
        columns = columns or list(rows[0])
        out = ["<table><tr>" + "".join(f"<th>{html.escape(str(c))}</th>" for c in columns) + "</tr>"]
        for r in rows:
            cells = []
            for c in columns:
                v = r.get(c)
                num = isinstance(v, int | float | np.floating | np.integer) and not isinstance(v, bool)
                s = _fmt(v, formats.get(c, ".4g"))
                cells.append(f'<td class="num">{html.escape(s)}</td>' if num else f"<td>{html.escape(s)}</td>")
            out.append("<tr>" + "".join(cells) + "</tr>")
        out.append("</table>")
        self.parts.append("".join(out))

    def figure(self, fig, caption: str = "") -> None:
        """Embed a matplotlib figure (closed afterwards)."""
        data = figure_png(fig)
        cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
        self.parts.append(f'<figure><img alt="{html.escape(caption or "figure")}" '
                          f'src="data:image/png;base64,{data}">{cap}</figure>')

    def html(self) -> str:
        body = "\n".join(self.parts)
        stamp = _dt.datetime.now().isoformat(timespec="seconds")
        return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>"
                f"<h1>{html.escape(self.title)}</h1>\n{body}\n"
                f'<p class="small">Generated {stamp} by osmobulge.</p></body></html>\n')

    def write(self, path) -> Path:
        """Write atomically."""
        return atomic_write_text(path, self.html())


def _json(path: Path) -> dict:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError):
        return {}


# ------------------------------------------------------------------------------------------------
# figures
# ------------------------------------------------------------------------------------------------
_MODEL_LABELS = {
    "constant_linear": "constant P_w, linear elastic (window)",
    "constant_hyperelastic": "constant P_w, hyperelastic",
    "double_exponential": "P_w(lambda_bar), Eqn 27, hyperelastic",
}
_MODEL_COLORS = {"constant_linear": "#c9a227", "constant_hyperelastic": "#e07b24", "double_exponential": "#11897f"}


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _var(ds, *names):
    for n in names:
        if n in ds.variables:
            return ds[n]
    return None


def plot_volume_ratio(fits, *, title: str = "", curated=None):
    """V/V0(t) with each fitted model (fine curves) and the residuals below.

    The constant linear-elastic model is drawn solid inside its window
    (V/V0 up to ``linear_window_volume_ratio``, the only data it was fitted to)
    and dashed beyond; its residuals are shown inside the window only.

    Parameters
    ----------
    fits : xarray.Dataset
        ``fits.nc`` content (:func:`osmobulge.experiments.runs.fit_observations`).
    title : str
    curated : xarray.Dataset, optional
        The extraction after :func:`~osmobulge.experiments.curation.apply_curation`:
        frames not used by the fits (excluded by a person, flagged, before the
        time origin) are drawn as red crosses.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _plt()
    fig, (ax, axr) = plt.subplots(2, 1, figsize=(7.5, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]})
    t = fits["time"].values / 3600.0
    v = fits["volume_ratio"].values
    ci = fits["chamber_index"].values.astype(int)
    window = float(fits.attrs.get("linear_window_volume_ratio", np.inf))
    markers = "osD^v<>p*h"
    for c in np.unique(ci):
        sel = ci == c
        ax.plot(t[sel], v[sel], markers[c % len(markers)], ms=4, mfc="none", color="k",
                label="data (used by the fits)" if c == 0 else None)
    if curated is not None and "kept" in curated and "volume_ratio" in curated:
        vr = curated["volume_ratio"]
        vr = vr.transpose("time", ...) if "chamber" in vr.dims else vr
        drop = ~np.asarray(curated["kept"].values, bool)
        vals = np.asarray(vr.values, float).reshape(curated.sizes["time"], -1)
        tt = np.asarray(curated["time"].values, float) / 3600.0
        if drop.any():
            ax.plot(np.repeat(tt[drop], vals.shape[1]), vals[drop].ravel(), "x", color="#c22", ms=6,
                    label="not used (excluded, flagged or before t = 0)")
    if "model" in fits.coords:
        for k, m in enumerate(fits["model"].values):
            m = str(m)
            color = _MODEL_COLORS.get(m)
            linear = m == "constant_linear"
            for c in range(fits.sizes.get("chamber", 0)):
                ft = fits["fine_time"].values[c] / 3600.0
                fv = fits["fine_volume_ratio"].values[k, c]
                inside = fv <= window if linear else np.ones(fv.shape, bool)
                ax.plot(np.where(inside, ft, np.nan), fv, "-", color=color, lw=1.6,
                        label=_MODEL_LABELS.get(m, m) if c == 0 else None)
                if linear and (~inside).any():
                    last = max(int(np.argmax(~inside)) - 1, 0)
                    out = ~inside
                    out[last] = True
                    ax.plot(np.where(out, ft, np.nan), fv, "--", color=color, lw=0.9,
                            label="(linear model beyond its window)" if c == 0 else None)
            r = fits["residual"].values[k]
            use = v <= window if linear else np.ones(v.shape, bool)
            axr.plot(t[use], r[use], "o", ms=3, color=color)
    axr.axhline(0, color="0.5", lw=0.8)
    if np.isfinite(window) and "model" in fits.coords and "constant_linear" in [str(m) for m in fits["model"].values]:
        ax.axhline(window, color=_MODEL_COLORS["constant_linear"], lw=0.6, ls=":")
    ax.set_ylabel("V/V0")
    axr.set_ylabel("data - model")
    axr.set_xlabel("time (h)")
    ax.legend(fontsize=8, loc="upper left")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return fig


def plot_instantaneous(fits, summary: dict | None = None, *, title: str = ""):
    """Instantaneous P_w(lambda_bar) (values and stretch bins) with the fitted laws.

    Parameters
    ----------
    fits : xarray.Dataset
    summary : dict, optional
        The ``fits.json`` content (fitted constants).

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    lam = _var(fits, "inst_lambda_bar")
    pw = _var(fits, "inst_permeability")
    if lam is not None and pw is not None:
        ax.plot(lam.values, pw.values, ".", color="0.6", ms=3, label="instantaneous (Eqn 25)")
    bl, bp = _var(fits, "bin_lambda_bar", "inst_bin_lambda_bar"), _var(fits, "bin_permeability",
                                                                      "inst_bin_permeability")
    if bl is not None and bp is not None:
        be = _var(fits, "bin_permeability_std", "inst_bin_permeability_std", "bin_permeability_sem")
        bx = _var(fits, "bin_lambda_bar_std", "inst_bin_lambda_bar_std")
        ax.errorbar(bl.values, bp.values, yerr=None if be is None else be.values,
                    xerr=None if bx is None else bx.values, fmt="o", color="k", ms=5, capsize=2,
                    label="binned by stretch")
    lo = np.nanmin(lam.values) if lam is not None and np.isfinite(lam.values).any() else 1.0
    hi = np.nanmax(lam.values) if lam is not None and np.isfinite(lam.values).any() else 3.0
    grid = np.linspace(1.0, max(hi, 1.2), 200)
    models = (summary or {}).get("models", {})
    for m, rec in models.items():
        if not rec.get("ok"):
            continue
        p = rec["params"]
        if rec["family"] == "double_exponential" and {"c1", "c2", "c3", "c4"} <= set(p):
            y = p["c1"] * np.exp(p["c2"] * grid) + p["c3"] * np.exp(p["c4"] * grid)
        else:
            y = np.full_like(grid, rec.get("P_w1") or np.nan)
        ax.plot(grid, y, "-", color=_MODEL_COLORS.get(m), lw=1.8, label=_MODEL_LABELS.get(m, m))
    ax.set_xlim(min(lo, 1.0) - 0.05, max(hi, 1.2) + 0.05)
    ax.set_yscale("log")
    ax.set_xlabel("average biaxial stretch lambda_bar")
    ax.set_ylabel("P_w (m^2/s)")
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return fig


def plot_prestretch(extraction):
    """Rim pre-stretch lambda_pre against Vtilde (extraction), with the paper's quadratic through (0, 1)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    vt, lp = _var(extraction, "vtilde"), _var(extraction, "lambda_pre")
    if vt is None or lp is None:
        ax.text(0.5, 0.5, "no rim radius in the extraction", ha="center", transform=ax.transAxes)
        return fig
    x, y = np.ravel(vt.values).astype(float), np.ravel(lp.values).astype(float)
    ok = np.isfinite(x) & np.isfinite(y)
    if "flag" in extraction.variables and extraction["flag"].shape == vt.shape:
        good = np.ravel(extraction["flag"].values).astype(str) == "ok"
        if (ok & ~good).any():
            ax.plot(x[ok & ~good], y[ok & ~good], "x", ms=5, color="#c22", label="flagged frames (not fitted)")
        ok &= good
    ax.plot(x[ok], y[ok], "o", ms=4, mfc="none", color="k", label="measured (rim radius / flat rim radius)")
    if ok.sum() >= 3:
        try:
            from osmobulge.modeling.prestretch import fit_prestretch

            pre = fit_prestretch(x[ok], y[ok])
            g = np.linspace(0, x[ok].max(), 100)
            ax.plot(g, pre(g), "-", color="#11897f", label=f"1 + {pre.c1:.3g} V + {pre.c2:.3g} V^2")
        except Exception:  # noqa: BLE001 - the plot is informative only
            pass
    ax.set_xlabel("Vtilde")
    ax.set_ylabel("lambda_pre")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _frame_images(exp, positions):
    """Frames at these positions of the extraction's time axis (read with the process step's reader)."""
    import dask

    from osmobulge.experiments.runs import open_experiment_frames

    ef = open_experiment_frames(exp)
    with dask.config.set(scheduler="synchronous"):
        return [np.asarray(ef.frames[int(i)]) for i in positions]


def _profile_pixels(extraction, i: int) -> list:
    """``[(rows, cols), ...]`` of the traced profile(s) of entry ``i`` in frame pixels (one per chamber)."""
    if "profile_row" not in extraction.variables or "profile_col" not in extraction.variables:
        return []
    r = extraction["profile_row"].isel(time=i)
    c = extraction["profile_col"].isel(time=i)
    if "chamber" in r.dims:
        r, c = r.transpose("chamber", ...), c.transpose("chamber", ...)
        return [(np.asarray(r.values[k], float), np.asarray(c.values[k], float)) for k in range(r.sizes["chamber"])]
    return [(np.asarray(r.values, float), np.asarray(c.values, float))]


def _entry_str(extraction, name: str, i: int, k: int) -> str:
    if name not in extraction.variables:
        return ""
    v = extraction[name].isel(time=i)
    if "chamber" in v.dims:
        v = v.isel(chamber=k)
    return str(np.ravel(v.values)[0])


def plot_frame_strip(exp, extraction, *, n: int = 6, crop: bool = True):
    """A strip of frames with the traced profile(s) overlaid (manual profiles in red).

    Parameters
    ----------
    exp : Experiment
    extraction : xarray.Dataset
        ``results/extraction.nc`` (``profile_row``/``profile_col`` in frame pixels).
    n : int
        Frames shown, evenly spread over the series.
    crop : bool
        Zoom on the traced domes (with a margin) instead of the whole frame.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _plt()
    nt = extraction.sizes["time"]
    idx = np.unique(np.linspace(0, nt - 1, min(n, nt)).round().astype(int))
    frames_idx = (np.asarray(extraction["frame"].values).astype(int)[idx] if "frame" in extraction.variables
                  else idx)
    images = _frame_images(exp, list(idx))
    # one zoom window for every panel: all traced points of the shown frames, plus a margin
    window = None
    if crop:
        traced = [rc for i in idx for rc in _profile_pixels(extraction, int(i))]
        rows = np.concatenate([rc[0] for rc in traced]) if traced else np.array([])
        cols = np.concatenate([rc[1] for rc in traced]) if traced else np.array([])
        ok = np.isfinite(rows) & np.isfinite(cols)
        if ok.sum() > 10:
            h, w = images[0].shape[:2]
            m = 0.25 * max(np.ptp(rows[ok]), np.ptp(cols[ok]), 20.0)
            window = (max(0, rows[ok].min() - m), min(h, rows[ok].max() + m),
                      max(0, cols[ok].min() - m), min(w, cols[ok].max() + m))
    ncols = len(idx)
    fig, axes = plt.subplots(1, ncols, figsize=(2.4 * ncols, 2.8))
    axes = np.atleast_1d(axes)
    for ax, i, f, img in zip(axes, idx, frames_idx, images, strict=True):
        ax.imshow(img, cmap="gray", interpolation="nearest")
        flags = []
        for k, (r, c) in enumerate(_profile_pixels(extraction, int(i))):
            manual = _entry_str(extraction, "profile_source", int(i), k) == "manual"
            ax.plot(c, r, "-", color="#ff3b30" if manual else "#00d0ff", lw=0.9, alpha=0.85)
            flag = _entry_str(extraction, "flag", int(i), k)
            if flag and flag != "ok":
                flags.append(flag)
        if window is not None:
            ax.set_xlim(window[2], window[3])
            ax.set_ylim(window[1], window[0])
        t = float(extraction["time"].values[i]) / 3600.0
        ax.set_title(f"frame {f}, {t:.1f} h" + (f"\n{', '.join(sorted(set(flags)))}" if flags else ""), fontsize=8)
        ax.set_axis_off()
    fig.tight_layout()
    return fig


# ------------------------------------------------------------------------------------------------
# reports
# ------------------------------------------------------------------------------------------------
def _param_rows(models: dict) -> list[dict]:
    rows = []
    for m, rec in models.items():
        if not rec.get("ok"):
            rows.append({"model": m, "parameter": "(failed)", "value": rec.get("error", ""), "stderr": None})
            continue
        for k, v in rec["params"].items():
            rows.append({"model": m, "parameter": k, "value": v, "stderr": rec["stderr"].get(k)})
        rows.append({"model": m, "parameter": "P_w(lambda_bar=1) m^2/s", "value": rec.get("P_w1"),
                     "stderr": rec.get("P_w1_stderr")})
        rows.append({"model": m, "parameter": "RMS residual (V/V0)", "value": rec.get("rms"), "stderr": None})
    return rows


def write_experiment_report(exp, path) -> Path:
    """Write the self-contained HTML report of one experiment.

    Parameters
    ----------
    exp : Experiment
        With ``results/extraction.nc``, ``fits.json`` and ``fits.nc`` present.
    path : path
        The HTML file (written atomically).

    Returns
    -------
    pathlib.Path
    """
    import xarray as xr

    from osmobulge import __version__
    from osmobulge.experiments.curation import apply_curation, curation_summary, load_curation
    from osmobulge.experiments.runs import code_version, read_state

    results = exp.results_dir
    extraction = xr.load_dataset(results / "extraction.nc", engine="h5netcdf")
    fits = xr.load_dataset(results / "fits.nc", engine="h5netcdf")
    js = _json(results / "fits.json")
    cur = load_curation(exp.path)
    rep = HtmlReport(f"osmobulge report: {exp.name}")
    rep.p(f"{exp.path}", cls="small")

    warnings = extraction_warnings(extraction) + list(js.get("warnings", []))
    rep.h2("Quality")
    if warnings:
        for w in warnings:
            rep.note(w, "warn")
    else:
        rep.note("no warnings: every frame traced without a flag and every model converged with determined "
                 "parameters", "ok")

    rep.h2("Experiment")
    rep.table(exp.summary())

    rep.h2("Curation")
    cs = curation_summary(cur)
    flags = read_state(exp.path).get("steps", {}).get("process", {}).get("summary", {}).get("flags", {})
    rows = {"frames": extraction.sizes["time"], "used by the fits": js.get("n_kept"),
            "excluded by a person": cs["n_excluded"], "automatic flags": ", ".join(
                f"{k}: {v}" for k, v in flags.items()) or "none",
            "kept although flagged": cs["n_kept_flagged"], "manual profiles": cs["n_manual_profiles"],
            "time origin (s)": cs["time_origin_s"], "curation revision": cs["revision"]}
    if cs["rim_px"] is not None:
        rows["rim given (col, row px)"] = "({:.1f}, {:.1f}) - ({:.1f}, {:.1f})".format(*cs["rim_px"])
    rep.table(rows)
    if cs["excluded"]:
        rep.table([{"frame": k, "reason": v["reason"], "note": v["note"]} for k, v in cs["excluded"].items()])

    rep.h2("Frames and traced profiles")
    try:
        rep.figure(plot_frame_strip(exp, extraction), "Frames (zoomed on the chamber) with the traced membrane "
                   "midline (cyan: automatic, red: manual profile); the title names the automatic flag if any.")
    except Exception as err:  # noqa: BLE001 - a report is still useful without the strip
        rep.note(f"frame strip unavailable: {type(err).__name__}: {err}", "warn")

    rep.h2("Volume ratio V/V0(t) and fits")
    curated = apply_curation(extraction, cur)
    rep.figure(plot_volume_ratio(fits, curated=curated),
               "Observed V/V0 with each fitted model (the linear-elastic one is fitted up to the dotted "
               "line only); residuals below. Red crosses: frames the fits do not use.")
    rep.h2("Rim pre-stretch")
    rep.figure(plot_prestretch(extraction), "lambda_pre(Vtilde): rim radius / the flat frame's, with the quadratic "
               "through (0, 1) "
               "(supplement Sec 5.7).")
    rep.h2("Instantaneous permeability")
    inst = js.get("instantaneous", {})
    if inst.get("error"):
        rep.note(f"instantaneous permeability: {inst['error']}", "err")
    if "instantaneous" not in js:
        rep.note("not computed ([analysis] instantaneous = false); the fitted laws only", "ok")
    rep.figure(plot_instantaneous(fits, js), "Instantaneous P_w (main text Eqn 25, corrected) against lambda_bar, "
               "binned, with the fitted laws.")
    if inst.get("P_w1") is not None:
        rep.p(f"Eqn 27 fitted to the instantaneous values: P_w(1) = {inst['P_w1']:.4g} m^2/s "
              f"(+/- {_fmt(inst.get('P_w1_stderr'), '.2g')}).")

    rep.h2("Parameters")
    rep.table(_param_rows(js.get("models", {})), ["model", "parameter", "value", "stderr"])
    for m, rec in js.get("models", {}).items():
        if rec.get("report"):
            rep.parts.append(f"<details><summary>{html.escape(m)}: fit report</summary>")
            rep.pre(rec["report"])
            rep.parts.append("</details>")

    rep.h2("Software and parameters")
    steps = read_state(exp.path).get("steps", {})
    rep.table({"osmobulge": __version__, "code (version + source hash)": code_version(),
               "extraction made by": extraction.attrs.get("osmobulge_code", extraction.attrs.get("osmobulge_version")),
               "fits made by": js.get("code"),
               **{f"{k} step finished": steps.get(k, {}).get("finished") for k in ("process", "fit")},
               "analysis ([analysis] of experiment.toml)": json.dumps(js.get("analysis", {}))})
    rep.parts.append("<details><summary>every extraction parameter (attributes of extraction.nc)</summary>")
    rep.table({k: _fmt(v) if not isinstance(v, np.ndarray) else ", ".join(map(str, v.tolist()))
               for k, v in extraction.attrs.items() if not k.startswith("experiment_")})
    rep.parts.append("</details>")
    return rep.write(path)


def extraction_warnings(extraction) -> list[str]:
    """Quality warnings of an extraction: flagged frames, skipped files, half-volume disagreement, drift.

    Parameters
    ----------
    extraction : xarray.Dataset
        ``results/extraction.nc``.

    Returns
    -------
    list of str
    """
    out = []
    if "flag" in extraction.variables:
        flags = np.asarray(extraction["flag"].values).astype(str)
        frames = np.asarray(extraction["frame"].values) if "frame" in extraction.variables else \
            np.arange(extraction.sizes["time"])
        per_frame = flags.reshape(len(frames), -1)
        for f in sorted(set(flags.ravel()) - {"ok"}):
            hit = frames[(per_frame == f).any(axis=1)]
            listed = ", ".join(map(str, hit[:12])) + (" ..." if hit.size > 12 else "")
            out.append(f"extraction flagged {hit.size} frame(s) '{f}': {listed} (not fitted unless kept in the "
                       "curation)")
    bad = str(extraction.attrs.get("bad_frames", "none"))
    if bad and bad != "none":
        out.append(f"unreadable frame files skipped by the reader: {bad}")
    if "volume_disagreement" in extraction.variables:
        vd = np.asarray(extraction["volume_disagreement"].values, float)
        ok = np.asarray(extraction["flag"].values).astype(str) == "ok" if "flag" in extraction.variables else \
            np.ones(vd.shape, bool)
        vd = vd[ok & np.isfinite(vd)]
        if vd.size and np.median(vd) > 0.05:
            out.append(f"left and right halves of the domes differ by {np.median(vd) * 100:.0f} % in volume "
                       "(median): the chamber axis or the focus may be off")
    return out


def write_campaign_report(summary: dict, datasets: dict, path) -> Path:
    """Write the campaign report: Table 2 and 3 analogues, Fig. 6 and 7 from the user's data.

    Parameters
    ----------
    summary : dict
        From :func:`osmobulge.experiments.runs.run_campaign`.
    datasets : dict of str -> xarray.Dataset
        The fit dataset of each group.
    path : path

    Returns
    -------
    pathlib.Path
    """
    from osmobulge import __version__

    plt = _plt()
    path = Path(path)
    rep = HtmlReport("osmobulge campaign report")
    groups = summary["groups"]
    rep.p(f"{len(groups)} groups by {', '.join(summary['group_by'])}; every model fitted simultaneously to all "
          "chambers of a group.", cls="small")
    for g in groups:
        for w in g.get("warnings", []):
            rep.note(f"{g['group']}: {w}", "warn")

    rep.h2("Permeability from fits (the paper's Table 2)")
    rows = []
    for g in groups:
        row = {"group": g["group"], "experiments": g["n_experiments"]}
        for m in ("constant_linear", "constant_hyperelastic", "double_exponential"):
            rec = g["models"].get(m, {})
            row[m + " P_w(1)"] = rec.get("P_w1") if rec.get("ok") else None
            row[m + " +/-"] = rec.get("P_w1_stderr") if rec.get("ok") else None
        inst = g.get("instantaneous", {})
        row["instantaneous Eqn 27 P_w(1)"] = inst.get("P_w1")
        rows.append(row)
    rep.table(rows, formats=dict.fromkeys(rows[0], ".3e") if rows else None)

    rep.h2("Stretch-dependent law, Eqn 27 (the paper's Table 3)")
    rows = []
    for g in groups:
        rec = g["models"].get("double_exponential", {})
        if rec.get("ok"):
            r = {"group": g["group"]}
            for k in ("c1", "c2", "c3", "c4"):
                r[k] = rec["params"].get(k)
                r[k + " +/-"] = rec["stderr"].get(k)
            r["RMS V/V0"] = rec.get("rms")
            rows.append(r)
    rep.table(rows, formats={"c1": ".3e", "c1 +/-": ".2e", "c3": ".3e", "c3 +/-": ".2e"})

    rep.h2("Instantaneous permeability across chambers (Fig. 6a)")
    for label, ds in datasets.items():
        g = next(x for x in groups if x["group"] == label)
        rep.figure(plot_instantaneous(ds, g, title=label), f"{label}: instantaneous P_w binned by stretch "
                   "across chambers, with the fitted laws.")
    rep.h2("Time courses with the stretch-dependent model (Fig. 6b)")
    for label, ds in datasets.items():
        rep.figure(plot_volume_ratio(ds, title=label), f"{label}: every chamber's V/V0(t) with each model.")

    rep.h2("Materials compared (Fig. 7)")
    fig, ax = plt.subplots(figsize=(7, 4.2))
    grid = np.linspace(1.0, 4.0, 200)
    for g in groups:
        rec = g["models"].get("double_exponential", {})
        if rec.get("ok"):
            p = rec["params"]
            ax.plot(grid, p["c1"] * np.exp(p["c2"] * grid) + p["c3"] * np.exp(p["c4"] * grid), lw=2,
                    label=g["group"])
    ax.set_yscale("log")
    ax.set_xlabel("lambda_bar")
    ax.set_ylabel("P_w (m^2/s)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    rep.figure(fig, "Fitted P_w(lambda_bar) of each group.")

    rep.h2("Experiments")
    rows = []
    for g in groups:
        for p in g["experiments"]:
            rp = Path(p) / "results" / "report.html"
            rel = None
            try:
                import os

                rel = os.path.relpath(rp, path.parent)
            except ValueError:
                rel = str(rp)
            rows.append({"group": g["group"], "experiment": Path(p).name, "report": rel})
    out = ["<table><tr><th>group</th><th>experiment</th><th>report</th></tr>"]
    for r in rows:
        out.append(f"<tr><td>{html.escape(r['group'])}</td><td>{html.escape(r['experiment'])}</td>"
                   f'<td><a href="{html.escape(r["report"])}">{html.escape(r["report"])}</a></td></tr>')
    out.append("</table>")
    rep.parts.append("".join(out))
    rep.h2("Software")
    rep.table({"osmobulge": __version__, "code": summary.get("code", "")})
    return rep.write(path)
