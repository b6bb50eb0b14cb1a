r"""Figures of the transport model and permeability fits (paper Figs 4-7; no file I/O).

Each figure has a ``figureN_data`` function that gathers the plotted numbers into
an :class:`xarray.Dataset` (SI units in ``units`` attrs; callers may save it as
CSV or netCDF) and a ``plot_figureN`` function that draws that dataset and returns
a :class:`matplotlib.figure.Figure`, built without ``pyplot`` (no display, no
global state):

* Fig. 4 -- :math:`V/V_0` against :math:`t/\tau` (a) and the membrane geometry
  :math:`f_A f_l` and driving force :math:`(\Pi + P_t)/\Pi_0` (b);
* Fig. 5 -- short- (a) and long-time (b) fits of the reference chamber: linear
  elastic with constant :math:`P_w`, hyperelastic with constant :math:`P_w`,
  hyperelastic with :math:`P_w(\bar\lambda)`;
* Fig. 6 -- (a) instantaneous :math:`P_w` binned by stretch with error bars, the
  Eqn 27 fit and Firpo curves (Eqn 26) through :math:`P_w(1)`, thickness on the
  upper axis; (b) the :math:`P_w(\bar\lambda)` model against the data of every
  chamber;
* Fig. 7 -- PEO-PDMS against PDMS: :math:`P_w(\bar\lambda)` (a) and
  :math:`V/V_0(t)` of the reference chamber (b).
"""

from __future__ import annotations

import math

import numpy as np
import xarray as xr

from osmobulge.modeling.permeability import Firpo

__all__ = [
    "figure4_data",
    "plot_figure4",
    "figure5_data",
    "plot_figure5",
    "figure6a_data",
    "plot_figure6a",
    "figure6b_data",
    "plot_figure6b",
    "figure7_data",
    "plot_figure7",
    "CONDITION_COLOURS",
    "FIRPO_CRITICAL_THICKNESSES",
]

_HOUR = 3600.0
_UM = 1e-6

#: Fig. 4 caption: reference navy, thick membrane gold, reduced loading gray, small radius orange
CONDITION_COLOURS = {
    "reference": "#1b2a6b",
    "thick_membrane": "#c9971c",
    "low_concentration": "#7f7f7f",
    "small_radius": "#e0661a",
}
_OTHER = ("#4d9221", "#762a83", "#b2182b", "#01665e", "#8c510a")
#: Fig. 5 colours: linear gold, hyperelastic constant orange, P_w(lambda_bar) teal
_MODEL_COLOURS = {"linear": "#c9971c", "constant": "#e0661a", "stretch": "#138d8d"}
_TEAL = "#138d8d"
_PEO = "#1f5fa8"
_PEO_LIGHT = "#6fb3e6"

#: the critical thicknesses L_c of Fig. 6a, m
FIRPO_CRITICAL_THICKNESSES = (10e-6, 20e-6, 40e-6, 80e-6, 200e-6)


def _new_figure(**kwargs):
    from matplotlib.figure import Figure

    return Figure(**kwargs)


def _colour(label, i):
    key = str(label).split(" ")[0].split("#")[0]
    return CONDITION_COLOURS.get(key, _OTHER[i % len(_OTHER)])


def _lighten(colour, amount=0.55):
    from matplotlib.colors import to_rgb

    r, g, b = to_rgb(colour)
    return (r + (1 - r) * amount, g + (1 - g) * amount, b + (1 - b) * amount)


# --------------------------------------------------------------------------- Fig. 4


def figure4_data(observations, material, *, permeability=2e-12, mechanics="hyperelastic") -> xr.Dataset:
    r"""Numbers of Fig. 4: the dimensionless-time collapse.

    Thin wrapper of :func:`osmobulge.modeling.instantaneous.dimensionless_collapse`.

    Parameters
    ----------
    observations : sequence
        ``(chamber, t, volume_ratio[, label])`` tuples or datasets, e.g. the four
        PDMS chambers simulated with a constant :math:`P_w = 2\times10^{-12}` m**2/s.
    material : Material
    permeability : float, m**2/s
        :math:`P_w` of :math:`\tau` (Eqn 9).
    mechanics : {"hyperelastic", "linear"}

    Returns
    -------
    xarray.Dataset
    """
    from osmobulge.modeling.instantaneous import dimensionless_collapse

    return dimensionless_collapse(observations, material, permeability=permeability, mechanics=mechanics)


