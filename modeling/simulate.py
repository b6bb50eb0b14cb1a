r"""Time course of a bulging chamber: main text Eqn 8 solved by quadrature.

The flux ODE is scalar and autonomous, :math:`dv/dt = g(v)` with
:math:`v = V/V_0`, so its solution is the inverse of

.. math:: t(v) = \int_{v_0}^{v} \frac{dv'}{g(v')} .

:class:`VolumePath` evaluates the mechanics (:math:`f_A, f_l, P_t,
\bar\lambda`) once on a graded :math:`v` grid from :math:`v_0` towards the end of
the motion, integrates :math:`1/g` cumulatively (piecewise parabolas, O(h^4)), and interpolates
:math:`v(t)` with cubic Hermite polynomials using the exact slopes
:math:`g(v_i)`.  Where the driving force vanishes (an equilibrium volume
:math:`v_{eq}`: osmotic pull equals turgor, or :math:`V/V_0 \to 1` in isotonic
reverse actuation) :math:`t(v)` diverges logarithmically; the last stretch is
integrated in :math:`s = -\ln|v - v_{eq}|`, where the integrand
:math:`|v - v_{eq}|/|g|` stays finite, and the approach beyond the grid is the
exact linearised exponential.  Where the motion instead leaves the mechanics'
range (:math:`\tilde V` beyond the table end near Gent locking, or
:math:`\tilde V < 0`: inward deflection is not modelled) the path ends there
at a finite time.

Because the permeability only rescales :math:`g` pointwise, the grid and the
mechanics are computed once per chamber and reused for every permeability
tried in a fit (:mod:`osmobulge.modeling.fitting`).
"""

from __future__ import annotations

import math

import numpy as np
import xarray as xr
from scipy.interpolate import CubicHermiteSpline
from scipy.optimize import brentq

from osmobulge import __version__
from osmobulge.modeling.permeability import accepts_thickness, evaluate_permeability
from osmobulge.modeling.transport import (
    MECHANICS_KINDS,
    Chamber,
    mechanics_model,
    osmotic_term,
    time_constant,
    volume_ratio_from_vtilde,
    vtilde_from_volume_ratio,
)

__all__ = ["simulate", "VolumePath", "MechanicsRangeError", "SIMULATE_ATTRS", "ON_LIMIT", "permeability_attrs"]

ON_LIMIT = ("raise", "truncate")

SIMULATE_ATTRS = {
    "volume_ratio": {"units": "1", "long_name": "chamber volume ratio V/V0"},
    "vtilde": {"units": "1", "long_name": "dimensionless bulge volume (V-V0)/(A0 a)"},
    "lambda_bar": {"units": "1", "long_name": "average biaxial stretch sqrt(A/A0)"},
    "area_ratio": {"units": "1", "long_name": "membrane area ratio f_A = A/A0"},
    "inverse_thickness": {"units": "1", "long_name": "mean inverse thickness ratio f_l = <l0/l>"},
    "thickness": {"units": "m", "long_name": "mean membrane thickness l0/f_l"},
    "turgor_pressure": {"units": "Pa", "long_name": "turgor pressure P_t"},
    "driving_force": {"units": "1", "long_name": "driving force (DeltaPi + P_t)/Pi0"},
    "permeability": {"units": "m^2/s", "long_name": "water permeability P_w"},
    "volume_rate": {"units": "1/s", "long_name": "rate d(V/V0)/dt"},
}


def _cumulative_quadratic(f, x):
    """Cumulative integral of samples ``f`` on a strictly increasing, possibly non-uniform ``x``.

    Each interval is integrated with the parabola through it and its right
    neighbour and with the one through its left neighbour, averaged (the
    two-parabola average is the 4-point cubic rule on uniform grids, error O(h^4));
    the end intervals use the single parabola available.
    """
    n = x.size
    if n < 3:
        return np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(x))])
    h = np.diff(x)

    def parabola(h, d, fa, fb, fc):
        # integral over [0, h] of the parabola through (0, fa), (h, fb), (d, fc)
        return (fa * (h / 2 - h * h / (6 * d)) + fb * h * (2 * h - 3 * d) / (6 * (h - d))
                - fc * h**3 / (6 * d * (d - h)))

    fwd = parabola(h[:-1], x[2:] - x[:-2], f[:-2], f[1:-1], f[2:])  # intervals 0..n-3
    bwd = parabola(h[1:], x[:-2] - x[1:-1], f[1:-1], f[2:], f[:-2])  # intervals 1..n-2
    integral = np.empty(n - 1)
    integral[0] = fwd[0]
    integral[-1] = bwd[-1]
    integral[1:-1] = 0.5 * (fwd[1:] + bwd[:-1])
    return np.concatenate([[0.0], np.cumsum(integral)])


