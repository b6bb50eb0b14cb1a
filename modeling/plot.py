r"""Matplotlib figures of the membrane mechanics (no file I/O: callers save the figure).

* :func:`plot_mechanics` -- :math:`f_A, f_l, f_p` against :math:`\tilde V` for any datasets;
* :func:`figure3_data` / :func:`plot_figure3` -- the paper's Fig. 3 b-e (main text
  Sec. 3.3-3.5): the mechanics functions of a linear-elastic, a PDMS and a PEO-PDMS
  membrane, and the bulge profiles of PDMS.

Figures are built with :class:`matplotlib.figure.Figure` directly, not through
``pyplot``: no display backend is needed and no global figure state is kept.
"""

from __future__ import annotations

import math

import numpy as np
import xarray as xr

from osmobulge.modeling.bulge import bulge_mechanics, bulge_profile, locking_volume, turgor_ratio
from osmobulge.modeling.materials import PDMS, PEO_PDMS, PRESETS, LinearElastic, Material

__all__ = ["plot_mechanics", "figure3_data", "plot_figure3", "SMALL_STRAIN_VTILDE"]

#: upper end of the linear-elastic (small-stretch) regime of Fig. 3, main text Sec. 3.3:
#: "Vtilde < 0.05 (saturated gold region) ... lambda_bar ~ 1.2"
SMALL_STRAIN_VTILDE = 0.05

#: the paper's colours (Fig. 3 caption): gold / light gold, navy, light blue
_GOLD = "#c9971c"
_LIGHT_GOLD = "#ead7a0"
_NAVY = "#1b2a6b"
_LIGHT_BLUE = "#4fa3d9"
_OTHER_COLOURS = ("#b2182b", "#4d9221", "#762a83", "#e08214", "#01665e")


def _new_figure(**kwargs):
    from matplotlib.figure import Figure

    return Figure(**kwargs)