def plot_figure4(data: xr.Dataset, *, t_tilde_max=None):
    r"""Draw Fig. 4: (a) :math:`V/V_0` vs :math:`t/\tau`; (b) :math:`f_A f_l` and :math:`(\Pi + P_t)/\Pi_0`.

    Parameters
    ----------
    data : xarray.Dataset
        From :func:`figure4_data`.
    t_tilde_max : float, optional
        Right end of the axes (default: the longest record).

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = _new_figure(figsize=(11, 4.4), layout="constrained")
    ax_a, ax_b = fig.subplots(1, 2)
    ax_d = ax_b.twinx()
    for i in range(data.sizes["chamber"]):
        label = str(data["label"].values[i])
        col = _colour(label, i)
        tt = data["t_tilde"].values[i]
        ok = np.isfinite(tt)
        ax_a.plot(tt[ok], data["volume_ratio"].values[i][ok], color=col, lw=2, label=label.replace("_", " "))
        ax_b.plot(tt[ok], data["geometry"].values[i][ok], color=col, lw=2)
        ax_d.plot(tt[ok], data["driving_force"].values[i][ok], color=col, lw=1.6, ls="--")
    top = float(np.nanmax(data["t_tilde"].values)) if t_tilde_max is None else float(t_tilde_max)
    for ax in (ax_a, ax_b):
        ax.set_xlim(0, top)
        ax.set_xlabel(r"dimensionless time $\tilde t = t/\tau$")
        ax.grid(alpha=0.3)
    ax_a.set_ylabel(r"volume ratio $V/V_0$")
    ax_a.legend(fontsize=9, loc="upper left")
    ax_b.set_yscale("log")
    ax_b.set_ylabel(r"membrane geometry $f_A f_l = (A/A_0)\langle l_0/l\rangle$ (solid)")
    ax_d.set_ylabel(r"driving force $(\Pi + P_t)/\Pi_0$ (dashed)")
    ax_d.set_ylim(0, 1.05)
    tau = ", ".join(f"{v / _HOUR:.2f}" for v in data["tau"].values)
    ax_a.set_title("a", loc="left", fontweight="bold")
    ax_b.set_title("b", loc="left", fontweight="bold")
    fig.suptitle(
        rf"Dimensionless-time collapse (Fig. 4), constant $P_w$ = {data.attrs.get('tau_permeability', np.nan):.3g}"
        rf" m$^2$/s; $\tau$ = {tau} h", fontsize=11)
    return fig


# --------------------------------------------------------------------------- Fig. 5


def figure5_data(fits, *, index=0, data=None, t_end=None, n=400, linear_window=1.3) -> xr.Dataset:
    r"""Numbers of Fig. 5: the reference chamber's data and three fitted models.

    Parameters
    ----------
    fits : mapping of str to PermeabilityFit
        Keys ``"linear"`` (linear-elastic mechanics, constant :math:`P_w`, fitted
        on :math:`V/V_0 \le` ``linear_window``), ``"constant"`` (hyperelastic,
        constant :math:`P_w`), ``"stretch"`` (hyperelastic, Eqn 27); any subset.
    index : int
        Observation (chamber) of the fits to draw.
    data : tuple of ndarray, optional
        ``(t, volume_ratio)`` to draw as data (default: the observation stored in
        the hyperelastic fits, all points).
    t_end : float, s, optional
        End of the model curves (default: the last data time).
    n : int
        Points of each model curve.
    linear_window : float
        Upper :math:`V/V_0` of the linear fit's window (supplement Sec. 7.1).

    Returns
    -------
    xarray.Dataset
        ``data_volume_ratio`` over ``time``; ``model_volume_ratio`` over
        ``(model, model_time)``; ``permeability_at_rest`` over ``model`` (m**2/s).
    """
    fits = {k: v for k, v in dict(fits).items() if v is not None}
    if not fits:
        raise ValueError("fits is empty: give at least one of 'linear', 'constant', 'stretch'")
    for k in fits:
        if k not in _MODEL_COLOURS:
            raise ValueError(f"fits keys must be among {tuple(_MODEL_COLOURS)}, got {k!r}")
    if data is None:
        src = fits.get("stretch") or fits.get("constant") or fits["linear"]
        ob = src.observations[index]
        t, v = np.asarray(ob.time, float), np.asarray(ob.volume_ratio, float)
    else:
        t, v = (np.asarray(a, float) for a in data)
    end = float(t.max()) if t_end is None else float(t_end)
    tm = np.linspace(0.0, end, int(n))
    names = list(fits)
    curves = np.array([fits[k].curve(index, tm) for k in names])
    p1 = np.array([float(fits[k].p_at_rest) for k in names])
    return xr.Dataset(
        {
            "data_volume_ratio": ("time", v, {"units": "1", "long_name": "observed V/V0"}),
            "model_volume_ratio": (("model", "model_time"), curves, {"units": "1", "long_name": "model V/V0"}),
            "permeability_at_rest": ("model", p1, {"units": "m^2/s", "long_name": "P_w(lambda_bar=1)"}),
        },
        coords={
            "time": ("time", t, {"units": "s"}),
            "model_time": ("model_time", tm, {"units": "s"}),
            "model": ("model", names),
        },
        attrs={"title": "Fig. 5: fits of the reference chamber", "linear_window_volume_ratio": float(linear_window)},
    )


_MODEL_LABELS = {
    "linear": r"linear elastic, constant $P_w$",
    "constant": r"hyperelastic, constant $P_w$",
    "stretch": r"hyperelastic, $P_w(\bar\lambda)$ (Eqn 27)",
}


def plot_figure5(data: xr.Dataset, *, short_time=6 * _HOUR):
    r"""Draw Fig. 5: (a) short-time and (b) long-time fits of the reference chamber.

    The linear-elastic curve is saturated inside its fitting window
    (:math:`V/V_0 \le 1.3`) and light where it is extrapolated, as in the paper.

    Parameters
    ----------
    data : xarray.Dataset
        From :func:`figure5_data`.
    short_time : float, s
        End of panel (a).

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = _new_figure(figsize=(11, 4.4), layout="constrained")
    axes = fig.subplots(1, 2)
    t = data["time"].values / _HOUR
    tm = data["model_time"].values / _HOUR
    win = float(data.attrs.get("linear_window_volume_ratio", 1.3))
    for k, ax in enumerate(axes):
        ax.plot(t, data["data_volume_ratio"].values, "o", ms=4, mfc="none", color="0.25", label="data")
        for j, name in enumerate(data["model"].values):
            y = data["model_volume_ratio"].values[j]
            col = _MODEL_COLOURS.get(str(name), _OTHER[j])
            p1 = float(data["permeability_at_rest"].values[j])
            lab = f"{_MODEL_LABELS.get(str(name), str(name))}: $P_w(1)$ = {p1:.3g}"
            if name == "linear":
                inside = y <= win
                ax.plot(tm[inside], y[inside], color=col, lw=2.4, label=lab)
                ax.plot(tm[~inside], y[~inside], color=_lighten(col), lw=2.0, label="_extrapolated")
            else:
                ax.plot(tm, y, color=col, lw=2.0, label=lab)
        ax.set_xlabel("time t [h]")
        ax.set_ylabel(r"volume ratio $V/V_0$")
        ax.grid(alpha=0.3)
        ax.set_title("ab"[k], loc="left", fontweight="bold")
    short = float(short_time) / _HOUR
    axes[0].set_xlim(0, short)
    sel = t <= short
    vmax = float(np.nanmax(data["data_volume_ratio"].values[sel])) if sel.any() else 2.0
    axes[0].set_ylim(0.95, 1.15 * vmax)
    axes[1].set_xlim(0, float(max(t.max(), tm.max())))
    vtop = float(np.nanmax(data["data_volume_ratio"].values))
    axes[1].set_ylim(0.8, 1.25 * vtop)
    axes[0].axhline(win, color=_MODEL_COLOURS["linear"], lw=0.8, ls=":")
    axes[1].legend(fontsize=8, loc="upper left")
    fig.suptitle("Reference chamber: short- (a) and long-time (b) fits (Fig. 5)", fontsize=11)
    return fig


