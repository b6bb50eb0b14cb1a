r"""Permeability fits through the flux ODE (main text Sec. 3.6-3.7, supplement Sec. 7).

:func:`fit_permeability` fits a permeability law :math:`P_w(\bar\lambda, l)`
simultaneously to the :math:`V/V_0(t)` curves of several chambers by
nonlinear least squares (lmfit), integrating Eqn 8 for every trial parameter
set.  The integration is a quadrature on a per-chamber grid that is built once
(:class:`osmobulge.modeling.simulate.VolumePath`): a trial law only rescales
the integrand, so one evaluation of 20 chambers x 100 points costs about 10 ms.

Observations
------------
A sequence of either

* tuples ``(chamber, t, volume_ratio)`` with a
  :class:`~osmobulge.modeling.transport.Chamber`, times in s (``t = 0`` is the
  start of actuation, where :math:`V/V_0 = v_0`, default 1) and :math:`V/V_0`; or
* ``xarray.Dataset`` with a ``time`` coordinate (s), a ``volume_ratio``
  variable and the chamber in attrs, SI, under the names of
  :data:`~osmobulge.modeling.transport.CHAMBER_ATTRS`: ``chamber_radius`` (m),
  ``chamber_depth`` (m), ``membrane_thickness`` (m), ``concentration``
  (mol/m**3), and optionally ``feed_concentration`` (mol/m**3), ``temperature``
  (K), ``vant_hoff``; optional ``v0`` (initial :math:`V/V_0`) and ``name``.
  :func:`~osmobulge.modeling.simulate.simulate` writes exactly these.

Models
------
``"constant"``, ``"double_exponential"`` (Eqn 27), ``"firpo"`` (Eqn 26, of the
mean thickness :math:`l_0/f_l`), or any :class:`lmfit.Model` whose independent
variables are among ``lambda_bar`` and ``thickness`` (m), passed directly or
registered by name with :func:`register_model`.  Positive scale constants are
fitted as logarithms (see :mod:`osmobulge.modeling.permeability`).
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field

import lmfit
import numpy as np
import xarray as xr
from scipy.optimize import minimize_scalar
from scipy.stats import norm

from osmobulge import __version__
from osmobulge.modeling.permeability import ConstantPermeabilityModel, DoubleExponentialModel, FirpoModel
from osmobulge.modeling.simulate import VolumePath
from osmobulge.modeling.transport import (
    CHAMBER_ATTRS,
    MECHANICS_KINDS,
    Chamber,
    mechanics_model,
    vtilde_from_volume_ratio,
)

__all__ = [
    "fit_permeability",
    "PermeabilityFit",
    "FitObservation",
    "FitError",
    "register_model",
    "registered_models",
    "NAN_POLICIES",
    "ERROR_MODELS",
    "CI_METHODS",
    "WINDOW_KEYS",
]

NAN_POLICIES = ("raise", "omit")
ERROR_MODELS = ("relative", "absolute")
CI_METHODS = ("covariance", "profile")
ERRORS = ("raise", "flag")
WINDOW_KEYS = ("volume_ratio_max", "lambda_bar_max", "vtilde_max", "time_max")
_INDEPENDENT = ("lambda_bar", "thickness")
_SIGMAS = (1, 2)
_PENALTY = 1e3  # residual for non-physical trial laws (P_w <= 0 or not finite)


class FitError(RuntimeError):
    """A permeability fit did not converge or its uncertainties could not be estimated."""


# ---------------------------------------------------------------------------
# Model registry
# ---------------------------------------------------------------------------
_REGISTRY = {
    "constant": ConstantPermeabilityModel,
    "double_exponential": DoubleExponentialModel,
    "firpo": FirpoModel,
}


def _instantiate(family):
    if isinstance(family, lmfit.Model):
        return family
    if callable(family):
        obj = family()
        if isinstance(obj, lmfit.Model):
            return obj
    raise TypeError(f"a permeability family must be an lmfit.Model or a factory of one, got {family!r}")


def _check_family(model: lmfit.Model) -> lmfit.Model:
    bad = [v for v in model.independent_vars if v not in _INDEPENDENT]
    if bad or not model.independent_vars:
        raise ValueError(
            f"a permeability family's independent variables must be among {_INDEPENDENT}, got "
            f"{model.independent_vars!r}"
        )
    return model


def register_model(name: str, family, *, overwrite: bool = False) -> None:
    """Register a permeability family for ``fit_permeability(model=name)``.

    Parameters
    ----------
    name : str
    family : lmfit.Model or callable returning one
        Independent variables among ``lambda_bar`` and ``thickness`` (m); returns
        m**2/s.  Its ``make_params()`` (hints) give the starting values unless it has a
        ``guess(data, lambda_bar=..., thickness=...)`` method.
    overwrite : bool
        Replace an existing registration (built-in names cannot be replaced).

    Examples
    --------
    >>> import lmfit
    >>> def linear_law(lambda_bar, p0, slope):
    ...     return p0 * (1 + slope * (lambda_bar - 1))
    >>> m = lmfit.Model(linear_law, independent_vars=["lambda_bar"])
    >>> m.set_param_hint("p0", value=2e-12, min=0)
    >>> register_model("linear_in_stretch", m)
    >>> "linear_in_stretch" in registered_models()
    True
    """
    name = str(name)
    if name in ("constant", "double_exponential", "firpo"):
        raise ValueError(f"{name!r} is a built-in permeability model and cannot be replaced")
    if name in _REGISTRY and not overwrite:
        raise ValueError(f"a permeability model {name!r} is already registered (pass overwrite=True)")
    _check_family(_instantiate(family))
    _REGISTRY[name] = family


def registered_models() -> tuple:
    """Names accepted by ``fit_permeability(model=...)``."""
    return tuple(_REGISTRY)


def _get_family(model):
    if isinstance(model, str):
        if model not in _REGISTRY:
            raise ValueError(f"model must be one of {registered_models()} or an lmfit.Model, got {model!r}")
        return model, _check_family(_instantiate(_REGISTRY[model]))
    fam = _check_family(_instantiate(model))
    return getattr(fam, "name", None) or fam.__class__.__name__, fam


# ---------------------------------------------------------------------------
# Observations
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class FitObservation:
    """One chamber's data as used by a fit (after cleaning and windowing).

    Attributes
    ----------
    chamber : Chamber
    time : ndarray of shape (K,), s
    volume_ratio : ndarray of shape (K,)
        Observed :math:`V/V_0`.
    fitted : ndarray of shape (K,)
        Model :math:`V/V_0` at ``time`` (NaN if the fit failed).
    residual : ndarray of shape (K,)
        ``fitted - volume_ratio``.
    weight : ndarray of shape (K,)
        Weights the residuals were multiplied by in the fit.
    name : str
    v0 : float
        :math:`V/V_0` at ``t = 0``.
    n_dropped : int
        Points removed by ``nan_policy="omit"`` or the window.
    """

    chamber: Chamber
    time: np.ndarray = field(repr=False)
    volume_ratio: np.ndarray = field(repr=False)
    fitted: np.ndarray = field(repr=False)
    residual: np.ndarray = field(repr=False)
    weight: np.ndarray = field(repr=False)
    name: str = ""
    v0: float = 1.0
    n_dropped: int = 0


def _as_raw(obs, index):
    """(chamber, t, v, name, v0) from a tuple or a Dataset."""
    if isinstance(obs, xr.Dataset):
        if "volume_ratio" not in obs or "time" not in obs.coords:
            raise ValueError(f"observation {index}: a Dataset needs a 'time' coordinate (s) and 'volume_ratio'")
        units = obs["time"].attrs.get("units", "s")
        if units not in ("s", "second", "seconds"):
            raise ValueError(f"observation {index}: time must be in s, got units={units!r}")
        try:
            chamber = Chamber.from_attrs(obs.attrs)
        except ValueError as err:
            raise ValueError(f"observation {index}: {err}") from None
        return (chamber, np.asarray(obs["time"].values, float), np.asarray(obs["volume_ratio"].values, float),
                str(obs.attrs.get("name", f"chamber {index}")), float(obs.attrs.get("v0", 1.0)))
    try:
        chamber, t, v = obs
    except (TypeError, ValueError):
        raise TypeError(
            f"observation {index} must be (chamber, t_seconds, volume_ratio) or an xarray.Dataset, got "
            f"{type(obs).__name__}") from None
    if not isinstance(chamber, Chamber):
        raise TypeError(f"observation {index}: the first item must be a Chamber, got {type(chamber).__name__}")
    return chamber, np.asarray(t, float).ravel(), np.asarray(v, float).ravel(), f"chamber {index}", 1.0


def _clean(index, t, v, w, nan_policy):
    if t.shape != v.shape:
        raise ValueError(f"observation {index}: time and volume_ratio differ in length ({t.size} vs {v.size})")
    keep = np.ones(t.shape, bool)
    bad = ~(np.isfinite(t) & np.isfinite(v))
    if w is not None:
        bad |= ~np.isfinite(w)
    if bad.any():
        if nan_policy == "raise":
            raise ValueError(
                f"observation {index}: {int(bad.sum())} NaN/inf value(s) in time or volume_ratio; "
                "clean the data or pass nan_policy='omit' to drop them")
        keep &= ~bad
    neg = keep & (t < 0)
    if neg.any():
        if nan_policy == "raise":
            raise ValueError(f"observation {index}: times must be >= 0 s (t = 0 is the start of actuation)")
        keep &= ~neg
    # strictly increasing times
    tk = np.where(keep, t, -np.inf)
    running = np.maximum.accumulate(np.concatenate([[-np.inf], tk[:-1]]))
    nonmono = keep & (t <= running)
    if nonmono.any():
        if nan_policy == "raise":
            i = int(np.flatnonzero(nonmono)[0])
            raise ValueError(
                f"observation {index}: times must be strictly increasing; t[{i}]={t[i]!r} s is not after the "
                "earlier points (sort the data, or pass nan_policy='omit' to drop such points)")
        keep &= ~nonmono
    if np.any(v[keep] <= 0):
        raise ValueError(f"observation {index}: volume_ratio must be > 0")
    return keep


def _window_mask(window, t, v, chamber, mech):
    keep = np.ones(t.shape, bool)
    if not window:
        return keep
    if "time_max" in window:
        keep &= t <= float(window["time_max"])
    if "volume_ratio_max" in window:
        keep &= v <= float(window["volume_ratio_max"])
    vt = vtilde_from_volume_ratio(v, chamber)
    if "vtilde_max" in window:
        keep &= vt <= float(window["vtilde_max"])
    if "lambda_bar_max" in window:
        vt_c = np.clip(vt, 0.0, mech.vtilde_max if math.isfinite(mech.vtilde_max) else np.inf)
        lam = np.asarray(mech.lambda_bar(vt_c), float).reshape(vt.shape)
        lam = np.where(vt > mech.vtilde_max, np.inf, lam)
        keep &= lam <= float(window["lambda_bar_max"])
    return keep


def _check_window(window):
    if window is None:
        return {}
    if not isinstance(window, dict):
        raise TypeError(f"window must be a dict with keys among {WINDOW_KEYS}, got {type(window).__name__}")
    bad = [k for k in window if k not in WINDOW_KEYS]
    if bad:
        raise ValueError(f"window keys must be among {WINDOW_KEYS}, got {bad}")
    out = {}
    for k, val in window.items():
        x = float(val)
        if not math.isfinite(x) or x <= 0:
            raise ValueError(f"window[{k!r}] must be finite and > 0, got {val!r}")
        out[k] = x
    return out


# ---------------------------------------------------------------------------
# The result
# ---------------------------------------------------------------------------
def _json(x):
    if isinstance(x, dict):
        return {str(k): _json(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_json(v) for v in x]
    if isinstance(x, bool | np.bool_):
        return bool(x)
    if isinstance(x, int | np.integer):
        return int(x)
    if isinstance(x, float | np.floating):
        return float(x) if math.isfinite(x) else None
    if x is None or isinstance(x, str):
        return x
    return str(x)


@dataclass(frozen=True)
class PermeabilityFit:
    """Result of :func:`fit_permeability` (frozen; falsy if the fit failed).

    Attributes
    ----------
    model : str
        Family name.
    params : dict of str to float
        Best-fit values of all parameters (free ``ln_*`` and derived physical ones),
        NaN if the fit failed.
    stderr : dict of str to float
        Standard errors (covariance scaled by the reduced chi-square), NaN if unavailable.
    ci : dict of str to list of (float, float)
        Confidence limits as lmfit's ``conf_interval`` lays them out:
        ``[(0.9545, lo2), (0.6827, lo1), (0.0, best), (0.6827, hi1), (0.9545, hi2)]``.
        ``ci_method="covariance"``: best +- z stderr (normal approximation) for every
        parameter; ``"profile"``: lmfit's profile-likelihood ``conf_interval`` for the
        free parameters (derived ones then use the covariance).
    p_at_rest, p_at_rest_stderr : float, m**2/s
        :math:`P_w(\\bar\\lambda = 1, l = l_0)` of the first chamber and its standard error (delta method).
    success : bool
    message : str
    observations : tuple of FitObservation
        The data used, with fitted curves and residuals.
    """

    model: str
    params: dict
    stderr: dict
    ci: dict
    ci_method: str
    var_names: tuple
    covariance: np.ndarray | None = field(repr=False, compare=False)
    success: bool = True
    message: str = ""
    nfev: int = 0
    n_ode_solves: int = 0
    chisqr: float = math.nan
    redchi: float = math.nan
    aic: float = math.nan
    bic: float = math.nan
    ndata: int = 0
    nvarys: int = 0
    p_at_rest: float = math.nan
    p_at_rest_stderr: float = math.nan
    mechanics: str = "hyperelastic"
    material: object = field(default=None, repr=False)
    lambda_pre: object = 1.0
    window: tuple = ()
    error_model: str = "relative"
    elapsed: float = math.nan
    observations: tuple = field(default=(), repr=False, compare=False)
    family: lmfit.Model | None = field(default=None, repr=False, compare=False)
    lmfit_result: object = field(default=None, repr=False, compare=False)
    _paths: tuple = field(default=(), repr=False, compare=False)

    def __bool__(self):
        return bool(self.success)

    # -- evaluation ---------------------------------------------------------------
    def _lmfit_params(self):
        pars = self.lmfit_result.params if self.lmfit_result is not None else None
        if pars is None:
            raise FitError("the fit has no parameters")
        return pars

    def permeability(self, lambda_bar, thickness=None):
        """Fitted :math:`P_w` (m**2/s) at stretches ``lambda_bar`` (and mean thicknesses, m).

        Parameters
        ----------
        lambda_bar : float or ndarray
        thickness : float or ndarray, m, optional
            Needed by thickness-dependent families (``"firpo"``).

        Returns
        -------
        float or ndarray, m**2/s (NaN if the fit failed)
        """
        lam = np.asarray(lambda_bar, float)
        if not self.success:
            return np.full(lam.shape, np.nan) if lam.ndim else math.nan
        kw = _family_kwargs(self.family, lam, thickness)
        out = np.broadcast_to(np.asarray(self.family.eval(self._lmfit_params(), **kw), float), lam.shape)
        return float(out) if out.ndim == 0 else out.copy()

    def permeability_stderr(self, lambda_bar, thickness=None):
        """Standard error (m**2/s) of :meth:`permeability` by the delta method on the covariance."""
        lam = np.asarray(lambda_bar, float)
        if not self.success or self.covariance is None:
            return np.full(lam.shape, np.nan) if lam.ndim else math.nan
        out = _delta_stderr(self.family, self._lmfit_params(), self.var_names, self.covariance,
                            _family_kwargs(self.family, lam, thickness))
        out = np.broadcast_to(out, lam.shape)
        return float(out) if out.ndim == 0 else out.copy()

    def curve(self, index, t):
        """Fitted :math:`V/V_0` of observation ``index`` at times ``t`` (s); beyond the mechanics' range: NaN."""
        if not self.success:
            return np.full(np.shape(t), np.nan)
        path = self._paths[index]
        pw = _eval_grid(self.family, self._lmfit_params(), path)
        return path.volume_ratio(np.asarray(t, float), pw=pw, beyond="nan")

    # -- reports ----------------------------------------------------------------
    def report(self) -> str:
        """Human-readable report: setup, lmfit's ``fit_report`` (with its at-boundary and
        at-initial-value warnings), :math:`P_w(1)` and per-chamber residuals."""
        lines = [
            f"[[Permeability fit: {self.model}]]",
            f"    mechanics          = {self.mechanics} ({getattr(self.material, 'law', self.material)})",
            f"    lambda_pre         = {self.lambda_pre}",
            f"    window             = {dict(self.window) or 'all data'}",
            f"    error model        = {self.error_model}",
            f"    chambers           = {len(self.observations)}",
            f"    success            = {self.success}",
            f"    message            = {self.message}",
            f"    ODE solves         = {self.n_ode_solves}",
            f"    wall time          = {self.elapsed:.3g} s",
        ]
        if self.lmfit_result is not None:
            lines.append(lmfit.fit_report(self.lmfit_result))
        lines.append("[[Permeability at rest]]")
        lines.append(f"    P_w(lambda_bar=1) = {self.p_at_rest:.6g} +/- {self.p_at_rest_stderr:.3g} m^2/s")
        lines.append(f"[[Confidence intervals ({self.ci_method})]]")
        for name, lim in self.ci.items():
            lo2, lo1, best, hi1, hi2 = (v for _, v in lim)
            lines.append(f"    {name:>20s}: 95.45% [{lo2:.6g}, {hi2:.6g}]  68.27% [{lo1:.6g}, {hi1:.6g}]")
        lines.append("[[Chambers]]")
        for o in self.observations:
            rms = float(np.sqrt(np.mean(o.residual**2))) if o.residual.size else math.nan
            lines.append(
                f"    {o.name}: a={o.chamber.radius * 1e6:.4g} um, h={o.chamber.depth * 1e6:.4g} um, "
                f"l0={o.chamber.thickness * 1e6:.4g} um, C0={o.chamber.concentration / 1000:.4g} M: "
                f"{o.time.size} points, rms residual {rms:.3g}")
        return "\n".join(lines)

    def summary(self) -> dict:
        """JSON-safe dict of plain types (NaN -> None)."""
        params = {}
        for name, val in self.params.items():
            entry = {"value": val, "stderr": self.stderr.get(name, math.nan),
                     "vary": name in self.var_names}
            if name in self.ci:
                entry["ci"] = [list(x) for x in self.ci[name]]
            params[name] = entry
        chambers = []
        for o in self.observations:
            chambers.append({
                "name": o.name, **o.chamber.to_attrs(), "v0": o.v0, "n_points": int(o.time.size),
                "n_dropped": o.n_dropped,
                "rms_residual": float(np.sqrt(np.mean(o.residual**2))) if o.residual.size else math.nan,
            })
        return _json({
            "model": self.model, "mechanics": self.mechanics,
            "material": getattr(self.material, "law", str(self.material)),
            "material_constants": getattr(self.material, "constants", {}),
            "lambda_pre": self.lambda_pre if isinstance(self.lambda_pre, float | int) else repr(self.lambda_pre),
            "window": dict(self.window), "error_model": self.error_model,
            "success": self.success, "message": self.message, "nfev": self.nfev,
            "n_ode_solves": self.n_ode_solves, "chisqr": self.chisqr, "redchi": self.redchi,
            "aic": self.aic, "bic": self.bic, "ndata": self.ndata, "nvarys": self.nvarys,
            "ci_method": self.ci_method, "params": params,
            "p_at_rest": {"value": self.p_at_rest, "stderr": self.p_at_rest_stderr, "units": "m^2/s"},
            "chambers": chambers, "elapsed_s": self.elapsed, "osmobulge_version": __version__,
        })

    def to_dataset(self) -> xr.Dataset:
        """The fit as an ``xarray.Dataset``.

        Dims ``point`` (all data points, chamber after chamber), ``chamber`` and ``param``:
        ``time``, ``volume_ratio``, ``fitted``, ``residual``, ``weight``, ``chamber_index``
        over ``point``; the chamber fields (``chamber_radius``...) over ``chamber``;
        ``modelfit_coefficients`` and ``modelfit_stderr`` over ``param``.  Attrs are
        netCDF-safe.
        """
        obs = self.observations
        idx = np.concatenate([np.full(o.time.size, i) for i, o in enumerate(obs)]) if obs else np.zeros(0, int)

        def cat(attr):
            return np.concatenate([getattr(o, attr) for o in obs]) if obs else np.zeros(0)

        names = list(self.params)
        data = {
            "time": ("point", cat("time"), {"units": "s", "long_name": "time"}),
            "volume_ratio": ("point", cat("volume_ratio"), {"units": "1", "long_name": "observed V/V0"}),
            "fitted": ("point", cat("fitted"), {"units": "1", "long_name": "fitted V/V0"}),
            "residual": ("point", cat("residual"), {"units": "1", "long_name": "fitted - observed V/V0"}),
            "weight": ("point", cat("weight"), {"units": "1", "long_name": "residual weight in the fit"}),
            "chamber_index": ("point", idx, {"units": "1", "long_name": "index of the chamber"}),
            "modelfit_coefficients": ("param", np.array([self.params[n] for n in names], float),
                                      {"long_name": "best-fit parameters (SI)"}),
            "modelfit_stderr": ("param", np.array([self.stderr.get(n, math.nan) for n in names], float),
                                {"long_name": "standard errors of the parameters (SI)"}),
        }
        for fname, (attr, unit, desc) in CHAMBER_ATTRS.items():
            data[attr] = ("chamber", np.array([getattr(o.chamber, fname) for o in obs], float),
                          {"units": unit, "long_name": desc})
        attrs = {
            "model": self.model, "mechanics": self.mechanics, "success": int(self.success),
            "message": self.message, "chisqr": float(self.chisqr), "redchi": float(self.redchi),
            "ndata": int(self.ndata), "nvarys": int(self.nvarys), "p_at_rest": float(self.p_at_rest),
            "p_at_rest_stderr": float(self.p_at_rest_stderr), "error_model": self.error_model,
            "ci_method": self.ci_method, "material_law": str(getattr(self.material, "law", self.material)),
            "window": repr(dict(self.window)), "osmobulge_version": __version__,
        }
        return xr.Dataset(data, coords={"param": ("param", names), "chamber_name": ("chamber", [o.name for o in obs])},
                          attrs=attrs)


