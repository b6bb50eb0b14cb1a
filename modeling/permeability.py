r"""Water permeability laws :math:`P_w` of a stretched membrane (main text Sec. 3.7).

Three laws, each as a plain function, a small frozen callable class (usable as
the ``permeability`` argument of :func:`osmobulge.modeling.simulate`) and an
:class:`lmfit.Model` with physical parameter hints and ``guess()``:

=====================  ==========================================  ==========================
law                    :math:`P_w` (m**2/s)                        depends on
=====================  ==========================================  ==========================
``Constant(p)``        :math:`p`                                   nothing
``DoubleExponential``  :math:`c_1 e^{c_2\bar\lambda} + c_3 e^{c_4\bar\lambda}` (Eqn 27)   average stretch
``Firpo``              :math:`P_{Henry}\frac{l/L_c}{1 + l/L_c}` (Eqn 26)          mean thickness :math:`l`
=====================  ==========================================  ==========================

A permeability callable takes ``lambda_bar`` (the average biaxial stretch
:math:`\sqrt{A/A_0}`) and, if its signature has a ``thickness`` parameter,
also ``thickness=`` (the mean membrane thickness :math:`l_0/f_l`, m).
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from typing import ClassVar

import lmfit
import numpy as np

__all__ = [
    "constant_permeability",
    "double_exponential",
    "firpo",
    "Constant",
    "DoubleExponential",
    "Firpo",
    "ConstantPermeabilityModel",
    "DoubleExponentialModel",
    "FirpoModel",
    "accepts_thickness",
    "evaluate_permeability",
]


def _out(x):
    x = np.asarray(x, float)
    return float(x) if x.ndim == 0 else x


# ---------------------------------------------------------------------------
# Plain functions
# ---------------------------------------------------------------------------
def constant_permeability(lambda_bar, p):
    """Stretch-independent permeability ``p`` (m**2/s), broadcast to ``lambda_bar``."""
    return _out(np.full(np.shape(lambda_bar), float(p)) if np.ndim(lambda_bar) else float(p))


def double_exponential(lambda_bar, c1, c2, c3, c4):
    r"""Stretch-dependent permeability of main text Eqn 27, m**2/s.

    .. math:: P_w(\bar\lambda) = c_1 e^{c_2\bar\lambda} + c_3 e^{c_4\bar\lambda}

    Parameters
    ----------
    lambda_bar : float or ndarray
        Average biaxial stretch :math:`\sqrt{A/A_0}`.
    c1, c3 : float, m**2/s
    c2, c4 : float
    """
    lam = np.asarray(lambda_bar, float)
    return _out(c1 * np.exp(c2 * lam) + c3 * np.exp(c4 * lam))


def firpo(thickness, p_henry, critical_thickness):
    r"""Thickness-dependent permeability of Firpo et al., main text Eqn 26, m**2/s.

    .. math:: P = P_{Henry}\,\frac{l/L_c}{1 + l/L_c}

    Parameters
    ----------
    thickness : float or ndarray, m
        Membrane thickness :math:`l`.
    p_henry : float, m**2/s
        Permeability when the surface reactions are at equilibrium (thick films).
    critical_thickness : float, m
        :math:`L_c = 2 D_w/k_2`.
    """
    x = np.asarray(thickness, float) / critical_thickness
    return _out(p_henry * x / (1.0 + x))


# ---------------------------------------------------------------------------
# Callable classes
# ---------------------------------------------------------------------------
def _finite(name, value, *, positive=False):
    x = float(value)
    if not math.isfinite(x) or (positive and x <= 0):
        raise ValueError(f"{name} must be finite{' and > 0' if positive else ''}, got {value!r}")
    return x


@dataclass(frozen=True)
class Constant:
    """Constant permeability ``p`` (m**2/s).

    Examples
    --------
    >>> Constant(2e-12)(1.7)
    2e-12
    """

    p: float

    def __post_init__(self):
        object.__setattr__(self, "p", _finite("p", self.p, positive=True))

    def __call__(self, lambda_bar):
        return constant_permeability(lambda_bar, self.p)


@dataclass(frozen=True)
class DoubleExponential:
    r"""Eqn 27, :math:`P_w = c_1 e^{c_2\bar\lambda} + c_3 e^{c_4\bar\lambda}` (m**2/s).

    Parameters
    ----------
    c1, c3 : float, m**2/s
    c2, c4 : float

    Attributes
    ----------
    PDMS, PEO_PDMS : DoubleExponential
        Main text Table 3 (Solaris and PEO-Solaris).

    Examples
    --------
    >>> f"{DoubleExponential.PDMS(1.0):.3e}", f"{DoubleExponential.PEO_PDMS(1.0):.3e}"
    ('1.988e-12', '1.996e-12')
    """

    c1: float
    c2: float
    c3: float
    c4: float
    PDMS: ClassVar[DoubleExponential]
    PEO_PDMS: ClassVar[DoubleExponential]

    def __post_init__(self):
        for name in ("c1", "c2", "c3", "c4"):
            object.__setattr__(self, name, _finite(name, getattr(self, name)))

    def __call__(self, lambda_bar):
        return double_exponential(lambda_bar, self.c1, self.c2, self.c3, self.c4)


DoubleExponential.PDMS = DoubleExponential(2.07e-8, -9.79, 1.13e-12, -0.31)
DoubleExponential.PEO_PDMS = DoubleExponential(4.85e-10, -6.27, 1.33e-12, -0.21)


@dataclass(frozen=True)
class Firpo:
    r"""Eqn 26, :math:`P = P_{Henry}(l/L_c)/(1 + l/L_c)`: a function of the mean thickness.

    Parameters
    ----------
    p_henry : float, m**2/s
    critical_thickness : float, m

    Examples
    --------
    The paper pins Eqn 26 to 1.99e-12 m**2/s at l0 = 20 um (Fig. 6a):

    >>> law = Firpo.through(1.99e-12, thickness=20e-6, critical_thickness=10e-6)
    >>> f"{law.p_henry:.3e}"
    '2.985e-12'
    """

    p_henry: float
    critical_thickness: float

    def __post_init__(self):
        object.__setattr__(self, "p_henry", _finite("p_henry", self.p_henry, positive=True))
        object.__setattr__(
            self, "critical_thickness", _finite("critical_thickness", self.critical_thickness, positive=True)
        )

    def __call__(self, lambda_bar=None, thickness=None):
        if thickness is None:
            raise ValueError("Firpo permeability needs thickness= (mean membrane thickness, m)")
        return firpo(thickness, self.p_henry, self.critical_thickness)

    @classmethod
    def through(cls, permeability, *, thickness, critical_thickness) -> Firpo:
        """The law of critical thickness ``critical_thickness`` (m) through ``permeability`` at ``thickness`` (m)."""
        x = _finite("thickness", thickness, positive=True) / _finite(
            "critical_thickness", critical_thickness, positive=True
        )
        return cls(_finite("permeability", permeability, positive=True) * (1.0 + x) / x, critical_thickness)


# ---------------------------------------------------------------------------
# Evaluation helper used by the ODE
# ---------------------------------------------------------------------------
def accepts_thickness(func) -> bool:
    """True if ``func`` can be called with a ``thickness=`` keyword."""
    try:
        sig = inspect.signature(func)
    except (TypeError, ValueError):
        return False
    return any(
        p.kind == p.VAR_KEYWORD or (p.name == "thickness" and p.kind != p.POSITIONAL_ONLY)
        for p in sig.parameters.values()
    )


def evaluate_permeability(permeability, lambda_bar, thickness=None):
    """Evaluate a permeability (float or callable) on stretches (and mean thicknesses).

    Parameters
    ----------
    permeability : float or callable, m**2/s
        Constant, or ``f(lambda_bar)`` / ``f(lambda_bar, thickness=...)``.
    lambda_bar : float or ndarray
        Average biaxial stretch.
    thickness : float or ndarray, m, optional
        Mean membrane thickness, passed if the callable accepts ``thickness``.

    Returns
    -------
    float or ndarray, m**2/s
        Same shape as ``lambda_bar``.

    Raises
    ------
    ValueError
        Non-finite or non-positive permeabilities.
    """
    lam = np.asarray(lambda_bar, float)
    if callable(permeability):
        if thickness is not None and accepts_thickness(permeability):
            out = permeability(lam, thickness=np.broadcast_to(np.asarray(thickness, float), lam.shape))
        else:
            out = permeability(lam)
        out = np.asarray(out, float)
        if out.shape != lam.shape:
            try:
                out = np.broadcast_to(out, lam.shape).copy()
            except ValueError:
                raise ValueError(
                    f"permeability callable returned shape {out.shape} for lambda_bar of shape {lam.shape}; "
                    "it must be vectorised (numpy) over lambda_bar"
                ) from None
    else:
        out = np.full(lam.shape, float(permeability))
    if np.any(~np.isfinite(out)) or np.any(out <= 0):
        bad = out[~np.isfinite(out) | (out <= 0)].flat[0]
        raise ValueError(f"permeability must be finite and > 0 m^2/s, got {bad!r}")
    return _out(out)


# ---------------------------------------------------------------------------
# lmfit models
# ---------------------------------------------------------------------------
# Permeabilities are ~1e-12 m**2/s.  lmfit's transform for a ``min=0`` bound,
# sqrt((x + 1)**2 - 1), loses every digit of such values, so the positive scale
# constants are fitted as natural logarithms (``ln_*``, free) and the physical
# constants are expressions of them (``min=0`` kept as documentation; stderr
# propagated by lmfit).  This also conditions the problem.
def _set_ln_hint(model, name, value):
    model.set_param_hint(f"ln_{name}", value=math.log(value))
    model.set_param_hint(name, expr=f"exp({model.prefix}ln_{name})", min=0.0)


class ConstantPermeabilityModel(lmfit.Model):
    """:class:`lmfit.Model` of a constant permeability ``p`` (m**2/s) over ``lambda_bar``.

    ``p = exp(ln_p)``: the free parameter is ``ln_p`` (see module notes).
    """

    def __init__(self, independent_vars=("lambda_bar",), prefix="", nan_policy="raise", **kwargs):
        super().__init__(
            constant_permeability, independent_vars=list(independent_vars), prefix=prefix,
            nan_policy=nan_policy, **kwargs
        )
        _set_ln_hint(self, "p", 2e-12)

    def guess(self, data, lambda_bar=None, **kwargs):
        """Initial ``p``: the median of the positive data."""
        d = np.asarray(data, float)
        d = d[np.isfinite(d) & (d > 0)]
        pars = self.make_params()
        pars[f"{self.prefix}ln_p"].value = math.log(float(np.median(d)) if d.size else 2e-12)
        return lmfit.models.update_param_vals(pars, self.prefix, **kwargs)

    def fit_starts(self, p_rest, p_mean, thickness):
        """Starting points for ODE fits: the best constant ``p_mean`` (m**2/s)."""
        pars = self.make_params()
        pars[f"{self.prefix}ln_p"].value = math.log(p_mean)
        return [pars]


class DoubleExponentialModel(lmfit.Model):
    r""":class:`lmfit.Model` of Eqn 27 over ``lambda_bar``.

    Free parameters, for conditioning: ``ln_a1``, ``ln_a3`` (logs of the two
    terms at :math:`\bar\lambda = 1`, m**2/s), ``c4`` and ``gap = c4 - c2 >= 0``
    (orders the terms: term 1 is the fast one).  Expressions: ``c1 = exp(ln_a1 - c2)``,
    ``c3 = exp(ln_a3 - c4)``, ``c2 = c4 - gap`` and ``p_at_rest`` :math:`= P_w(1)`.
    """

    def __init__(self, independent_vars=("lambda_bar",), prefix="", nan_policy="raise", **kwargs):
        super().__init__(
            double_exponential, independent_vars=list(independent_vars), prefix=prefix,
            nan_policy=nan_policy, **kwargs
        )
        pf = self.prefix
        self.set_param_hint("ln_a1", value=math.log(1e-12))
        self.set_param_hint("ln_a3", value=math.log(1e-12))
        self.set_param_hint("c4", value=-0.3)
        self.set_param_hint("gap", value=5.0, min=0.0)
        self.set_param_hint("c2", expr=f"{pf}c4 - {pf}gap")
        self.set_param_hint("c1", expr=f"exp({pf}ln_a1 - {pf}c2)", min=0.0)
        self.set_param_hint("c3", expr=f"exp({pf}ln_a3 - {pf}c4)", min=0.0)
        self.set_param_hint("p_at_rest", expr=f"exp({pf}ln_a1) + exp({pf}ln_a3)", min=0.0)

    def make_params_from(self, c1, c2, c3, c4) -> lmfit.Parameters:
        """Parameters set to the Eqn 27 constants ``c1..c4`` (``c1, c3 > 0``; swapped if ``c2 > c4``)."""
        if c2 > c4:
            c1, c2, c3, c4 = c3, c4, c1, c2
        if c1 <= 0 or c3 <= 0:
            raise ValueError(f"c1 and c3 must be > 0 m^2/s, got {c1!r}, {c3!r}")
        pars = self.make_params()
        pf = self.prefix
        pars[f"{pf}ln_a1"].value = math.log(c1) + c2
        pars[f"{pf}ln_a3"].value = math.log(c3) + c4
        pars[f"{pf}c4"].value = c4
        pars[f"{pf}gap"].value = c4 - c2
        pars.update_constraints()
        return pars

    def guess(self, data, lambda_bar, **kwargs):
        """Initial constants: a log-linear fit to the upper half in stretch for the slow
        term, then to the remaining excess at low stretch for the fast term."""
        lam = np.asarray(lambda_bar, float)
        d = np.asarray(data, float)
        ok = np.isfinite(lam) & np.isfinite(d) & (d > 0)
        lam, d = lam[ok], d[ok]
        c1, c2, c3, c4 = 1e-12 * math.exp(5.0), -5.0, 1e-12 * math.exp(0.3), -0.3
        if lam.size >= 4 and np.ptp(lam) > 0:
            order = np.argsort(lam)
            lam, d = lam[order], d[order]
            hi = lam >= np.median(lam)
            if np.ptp(lam[hi]) > 0:
                c4, lnc3 = np.polyfit(lam[hi], np.log(d[hi]), 1)
                c3 = math.exp(lnc3)
            excess = d - c3 * np.exp(c4 * lam)
            lo = (~hi) & (excess > 0)
            if lo.sum() >= 2 and np.ptp(lam[lo]) > 0:
                c2, lnc1 = np.polyfit(lam[lo], np.log(excess[lo]), 1)
                c1 = math.exp(lnc1)
            else:
                c2 = c4 - 5.0
                c1 = 0.5 * d[0] * math.exp(-c2 * lam[0])
        pars = self.make_params_from(float(c1), float(c2), float(c3), float(c4))
        return lmfit.models.update_param_vals(pars, self.prefix, **kwargs)

    def fit_starts(self, p_rest, p_mean, thickness):
        """Starting points for ODE fits from the small-deflection and all-data constant fits.

        The slow term starts at ``p_mean`` (what the stretched membrane passes on
        average), the fast one makes up ``p_rest`` at rest; two decay rates.
        """
        a3 = min(p_mean, 0.75 * p_rest)
        a1 = max(p_rest - a3, 0.25 * p_rest)
        starts = []
        for c4, gap in ((-0.3, 6.0), (-0.1, 12.0), (-1.0, 3.0)):
            starts.append(self.make_params_from(a1 * math.exp(-(c4 - gap)), c4 - gap, a3 * math.exp(-c4), c4))
        return starts


class FirpoModel(lmfit.Model):
    r""":class:`lmfit.Model` of Eqn 26 over ``thickness`` (m).

    Free parameters ``ln_p_henry`` and ``ln_critical_thickness``; ``p_henry`` (m**2/s)
    and ``critical_thickness`` (m) are their exponentials.
    """

    def __init__(self, independent_vars=("thickness",), prefix="", nan_policy="raise", **kwargs):
        super().__init__(
            firpo, independent_vars=list(independent_vars), prefix=prefix, nan_policy=nan_policy, **kwargs
        )
        _set_ln_hint(self, "p_henry", 4e-12)
        _set_ln_hint(self, "critical_thickness", 20e-6)

    def guess(self, data, thickness, **kwargs):
        """Initial constants: :math:`L_c` = median thickness, :math:`P_{Henry}` = 2 x median data."""
        t = np.asarray(thickness, float)
        d = np.asarray(data, float)
        ok = np.isfinite(t) & np.isfinite(d) & (d > 0) & (t > 0)
        lc = float(np.median(t[ok])) if ok.any() else 20e-6
        ph = 2.0 * float(np.median(d[ok])) if ok.any() else 4e-12
        pars = self.make_params()
        pars[f"{self.prefix}ln_p_henry"].value = math.log(ph)
        pars[f"{self.prefix}ln_critical_thickness"].value = math.log(lc)
        pars.update_constraints()
        return lmfit.models.update_param_vals(pars, self.prefix, **kwargs)

    def fit_starts(self, p_rest, p_mean, thickness):
        """Starting points for ODE fits: :math:`L_c = l_0` and :math:`l_0/4`, through ``p_rest`` at :math:`l_0`."""
        starts = []
        for lc in (thickness, thickness / 4):
            pars = self.make_params()
            pars[f"{self.prefix}ln_p_henry"].value = math.log(p_rest * (1 + lc / thickness))
            pars[f"{self.prefix}ln_critical_thickness"].value = math.log(lc)
            pars.update_constraints()
            starts.append(pars)
        return starts
