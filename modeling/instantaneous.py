r"""Instantaneous permeability, stretch binning and the dimensionless-time collapse.

Main text Sec. 3.5 and 3.7, supplement Sec. 7.3.  Solving the flux ODE for the
mobility at each instant gives the *instantaneous* mobility (Eqn 25, corrected):

.. math::

    L = -\frac{d(V/V_0)}{dt}\,\frac{l_0 V_0}{A_0 \Pi_0}\,\frac{1}{f_A f_l}\,
        \frac{1}{1/(V/V_0) - C_{feed}/C_0 + P_t/\Pi_0},

and :math:`P_w = L R T / V_m` (Eqn 2).  The printed Eqn 25 has :math:`1/V_0` where
Eqn 8 has :math:`1/(V/V_0)`, and supplement Eqn 63 multiplies by the driving
force instead of dividing (``docs/paper-errata.md``, T1 and T2).

Rates :math:`d(V/V_0)/dt` come from one of

* ``"bins"`` -- the paper's overlapping time bins, each fitted with a straight
  line whose slope is the rate at the bin's mid time (supplement Fig. S9);
* ``"savgol"`` -- a Savitzky-Golay derivative (uniform sampling);
* ``"spline"`` -- the derivative of a cubic smoothing spline of
  :math:`\ln(V/V_0)` (:func:`scipy.interpolate.make_smoothing_spline`) whose
  smoothing is set from the data: the smoother of generalised cross-validation
  and the discrepancy principle with the noise level estimated from the data
  (:func:`noise_level`).  Relative (multiplicative) noise is
  homoscedastic in :math:`\ln(V/V_0)`, and the log grows smoothly.  No bin
  width to tune: on 1 %-noise synthetic data its rates beat the paper's 2-h bins.

The values are binned by average stretch :math:`\bar\lambda` and averaged across
chambers (Fig. 6a) and Eqn 27 is fitted to them as in the paper; the direct fit
of Eqn 27 through the ODE (:func:`osmobulge.modeling.fitting.fit_permeability`)
can be run on the same data and reported beside it
(:func:`analyze_instantaneous`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from scipy.interpolate import make_smoothing_spline
from scipy.optimize import brentq
from scipy.signal import savgol_filter

from osmobulge import __version__
from osmobulge.modeling.transport import (
    Chamber,
    mechanics_model,
    mobility,
    osmotic_term,
    time_constant,
    vtilde_from_volume_ratio,
)

__all__ = [
    "RATE_METHODS",
    "volume_rates",
    "instantaneous_permeability",
    "bin_by_stretch",
    "fit_eqn27",
    "Eqn27Fit",
    "InstantaneousAnalysis",
    "analyze_instantaneous",
    "dimensionless_collapse",
    "collapse_spread",
    "as_observations",
    "noise_level",
]

RATE_METHODS = ("bins", "savgol", "spline")
_FIT_TO = ("bins", "values")
_HOUR = 3600.0
#: order of the local polynomial that replaces the smoothing spline at the ends
EDGE_ORDER = 3


# --------------------------------------------------------------------------- observations


def _check_series(t, volume_ratio, *, name="observation"):
    t = np.asarray(t, dtype=float)
    v = np.asarray(volume_ratio, dtype=float)
    if t.ndim != 1 or v.ndim != 1:
        raise ValueError(f"{name}: t and volume_ratio must be 1-D, got shapes {t.shape} and {v.shape}")
    if t.size != v.size:
        raise ValueError(f"{name}: t and volume_ratio must have the same length, got {t.size} and {v.size}")
    if t.size < 5:
        raise ValueError(f"{name}: need at least 5 samples, got {t.size}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
        raise ValueError(f"{name}: t (s) and volume_ratio must be finite (drop NaN samples first)")
    if np.any(np.diff(t) <= 0):
        raise ValueError(f"{name}: t must be strictly increasing (seconds)")
    if np.any(v <= 0):
        raise ValueError(f"{name}: volume_ratio V/V0 must be > 0")
    return t, v


def as_observations(observations) -> list:
    """Normalise observations to a list of ``(chamber, t, volume_ratio, label)``.

    Parameters
    ----------
    observations : sequence
        Items are ``(chamber, t, volume_ratio)`` tuples (optionally with a
        fourth element, a label) or ``xarray.Dataset`` objects with a
        ``volume_ratio`` variable over a time coordinate ``time`` or ``t`` (s) and the
        chamber in their attrs (:meth:`Chamber.to_attrs`), such as the output
        of :func:`osmobulge.modeling.simulate`.

    Returns
    -------
    list of tuple
    """
    if isinstance(observations, xr.Dataset) or (
        isinstance(observations, tuple) and len(observations) in (3, 4) and isinstance(observations[0], Chamber)
    ):
        observations = [observations]
    out = []
    for i, obs in enumerate(observations):
        if isinstance(obs, xr.Dataset):
            if "volume_ratio" not in obs:
                raise ValueError(f"observations[{i}]: dataset has no 'volume_ratio' variable")
            tname = next((n for n in ("time", "t") if n in obs.coords), obs["volume_ratio"].dims[0])
            chamber = Chamber.from_attrs(obs.attrs)
            label = next((str(obs.attrs[k]) for k in ("label", "name", "chamber_label") if k in obs.attrs),
                         f"chamber {i}")
            t, v = obs[tname].values, obs["volume_ratio"].values
        else:
            try:
                chamber, t, v, *rest = obs
            except (TypeError, ValueError):
                raise TypeError(
                    f"observations[{i}] must be (chamber, t, volume_ratio) or an xarray.Dataset, got {obs!r:.80}"
                ) from None
            if not isinstance(chamber, Chamber):
                raise TypeError(f"observations[{i}][0] must be a Chamber, got {type(chamber).__name__}")
            label = str(rest[0]) if rest else f"chamber {i}"
        t, v = _check_series(t, v, name=f"observations[{i}]")
        out.append((chamber, t, v, label))
    if not out:
        raise ValueError("observations is empty")
    return out


# --------------------------------------------------------------------------- rates


def volume_rates(
    t,
    volume_ratio,
    *,
    method: str = "spline",
    bin_width: float = 2 * _HOUR,
    overlap: float = 0.5,
    window: int = 9,
    polyorder: int = 2,
    smoothing="auto",
    edge_window: int = 9,
):
    r"""Rates :math:`d(V/V_0)/dt` of a volume-ratio time series.

    Parameters
    ----------
    t : array_like of shape (N,), s
        Strictly increasing times.
    volume_ratio : array_like of shape (N,)
        :math:`V/V_0`.
    method : {"bins", "savgol", "spline"}
        See the module notes.
    bin_width : float, s
        ``"bins"``: width of each time bin (default 2 h).
    overlap : float
        ``"bins"``: overlap of consecutive bins as a fraction of the width, in [0, 1).
    window : int
        ``"savgol"``: window length in samples (odd, > ``polyorder``).
    polyorder : int
        ``"savgol"``: polynomial order.
    smoothing : {"auto", "discrepancy", "gcv"} or float
        ``"spline"``: how the regularisation :math:`\lambda` of
        :func:`~scipy.interpolate.make_smoothing_spline` (time in hours) is
        chosen.  ``"discrepancy"``: the residual sum of squares of
        :math:`\ln(V/V_0)` equals :math:`N\hat\sigma^2`, with :math:`\hat\sigma`
        from :func:`noise_level` (Morozov's principle); ``"gcv"``: generalised
        cross-validation; ``"auto"`` (default): the smoother of the two, since
        a derivative needs at least the smoothing that suits the function
        itself.  A number is used as :math:`\lambda`.
    edge_window : int
        ``"spline"``: the first ``edge_window // 2`` rates come from a cubic
        (:data:`EDGE_ORDER`) fitted to the first ``edge_window`` samples of
        :math:`\ln(V/V_0)` instead of the spline, whose natural end condition
        biases the derivative at the start, where the curve bends most and
        which alone fixes :math:`P_w(\bar\lambda \to 1)`; 0 disables.

    Returns
    -------
    t_eval : ndarray of shape (M,), s
        Times of the rates (bin mid times for ``"bins"``, the samples otherwise).
    volume_ratio_eval : ndarray of shape (M,)
        Smoothed :math:`V/V_0` at ``t_eval`` (for bins: a parabola fitted to the
        bin at its mid time; the rate is the slope of the bin's straight line).
    rate : ndarray of shape (M,), 1/s

    Notes
    -----
    Supplement Sec. 7.3 and Fig. S9 (bins).
    """
    t, v = _check_series(t, volume_ratio, name="volume_rates")
    if method not in RATE_METHODS:
        raise ValueError(f"method must be one of {RATE_METHODS}, got {method!r}")
    if method == "bins":
        width = float(bin_width)
        if not math.isfinite(width) or width <= 0:
            raise ValueError(f"bin_width must be finite and > 0 (s), got {bin_width!r}")
        ov = float(overlap)
        if not (0.0 <= ov < 1.0):
            raise ValueError(f"overlap must be in [0, 1), got {overlap!r}")
        step = width * (1.0 - ov)
        starts = np.arange(t[0], t[-1] - width + 1e-9 * width, step)
        tm, vm, rate = [], [], []
        for s0 in starts:
            sel = (t >= s0 - 1e-9 * width) & (t <= s0 + width + 1e-9 * width)
            if sel.sum() < 3:
                continue
            mid = s0 + 0.5 * width
            slope, icpt = np.polyfit(t[sel] - mid, v[sel], 1)
            if sel.sum() >= 4:
                # the line's value at mid time is biased by the curvature; a parabola's is not
                icpt = np.polyfit(t[sel] - mid, v[sel], 2)[-1]
            tm.append(mid)
            vm.append(icpt)
            rate.append(slope)
        if len(tm) == 0:
            raise ValueError(
                f"bin_width={width:g} s gives no bin with >= 3 samples in {t[-1] - t[0]:g} s of data"
            )
        return np.array(tm), np.array(vm), np.array(rate)
    if method == "savgol":
        w, po = int(window), int(polyorder)
        if w % 2 == 0 or w <= po or w > t.size:
            raise ValueError(
                f"window must be odd, > polyorder ({po}) and <= the number of samples ({t.size}), got {window!r}"
            )
        dt = np.diff(t)
        if np.ptp(dt) > 1e-6 * dt.mean():
            raise ValueError("method='savgol' needs uniform time steps; use method='spline' for irregular sampling")
        vs = savgol_filter(v, w, po, mode="interp")
        rate = savgol_filter(v, w, po, deriv=1, delta=float(dt.mean()), mode="interp")
        return t.copy(), vs, rate
    # spline of ln(V/V0) in hours
    x = (t - t[0]) / _HOUR
    y = np.log(v)
    spl = _smoothing_spline(x, y, smoothing)
    lnv, dlnv = spl(x), spl.derivative()(x)
    ew = int(edge_window)
    if ew:
        if ew < EDGE_ORDER + 2 or ew > x.size:
            raise ValueError(
                f"edge_window must be 0 or in [{EDGE_ORDER + 2}, {x.size}] samples, got {edge_window!r}")
        # smoothing splines are biased at the ends (natural boundary conditions): use a
        # local cubic there, which has no such bias (local polynomial regression)
        # at the start, where ln V bends most and which alone fixes P_w(lambda_bar -> 1); at the
        # end the curve is straighter and a local polynomial would only add variance
        h = ew // 2
        c = np.polyfit(x[:ew], y[:ew], EDGE_ORDER)
        lnv[:h] = np.polyval(c, x[:h])
        dlnv[:h] = np.polyval(np.polyder(c), x[:h])
    vs = np.exp(lnv)
    rate = vs * dlnv / _HOUR
    return t.copy(), vs, rate


def noise_level(y) -> float:
    r"""Robust estimate of the standard deviation of white noise on a smooth series.

    From the second differences :math:`y_{i-1} - 2y_i + y_{i+1}` (variance
    :math:`6\sigma^2` for white noise; a smooth signal contributes little) via
    their median absolute deviation.

    Parameters
    ----------
    y : array_like of shape (N,), N >= 5

    Returns
    -------
    float
    """
    y = np.asarray(y, float)
    d2 = y[:-2] - 2.0 * y[1:-1] + y[2:]
    return float(1.482602218505602 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))


_SMOOTHING = ("auto", "discrepancy", "gcv")


def _smoothing_spline(x, y, smoothing):
    """Cubic smoothing spline of y(x) with the regularisation chosen by ``smoothing``."""
    if isinstance(smoothing, str):
        if smoothing not in _SMOOTHING:
            raise ValueError(f"smoothing must be one of {_SMOOTHING} or a number >= 0, got {smoothing!r}")
    else:
        lam = float(smoothing)
        if not math.isfinite(lam) or lam < 0:
            raise ValueError(f"smoothing must be one of {_SMOOTHING} or a number >= 0, got {smoothing!r}")
        return make_smoothing_spline(x, y, lam=lam)
    if smoothing == "gcv":
        return make_smoothing_spline(x, y)
    # discrepancy principle: the residual sum of squares equals N sigma^2
    target = y.size * noise_level(y) ** 2
    if smoothing == "auto":
        # a derivative needs at least the smoothing that is optimal for the function
        # itself: take the smoother of the discrepancy and the GCV choices
        gcv = make_smoothing_spline(x, y)
        target = max(target, float(np.sum((gcv(x) - y) ** 2)))
    if target <= 0:
        return make_smoothing_spline(x, y, lam=0.0)

    def excess(log_lam):
        spl = make_smoothing_spline(x, y, lam=10.0**log_lam)
        return float(np.sum((spl(x) - y) ** 2)) - target

    lo, hi = -12.0, 8.0
    if excess(lo) >= 0:
        log_lam = lo
    elif excess(hi) <= 0:
        log_lam = hi
    else:
        log_lam = brentq(excess, lo, hi, xtol=1e-3)
    return make_smoothing_spline(x, y, lam=10.0**log_lam)


# --------------------------------------------------------------------------- Eqn 25


_INST_ATTRS = {
    "time": ("s", "time of the rate"),
    "volume_ratio": ("1", "smoothed volume ratio V/V0"),
    "rate": ("1/s", "rate d(V/V0)/dt"),
    "vtilde": ("1", "dimensionless bulge volume dV/(pi a^3)"),
    "lambda_bar": ("1", "average biaxial stretch sqrt(A/A0)"),
    "area_ratio": ("1", "membrane area ratio f_A"),
    "inverse_thickness": ("1", "mean inverse thickness ratio f_l"),
    "thickness": ("m", "mean membrane thickness l0/f_l"),
    "turgor_pressure": ("Pa", "turgor pressure P_t"),
    "driving_force": ("1", "driving force (Pi + P_t)/Pi0 = 1/(V/V0) - C_feed/C0 + P_t/Pi0"),
    "mobility": ("m^2/(Pa s)", "instantaneous water mobility L (Eqn 25, corrected)"),
    "permeability": ("m^2/s", "instantaneous water permeability P_w (Eqns 25, 2)"),
}


def _mechanics_at(chamber, mech, v):
    """f_A, f_l, lambda_bar, P_t at volume ratios; NaN beyond the mechanics table."""
    vt = vtilde_from_volume_ratio(v, chamber)
    vt = np.maximum(np.asarray(vt, float), 0.0)  # noise below V0: flat membrane
    vmax = getattr(mech, "vtilde_max", math.inf)
    ok = vt <= vmax
    vq = np.where(ok, vt, 0.0)
    fa = np.where(ok, mech.area_ratio(vq), np.nan)
    fl = np.where(ok, mech.inverse_thickness(vq), np.nan)
    lam = np.where(ok, mech.lambda_bar(vq), np.nan)
    pt = np.where(ok, mech.turgor_pressure(vq, thickness=chamber.thickness, radius=chamber.radius), np.nan)
    return vt, fa, fl, lam, pt


def instantaneous_permeability(
    chamber: Chamber,
    material,
    t,
    volume_ratio,
    *,
    method: str = "spline",
    mechanics: str = "hyperelastic",
    lambda_pre=1.0,
    label: str = "",
    min_drive: float = 0.05,
    **rate_options,
) -> xr.Dataset:
    r"""Instantaneous water permeability of one chamber (Eqn 25 corrected, Eqn 2).

    Parameters
    ----------
    chamber : Chamber
        Geometry and loading (SI).
    material : Material or LinearElastic
        Membrane law for :math:`f_A, f_l, P_t`.
    t : array_like of shape (N,), s
    volume_ratio : array_like of shape (N,)
        Observed :math:`V/V_0`.
    method : {"bins", "savgol", "spline"}
        Rate estimator, see :func:`volume_rates`.
    mechanics : {"hyperelastic", "linear"}
        Membrane mechanics (see :func:`osmobulge.modeling.transport.mechanics_model`).
    lambda_pre : float or callable
        Rim pre-stretch.
    label : str
        Chamber name stored in the attrs.
    min_drive : float
        Samples whose driving force :math:`(\Pi + P_t)/\Pi_0` is below this get
        NaN permeability: near the osmotic-turgor equilibrium Eqn 25 divides a
        vanishing rate by a vanishing force.
    **rate_options
        Passed to :func:`volume_rates` (``bin_width``, ``overlap``, ``window``,
        ``polyorder``, ``smoothing``).

    Returns
    -------
    xarray.Dataset
        Over ``sample``: ``time``, ``volume_ratio`` (smoothed), ``rate``,
        ``vtilde``, ``lambda_bar``, ``area_ratio``, ``inverse_thickness``,
        ``thickness``, ``turgor_pressure``, ``driving_force``, ``mobility``,
        ``permeability``.  Samples beyond the mechanics table (Gent locking) or
        with a driving force below ``min_drive`` have NaN mobility and permeability.

    Notes
    -----
    .. math::

        P_w = \frac{d(V/V_0)}{dt}\,\frac{\tau(P_w = 1)}{f_A f_l\,\left(1/(V/V_0) -
        C_{feed}/C_0 + P_t/\Pi_0\right)}

    with :math:`\tau(P_w=1) = l_0 h/(V_m i C_0)` (Eqn 9): the corrected Eqn 25,
    converted with Eqn 2.
    """
    if not isinstance(chamber, Chamber):
        raise TypeError(f"chamber must be a Chamber, got {type(chamber).__name__}")
    te, ve, rate = volume_rates(t, volume_ratio, method=method, **rate_options)
    mech = mechanics_model(material, lambda_pre, mechanics)
    vt, fa, fl, lam, pt = _mechanics_at(chamber, mech, ve)
    drive = osmotic_term(ve, chamber.feed_ratio) + pt / chamber.osmotic_potential
    drive = np.asarray(drive, float)
    tau1 = time_constant(chamber, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        pw = np.where(np.isfinite(drive) & (drive > float(min_drive)), rate * tau1 / (fa * fl * drive), np.nan)
        mob = np.asarray(mobility(pw, chamber.temperature), float)
        thick = chamber.thickness / fl
    values = {
        "time": te, "volume_ratio": ve, "rate": rate, "vtilde": vt, "lambda_bar": lam, "area_ratio": fa,
        "inverse_thickness": fl, "thickness": thick, "turgor_pressure": pt, "driving_force": drive,
        "mobility": mob, "permeability": pw,
    }
    data = {k: ("sample", np.asarray(v, float), {"units": _INST_ATTRS[k][0], "long_name": _INST_ATTRS[k][1]})
            for k, v in values.items()}
    attrs = chamber.to_attrs() | {
        "title": "instantaneous permeability",
        "label": str(label),
        "rate_method": method,
        "mechanics": mechanics,
        "min_drive": float(min_drive),
        "material_law": getattr(material, "law", type(material).__name__),
        "osmobulge_version": __version__,
    }
    for k, v in rate_options.items():
        if v is not None:
            attrs[f"rate_{k}"] = v if isinstance(v, str) else float(v)
    return xr.Dataset(data, coords={"sample": np.arange(te.size)}, attrs=attrs)


# --------------------------------------------------------------------------- binning


def bin_by_stretch(values, *, edges=None, per_bin: int | None = None, min_count: int = 2) -> xr.Dataset:
    r"""Average instantaneous permeabilities in bins of average stretch (Fig. 6a).

    Parameters
    ----------
    values : xarray.Dataset or sequence of them
        Outputs of :func:`instantaneous_permeability` (any number of chambers).
    edges : array_like, optional
        Bin edges in :math:`\bar\lambda`.  Default: consecutive groups of
        ``per_bin`` values sorted by stretch (the paper averages five).
    per_bin : int, optional
        Values per group when ``edges`` is not given (default 5).
    min_count : int
        Bins with fewer values are dropped.

    Returns
    -------
    xarray.Dataset
        Over ``bin``: ``lambda_bar`` (mean), ``lambda_bar_std``,
        ``permeability`` (mean, m**2/s), ``permeability_std``, ``permeability_sem``,
        ``thickness`` (mean, m), ``count``.
    """
    if isinstance(values, xr.Dataset):
        values = [values]
    lam = np.concatenate([np.asarray(v["lambda_bar"].values, float) for v in values])
    pw = np.concatenate([np.asarray(v["permeability"].values, float) for v in values])
    th = np.concatenate([np.asarray(v["thickness"].values, float) for v in values])
    ok = np.isfinite(lam) & np.isfinite(pw)
    lam, pw, th = lam[ok], pw[ok], th[ok]
    if lam.size == 0:
        raise ValueError("no finite instantaneous permeabilities to bin")
    if int(min_count) < 1:
        raise ValueError(f"min_count must be >= 1, got {min_count!r}")
    if edges is not None:
        if per_bin is not None:
            raise ValueError("give edges or per_bin, not both")
        e = np.asarray(edges, float)
        if e.ndim != 1 or e.size < 2 or np.any(np.diff(e) <= 0):
            raise ValueError("edges must be a strictly increasing 1-D array of at least 2 stretches")
        idx = np.digitize(lam, e) - 1
        groups = [np.nonzero(idx == k)[0] for k in range(e.size - 1)]
    else:
        n = 5 if per_bin is None else int(per_bin)
        if n < 1:
            raise ValueError(f"per_bin must be >= 1, got {per_bin!r}")
        order = np.argsort(lam, kind="stable")
        groups = [order[k:k + n] for k in range(0, order.size, n)]
    groups = [g for g in groups if g.size >= int(min_count)]
    if not groups:
        raise ValueError("no bin holds min_count values")

    def stat(fn, arr):
        return np.array([fn(arr[g]) for g in groups])

    ddof = {"ddof": 1} if min(g.size for g in groups) > 1 else {}
    count = np.array([g.size for g in groups])
    pw_std = stat(lambda a: np.std(a, **ddof), pw)
    data = {
        "lambda_bar": ("bin", stat(np.mean, lam), {"units": "1", "long_name": "mean average biaxial stretch"}),
        "lambda_bar_std": ("bin", stat(lambda a: np.std(a, **ddof), lam),
                           {"units": "1", "long_name": "std of the stretch in the bin"}),
        "permeability": ("bin", stat(np.mean, pw), {"units": "m^2/s", "long_name": "mean instantaneous P_w"}),
        "permeability_std": ("bin", pw_std, {"units": "m^2/s", "long_name": "std of P_w in the bin"}),
        "permeability_sem": ("bin", pw_std / np.sqrt(count), {"units": "m^2/s", "long_name": "standard error"}),
        "thickness": ("bin", stat(np.mean, th), {"units": "m", "long_name": "mean membrane thickness l0/f_l"}),
        "count": ("bin", count, {"units": "1", "long_name": "number of values"}),
    }
    return xr.Dataset(data, coords={"bin": np.arange(count.size)}, attrs={"title": "P_w binned by stretch"})


# --------------------------------------------------------------------------- Eqn 27 on instantaneous values


@dataclass(frozen=True)
class Eqn27Fit:
    r"""Eqn 27 fitted to instantaneous permeabilities.

    Attributes
    ----------
    params : dict
        ``c1`` (m**2/s), ``c2``, ``c3`` (m**2/s), ``c4`` and ``p_at_rest``
        (:math:`P_w(\bar\lambda = 1)`, m**2/s).
    stderr : dict
        Their standard errors (NaN if not estimated).
    lambda_bar, permeability, weights : ndarray
        Data fitted.
    source : str
        ``"bins"`` or ``"values"``.
    """

    params: dict
    stderr: dict
    lambda_bar: np.ndarray
    permeability: np.ndarray
    weights: np.ndarray
    source: str
    redchi: float
    success: bool
    lmfit_result: object = field(default=None, repr=False, compare=False)

    def permeability_at(self, lambda_bar):
        """Fitted :math:`P_w(\\bar\\lambda)`, m**2/s."""
        from osmobulge.modeling.permeability import double_exponential

        p = self.params
        return double_exponential(lambda_bar, p["c1"], p["c2"], p["c3"], p["c4"])

    def law(self):
        """The fit as a :class:`~osmobulge.modeling.permeability.DoubleExponential`."""
        from osmobulge.modeling.permeability import DoubleExponential

        p = self.params
        return DoubleExponential(p["c1"], p["c2"], p["c3"], p["c4"])


def fit_eqn27(lambda_bar, permeability, *, sigma=None) -> Eqn27Fit:
    r"""Fit Eqn 27 to permeability values against stretch (as the paper does).

    Parameters
    ----------
    lambda_bar : array_like of shape (N,)
    permeability : array_like of shape (N,), m**2/s
    sigma : array_like of shape (N,), m**2/s, optional
        Standard errors; default relative errors (``sigma = permeability``),
        i.e. a fit of the relative misfit.

    Returns
    -------
    Eqn27Fit

    Notes
    -----
    Uses :class:`osmobulge.modeling.permeability.DoubleExponentialModel`
    (lmfit, prefactors fitted as logarithms).
    """
    from osmobulge.modeling.permeability import DoubleExponentialModel

    lam = np.asarray(lambda_bar, float)
    pw = np.asarray(permeability, float)
    if lam.shape != pw.shape or lam.ndim != 1:
        raise ValueError(f"lambda_bar and permeability must be 1-D of equal length, got {lam.shape}, {pw.shape}")
    ok = np.isfinite(lam) & np.isfinite(pw) & (pw > 0)
    if sigma is None:
        sig = np.abs(pw)
    else:
        sig = np.broadcast_to(np.asarray(sigma, float), pw.shape)
        ok &= np.isfinite(sig) & (sig > 0)
    if ok.sum() < 5:
        raise ValueError(f"Eqn 27 has 4 constants: need at least 5 finite positive values, got {int(ok.sum())}")
    lam, pw, sig = lam[ok], pw[ok], np.asarray(sig)[ok]
    model = DoubleExponentialModel()
    pars = model.guess(pw, lambda_bar=lam)
    # keep the exponents finite over any stretch a membrane reaches (no overflow to NaN)
    pars["c4"].set(min=-20.0, max=20.0, value=float(np.clip(pars["c4"].value, -19.0, 19.0)))
    pars["gap"].set(max=200.0, value=float(np.clip(pars["gap"].value, 0.0, 190.0)))
    for k in ("ln_a1", "ln_a3"):
        pars[k].set(min=math.log(1e-30), max=math.log(1e-3),
                    value=float(np.clip(pars[k].value, math.log(1e-29), math.log(1e-4))))
    res = model.fit(pw, pars, lambda_bar=lam, weights=1.0 / sig)
    names = ("c1", "c2", "c3", "c4", "p_at_rest")
    params = {k: float(res.params[k].value) for k in names}
    stderr = {k: float(res.params[k].stderr) if res.params[k].stderr is not None else float("nan") for k in names}
    return Eqn27Fit(params=params, stderr=stderr, lambda_bar=lam, permeability=pw, weights=1.0 / sig,
                    source="values" if sigma is None else "given sigma", redchi=float(res.redchi),
                    success=bool(res.success), lmfit_result=res)


# --------------------------------------------------------------------------- analysis


@dataclass(frozen=True)
class InstantaneousAnalysis:
    r"""Instantaneous permeabilities of several chambers, binned, with Eqn 27 fitted two ways.

    Attributes
    ----------
    values : tuple of xarray.Dataset
        :func:`instantaneous_permeability` per chamber.
    binned : xarray.Dataset
        :func:`bin_by_stretch` of all values.
    eqn27 : Eqn27Fit
        Eqn 27 fitted to the instantaneous values (the paper's way).
    direct : object or None
        :func:`osmobulge.modeling.fitting.fit_permeability` with
        ``model="double_exponential"`` on the same observations (Eqn 27 through
        the ODE), or None if not requested.
    direct_error : str
        Why the direct fit is missing, if it is.
    """

    values: tuple
    binned: xr.Dataset
    eqn27: Eqn27Fit
    direct: object = None
    direct_error: str = ""
    method: str = "spline"
    mechanics: str = "hyperelastic"

    def direct_params(self) -> dict:
        """Eqn 27 constants of the direct ODE fit (empty if absent)."""
        if self.direct is None:
            return {}
        p = dict(self.direct.params)
        out = {k: float(p[k]) for k in ("c1", "c2", "c3", "c4") if k in p}
        p1 = getattr(self.direct, "p_at_rest", None)
        out["p_at_rest"] = float(p1) if p1 is not None else float(self.direct.permeability(1.0))
        return out

    def direct_stderr(self) -> dict:
        """Standard errors of the direct fit (empty if absent)."""
        if self.direct is None:
            return {}
        s = {k: (float(v) if v is not None else float("nan")) for k, v in dict(self.direct.stderr).items()}
        s["p_at_rest"] = float(getattr(self.direct, "p_at_rest_stderr", float("nan")))
        return s

    def summary(self) -> dict:
        """JSON-safe comparison of the two Eqn 27 fits and the data used."""

        def f(x):
            x = float(x)
            return x if math.isfinite(x) else None

        out = {
            "rate_method": self.method,
            "mechanics": self.mechanics,
            "n_chambers": len(self.values),
            "n_values": int(sum(np.isfinite(v["permeability"].values).sum() for v in self.values)),
            "n_bins": int(self.binned.sizes["bin"]),
            "instantaneous_fit": {
                "source": self.eqn27.source,
                "params": {k: f(v) for k, v in self.eqn27.params.items()},
                "stderr": {k: f(v) for k, v in self.eqn27.stderr.items()},
                "redchi": f(self.eqn27.redchi),
            },
        }
        if self.direct is not None:
            dp = self.direct_params()
            out["direct_ode_fit"] = {
                "params": {k: f(v) for k, v in dp.items()},
                "stderr": {k: f(v) for k, v in self.direct_stderr().items()},
            }
            p_inst, p_dir = self.eqn27.params["p_at_rest"], dp.get("p_at_rest", np.nan)
            out["p_at_rest_ratio_instantaneous_over_direct"] = f(p_inst / p_dir)
        else:
            out["direct_ode_fit"] = None
            out["direct_error"] = self.direct_error
        out["osmobulge_version"] = __version__
        return out

    def report(self) -> str:
        """Side-by-side text report of the two Eqn 27 fits."""
        lines = [
            f"[[Instantaneous permeability]] rates: {self.method}, mechanics: {self.mechanics}",
            f"    {len(self.values)} chambers, {self.binned.sizes['bin']} stretch bins "
            f"(lambda_bar {float(self.binned.lambda_bar.min()):.3g}-{float(self.binned.lambda_bar.max()):.3g})",
            "[[Eqn 27]]            instantaneous (paper)         direct ODE fit",
        ]
        dp, ds = self.direct_params(), self.direct_stderr()
        for k, unit in (("c1", "m^2/s"), ("c2", ""), ("c3", "m^2/s"), ("c4", ""), ("p_at_rest", "m^2/s")):
            a, sa = self.eqn27.params[k], self.eqn27.stderr[k]
            left = f"{a:.4g} +/- {sa:.2g}" if np.isfinite(sa) else f"{a:.4g}"
            if dp:
                b, sb = dp.get(k, np.nan), ds.get(k, np.nan)
                right = f"{b:.4g} +/- {sb:.2g}" if np.isfinite(sb) else f"{b:.4g}"
            else:
                right = "(not run)"
            name = "P_w(1)" if k == "p_at_rest" else k
            lines.append(f"    {name:>9} {unit:>6}  {left:<28}  {right}")
        if self.direct is None and self.direct_error:
            lines.append(f"    direct fit: {self.direct_error}")
        return "\n".join(lines)

    def to_dataset(self) -> xr.Dataset:
        """All instantaneous values (with their chamber index), the bins and both fits' constants."""
        parts = []
        for i, v in enumerate(self.values):
            d = v.reset_coords(drop=True).drop_vars("sample")
            d = d.assign(chamber=("sample", np.full(v.sizes["sample"], i),
                                  {"units": "1", "long_name": "index of the chamber"}))
            d.attrs = {}
            parts.append(d)
        vals = xr.concat(parts, dim="sample")
        vals = vals.assign_coords(sample=np.arange(vals.sizes["sample"]))
        binned = self.binned.rename({k: f"bin_{k}" for k in self.binned.data_vars})
        names = ["c1", "c2", "c3", "c4", "p_at_rest"]
        coef = [self.eqn27.params[k] for k in names]
        err = [self.eqn27.stderr[k] for k in names]
        dp, ds = self.direct_params(), self.direct_stderr()
        out = xr.merge([vals, binned])
        out["modelfit_coefficients"] = (("fit", "param"), np.array([coef, [dp.get(k, np.nan) for k in names]]))
        out["modelfit_stderr"] = (("fit", "param"), np.array([err, [ds.get(k, np.nan) for k in names]]))
        out = out.assign_coords(param=names, fit=["instantaneous", "direct_ode"],
                                chamber_label=("chamber_index", [v.attrs.get("label", "") for v in self.values]))
        out.attrs = {"title": "instantaneous permeability analysis", "rate_method": self.method,
                     "mechanics": self.mechanics, "osmobulge_version": __version__}
        return out


def analyze_instantaneous(
    observations,
    material,
    *,
    method: str = "spline",
    mechanics: str = "hyperelastic",
    lambda_pre=1.0,
    edges=None,
    per_bin: int | None = None,
    fit_to: str = "bins",
    direct: bool = True,
    direct_options: dict | None = None,
    **rate_options,
) -> InstantaneousAnalysis:
    r"""Instantaneous permeability of several chambers, binned, and Eqn 27 fitted two ways.

    Parameters
    ----------
    observations : sequence
        ``(chamber, t, volume_ratio[, label])`` tuples or datasets, see
        :func:`as_observations`.
    material : Material or LinearElastic
    method : {"bins", "savgol", "spline"}
        Rate estimator (:func:`volume_rates`).
    mechanics : {"hyperelastic", "linear"}
    lambda_pre : float or callable
    edges, per_bin
        Stretch binning, see :func:`bin_by_stretch`.
    fit_to : {"bins", "values"}
        Fit Eqn 27 to the bin means (weights 1/standard error, as the paper's
        Fig. 6a points) or to every value (relative weights).
    direct : bool
        Also fit Eqn 27 through the ODE to all curves at once
        (:func:`osmobulge.modeling.fitting.fit_permeability`).
    direct_options : dict, optional
        Extra keyword arguments of ``fit_permeability``.
    **rate_options
        Options of :func:`volume_rates`.

    Returns
    -------
    InstantaneousAnalysis

    Notes
    -----
    Main text Sec. 3.7, Eqns 25-27 and Fig. 6a; supplement Sec. 7.3.
    """
    if fit_to not in _FIT_TO:
        raise ValueError(f"fit_to must be one of {_FIT_TO}, got {fit_to!r}")
    obs = as_observations(observations)
    values = tuple(
        instantaneous_permeability(c, material, t, v, method=method, mechanics=mechanics, lambda_pre=lambda_pre,
                                   label=label, **rate_options)
        for c, t, v, label in obs
    )
    binned = bin_by_stretch(values, edges=edges, per_bin=per_bin)
    if fit_to == "bins":
        sem = binned["permeability_sem"].values
        p = binned["permeability"].values
        # bins of identical values (noise-free data) have sem 0: fall back to 1 % relative
        sig = np.where(np.isfinite(sem) & (sem > 1e-3 * np.abs(p)), sem, 1e-2 * np.abs(p))
        fit = fit_eqn27(binned["lambda_bar"].values, p, sigma=sig)
        fit = Eqn27Fit(**{**fit.__dict__, "source": "bins"})
    else:
        lam = np.concatenate([v["lambda_bar"].values for v in values])
        pw = np.concatenate([v["permeability"].values for v in values])
        fit = fit_eqn27(lam, pw)
    direct_result, direct_error = None, ""
    if direct:
        try:
            from osmobulge.modeling.fitting import fit_permeability
        except ImportError as err:  # pragma: no cover - depends on the fitting module being present
            direct_error = f"osmobulge.modeling.fitting is not available: {err}"
        else:
            opts = {"mechanics": mechanics} | dict(direct_options or {})
            if not (isinstance(lambda_pre, float | int) and float(lambda_pre) == 1.0):
                opts.setdefault("lambda_pre", lambda_pre)
            direct_result = fit_permeability([(c, t, v) for c, t, v, _ in obs], material,
                                             model="double_exponential", **opts)
    return InstantaneousAnalysis(values=values, binned=binned, eqn27=fit, direct=direct_result,
                                 direct_error=direct_error, method=method, mechanics=mechanics)


# --------------------------------------------------------------------------- Fig. 4


def dimensionless_collapse(observations, material, *, permeability=2e-12, mechanics="hyperelastic",
                           lambda_pre=1.0) -> xr.Dataset:
    r"""Volume ratio, membrane geometry and driving force against dimensionless time (Fig. 4).

    Parameters
    ----------
    observations : sequence
        ``(chamber, t, volume_ratio[, label])`` tuples or datasets (see
        :func:`as_observations`), e.g. curves simulated with a constant
        :math:`P_w` as in Fig. 4a, or measured curves (supplement Fig. S7a).
    material : Material or LinearElastic
    permeability : float, m**2/s
        :math:`P_w` of the time constant :math:`\tau` (Eqn 9); the paper uses
        :math:`2\times 10^{-12}`.
    mechanics : {"hyperelastic", "linear"}
    lambda_pre : float or callable

    Returns
    -------
    xarray.Dataset
        Over ``(chamber, sample)``, NaN-padded: ``t_tilde`` (:math:`t/\tau`),
        ``volume_ratio``, ``geometry`` (:math:`f_A f_l`), ``driving_force``
        (:math:`(\Pi + P_t)/\Pi_0`), ``lambda_bar``; over ``chamber``: ``tau`` (s),
        ``label``.

    Notes
    -----
    Main text Eqns 9-10 and Fig. 4; supplement Fig. S7a.
    """
    obs = as_observations(observations)
    p = float(permeability)
    if not math.isfinite(p) or p <= 0:
        raise ValueError(f"permeability must be finite and > 0 (m^2/s), got {permeability!r}")
    mech = mechanics_model(material, lambda_pre, mechanics)
    n = max(t.size for _, t, _, _ in obs)
    shape = (len(obs), n)
    out = {k: np.full(shape, np.nan) for k in ("t_tilde", "volume_ratio", "geometry", "driving_force", "lambda_bar")}
    taus, labels = [], []
    for i, (c, t, v, label) in enumerate(obs):
        tau = time_constant(c, p)
        _, fa, fl, lam, pt = _mechanics_at(c, mech, v)
        k = t.size
        out["t_tilde"][i, :k] = (t - t[0]) / tau
        out["volume_ratio"][i, :k] = v
        out["geometry"][i, :k] = fa * fl
        out["driving_force"][i, :k] = osmotic_term(v, c.feed_ratio) + pt / c.osmotic_potential
        out["lambda_bar"][i, :k] = lam
        taus.append(tau)
        labels.append(label)
    attrs = {
        "t_tilde": ("1", "dimensionless time t/tau (Eqn 9)"),
        "volume_ratio": ("1", "volume ratio V/V0"),
        "geometry": ("1", "membrane geometry factor f_A f_l"),
        "driving_force": ("1", "driving force (Pi + P_t)/Pi0"),
        "lambda_bar": ("1", "average biaxial stretch"),
    }
    data = {k: (("chamber", "sample"), v, {"units": attrs[k][0], "long_name": attrs[k][1]}) for k, v in out.items()}
    data["tau"] = ("chamber", np.array(taus), {"units": "s", "long_name": "time constant tau (Eqn 9)"})
    ds = xr.Dataset(data, coords={"chamber": np.arange(len(obs)), "label": ("chamber", labels)},
                    attrs={"title": "dimensionless-time collapse", "tau_permeability": p, "mechanics": mechanics})
    return ds


def collapse_spread(collapse: xr.Dataset, *, chambers: Sequence[int] | None = None, t_tilde_max: float = 1.0,
                    n: int = 50) -> float:
    r"""Largest relative spread of :math:`V/V_0` among chambers at equal :math:`t/\tau`.

    Parameters
    ----------
    collapse : xarray.Dataset
        From :func:`dimensionless_collapse`.
    chambers : sequence of int, optional
        Chamber indices compared (default: all).
    t_tilde_max : float
        Compare on :math:`0 < t/\tau \leq` ``t_tilde_max`` (limited to the
        shortest record).
    n : int
        Number of comparison times.

    Returns
    -------
    float
        :math:`\max_t (\max_c V/V_0 - \min_c V/V_0) / \mathrm{mean}_c (V/V_0 - 1)`:
        the spread relative to the mean volume gained.
    """
    idx = list(range(collapse.sizes["chamber"])) if chambers is None else [int(c) for c in chambers]
    if len(idx) < 2:
        raise ValueError("collapse_spread needs at least 2 chambers")
    ends = []
    for c in idx:
        tt = collapse["t_tilde"].values[c]
        ends.append(np.nanmax(tt))
    top = min(float(t_tilde_max), min(ends))
    if not top > 0:
        raise ValueError(f"t_tilde_max must be > 0, got {t_tilde_max!r}")
    grid = np.linspace(top / n, top, int(n))
    curves = []
    for c in idx:
        tt = collapse["t_tilde"].values[c]
        vv = collapse["volume_ratio"].values[c]
        ok = np.isfinite(tt) & np.isfinite(vv)
        curves.append(np.interp(grid, tt[ok], vv[ok]))
    curves = np.array(curves)
    gain = np.mean(curves, axis=0) - 1.0
    return float(np.max(np.ptp(curves, axis=0) / np.maximum(gain, 1e-12)))