# ---------------------------------------------------------------------------
# Internals
# ---------------------------------------------------------------------------
def _family_kwargs(family, lam, thickness):
    kw = {}
    if "lambda_bar" in family.independent_vars:
        kw["lambda_bar"] = lam
    if "thickness" in family.independent_vars:
        if thickness is None:
            raise ValueError(f"the {family.name} permeability depends on thickness: pass thickness= (m)")
        kw["thickness"] = np.broadcast_to(np.asarray(thickness, float), np.shape(lam))
    return kw


def _eval_grid(family, params, path):
    kw = _family_kwargs(family, path.lambda_bar, path.thickness)
    return np.broadcast_to(np.asarray(family.eval(params, **kw), float), path.v.shape)


def _delta_stderr(family, params, var_names, cov, kw):
    """Standard error of family(params) by the delta method (central differences in the free parameters)."""
    work = params.copy()
    grads = []
    for name in var_names:
        x = params[name].value
        h = 1e-6 * max(abs(x), 1.0)
        vals = []
        for xv in (x + h, x - h):
            work[name].value = xv
            work.update_constraints()
            vals.append(np.asarray(family.eval(work, **kw), float))
        work[name].value = x
        grads.append((vals[0] - vals[1]) / (2 * h))
    work.update_constraints()
    jac = np.stack(np.broadcast_arrays(*grads), axis=-1)
    var = np.einsum("...i,ij,...j->...", jac, cov, jac)
    return np.sqrt(np.maximum(var, 0.0))