def _hermite(tn, vn, gn, tq):
    """Cubic Hermite interpolation of ``v(t)`` with slopes ``g`` at ``tq`` inside ``[tn[0], tn[-1]]``."""
    i = np.clip(np.searchsorted(tn, tq, side="right") - 1, 0, tn.size - 2)
    h = tn[i + 1] - tn[i]
    s = (tq - tn[i]) / h
    s2 = s * s
    s3 = s2 * s
    return ((2 * s3 - 3 * s2 + 1) * vn[i] + (s3 - 2 * s2 + s) * h * gn[i]
            + (3 * s2 - 2 * s3) * vn[i + 1] + (s3 - s2) * h * gn[i + 1])


class MechanicsRangeError(ValueError):
    """The volume leaves the range the mechanics can describe (Gent locking or inward deflection)."""

    def __init__(self, message, *, time, vtilde):
        super().__init__(message)
        self.time = float(time)
        self.vtilde = float(vtilde)


class VolumePath:
    r"""The solution :math:`V/V_0(t)` of the flux ODE for one chamber, by quadrature.

    Build once per chamber and mechanics; call :meth:`solve` / :meth:`volume_ratio`
    with any permeability.

    Parameters
    ----------
    chamber : Chamber
    mechanics : MechanicsTable or LinearMechanics
        From :func:`osmobulge.modeling.transport.mechanics_model`.
    v0 : float
        Initial volume ratio :math:`V/V_0` at ``t = 0`` (>= 1).
    n : int
        Grid resolution: the step in :math:`v` is at most ``|v_end - v0|/(n - 1)``
        and ``3 v/(n - 1)`` (the geometric equilibrium tail adds ~600 points).

    Attributes
    ----------
    v : ndarray of shape (N,)
        Volume-ratio grid from ``v0`` towards the end of the motion.
    direction : int
        +1 (swelling), -1 (shrinking) or 0 (at rest).
    v_end : float
        Equilibrium volume ratio (``end == "equilibrium"``) or where the mechanics
        run out (``end == "limit"``).
    end : {"equilibrium", "limit", "rest"}
    lambda_bar, thickness : ndarray of shape (N,)
        Average stretch and mean thickness (m) on the grid, the arguments of the permeability.
    """

    _TAIL_MIN = 1e-13  # equilibrium tail: |v - v_eq| down to 1e-13 of the distance travelled
    _TAIL_STEP = 0.05  # step in s = -ln|v - v_eq| in the geometric tail

    def __init__(self, chamber: Chamber, mechanics, v0: float = 1.0, *, n: int = 1201):
        if not isinstance(chamber, Chamber):
            raise TypeError(f"chamber must be a Chamber, got {type(chamber).__name__}")
        v0 = float(v0)
        if not math.isfinite(v0) or v0 < 1.0:
            raise ValueError(f"v0 must be a finite volume ratio >= 1 (no inward deflection), got {v0!r}")
        n = int(n)
        if n < 21:
            raise ValueError(f"n must be >= 21, got {n!r}")
        self.chamber = chamber
        self.mechanics = mechanics
        self.v0 = v0
        self._tau1 = time_constant(chamber, 1.0)  # tau at P_w = 1 m^2/s
        v_hi = volume_ratio_from_vtilde(mechanics.vtilde_max, chamber) if math.isfinite(mechanics.vtilde_max) \
            else math.inf
        if v0 > v_hi:
            raise MechanicsRangeError(
                f"v0={v0!r} is beyond the mechanics' range (vtilde_max={mechanics.vtilde_max:.6g}, "
                f"V/V0 <= {v_hi:.6g})", time=0.0, vtilde=vtilde_from_volume_ratio(v0, chamber))
        d0 = self._drive(np.array([v0]))[0]
        self.direction = int(np.sign(d0))
        if self.direction == 0:
            self.end, self.v_end = "rest", v0
            self.v = np.array([v0])
        else:
            self._locate_end(v_hi)
            self._build_grid(n)
        vt = vtilde_from_volume_ratio(self.v, chamber)
        self.vtilde = vt
        self.area_ratio = np.asarray(mechanics.area_ratio(vt), float).reshape(self.v.shape)
        self.inverse_thickness = np.asarray(mechanics.inverse_thickness(vt), float).reshape(self.v.shape)
        self.lambda_bar = np.asarray(mechanics.lambda_bar(vt), float).reshape(self.v.shape)
        self.thickness = chamber.thickness / self.inverse_thickness
        self.turgor_pressure = np.asarray(
            mechanics.turgor_pressure(vt, thickness=chamber.thickness, radius=chamber.radius), float
        ).reshape(self.v.shape)
        self.driving_force = osmotic_term(self.v, chamber.feed_ratio) + self.turgor_pressure / chamber.osmotic_potential
        self.driving_force = np.asarray(self.driving_force, float).reshape(self.v.shape)
        # rate per unit permeability: g(v) = P_w(v) * unit_rate(v)
        self.unit_rate = self.area_ratio * self.inverse_thickness * self.driving_force / self._tau1

    # -- construction -------------------------------------------------------------
    def _drive(self, v):
        vt = np.maximum(vtilde_from_volume_ratio(v, self.chamber), 0.0)
        pt = self.mechanics.turgor_pressure(vt, thickness=self.chamber.thickness, radius=self.chamber.radius)
        return osmotic_term(v, self.chamber.feed_ratio) + np.asarray(pt) / self.chamber.osmotic_potential

    def _locate_end(self, v_hi):
        """Find the equilibrium volume on the way, or the end of the mechanics' range."""
        c = self.chamber
        if self.direction > 0:
            if math.isfinite(v_hi):
                probe = np.linspace(self.v0, v_hi, 4001)
            else:  # linear mechanics: no range limit; march out geometrically
                probe = self.v0 + np.concatenate([[0.0], np.geomspace(1e-6, 1e7, 4000)]) * self.v0
        else:
            probe = np.linspace(self.v0, 1.0, 4001)
        d = self._drive(probe)
        crossed = np.flatnonzero(np.sign(d) != self.direction)
        if crossed.size:
            k = crossed[0]
            if d[k] == 0.0:
                v_eq = float(probe[k])
            else:
                v_eq = brentq(lambda x: self._drive(np.array([x]))[0], probe[k - 1], probe[k], xtol=1e-15, rtol=1e-15)
            self.end, self.v_end = "equilibrium", float(v_eq)
        elif self.direction > 0:
            if not math.isfinite(v_hi):
                raise ValueError(f"no equilibrium volume up to V/V0={probe[-1]:.3g} for {c!r}")
            self.end, self.v_end = "limit", float(v_hi)
        else:
            self.end, self.v_end = "limit", 1.0

    def _build_grid(self, n):
        """March a graded grid from v0 towards v_end.

        Step ``min(dist/(n-1), 3 v/(n-1), TAIL_STEP |v - v_eq|)``: uniform for
        short paths, geometric in v for long ones (the osmotic 1/v and the
        mechanics vary on the scale of v), geometric in the distance to an
        equilibrium near it.  The step changes continuously along the path.
        """
        dist = abs(self.v_end - self.v0)
        sgn = 1.0 if self.v_end > self.v0 else -1.0
        h_abs = dist / (n - 1)
        h_rel = 3.0 / (n - 1)
        eq = self.end == "equilibrium"
        d_min = self._TAIL_MIN * max(dist, abs(self.v_end)) if eq else 0.0
        pts = [self.v0]
        v = self.v0
        while True:
            d = abs(self.v_end - v)
            step = min(h_abs, h_rel * v, self._TAIL_STEP * d if eq else math.inf)
            if eq:
                if d - step < d_min:
                    break
            elif d <= step * 1.5:
                # last step: finish exactly at the range end (avoid a sliver)
                pts.append(self.v_end)
                break
            v = v + sgn * step
            pts.append(v)
        self.v = np.asarray(pts, float)
        if eq:
            self._x = -np.log(np.abs(self.v - self.v_end) / dist)  # s = -ln(q), strictly increasing
        else:
            self._x = np.abs(self.v - self.v0)

    # -- solution ------------------------------------------------------------------
    def permeability_on_grid(self, permeability):
        """The permeability (m**2/s) at the grid points (callables get ``lambda_bar`` and ``thickness=``)."""
        if self.direction == 0:
            return np.full(self.v.shape, np.nan)
        return np.asarray(
            evaluate_permeability(permeability, self.lambda_bar, self.thickness if accepts_thickness(permeability)
                                  else None), float).reshape(self.v.shape)

    def solve(self, pw):
        """Times (s) at the grid points and rates (1/s) for permeabilities ``pw`` on the grid.

        Parameters
        ----------
        pw : ndarray of shape (N,), m**2/s
            From :meth:`permeability_on_grid`.

        Returns
        -------
        t, rate : ndarray of shape (N,)
        """
        g = pw * self.unit_rate
        if self.direction == 0:
            return np.zeros(1), np.zeros(1)
        if self.end == "limit":
            # x = |v - v0|: dt/dx = 1/|g|
            t = _cumulative_quadratic(1.0 / np.abs(g), self._x)
        else:
            # x = s = -ln(|v - v_eq|/|v0 - v_eq|): dt/ds = |v - v_eq| / |g|, finite at the equilibrium
            t = _cumulative_quadratic(np.abs(self.v - self.v_end) / np.abs(g), self._x)
        return t, g

    def nodes(self, pw):
        """``(t, v, rate)`` at the grid nodes for permeabilities ``pw`` (m**2/s) on the grid.

        Times are strictly increasing (nodes an extreme trial law in a fit would
        stall in floating point are dropped).
        """
        t, g = self.solve(pw)
        keep = np.isfinite(t)
        keep[1:] &= np.diff(t) > 0
        if not keep.all():
            keep &= np.concatenate([[True], np.maximum.accumulate(np.where(keep, t, -np.inf))[:-1] < t[1:]])
            return t[keep], self.v[keep], g[keep]
        return t, self.v, g

    def interpolant(self, pw):
        """:class:`scipy.interpolate.CubicHermiteSpline` of :math:`v(t)` through the nodes."""
        t, v, g = self.nodes(pw)
        return CubicHermiteSpline(t, v, g, extrapolate=False)

    def volume_ratio(self, t, permeability=None, *, pw=None, beyond="raise"):
        """:math:`V/V_0` at times ``t`` (s).

        Parameters
        ----------
        t : ndarray, s
            Times >= 0.
        permeability : float or callable, optional
            Or give ``pw`` (values on the grid) directly.
        beyond : {"raise", "clip", "nan"}
            Times after the path reached the mechanics' range end: raise
            :class:`MechanicsRangeError`, return the end volume, or NaN.

        Returns
        -------
        ndarray
        """
        t = np.asarray(t, float)
        if self.direction == 0:
            return np.full(t.shape, self.v0)
        if pw is None:
            pw = self.permeability_on_grid(permeability)
        tn, vn, g = self.nodes(pw)
        out = np.empty(t.shape)
        inside = t <= tn[-1]
        out[inside] = _hermite(tn, vn, g, t[inside])
        after = ~inside
        if after.any():
            if self.end == "equilibrium":
                k = abs(g[-1] / (vn[-1] - self.v_end))
                out[after] = self.v_end + (vn[-1] - self.v_end) * np.exp(-k * (t[after] - tn[-1]))
            elif beyond == "clip":
                out[after] = self.v_end
            elif beyond == "nan":
                out[after] = np.nan
            else:
                raise self.limit_error(tn[-1], float(t[after].max()))
        return out

    def limit_error(self, t_end, t_wanted):
        """The :class:`MechanicsRangeError` for a path ending at ``t_end`` (s)."""
        vt = vtilde_from_volume_ratio(self.v_end, self.chamber)
        if self.direction > 0:
            lock = getattr(self.mechanics, "vtilde_lock", math.inf)
            why = (f"the end of the mechanics table (vtilde_max={self.mechanics.vtilde_max:.6g}"
                   + (f", {100 * self.mechanics.vtilde_max / lock:.3g} % of Gent locking at {lock:.6g})"
                      if math.isfinite(lock) else ")"))
        else:
            why = "V/V0 = 1: the membrane would deflect inward, which is not modelled"
        return MechanicsRangeError(
            f"the chamber reaches {why} at t = {t_end:.6g} s ({t_end / 3600:.4g} h), Vtilde = {vt:.6g}, "
            f"V/V0 = {self.v_end:.6g}; times up to {t_wanted:.6g} s were asked for "
            "(use on_limit='truncate' to keep the data up to there)",
            time=t_end, vtilde=vt)