# --------------------------------------------------------------------------- Fig. 6


def figure6a_data(analysis, material, *, thickness=20e-6, critical_thicknesses=FIRPO_CRITICAL_THICKNESSES,
                  lambda_max=None, n=200, lambda_pre=1.0) -> xr.Dataset:
    r"""Numbers of Fig. 6a: binned instantaneous :math:`P_w`, Eqn 27 fits and Firpo curves.

    Parameters
    ----------
    analysis : InstantaneousAnalysis
        From :func:`osmobulge.modeling.instantaneous.analyze_instantaneous`.
    material : Material
        Membrane law (maps :math:`\bar\lambda` to the mean thickness :math:`l_0/f_l`).
    thickness : float, m
        Initial membrane thickness :math:`l_0` of the upper axis and of the
        Firpo curves (the paper drops the 26 um chambers there; 20 um).
    critical_thicknesses : sequence of float, m
        :math:`L_c` of the Firpo curves (Eqn 26), each constrained through
        :math:`(\bar\lambda = 1, P_w(1))` of the Eqn 27 fit.
    lambda_max : float, optional
        End of the curves (default: the largest binned stretch + 5 %).
    n : int
        Points of each curve.
    lambda_pre : float or callable
        Rim pre-stretch of the mechanics.

    Returns
    -------
    xarray.Dataset
        Over ``bin``: ``lambda_bar``, ``lambda_bar_std``, ``permeability``,
        ``permeability_std``, ``count``; over ``lambda_grid``:
        ``mean_thickness`` (m), ``eqn27_instantaneous``, ``eqn27_direct``
        (m**2/s); over ``(critical_thickness, lambda_grid)``: ``firpo``; over
        ``critical_thickness``: ``p_henry`` (m**2/s).
    """
    from osmobulge.modeling.transport import mechanics_model

    b = analysis.binned
    top = float(b["lambda_bar"].max()) * 1.05 if lambda_max is None else float(lambda_max)
    mech = mechanics_model(material, lambda_pre)
    vt = np.linspace(0.0, mech.vtilde_max, 800)
    lam_tab = np.asarray(mech.lambda_bar(vt), float)
    fl_tab = np.asarray(mech.inverse_thickness(vt), float)
    top = min(top, float(lam_tab.max()))
    grid = np.linspace(1.0, top, int(n))
    mean_thick = float(thickness) / np.interp(grid, lam_tab, fl_tab)
    p1 = float(analysis.eqn27.params["p_at_rest"])
    inst = np.asarray(analysis.eqn27.permeability_at(grid), float)
    direct = (np.asarray(analysis.direct.permeability(grid), float) if analysis.direct is not None
              else np.full(grid.shape, np.nan))
    lcs = np.asarray(critical_thicknesses, float)
    laws = [Firpo.through(p1, thickness=float(thickness), critical_thickness=float(lc)) for lc in lcs]
    firpo = np.array([law(grid, thickness=mean_thick) for law in laws])
    ds = xr.Dataset(
        {
            "lambda_bar": ("bin", b["lambda_bar"].values, {"units": "1", "long_name": "mean stretch of the bin"}),
            "lambda_bar_std": ("bin", b["lambda_bar_std"].values, {"units": "1"}),
            "permeability": ("bin", b["permeability"].values, {"units": "m^2/s",
                                                                "long_name": "mean instantaneous P_w"}),
            "permeability_std": ("bin", b["permeability_std"].values, {"units": "m^2/s"}),
            "count": ("bin", b["count"].values, {"units": "1"}),
            "mean_thickness": ("lambda_grid", mean_thick, {"units": "m", "long_name": "mean thickness l0/f_l"}),
            "eqn27_instantaneous": ("lambda_grid", inst, {"units": "m^2/s",
                                                          "long_name": "Eqn 27 fitted to instantaneous P_w"}),
            "eqn27_direct": ("lambda_grid", direct, {"units": "m^2/s",
                                                     "long_name": "Eqn 27 fitted through the ODE"}),
            "firpo": (("critical_thickness", "lambda_grid"), firpo, {"units": "m^2/s",
                                                                      "long_name": "Firpo Eqn 26 through P_w(1)"}),
            "p_henry": ("critical_thickness", np.array([law.p_henry for law in laws]), {"units": "m^2/s"}),
        },
        coords={
            "bin": np.arange(b.sizes["bin"]),
            "lambda_grid": ("lambda_grid", grid, {"units": "1", "long_name": "average biaxial stretch"}),
            "critical_thickness": ("critical_thickness", lcs, {"units": "m", "long_name": "L_c"}),
        },
        attrs={"title": "Fig. 6a", "initial_thickness": float(thickness), "p_at_rest": p1,
               "rate_method": analysis.method},
    )
    return ds