def _best_constant(paths, data, masks=None):
    """Best constant permeability (m**2/s) by a 1-D search, using v(t; P) = v(P t; 1)."""
    curves = []
    for k, (path, (t, v, w)) in enumerate(zip(paths, data, strict=True)):
        m = slice(None) if masks is None else masks[k]
        if t[m].size == 0:
            continue
        spline = path.interpolant(np.ones(path.v.shape))
        curves.append((spline, spline.x[-1], path.v_end, t[m], v[m], w[m]))

    def cost(lnp):
        p = math.exp(lnp)
        total = 0.0
        for spline, t_end, v_end, t, v, w in curves:
            tt = p * t
            model = np.where(tt <= t_end, spline(np.minimum(tt, t_end)), v_end)
            total += float(np.sum(((model - v) * w) ** 2))
        return total

    grid = np.linspace(math.log(1e-17), math.log(1e-8), 91)
    costs = [cost(g) for g in grid]
    k = int(np.argmin(costs))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    res = minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-6})
    return math.exp(res.x)


def _profile_1d(residual, result, probs):
    """Profile-likelihood limits of a single free parameter with lmfit's F-test."""
    from scipy.optimize import brentq
    from scipy.stats import f as f_dist

    name = result.var_names[0]
    best = result.params[name].value
    se = result.params[name].stderr
    pars = result.params.copy()
    ndata, chi0 = result.ndata, result.chisqr

    def prob(x):
        pars[name].value = x
        pars.update_constraints()
        chi = float(np.sum(residual(pars) ** 2))
        return f_dist.cdf(max(chi / chi0 - 1.0, 0.0) * (ndata - 1), 1, ndata - 1)

    lims = {}
    for side in (-1, 1):
        for sigma, level in probs.items():
            step = se * sigma
            x = best + side * step
            for _ in range(30):  # widen until the level is passed
                if prob(x) >= level:
                    break
                step *= 2.0
                x = best + side * step
            lims[(side, sigma)] = brentq(lambda x, lv=level: prob(x) - lv, best, x, xtol=1e-10 * max(abs(best), 1))
    out = [(probs[2], lims[(-1, 2)]), (probs[1], lims[(-1, 1)]), (0.0, best),
           (probs[1], lims[(1, 1)]), (probs[2], lims[(1, 2)])]
    return {name: out}