def _check_times(t):
    t = np.asarray(t, float)
    if t.ndim != 1 or t.size == 0:
        raise ValueError(f"t must be a non-empty 1-D array of times in s, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("t must be finite (s); found NaN or inf")
    if t[0] < 0 or np.any(np.diff(t) < 0):
        raise ValueError("t must be >= 0 and non-decreasing (s)")
    return t


def _material_attrs(material) -> dict:
    attrs = {"material_law": str(material.law)}
    for k, v in material.constants.items():
        attrs[f"material_{k}"] = float(v)
    attrs["material_E"] = float(material.E)
    return attrs


def permeability_attrs(permeability) -> dict:
    """netCDF-safe attrs describing a permeability (a float or a law object)."""
    if callable(permeability):
        attrs = {"permeability_law": repr(permeability)}
        fields = getattr(permeability, "__dataclass_fields__", None)
        if fields:
            for name in fields:
                value = getattr(permeability, name)
                if isinstance(value, int | float):
                    attrs[f"permeability_{name}"] = float(value)
        return attrs
    return {"permeability_law": "constant", "permeability_p": float(permeability)}


def simulate(chamber, material, permeability, t, *, lambda_pre=1.0, mechanics="hyperelastic", v0=1.0,
             on_limit="raise", n_grid=1201) -> xr.Dataset:
    r"""Chamber volume and membrane state over time (main text Eqn 8 with feed, supplement Eqn 32).

    Parameters
    ----------
    chamber : Chamber
        Geometry, loading (``concentration``, ``feed_concentration``) and temperature.
    material : Material or LinearElastic
        Membrane law, e.g. ``materials.PDMS``.
    permeability : float or callable, m**2/s
        A constant, or a function of ``lambda_bar`` (e.g. ``DoubleExponential.PDMS``);
        callables that also take ``thickness=`` get the mean thickness :math:`l_0/f_l`
        (m), e.g. :class:`~osmobulge.modeling.permeability.Firpo`.
    t : array_like of shape (T,), s
        Non-decreasing times >= 0; ``t = 0`` is the state ``v0``.
    lambda_pre : float or callable
        Rim pre-stretch (hyperelastic mechanics).
    mechanics : {"hyperelastic", "linear"}
        Cached hyperelastic table, or the linear-elastic membrane
        (:math:`f_A = 1 + 4\tilde V^2`, :math:`f_l = 1`,
        :math:`P_t = E\frac{128}{3}\frac{l_0}{a}\tilde V^3`, ``E = material.E``).
    v0 : float
        :math:`V/V_0` at ``t = 0`` (>= 1; e.g. a bulged start for reverse actuation
        with ``feed_concentration = concentration``).
    on_limit : {"raise", "truncate"}
        If the volume leaves the mechanics' range before ``t[-1]`` (Gent locking;
        :math:`V/V_0 < 1`): raise :class:`MechanicsRangeError` (a ``ValueError``
        giving the time and :math:`\tilde V` reached), or return only the times up
        to there with ``attrs["limit_reached"] = 1`` and ``attrs["limit_time"]`` (s).
    n_grid : int
        Quadrature grid size (default 1201: relative error ~1e-9).

    Returns
    -------
    xarray.Dataset
        Over ``time`` (s): ``volume_ratio``, ``vtilde``, ``lambda_bar``,
        ``area_ratio``, ``inverse_thickness``, ``thickness`` (m),
        ``turgor_pressure`` (Pa), ``driving_force``, ``permeability`` (m**2/s),
        ``volume_rate`` (1/s), each with ``units`` and ``long_name``.  Attrs
        (netCDF-safe): the chamber (:data:`~osmobulge.modeling.transport.CHAMBER_ATTRS`
        names), the material, the permeability law, ``mechanics``, ``lambda_pre``,
        ``v0``, ``end`` and ``end_volume_ratio`` (the equilibrium or range end),
        ``limit_reached``, ``limit_time``.

    Notes
    -----
    Solved by quadrature of :math:`t = \int dv/g(v)` (see module docs); agrees with
    ``scipy.integrate.solve_ivp`` at ``rtol=1e-10`` to better than 1e-6.

    Examples
    --------
    >>> from osmobulge.modeling.materials import PDMS
    >>> from osmobulge.modeling.transport import paper_chamber
    >>> ds = simulate(paper_chamber(), PDMS, 2e-12, [0.0, 3600.0], mechanics="linear")
    >>> round(float(ds.volume_ratio[1]), 4)
    1.319
    """
    if on_limit not in ON_LIMIT:
        raise ValueError(f"on_limit must be one of {ON_LIMIT}, got {on_limit!r}")
    if mechanics not in MECHANICS_KINDS:
        raise ValueError(f"mechanics must be one of {MECHANICS_KINDS}, got {mechanics!r}")
    if not callable(permeability):
        p = float(permeability)
        if not math.isfinite(p) or p <= 0:
            raise ValueError(f"permeability must be finite and > 0 m^2/s, got {permeability!r}")
    t = _check_times(t)
    mech = mechanics_model(material, lambda_pre, mechanics)
    path = VolumePath(chamber, mech, v0, n=n_grid)
    pw_grid = path.permeability_on_grid(permeability)
    limit_time = math.nan
    truncated = False
    if path.direction != 0 and path.end == "limit":
        tn, _ = path.solve(pw_grid)
        limit_time = float(tn[-1])
        if t[-1] > limit_time:
            if on_limit == "raise":
                raise path.limit_error(limit_time, float(t[-1]))
            t = t[t <= limit_time]
            truncated = True
    v = path.volume_ratio(t, pw=pw_grid, beyond="clip")
    vt = np.maximum(vtilde_from_volume_ratio(v, chamber), 0.0)
    fa = np.asarray(mech.area_ratio(vt), float).reshape(v.shape)
    fl = np.asarray(mech.inverse_thickness(vt), float).reshape(v.shape)
    lam = np.asarray(mech.lambda_bar(vt), float).reshape(v.shape)
    thick = chamber.thickness / fl
    pt = np.asarray(mech.turgor_pressure(vt, thickness=chamber.thickness, radius=chamber.radius), float)
    pt = pt.reshape(v.shape)
    drive = np.asarray(osmotic_term(v, chamber.feed_ratio), float) + pt / chamber.osmotic_potential
    pw = np.asarray(evaluate_permeability(permeability, lam, thick), float).reshape(v.shape)
    rate = pw * fa * fl * drive / time_constant(chamber, 1.0)

    data = {"volume_ratio": v, "vtilde": vtilde_from_volume_ratio(v, chamber) * np.ones_like(v),
            "lambda_bar": lam, "area_ratio": fa, "inverse_thickness": fl, "thickness": thick,
            "turgor_pressure": pt, "driving_force": drive, "permeability": pw, "volume_rate": rate}
    attrs = {
        **chamber.to_attrs(),
        **_material_attrs(material),
        **permeability_attrs(permeability),
        "mechanics": mechanics,
        "lambda_pre": float(lambda_pre) if not callable(lambda_pre) else repr(lambda_pre),
        "v0": float(v0),
        "end": path.end,
        "end_volume_ratio": float(path.v_end),
        "limit_reached": int(truncated),
        "limit_time": limit_time,
        "osmobulge_version": __version__,
    }
    ds = xr.Dataset(
        {k: ("time", np.asarray(val, float), dict(SIMULATE_ATTRS[k])) for k, val in data.items()},
        coords={"time": ("time", t, {"units": "s", "long_name": "time"})},
        attrs=attrs,
    )
    return ds