def plot_figure6a(data: xr.Dataset):
    r"""Draw Fig. 6a: instantaneous :math:`P_w` vs :math:`\bar\lambda` with Eqn 27 and Firpo curves.

    Error bars are the standard deviations of :math:`P_w` (vertical) and of
    :math:`\bar\lambda` (horizontal) in each bin; the upper axis gives the mean
    membrane thickness :math:`l_0/f_l` of the :math:`l_0` in ``data.attrs``.

    Parameters
    ----------
    data : xarray.Dataset
        From :func:`figure6a_data`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib import colormaps

    fig = _new_figure(figsize=(7.5, 5.4), layout="constrained")
    ax = fig.subplots()
    grid = data["lambda_grid"].values
    oranges = colormaps["Oranges"]
    lcs = data["critical_thickness"].values
    for k, lc in enumerate(lcs):
        col = oranges(0.3 + 0.65 * k / max(len(lcs) - 1, 1))
        ax.plot(grid, data["firpo"].values[k], color=col, lw=1.6,
                label=rf"Firpo, $L_c$ = {lc / _UM:g} $\mu$m ($P_{{Henry}}$ = {data['p_henry'].values[k]:.2g})")
    ax.errorbar(data["lambda_bar"].values, data["permeability"].values, yerr=data["permeability_std"].values,
                xerr=data["lambda_bar_std"].values, fmt="o", ms=4, color="k", ecolor="0.45", elinewidth=0.8,
                capsize=1.5, label=f"instantaneous $P_w$ (bins of {int(np.median(data['count'].values))})")
    ax.plot(grid, data["eqn27_instantaneous"].values, color=_TEAL, lw=2.4, label="Eqn 27 fit to the points")
    if np.any(np.isfinite(data["eqn27_direct"].values)):
        ax.plot(grid, data["eqn27_direct"].values, color=_TEAL, lw=1.6, ls="--", label="Eqn 27 fit through the ODE")
    ax.set_yscale("log")
    ax.set_xlabel(r"average biaxial stretch $\bar\lambda = \sqrt{A/A_0}$")
    ax.set_ylabel(r"water permeability $P_w$ [m$^2$/s]")
    ax.set_xlim(1.0, float(grid.max()))
    pw = data["permeability"].values
    pw = pw[np.isfinite(pw) & (pw > 0)]
    curve_lo = float(np.nanmin(data["eqn27_instantaneous"].values))
    lo = min(float(np.percentile(pw, 5)), curve_lo) if pw.size else curve_lo
    ax.set_ylim(0.5 * lo, 2.0 * float(data.attrs.get("p_at_rest", np.nanmax(pw))))
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7.5, loc="upper right")
    # upper axis: mean thickness l0 / f_l(lambda_bar)
    thick = data["mean_thickness"].values / _UM
    order = np.argsort(grid)

    def fwd(x):
        return np.interp(x, grid[order], thick[order])

    def inv(y):
        return np.interp(y, thick[::-1], grid[::-1])

    sec = ax.secondary_xaxis("top", functions=(fwd, inv))
    ticks = [x for x in (30, 25, 20, 15, 12, 10, 8, 7, 6, 5, 4, 3, 2.5, 2, 1.5, 1)
             if thick.min() <= x <= thick.max()]
    sec.set_xticks(ticks)
    sec.set_xticklabels([f"{x:g}" for x in ticks])
    sec.set_xlabel(rf"mean membrane thickness $l_0/f_l$ [$\mu$m] ($l_0$ = {data.attrs['initial_thickness'] / _UM:g}"
                   r" $\mu$m)")
    ax.set_title("a", loc="left", fontweight="bold")
    return fig


def figure6b_data(fit, *, labels=None, n=400, t_end=None) -> xr.Dataset:
    r"""Numbers of Fig. 6b: every chamber's data and the fitted :math:`P_w(\bar\lambda)` model.

    Parameters
    ----------
    fit : PermeabilityFit
        The direct Eqn 27 fit (:func:`osmobulge.modeling.fitting.fit_permeability`).
    labels : sequence of str, optional
        Name of each observation (default: the fit's names); names starting with
        a paper condition (``"reference"``, ``"small_radius"``, ...) get its colour.
    n : int
        Points of each model curve.
    t_end : float, s, optional
        End of the curves (default: the last data time).

    Returns
    -------
    xarray.Dataset
        ``time`` and ``volume_ratio`` over ``(chamber, sample)`` (NaN-padded),
        ``model_volume_ratio`` over ``(chamber, model_time)``, ``label`` over ``chamber``.
    """
    obs = fit.observations
    m = max(o.time.size for o in obs)
    t = np.full((len(obs), m), np.nan)
    v = np.full((len(obs), m), np.nan)
    for i, o in enumerate(obs):
        t[i, : o.time.size] = o.time
        v[i, : o.time.size] = o.volume_ratio
    end = float(np.nanmax(t)) if t_end is None else float(t_end)
    tm = np.linspace(0.0, end, int(n))
    model = np.array([fit.curve(i, tm) for i in range(len(obs))])
    if labels is None:
        labels = [o.name or f"chamber {i}" for i, o in enumerate(obs)]
    labels = [str(x) for x in labels]
    if len(labels) != len(obs):
        raise ValueError(f"labels has {len(labels)} names for {len(obs)} observations")
    return xr.Dataset(
        {
            "time": (("chamber", "sample"), t, {"units": "s"}),
            "volume_ratio": (("chamber", "sample"), v, {"units": "1", "long_name": "observed V/V0"}),
            "model_volume_ratio": (("chamber", "model_time"), model, {"units": "1", "long_name": "model V/V0"}),
        },
        coords={"chamber": np.arange(len(obs)), "label": ("chamber", labels),
                "model_time": ("model_time", tm, {"units": "s"})},
        attrs={"title": "Fig. 6b", "model": str(fit.model), "p_at_rest": float(fit.p_at_rest)},
    )


def plot_figure6b(data: xr.Dataset, *, short_time=4 * _HOUR):
    r"""Draw Fig. 6b: the :math:`P_w(\bar\lambda)` model (lines) against every chamber (circles).

    Parameters
    ----------
    data : xarray.Dataset
        From :func:`figure6b_data`.
    short_time : float, s
        End of the inset (short times).

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = _new_figure(figsize=(7.5, 5.4), layout="constrained")
    ax = fig.subplots()
    ins = ax.inset_axes([0.08, 0.55, 0.36, 0.38])
    tm = data["model_time"].values / _HOUR
    seen = set()
    for i in range(data.sizes["chamber"]):
        label = str(data["label"].values[i])
        group = label.split(" #")[0]
        col = _colour(group, len(seen))
        first = group not in seen
        seen.add(group)
        t = data["time"].values[i] / _HOUR
        for a, ms in ((ax, 3.5), (ins, 3.0)):
            a.plot(t, data["volume_ratio"].values[i], "o", ms=ms, mfc="none", mew=0.8, color=col,
                   label=group.replace("_", " ") if (first and a is ax) else "_nolegend_")
            a.plot(tm, data["model_volume_ratio"].values[i], color=col, lw=1.6)
    ax.set_xlabel("time t [h]")
    ax.set_ylabel(r"volume ratio $V/V_0$")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    short = float(short_time) / _HOUR
    ins.set_xlim(0, short)
    sel = data["time"].values / _HOUR <= short
    vmax = float(np.nanmax(np.where(sel, data["volume_ratio"].values, np.nan)))
    ins.set_ylim(0.95, 1.1 * vmax)
    ins.tick_params(labelsize=7)
    ins.grid(alpha=0.3)
    ax.set_title("b", loc="left", fontweight="bold")
    fig.suptitle(rf"Model with $P_w(\bar\lambda)$ (Eqn 27) against all chambers (Fig. 6b); "
                 rf"$P_w(1)$ = {data.attrs.get('p_at_rest', math.nan):.3g} m$^2$/s", fontsize=10)
    return fig


# --------------------------------------------------------------------------- Fig. 7


def figure7_data(pdms, peo, *, index_pdms=0, index_peo=0, n=300) -> xr.Dataset:
    r"""Numbers of Fig. 7: PEO-PDMS against PDMS.

    Parameters
    ----------
    pdms, peo : InstantaneousAnalysis
        Analyses with their direct Eqn 27 fits (``direct=True``); the binned
        instantaneous values of PEO-PDMS are drawn as data.
    index_pdms, index_peo : int
        Observation (a reference chamber) drawn in panel (b).
    n : int
        Points of the curves.

    Returns
    -------
    xarray.Dataset
        ``pw_pdms``, ``pw_peo`` over ``lambda_grid`` (m**2/s, the direct fits,
        NaN beyond the stretches of each material's data);
        ``peo_lambda_bar``, ``peo_permeability``, ``peo_permeability_std`` over
        ``bin``; ``time_pdms``/``volume_ratio_pdms`` and ``time_peo``/
        ``volume_ratio_peo`` (data) and ``model_pdms``, ``model_peo`` over ``model_time``.
    """
    for name, an in (("pdms", pdms), ("peo", peo)):
        if an.direct is None:
            raise ValueError(f"{name}: the analysis needs its direct ODE fit (analyze_instantaneous(direct=True))")
    top_p, top_q = (float(a.binned["lambda_bar"].max()) for a in (pdms, peo))
    grid = np.linspace(1.0, max(top_p, top_q), int(n))
    op, oq = pdms.direct.observations[index_pdms], peo.direct.observations[index_peo]
    end = max(float(op.time.max()), float(oq.time.max()))
    tm = np.linspace(0.0, end, int(n))
    b = peo.binned
    ds = xr.Dataset(
        {
            "pw_pdms": ("lambda_grid", np.where(grid <= top_p, pdms.direct.permeability(grid), np.nan),
                        {"units": "m^2/s", "long_name": "PDMS P_w, Eqn 27 through the ODE (its data range)"}),
            "pw_peo": ("lambda_grid", np.where(grid <= top_q, peo.direct.permeability(grid), np.nan),
                       {"units": "m^2/s", "long_name": "PEO-PDMS P_w, Eqn 27 through the ODE (its data range)"}),
            "peo_lambda_bar": ("bin", b["lambda_bar"].values, {"units": "1"}),
            "peo_lambda_bar_std": ("bin", b["lambda_bar_std"].values, {"units": "1"}),
            "peo_permeability": ("bin", b["permeability"].values, {"units": "m^2/s"}),
            "peo_permeability_std": ("bin", b["permeability_std"].values, {"units": "m^2/s"}),
            "volume_ratio_pdms": ("time_pdms", np.asarray(op.volume_ratio, float), {"units": "1"}),
            "volume_ratio_peo": ("time_peo", np.asarray(oq.volume_ratio, float), {"units": "1"}),
            "model_pdms": ("model_time", pdms.direct.curve(index_pdms, tm), {"units": "1"}),
            "model_peo": ("model_time", peo.direct.curve(index_peo, tm), {"units": "1"}),
        },
        coords={
            "lambda_grid": ("lambda_grid", grid, {"units": "1"}),
            "bin": np.arange(b.sizes["bin"]),
            "time_pdms": ("time_pdms", np.asarray(op.time, float), {"units": "s"}),
            "time_peo": ("time_peo", np.asarray(oq.time, float), {"units": "s"}),
            "model_time": ("model_time", tm, {"units": "s"}),
        },
        attrs={"title": "Fig. 7", "p_at_rest_pdms": float(pdms.direct.p_at_rest),
               "p_at_rest_peo": float(peo.direct.p_at_rest)},
    )
    return ds


def plot_figure7(data: xr.Dataset):
    r"""Draw Fig. 7: (a) :math:`P_w(\bar\lambda)` of PEO-PDMS and PDMS; (b) their reference chambers.

    Parameters
    ----------
    data : xarray.Dataset
        From :func:`figure7_data`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = _new_figure(figsize=(11, 4.4), layout="constrained")
    ax_a, ax_b = fig.subplots(1, 2)
    grid = data["lambda_grid"].values
    ax_a.errorbar(data["peo_lambda_bar"].values, data["peo_permeability"].values,
                  yerr=data["peo_permeability_std"].values, xerr=data["peo_lambda_bar_std"].values, fmt="o", ms=4,
                  color=_PEO_LIGHT, mec=_PEO, ecolor=_PEO_LIGHT, elinewidth=0.8, label="PEO-PDMS instantaneous")
    ax_a.plot(grid, data["pw_peo"].values, color=_PEO, lw=2.2, label="PEO-PDMS, Eqn 27")
    ax_a.plot(grid, data["pw_pdms"].values, color=_TEAL, lw=2.2, label="PDMS, Eqn 27")
    ax_a.set_yscale("log")
    ax_a.set_xlabel(r"average biaxial stretch $\bar\lambda$")
    ax_a.set_ylabel(r"$P_w$ [m$^2$/s]")
    ax_a.grid(alpha=0.3, which="both")
    ax_a.legend(fontsize=8)
    th = data["time_pdms"].values / _HOUR
    tq = data["time_peo"].values / _HOUR
    tm = data["model_time"].values / _HOUR
    ax_b.plot(th, data["volume_ratio_pdms"].values, "o", ms=3.5, mfc="none", color=_TEAL, label="PDMS data")
    ax_b.plot(tm, data["model_pdms"].values, color=_TEAL, lw=2)
    ax_b.plot(tq, data["volume_ratio_peo"].values, "o", ms=3.5, mfc="none", color=_PEO_LIGHT, label="PEO-PDMS data")
    ax_b.plot(tm, data["model_peo"].values, color=_PEO, lw=2)
    ax_b.set_xlabel("time t [h]")
    ax_b.set_ylabel(r"volume ratio $V/V_0$")
    ax_b.grid(alpha=0.3)
    ax_b.legend(fontsize=8, loc="upper left")
    ax_a.set_title("a", loc="left", fontweight="bold")
    ax_b.set_title("b", loc="left", fontweight="bold")
    fig.suptitle(
        rf"PEO-PDMS vs PDMS (Fig. 7): $P_w(1)$ = {data.attrs['p_at_rest_peo']:.3g} vs "
        rf"{data.attrs['p_at_rest_pdms']:.3g} m$^2$/s; reference chambers", fontsize=10)
    return fig