def plot_mechanics(datasets, *, labels=None, thickness_over_radius=0.1):
    r"""Plot :math:`f_A`, :math:`f_l` and :math:`f_p` against :math:`\tilde V`.

    Parameters
    ----------
    datasets : xarray.Dataset or sequence of them
        Outputs of :func:`~osmobulge.modeling.bulge_mechanics` (or
        ``MechanicsTable.to_dataset()``).
    labels : sequence of str, optional
        Legend labels, one per dataset.
    thickness_over_radius : float
        :math:`l_0/a` used to convert the pressure to :math:`f_p = P_t/E`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if not isinstance(datasets, list | tuple):
        datasets = [datasets]
    labels = labels or [ds.attrs.get("material_law", f"#{i}") for i, ds in enumerate(datasets)]
    fig = _new_figure(figsize=(12, 3.6), layout="constrained")
    axes = fig.subplots(1, 3)
    for ds, label in zip(datasets, labels, strict=True):
        v = ds["vtilde"].values
        scale = ds.attrs.get("stress_scale_Pa", np.nan) / ds.attrs.get("nondimensionalising_modulus_Pa", np.nan)
        axes[0].plot(v, ds["area_ratio"], label=label)
        axes[1].plot(v, ds["inverse_thickness"], label=label)
        axes[2].plot(v, ds["pressure"] * scale * thickness_over_radius, label=label)
    for ax, name in zip(axes, ["$f_A = A/A_0$", r"$f_l = \langle l_0/l\rangle$", "$f_p = P_t/E$"], strict=True):
        ax.set_xlabel(r"$\tilde V$")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
    axes[0].legend()
    axes[2].set_title(f"$l_0/a$ = {thickness_over_radius:g}", fontsize=9)
    return fig


# --------------------------------------------------------------------------- Fig. 3


def _default_materials():
    return (LinearElastic.equivalent_to(PDMS), PDMS, PEO_PDMS)


def _label(material) -> str:
    if isinstance(material, LinearElastic):
        return f"linear elastic (E = {material.E / 1e6:.3g} MPa)"
    for name, preset in PRESETS.items():
        if preset is material:
            return {"PDMS": "PDMS", "PEO_PDMS": "PEO-PDMS"}.get(name, name)
    consts = ", ".join(f"{k}={v:.3g}" for k, v in material.constants.items())
    return f"{material.law} ({consts})"


def _colour(material, i: int) -> str:
    if isinstance(material, LinearElastic):
        return _GOLD
    if material is PDMS:
        return _NAVY
    if material is PEO_PDMS:
        return _LIGHT_BLUE
    return _OTHER_COLOURS[i % len(_OTHER_COLOURS)]


def _check_positive(name: str, value, unit: str = "1") -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(x) or x <= 0:
        raise ValueError(f"{name} must be finite and > 0 ({unit}), got {value!r}")
    return x


def _figure3_grid(vtilde_max: float) -> np.ndarray:
    """Volumes for the curves: log-spaced below the small-stretch limit, linear above."""
    low = np.geomspace(1e-3, min(SMALL_STRAIN_VTILDE, vtilde_max), 16)
    high = np.linspace(min(SMALL_STRAIN_VTILDE, vtilde_max), vtilde_max, 180)
    return np.unique(np.r_[0.0, low, high])


def figure3_data(materials=None, *, thickness_over_radius=0.1, vtilde_max=None, profile_vtildes=(0.5, 1, 2, 3, 4)):
    r"""Numbers behind the paper's Fig. 3 b-e.

    Parameters
    ----------
    materials : sequence of Material or LinearElastic, optional
        Laws to compare; default linear elastic with the PDMS modulus
        (``LinearElastic.equivalent_to(PDMS)``), ``PDMS`` and ``PEO_PDMS``, all at
        :math:`\lambda_{pre} = 1` as in the paper.
    thickness_over_radius : float
        :math:`l_0/a` of the chamber used for :math:`f_p`; the paper's reference
        chamber has :math:`l_0/a = 20\,\mu m / 200\,\mu m = 0.1`.
    vtilde_max : float, optional
        Largest :math:`\tilde V` of the curves.  Default: 99 % of the smallest
        locking volume among the materials (PDMS: 7.14), else 8.  A law that
        locks below ``vtilde_max`` gets NaN beyond 99.5 % of its locking volume.
    profile_vtildes : sequence of float
        Volumes of the profiles of panel (e), drawn for the first hyperelastic
        law in ``materials`` (PDMS by default); the flat membrane (0) is added.

    Returns
    -------
    xarray.Dataset
        ``area_ratio``, ``inverse_thickness``, ``pressure``
        (:math:`P_t a/(C_1 l_0)`) and ``turgor_ratio`` (:math:`f_p = P_t/E`) over
        ``(material, vtilde)``; ``r`` and ``z`` (profile, in units of a) over
        ``(profile_vtilde, rho)``.  attrs: ``thickness_over_radius``,
        ``profile_material``, ``small_strain_vtilde``.

    Raises
    ------
    ValueError
        For a non-positive ``thickness_over_radius`` or ``vtilde_max``, an empty
        ``materials``, or profile volumes that are not positive or lie beyond
        the profile law's locking volume.
    TypeError
        For an entry of ``materials`` that is not a law.

    Notes
    -----
    :math:`f_A` and :math:`f_l` of the hyperelastic laws solve main text Eqns 19-24
    (supplement Eqns 50, 52); the linear-elastic ones are Eqns 11-13 with Eqn 12
    corrected to :math:`1 + 4\tilde V^2` (``docs/paper-errata.md``).
    :math:`f_p = \tilde P_t C_1 (l_0/a) / E` (supplement Sec. 5.6).
    """
    mats = tuple(_default_materials() if materials is None else materials)
    if not mats:
        raise ValueError("materials must contain at least one law, got an empty sequence")
    for m in mats:
        if not isinstance(m, Material | LinearElastic):
            raise TypeError(f"materials entries must be osmobulge material laws, got {type(m).__name__}")
    ratio = _check_positive("thickness_over_radius (l0/a)", thickness_over_radius)
    locks = np.array([locking_volume(m) for m in mats])
    if vtilde_max is None:
        finite = locks[np.isfinite(locks)]
        vmax = 0.99 * float(finite.min()) if finite.size else 8.0
    else:
        vmax = _check_positive("vtilde_max", vtilde_max)
    grid = _figure3_grid(vmax)

    labels = []
    for m in mats:
        label = _label(m)
        labels.append(label if label not in labels else f"{label} #{len(labels)}")

    # check the profile request before any solving
    hyper = [i for i, m in enumerate(mats) if not isinstance(m, LinearElastic)]
    pv = np.asarray(profile_vtildes, float).ravel()
    if pv.size and not hyper:
        raise ValueError("profile_vtildes needs a hyperelastic law in materials (LinearElastic has no profile)")
    if np.any(~np.isfinite(pv)) or np.any(pv <= 0):
        raise ValueError(f"profile_vtildes must be finite and > 0, got {profile_vtildes!r}")
    profile_label = labels[hyper[0]] if hyper else ""
    if pv.size and np.any(pv >= locks[hyper[0]]):
        raise ValueError(
            f"profile_vtildes must lie below the locking volume {locks[hyper[0]]:.4g} of {profile_label}, "
            f"got max {pv.max():.6g}"
        )

    quantities = ("area_ratio", "inverse_thickness", "pressure", "lambda_bar")
    curves = {q: np.full((len(mats), grid.size), np.nan) for q in (*quantities, "turgor_ratio")}
    for i, (m, lock) in enumerate(zip(mats, locks, strict=True)):
        ok = grid < 0.995 * lock
        ds = bulge_mechanics(m, grid[ok])
        for q in quantities:
            curves[q][i, ok] = ds[q].values
        curves["turgor_ratio"][i, ok] = turgor_ratio(ds["pressure"].values, m, ratio)

    n_rho = 201
    profile_vt = np.r_[0.0, np.sort(pv)]
    r = np.empty((profile_vt.size, n_rho))
    z = np.empty((profile_vt.size, n_rho))
    r[0], z[0] = np.linspace(0.0, 1.0, n_rho), 0.0  # flat membrane, lambda_pre = 1
    for j, v in enumerate(profile_vt[1:], start=1):
        prof = bulge_profile(mats[hyper[0]], float(v), n=n_rho)
        r[j], z[j] = prof["r"].values, prof["z"].values

    one = {"units": "1"}
    data_vars = {
        "area_ratio": (("material", "vtilde"), curves["area_ratio"], one | {"long_name": "area ratio f_A = A/A0"}),
        "inverse_thickness": (("material", "vtilde"), curves["inverse_thickness"],
                              one | {"long_name": "mean inverse thickness ratio f_l = <l0/l>"}),
        "pressure": (("material", "vtilde"), curves["pressure"],
                     one | {"long_name": "dimensionless turgor pressure P_t a/(C1 l0)"}),
        "lambda_bar": (("material", "vtilde"), curves["lambda_bar"],
                       one | {"long_name": "average biaxial stretch sqrt(A/A0)"}),
        "turgor_ratio": (("material", "vtilde"), curves["turgor_ratio"],
                         one | {"long_name": "turgor pressure over modulus f_p = P_t/E"}),
        "r": (("profile_vtilde", "rho"), r, one | {"long_name": "radial position r/a"}),
        "z": (("profile_vtilde", "rho"), z, one | {"long_name": "height above the rim plane z/a"}),
    }
    coords = {
        "material": ("material", labels, {"long_name": "constitutive law"}),
        "vtilde": ("vtilde", grid, one | {"long_name": "dimensionless bulge volume dV/(pi a^3)"}),
        "profile_vtilde": ("profile_vtilde", profile_vt, one | {"long_name": "bulge volume of the profile"}),
        "rho": ("rho", np.linspace(0.0, 1.0, n_rho), one | {"long_name": "reference radius rho/a"}),
    }
    attrs = {
        "title": "osmobulge: paper Fig. 3 b-e",
        "thickness_over_radius": ratio,
        "profile_material": profile_label,
        "small_strain_vtilde": SMALL_STRAIN_VTILDE,
        "lambda_pre": 1.0,
    }
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)


def _draw_curves(ax, data, var, mats, vsmall, *, lw=2.0):
    """Draw one mechanics function of every material; return the hyperelastic maxima."""
    v = data["vtilde"].values
    hyper_max = []
    n_hyper = 0
    for i, label in enumerate(data["material"].values):
        y = data[var].values[i]
        m = mats[i]
        is_linear = isinstance(m, LinearElastic) or (m is None and str(label).startswith("linear"))
        if is_linear:
            small = v <= vsmall
            ax.plot(v[small], y[small], color=_GOLD, lw=1.3 * lw, label=f"{label}, $\\tilde V \\leq {vsmall:g}$",
                    zorder=3)
            ax.plot(v[~small], y[~small], color=_LIGHT_GOLD, lw=lw, label=f"{label}, beyond", zorder=2)
            continue
        colour = _colour(m, i) if m is not None else _OTHER_COLOURS[i % len(_OTHER_COLOURS)]
        # later hyperelastic laws dashed: f_A is nearly law-independent and the curves overlap
        style = "-" if n_hyper == 0 else (0, (5, 2.5))
        n_hyper += 1
        ax.plot(v, y, color=colour, lw=lw, ls=style, label=str(label), zorder=3)
        if np.any(np.isfinite(y)):
            hyper_max.append(float(np.nanmax(y)))
    ax.axvspan(0.0, vsmall, color=_GOLD, alpha=0.18, lw=0, zorder=0)
    return hyper_max


def plot_figure3(
    materials=None,
    *,
    thickness_over_radius=0.1,
    vtilde_max=None,
    profile_vtildes=(0.5, 1, 2, 3, 4),
    data: xr.Dataset | None = None,
):
    r"""Draw the paper's Fig. 3 b-e: mechanics functions and bulge profiles.

    (b) :math:`f_A = A/A_0`, (c) :math:`f_l = \langle l_0/l\rangle`, (d)
    :math:`f_p = P_t/E` against :math:`\tilde V` for a linear-elastic membrane
    (gold; saturated in its small-stretch regime :math:`\tilde V < 0.05`, light
    beyond, as in the paper), PDMS (navy) and PEO-PDMS (light blue); (e) PDMS
    bulge profiles :math:`z/a` against :math:`r/a` for :math:`\tilde V` in 0-4,
    the whole dome mirrored about the axis.  All at :math:`\lambda_{pre} = 1`.

    Parameters
    ----------
    materials : sequence of Material or LinearElastic, optional
        As in :func:`figure3_data`.
    thickness_over_radius : float
        :math:`l_0/a` for :math:`f_p` (reference chamber 20/200 = 0.1).
    vtilde_max : float, optional
        Largest :math:`\tilde V` of panels b-d (default: 99 % of the smallest
        locking volume, 7.14 for PDMS).
    profile_vtildes : sequence of float
        Volumes of the profiles in panel (e); the flat membrane is added.
    data : xarray.Dataset, optional
        Precomputed :func:`figure3_data` output (then the other arguments are
        ignored); lets a caller save the plotted numbers without solving twice.

    Returns
    -------
    matplotlib.figure.Figure
        Four axes, titled "b" to "e".

    See Also
    --------
    figure3_data : the plotted numbers as an ``xarray.Dataset``.

    Notes
    -----
    Main text Fig. 3 and Sec. 3.3-3.5; linear elastic from Eqns 11-13 (Eqn 12
    corrected), hyperelastic from Eqns 19-24.  :math:`f_A` and :math:`f_p` span
    orders of magnitude between the laws and are drawn on log axes.

    Examples
    --------
    >>> fig = plot_figure3(profile_vtildes=(1.0,), vtilde_max=2.0)  # doctest: +SKIP
    >>> fig.savefig("fig3.png")  # doctest: +SKIP
    """
    if data is None:
        data = figure3_data(materials, thickness_over_radius=thickness_over_radius, vtilde_max=vtilde_max,
                            profile_vtildes=profile_vtildes)
    mats = tuple(_default_materials() if materials is None else materials)
    if len(mats) != data.sizes["material"]:
        mats = (None,) * data.sizes["material"]  # data from elsewhere: colours by label only
    v = data["vtilde"].values
    vsmall = float(data.attrs.get("small_strain_vtilde", SMALL_STRAIN_VTILDE))

    fig = _new_figure(figsize=(11, 8.6), layout="constrained")
    axes = fig.subplot_mosaic([["b", "c"], ["d", "e"]])
    panels = {
        "b": ("area_ratio", r"area ratio $f_A = A/A_0$", "log"),
        "c": ("inverse_thickness", r"inverse thickness $f_l = \langle l_0/l \rangle$", "linear"),
        "d": ("turgor_ratio", r"turgor pressure $f_p = P_t/E$", "log"),
    }
    for key, (var, ylabel, yscale) in panels.items():
        ax = axes[key]
        hyper_max = _draw_curves(ax, data, var, mats, vsmall)
        ax.set_yscale(yscale)
        ax.set_xlim(0.0, float(v.max()))
        ax.set_xlabel(r"dimensionless bulge volume $\tilde V = \Delta V/(\pi a^3)$")
        ax.set_ylabel(ylabel + " [-]")
        ax.grid(alpha=0.3, which="both" if yscale == "linear" else "major")
        if hyper_max and yscale == "log":
            # keep the hyperelastic curves readable: the stiff linear curve may leave the top
            top = 4.0 * max(hyper_max)
            bottom = 0.9 if var == "area_ratio" else max(1e-6, 1e-4 * max(hyper_max))
            ax.set_ylim(bottom, top)
        elif hyper_max:
            ax.set_ylim(0.0, 1.08 * max(hyper_max))
    axes["b"].legend(fontsize=8, loc="upper left")
    axes["d"].set_title(f"$l_0/a$ = {data.attrs['thickness_over_radius']:g}", fontsize=9, loc="right")
    # inset: the small-deflection regime on log-log axes, where the laws meet as V^3
    ins = axes["d"].inset_axes([0.50, 0.07, 0.47, 0.36])
    _draw_curves(ins, data, "turgor_ratio", mats, vsmall, lw=1.4)
    ins.set_xscale("log")
    ins.set_yscale("log")
    x_lo, x_hi = float(v[v > 0].min()), min(1.0, float(v.max()))
    ins.set_xlim(x_lo, x_hi)
    window = data["turgor_ratio"].sel(vtilde=slice(x_lo, x_hi)).values
    window = window[np.isfinite(window) & (window > 0)]
    if window.size:
        ins.set_ylim(0.5 * window.min(), 3.0 * window.max())
    ins.set_xlabel(r"$\tilde V$", fontsize=8, labelpad=1)
    ins.set_ylabel("$f_p$", fontsize=8, labelpad=1)
    ins.tick_params(labelsize=7)
    ins.grid(alpha=0.3)

    ax = axes["e"]
    from matplotlib import colormaps

    cmap = colormaps["Blues"]
    pvt = data["profile_vtilde"].values
    for j, vt in enumerate(pvt):
        r, z = data["r"].values[j], data["z"].values[j]
        x = np.r_[-r[::-1], r[1:]]
        y = np.r_[z[::-1], z[1:]]
        colour = "0.5" if vt == 0 else cmap(0.35 + 0.65 * j / max(len(pvt) - 1, 1))
        ax.plot(x, y, color=colour, lw=2.0, label=rf"$\tilde V$ = {vt:g}")
    ax.plot([-1.0, 1.0], [0.0, 0.0], ls="none", marker="|", ms=14, mew=2.5, color="k", label="clamped rim")
    ax.axvline(0.0, color="0.7", lw=0.8, ls=":")
    zmax = max(float(np.nanmax(data["z"].values)), 0.5)
    rmax = max(float(np.nanmax(data["r"].values)), 1.0)
    ax.set_xlim(-1.12 * rmax, 1.12 * rmax)
    ax.set_ylim(-0.08 * zmax, 1.5 * zmax)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("radial position $r/a$ [-]")
    ax.set_ylabel(r"height above the rim $z/a$ [-]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper center", ncol=3, columnspacing=1.0, handlelength=1.6,
              title=f"profiles of {data.attrs.get('profile_material', '')}", title_fontsize=8)

    for key, ax in axes.items():
        ax.set_title(key, loc="left", fontweight="bold", fontsize=13)
    fig.suptitle(r"Bulging membrane mechanics (paper Fig. 3 b-e), $\lambda_{pre} = 1$", fontsize=12)
    return fig