def _starts(family, paths, data, user_params):
    """Starting parameter sets: the user's, the family's ``fit_starts``, its ``guess`` or its hints."""
    if user_params is not None:
        missing = [n for n in family.param_names if n not in user_params]
        if missing:
            raise ValueError(f"params lacks {missing} of the {family.name} model")
        return [user_params.copy()]
    p_mean = _best_constant(paths, data)
    # the small-deflection permeability: points with V/V0 <= 1.3, else each curve's first 3
    masks = [v <= 1.3 for (_t, v, _w) in data]
    if sum(int(m.sum()) for m in masks) < 3:
        masks = [np.arange(v.size) < 3 for (_t, v, _w) in data]
    p_rest = _best_constant(paths, data, masks)
    l0 = paths[0].chamber.thickness
    if hasattr(family, "fit_starts"):
        return list(family.fit_starts(p_rest, p_mean, l0))
    if hasattr(family, "guess"):
        kw = {}
        if "lambda_bar" in family.independent_vars:
            kw["lambda_bar"] = np.linspace(1.0, 3.0, 21)
        if "thickness" in family.independent_vars:
            kw["thickness"] = np.linspace(l0 / 9, l0, 21)
        try:
            return [family.guess(np.full(21, p_mean), **kw)]
        except Exception:  # noqa: BLE001 - a user guess() unable to handle flat data: use the hints
            pass
    return [family.make_params()]


def fit_permeability(observations, material, *, model="constant", mechanics="hyperelastic", lambda_pre=1.0,
                     window=None, nan_policy="raise", weights=None, error_model="relative", params=None,
                     ci_method="covariance", errors="raise", method="leastsq", max_nfev=2000,
                     n_grid=401) -> PermeabilityFit:
    r"""Fit a permeability law to :math:`V/V_0(t)` of several chambers at once through Eqn 8.

    Parameters
    ----------
    observations : sequence of (Chamber, ndarray, ndarray) or of xarray.Dataset
        ``(chamber, t_seconds, volume_ratio)`` or Datasets as described in the module
        docs (``time`` in s, ``volume_ratio``, chamber attrs in SI).
    material : Material or LinearElastic
        Membrane law (``materials.PDMS``...); ``mechanics="linear"`` uses ``material.E``.
    model : str or lmfit.Model
        ``"constant"``, ``"double_exponential"``, ``"firpo"``, a name given to
        :func:`register_model`, or an :class:`lmfit.Model` of ``lambda_bar`` / ``thickness``.
    mechanics : {"hyperelastic", "linear"}
    lambda_pre : float or callable or sequence
        Rim pre-stretch; a sequence gives one per observation.
    window : dict, optional
        Keep only points with ``volume_ratio_max``, ``lambda_bar_max`` (of the chosen
        mechanics), ``vtilde_max`` or ``time_max`` (s) not exceeded, e.g.
        ``{"volume_ratio_max": 1.3}`` for the small-deflection linear fit (Sec. 3.6.1).
    nan_policy : {"raise", "omit"}
        NaN/inf values, negative or non-increasing times: raise ``ValueError``, or drop
        those points.
    weights : sequence of ndarray, optional
        Per-observation weights multiplying the residuals (e.g. 1/sigma);
        overrides ``error_model``.
    error_model : {"relative", "absolute"}
        Residuals ``(model - data)/data`` (multiplicative noise, default) or ``model - data``.
    params : lmfit.Parameters, optional
        Starting values (default: the family's ``guess`` from the best constant fit).
    ci_method : {"covariance", "profile"}
        How :attr:`PermeabilityFit.ci` is computed.
    errors : {"raise", "flag"}
        A fit that does not converge, or whose covariance cannot be estimated, raises
        :class:`FitError`, or returns a falsy result with ``success=False`` and NaN
        parameters.
    method : str
        lmfit method (default ``"leastsq"``, Levenberg-Marquardt).
    max_nfev : int
        Limit of residual evaluations.
    n_grid : int
        Quadrature resolution per chamber (401: relative error ~1e-6 in V/V0).

    Returns
    -------
    PermeabilityFit

    Raises
    ------
    ValueError
        Bad options or data (NaN, non-monotone or negative times with
        ``nan_policy="raise"``, too few points after windowing).
    FitError
        With ``errors="raise"``, a failed fit.

    Notes
    -----
    Each residual evaluation integrates Eqn 8 for every chamber by quadrature
    (:class:`~osmobulge.modeling.simulate.VolumePath`).  Data points after the model
    leaves the mechanics' range get the range-end volume (a large residual), so a
    trial law that runs into Gent locking too early is penalised, not an error.
    Standard errors scale the covariance by the reduced chi-square (lmfit's
    ``scale_covar=True``).

    Examples
    --------
    >>> import numpy as np
    >>> from osmobulge.modeling.materials import PDMS
    >>> from osmobulge.modeling.simulate import simulate
    >>> from osmobulge.modeling.transport import paper_chamber
    >>> ds = simulate(paper_chamber(), PDMS, 2e-12, np.arange(0, 7200.0, 300.0), mechanics="linear")
    >>> fit = fit_permeability([ds], PDMS, mechanics="linear")
    >>> f"{fit.params['p']:.4e}"
    '2.0000e-12'
    """
    t_start = _time.perf_counter()
    if mechanics not in MECHANICS_KINDS:
        raise ValueError(f"mechanics must be one of {MECHANICS_KINDS}, got {mechanics!r}")
    if nan_policy not in NAN_POLICIES:
        raise ValueError(f"nan_policy must be one of {NAN_POLICIES}, got {nan_policy!r}")
    if error_model not in ERROR_MODELS:
        raise ValueError(f"error_model must be one of {ERROR_MODELS}, got {error_model!r}")
    if ci_method not in CI_METHODS:
        raise ValueError(f"ci_method must be one of {CI_METHODS}, got {ci_method!r}")
    if errors not in ERRORS:
        raise ValueError(f"errors must be one of {ERRORS}, got {errors!r}")
    win = _check_window(window)
    name, family = _get_family(model)
    if isinstance(observations, xr.Dataset) or (isinstance(observations, tuple) and len(observations) == 3
                                                  and isinstance(observations[0], Chamber)):
        observations = [observations]
    observations = list(observations)
    if not observations:
        raise ValueError("observations is empty")
    if weights is not None:
        weights = list(weights)
        if len(weights) != len(observations):
            raise ValueError(f"weights must have one array per observation ({len(observations)}), got {len(weights)}")
    if isinstance(lambda_pre, list | tuple):
        if len(lambda_pre) != len(observations):
            raise ValueError(f"lambda_pre must be one value or one per observation ({len(observations)})")
        pre = list(lambda_pre)
    else:
        pre = [lambda_pre] * len(observations)

    # -- data, mechanics and quadrature paths ----------------------------------------
    mechs = {}
    paths, data, kept = [], [], []
    for i, obs in enumerate(observations):
        chamber, t, v, oname, v0 = _as_raw(obs, i)
        w_raw = None
        if weights is not None:
            w_raw = np.asarray(weights[i], float).ravel()
            if w_raw.shape != t.shape:
                raise ValueError(f"weights[{i}] has {w_raw.size} values for {t.size} points")
        keep = _clean(i, t, v, w_raw, nan_policy)
        key = repr(pre[i]) if callable(pre[i]) else float(pre[i])
        if key not in mechs:
            mechs[key] = mechanics_model(material, pre[i], mechanics)
        mech = mechs[key]
        keep &= _window_mask(win, t, v, chamber, mech)
        n_dropped = int((~keep).sum())
        t, v = t[keep], v[keep]
        if t.size == 0:
            continue
        w = w_raw[keep] if w_raw is not None else (1.0 / v if error_model == "relative" else np.ones_like(v))
        paths.append(VolumePath(chamber, mech, v0, n=n_grid))
        data.append((t, v, w))
        kept.append((chamber, oname, v0, n_dropped))
    if not paths:
        raise ValueError(f"no data left after cleaning and windowing (window={win})")
    ndata = sum(d[0].size for d in data)

    # -- parameters -------------------------------------------------------------------
    starts = _starts(family, paths, data, params)
    nvary = sum(1 for p in starts[0].values() if p.vary and not p.expr)
    if ndata <= nvary:
        raise ValueError(f"{ndata} data points cannot determine {nvary} parameters")

    # one evaluation of the family per residual call on all grids at once
    splits = np.cumsum([p.v.size for p in paths])[:-1]
    lam_all = np.concatenate([p.lambda_bar for p in paths])
    thick_all = np.concatenate([p.thickness for p in paths])
    kw_all = _family_kwargs(family, lam_all, thick_all)
    solves = [0]

    def residual(pars_):
        pw_all = np.broadcast_to(np.asarray(family.eval(pars_, **kw_all), float), lam_all.shape)
        out = []
        if not np.all(np.isfinite(pw_all)) or np.any(pw_all <= 0):
            return np.full(ndata, _PENALTY)
        for path, pw, (t, v, w) in zip(paths, np.split(pw_all, splits), data, strict=True):
            solves[0] += 1
            out.append((path.volume_ratio(t, pw=pw, beyond="clip") - v) * w)
        return np.concatenate(out)

    # every start; keep the best converged one with uncertainties
    minimizer = result = None
    nfev = 0
    for start in starts:
        mz = lmfit.Minimizer(residual, start, nan_policy="raise", max_nfev=max_nfev)
        res = mz.minimize(method=method)
        nfev += int(res.nfev)
        ok = res.success and getattr(res, "errorbars", False)
        best_ok = result is not None and result.success and getattr(result, "errorbars", False)
        if result is None or (ok and (not best_ok or res.chisqr < result.chisqr)):
            minimizer, result = mz, res

    # -- success checks -----------------------------------------------------------------
    problems = []
    if not result.success:
        problems.append(f"did not converge: {result.message}")
    if not getattr(result, "errorbars", False) or result.covar is None:
        problems.append("the covariance could not be estimated (a parameter at a bound, not identifiable by "
                        "these data, or a singular Jacobian)")
    resid_final = residual(result.params)
    if np.all(resid_final == _PENALTY):
        problems.append("the best parameters give a non-physical permeability")
    success = not problems
    message = "; ".join(problems) if problems else str(result.message)
    if not success and errors == "raise":
        raise FitError(f"{name} permeability fit failed: {message}\n" + lmfit.fit_report(result))

    # -- collect ------------------------------------------------------------------------
    values = {n: (float(p.value) if success else math.nan) for n, p in result.params.items()}
    stderr = {n: (float(p.stderr) if success and p.stderr is not None else math.nan)
              for n, p in result.params.items()}
    cov = np.asarray(result.covar, float) if success else None
    ci = {}
    if success:
        z = {s: float(norm.ppf(0.5 + 0.5 * math.erf(s / math.sqrt(2)))) for s in _SIGMAS}
        probs = {s: math.erf(s / math.sqrt(2)) for s in _SIGMAS}
        for n in values:
            b, se = values[n], stderr[n]
            ci[n] = [(probs[2], b - z[2] * se), (probs[1], b - z[1] * se), (0.0, b),
                     (probs[1], b + z[1] * se), (probs[2], b + z[2] * se)]
        if ci_method == "profile":
            if result.nvarys >= 2:
                prof = lmfit.conf_interval(minimizer, result, sigmas=list(_SIGMAS))
            else:  # lmfit needs two free parameters: same F-test profile, by root finding
                prof = _profile_1d(residual, result, probs)
            for n, lim in prof.items():
                ci[n] = [(float(pr), float(val)) for pr, val in lim]
    first = paths[0].chamber
    kw_rest = _family_kwargs(family, np.array(1.0), first.thickness)
    if success:
        p_rest = float(np.asarray(family.eval(result.params, **kw_rest), float))
        p_rest_se = float(_delta_stderr(family, result.params, tuple(result.var_names), cov, kw_rest))
    else:
        p_rest = p_rest_se = math.nan
    fitted_obs = []
    r_final = np.split(resid_final, np.cumsum([d[0].size for d in data])[:-1])
    for (chamber, oname, v0, n_dropped), (t, v, w), r in zip(kept, data, r_final, strict=True):
        fitted = (v + r / w) if success else np.full_like(v, np.nan)
        fitted_obs.append(FitObservation(chamber=chamber, time=t, volume_ratio=v, fitted=fitted,
                                         residual=fitted - v, weight=w, name=oname, v0=v0, n_dropped=n_dropped))
    return PermeabilityFit(
        model=name, params=values, stderr=stderr, ci=ci, ci_method=ci_method,
        var_names=tuple(result.var_names), covariance=cov, success=success, message=message,
        nfev=nfev, n_ode_solves=solves[0], chisqr=float(result.chisqr), redchi=float(result.redchi),
        aic=float(result.aic), bic=float(result.bic), ndata=int(ndata), nvarys=int(result.nvarys),
        p_at_rest=p_rest, p_at_rest_stderr=p_rest_se, mechanics=mechanics, material=material,
        lambda_pre=lambda_pre if not isinstance(lambda_pre, list | tuple) else tuple(lambda_pre),
        window=tuple(win.items()), error_model=error_model if weights is None else "weights",
        elapsed=_time.perf_counter() - t_start, observations=tuple(fitted_obs), family=family,
        lmfit_result=result, _paths=tuple(paths),
    )
