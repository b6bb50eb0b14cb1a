r"""Hyperelastic constants from uniaxial tension and bulge profiles (supplement Sec. 6).

The paper fits the Gent 3-parameter law (supplement Eqn 57) *simultaneously* to
uniaxial tension data (Fig. S4) and to points picked by hand on a few bulge
profiles (Fig. S5).  The two data sets constrain different things:

* the uniaxial nominal stress :math:`T_{11}(\lambda)` (in Pa) sets the stress scale
  and, at small stretch, little else: the Gent stiffening term
  :math:`C_1 J_1/J_m` is nearly indistinguishable from the :math:`C_2` term
  until :math:`J_1` approaches :math:`J_m`;
* a bulge profile at a given dimensionless volume :math:`\tilde V` does not
  depend on the stress scale at all (the equations only see :math:`W/C_1`), but
  its shape near the locking volume depends strongly on :math:`J_m` and
  :math:`C_2/C_1`: the membrane at the pole is stretched far beyond any
  uniaxial test.

:func:`fit_material` minimises, with :mod:`lmfit`, the weighted residuals

.. math::

    r_i^{uni} = \frac{T_{11}^{model}(\lambda_i) - T_i}{\sigma_T}, \qquad
    r_{jk}^{bulge} = \frac{d_\pm\big((r_{jk}, z_{jk})/a_j,\ \Gamma(\tilde V_j)\big)}{\sigma_z / a_j},

where :math:`d_\pm` is the signed distance (positive outside the dome) from a
picked point to the model meridian :math:`\Gamma` of bulge *j* in units of its
chamber radius :math:`a_j`.  The uniaxial stress is the correctly derived one,
:meth:`~osmobulge.modeling.materials.Material.uniaxial_stress` (supplement Eqn 61
does not follow from Eqn 57; ``docs/paper-errata.md``, E5).

All profiles of one residual evaluation are solved in a single vectorised
shooting pass (:mod:`osmobulge.modeling._shooting`), so a fit with three bulges
costs about what one :func:`~osmobulge.modeling.bulge_profile` call costs per
evaluation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import lmfit
import numpy as np
import xarray as xr

from osmobulge import __version__
from osmobulge.modeling import _shooting
from osmobulge.modeling.bulge import NoSolutionError, _solve
from osmobulge.modeling.materials import Gent, GentGent, Material, MooneyRivlin, NeoHookean
from osmobulge.modeling.prestretch import check_prestretch

__all__ = [
    "LAWS",
    "BulgeProfilePoints",
    "MaterialFit",
    "MaterialFitError",
    "fit_material",
    "profile_distances",
    "paper_modulus",
]

#: fittable laws: name -> (class, constant names)
LAWS: dict[str, tuple[type, tuple[str, ...]]] = {
    "neo-hookean": (NeoHookean, ("c1",)),
    "mooney-rivlin": (MooneyRivlin, ("c1", "c2")),
    "gent": (Gent, ("c1", "jm")),
    "gent-gent": (GentGent, ("c1", "c2", "jm")),
}

#: units of each constant
_UNITS = {"c1": "Pa", "c2": "Pa", "jm": "1"}
#: residual (in units of sigma) of a picked point when the trial law cannot reach the bulge volume
_LOCKED_PENALTY = 1e3
#: largest plausible chamber radius, m (a value above it was almost certainly given in micrometres)
_MAX_RADIUS = 0.05
_WEIGHTS = ("auto", "given")


class MaterialFitError(RuntimeError):
    """The material fit did not converge."""


def paper_modulus(material) -> float:
    r"""The paper's "Young's modulus" :math:`6(C_1 + C_2)` (supplement Eqns 60, 62), Pa.

    Equals the true small-strain modulus :math:`3\mu` for the neo-Hookean,
    Mooney-Rivlin and Gent laws; for the Gent 3-parameter law the true value is
    :math:`6C_1 + 2C_2` (``docs/paper-errata.md``, E4).

    Parameters
    ----------
    material : Material
        A law of :mod:`osmobulge.modeling.materials`.

    Returns
    -------
    float, Pa
    """
    c = material.constants
    return 6.0 * (c.get("c1", 0.0) + c.get("c2", 0.0))


def _finite_array(name, values, unit):
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an array of real numbers ({unit})") from None
    arr = np.atleast_1d(arr)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.argmax(~np.isfinite(arr)))
        raise ValueError(f"{name} must be finite ({unit}); entry {bad} is {arr[bad]!r}")
    return arr


@dataclass(frozen=True)
class BulgeProfilePoints:
    r"""Points picked by hand on one bulge profile (supplement Fig. S5).

    Parameters
    ----------
    r : array_like of shape (K,), m
        Distance of each point from the chamber axis (the sign is ignored: both
        halves of the dome may be picked).
    z : array_like of shape (K,), m
        Height of each point above the rim plane (positive into the dome).
    radius : float, m
        Chamber radius :math:`a` (undeformed membrane radius).
    vtilde : float, optional
        Dimensionless bulge volume :math:`\tilde V = \Delta V/(\pi a^3)`.
    volume : float, m**3, optional
        Measured bulge volume :math:`\Delta V`; give exactly one of ``vtilde``
        and ``volume``.
    lambda_pre : float
        Rim pre-stretch of this bulge (>= 1).
    label : str
        Name used in reports.
    """

    r: np.ndarray
    z: np.ndarray
    radius: float
    vtilde: float | None = None
    volume: float | None = None
    lambda_pre: float = 1.0
    label: str = ""

    def __post_init__(self):
        r = _finite_array("r", self.r, "m")
        z = _finite_array("z", self.z, "m")
        if r.size != z.size:
            raise ValueError(f"r and z must have the same length, got {r.size} and {z.size}")
        if r.size < 1:
            raise ValueError("a bulge needs at least one picked point (r, z)")
        try:
            a = float(self.radius)
        except (TypeError, ValueError):
            raise TypeError(f"radius must be a real number (m), got {self.radius!r}") from None
        if not math.isfinite(a) or a <= 0 or a > _MAX_RADIUS:
            raise ValueError(
                f"radius must be in metres, in (0, {_MAX_RADIUS:g}] m, got {self.radius!r} "
                "(a chamber of 200 um has radius=200e-6)"
            )
        if (self.vtilde is None) == (self.volume is None):
            raise ValueError("give exactly one of vtilde (dimensionless) and volume (m**3) for each bulge")
        if self.volume is not None:
            vol = float(self.volume)
            if not math.isfinite(vol) or vol <= 0:
                raise ValueError(f"volume must be finite and > 0 (m**3), got {self.volume!r}")
            vt = vol / (math.pi * a**3)
        else:
            vt = float(self.vtilde)
        if not math.isfinite(vt) or vt <= 0:
            raise ValueError(f"vtilde must be finite and > 0 (bulge volume over pi a^3), got {vt!r}")
        scale = max(np.max(np.abs(r)), np.max(np.abs(z))) / a
        if scale > 20:
            raise ValueError(
                f"points lie up to {scale:.3g} chamber radii away: r and z must be in metres, like radius"
            )
        ell = float(check_prestretch(self.lambda_pre, 0.0))
        object.__setattr__(self, "r", r)
        object.__setattr__(self, "z", z)
        object.__setattr__(self, "radius", a)
        object.__setattr__(self, "vtilde", vt)
        object.__setattr__(self, "volume", vt * math.pi * a**3)
        object.__setattr__(self, "lambda_pre", ell)
        object.__setattr__(self, "label", str(self.label))

    @property
    def points(self) -> np.ndarray:
        """Points in units of the chamber radius, shape (K, 2): ``(|r|/a, z/a)``."""
        return np.column_stack([np.abs(self.r), self.z]) / self.radius


# --------------------------------------------------------------------------- profiles


def _meridians_from_shot(shot, rows):
    """Meridians ``(r/a, z/a)`` (pole to rim) of the given rows of a ``keep_path`` shot."""
    mesh, path = shot["rho"], shot["path"]
    out = {}
    for j in rows:
        rs = shot["rho_star"][j]
        inside = mesh < rs
        y_end = shot["y_star"][:, j]
        rho = np.r_[mesh[inside], rs] / rs
        lphi = np.r_[path[_shooting.IPHI, inside, j], y_end[_shooting.IPHI]]
        zz = np.r_[path[_shooting.IZ, inside, j], y_end[_shooting.IZ]]
        r = np.r_[0.0, lphi * rho]
        z = np.r_[y_end[_shooting.IZ] / rs, (y_end[_shooting.IZ] - zz) / rs]
        out[j] = np.column_stack([r, z])
    return out


class _MeridianSolver:
    """Model meridians of several bulges, warm-started between residual evaluations.

    The first call (and any call whose warm start fails) solves from scratch
    with the package's robust solver (:func:`osmobulge.modeling.bulge._solve`).
    Later calls, for nearby constants, run a secant iteration on the pole
    stretch from the previous solution: the shooting scaling trick makes any
    trial pressure exact after rescaling, so each iteration is one vectorised
    shot and 2-4 shots reach the solver's tolerance (``|ln V - ln V*| < 1e-11``).
    """

    rtol = 1e-11
    maxiter = 10

    def __init__(self, vtilde, ell):
        self.vt = np.asarray(vtilde, float)
        self.ell = np.asarray(ell, float)
        self.target = np.log(self.vt)
        self.q = None  # ln(lam0 - ell) of the last solution
        self.p = None  # its pressure
        self.slope = None  # d ln V / d q there
        self.shots = 0

    def _cold(self, material):
        res = _solve(material, self.vt, self.ell)
        shot = _shooting.shoot(material, res["lam0"], self.ell, res["pressure"], keep_path=True, rho_max=1.05)
        self.shots += 1
        if not np.all(np.isfinite(shot["rho_star"])):
            raise NoSolutionError("profile integration failed at the solved pole stretch")
        q = np.log(res["lam0"] - self.ell)
        # slope from a small step, for the next warm start
        dq = 1e-4
        shot2 = _shooting.shoot(material, self.ell + np.exp(q + dq), self.ell, res["pressure"], rho_max=1.5)
        self.shots += 1
        v2 = _shooting.scaled_results(self.ell + np.exp(q + dq), res["pressure"], shot2)["vtilde"]
        slope = (np.log(v2) - self.target) / dq
        self.q, self.p = q, res["pressure"]
        self.slope = np.where(np.isfinite(slope) & (slope > 0), slope, 1.0)
        m = _meridians_from_shot(shot, range(self.vt.size))
        return [m[j] for j in range(self.vt.size)]

    def _warm(self, material):
        n = self.vt.size
        q, p, slope = self.q.copy(), self.p.copy(), self.slope.copy()
        q_prev = np.full(n, np.nan)
        g_prev = np.full(n, np.nan)
        done = np.zeros(n, bool)
        found = {}
        for _ in range(self.maxiter):
            lam0 = self.ell + np.exp(q)
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                shot = _shooting.shoot(material, lam0, self.ell, p, keep_path=True, rho_max=1.5)
                self.shots += 1
                res = _shooting.scaled_results(lam0, p, shot)
                g = np.log(res["vtilde"]) - self.target
            if not np.all(np.isfinite(g) | done):
                return None
            conv = ~done & (np.abs(g) < self.rtol)
            if np.any(conv):
                rows = np.nonzero(conv)[0]
                found.update(_meridians_from_shot(shot, rows))
                self.p[rows] = res["pressure"][rows]
                self.q[rows] = q[rows]
                done |= conv
            if np.all(done):
                break
            with np.errstate(invalid="ignore", divide="ignore"):
                sec = (g - g_prev) / (q - q_prev)
            slope = np.where(np.isfinite(sec) & (sec > 0), sec, slope)
            q_prev, g_prev = q.copy(), g.copy()
            p = np.where(np.isfinite(res["pressure"]), res["pressure"], p)
            q = np.where(done, q, q - np.where(np.isfinite(g), g, 0.0) / slope)
        else:
            return None
        self.slope = slope
        return [found[j] for j in range(n)]

    def __call__(self, material):
        """List of meridians (arrays of shape (M, 2)); raises NoSolutionError beyond locking."""
        if self.q is not None:
            out = self._warm(material)
            if out is not None:
                return out
        return self._cold(material)


def _model_meridians(material, vtilde, ell):
    """Meridians ``(r/a, z/a)`` of several bulges from one vectorised solve (from scratch)."""
    return _MeridianSolver(vtilde, ell)(material)


def profile_distances(points, curve) -> np.ndarray:
    """Signed distance from points to a polyline meridian, in the curve's units.

    Parameters
    ----------
    points : ndarray of shape (K, 2)
        ``(r, z)`` of the points, ``r >= 0``.
    curve : ndarray of shape (M, 2)
        Meridian from the pole (``r = 0``) to the rim.

    Returns
    -------
    ndarray of shape (K,)
        Distance to the nearest point of the polyline; positive on the side
        away from the chamber (outside the dome), negative inside.
    """
    p = np.asarray(points, float)[:, None, :]
    a = np.asarray(curve, float)[None, :-1, :]
    d = np.diff(np.asarray(curve, float), axis=0)[None]
    dd = np.sum(d * d, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip(np.sum((p - a) * d, axis=-1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    foot = a + t[..., None] * d
    diff = p - foot
    dist = np.sqrt(np.sum(diff * diff, axis=-1))
    k = np.argmin(dist, axis=1)
    rows = np.arange(p.shape[0])
    # the meridian runs pole -> rim (r increasing, z falling): the outward normal is (dz, -dr) rotated
    seg = d[0, k]
    cross = seg[:, 0] * diff[rows, k, 1] - seg[:, 1] * diff[rows, k, 0]
    return np.where(cross >= 0, 1.0, -1.0) * dist[rows, k]


# --------------------------------------------------------------------------- result


@dataclass(frozen=True)
class MaterialFit:
    r"""Result of :func:`fit_material`.

    Attributes
    ----------
    law : str
        Law name (a key of :data:`LAWS`).
    params : dict of str to float
        Best-fit constants (``c1``, ``c2`` in Pa, ``jm`` dimensionless).
    stderr : dict of str to float
        Standard errors (NaN when they could not be estimated).
    material : Material
        The fitted law.
    youngs_modulus, youngs_modulus_stderr : float, Pa
        True small-strain modulus :math:`3\mu`.
    paper_modulus, paper_modulus_stderr : float, Pa
        The paper's :math:`6(C_1 + C_2)` (supplement Eqns 60-62).
    stretch, stress : ndarray, (1, Pa)
        Uniaxial data used.
    stress_model : ndarray, Pa
        Model nominal stress at ``stretch``.
    profiles : tuple of BulgeProfilePoints
        Bulge data used.
    profile_residuals : tuple of ndarray, m
        Signed distance of each picked point to its model profile.
    stress_sigma : float, Pa
        Standard deviation assumed (or estimated) for the uniaxial stress.
    profile_sigma : float, m
        Standard deviation assumed (or estimated) for the picked points.
    correlations : dict
        Correlation coefficients ``{"c1:jm": value, ...}``.
    success : bool
    errorbars : bool
        Whether the covariance could be estimated.
    nfev : int
        Number of residual evaluations (each solves every profile once).
    chisqr, redchi : float
    message : str
    """

    law: str
    params: dict
    stderr: dict
    material: Material
    youngs_modulus: float
    youngs_modulus_stderr: float
    paper_modulus: float
    paper_modulus_stderr: float
    stretch: np.ndarray
    stress: np.ndarray
    stress_model: np.ndarray
    profiles: tuple
    profile_residuals: tuple
    stress_sigma: float
    profile_sigma: float
    correlations: dict
    success: bool
    errorbars: bool
    nfev: int
    chisqr: float
    redchi: float
    message: str
    jm_lower_bound: float = float("nan")
    lmfit_result: object = field(default=None, repr=False, compare=False)

    def summary(self) -> dict:
        """JSON-safe summary: plain floats, ints, strings, lists and dicts."""

        def f(x):
            x = float(x)
            return x if math.isfinite(x) else None

        return {
            "law": self.law,
            "params": {k: f(v) for k, v in self.params.items()},
            "stderr": {k: f(v) for k, v in self.stderr.items()},
            "units": {k: _UNITS[k] for k in self.params},
            "youngs_modulus_Pa": f(self.youngs_modulus),
            "youngs_modulus_stderr_Pa": f(self.youngs_modulus_stderr),
            "paper_modulus_Pa": f(self.paper_modulus),
            "paper_modulus_stderr_Pa": f(self.paper_modulus_stderr),
            "shear_modulus_Pa": f(self.material.shear_modulus),
            "correlations": {k: f(v) for k, v in self.correlations.items()},
            "n_uniaxial": int(self.stretch.size),
            "n_profiles": len(self.profiles),
            "n_profile_points": int(sum(p.r.size for p in self.profiles)),
            "profile_vtilde": [float(p.vtilde) for p in self.profiles],
            "stress_sigma_Pa": f(self.stress_sigma),
            "profile_sigma_m": f(self.profile_sigma),
            "jm_lower_bound": f(self.jm_lower_bound),
            "success": bool(self.success),
            "errorbars": bool(self.errorbars),
            "nfev": int(self.nfev),
            "chisqr": f(self.chisqr),
            "redchi": f(self.redchi),
            "message": str(self.message),
            "osmobulge_version": __version__,
        }

    def report(self) -> str:
        """Human-readable report (constants, moduli, correlations, data, warnings)."""
        lines = [f"[[Material fit: {self.law}]]"]
        lines.append(
            f"    data: {self.stretch.size} uniaxial points (stretch "
            + (f"{self.stretch.min():.3g}-{self.stretch.max():.3g}" if self.stretch.size else "-")
            + f"), {len(self.profiles)} bulge profiles, "
            f"{sum(p.r.size for p in self.profiles)} picked points"
        )
        lines.append(
            f"    sigma: stress {self.stress_sigma:.4g} Pa, profile points {self.profile_sigma * 1e6:.4g} um"
        )
        lines.append(f"    evaluations {self.nfev}, chi-square {self.chisqr:.5g}, reduced {self.redchi:.5g}")
        lines.append("[[Constants]]")
        for k, v in self.params.items():
            s = self.stderr[k]
            rel = f" ({100 * s / abs(v):.2f}%)" if np.isfinite(s) and v != 0 else ""
            unit = _UNITS[k]
            err = f" +/- {s:.4g}" if np.isfinite(s) else " +/- (not estimated)"
            lines.append(f"    {k:>3} = {v:.6g}{err}{rel} {unit}")
        lines.append("[[Moduli]]")
        lines.append(
            f"    E = 3 mu (small-strain)   = {self.youngs_modulus / 1e6:.5g} +/- "
            f"{self.youngs_modulus_stderr / 1e6:.2g} MPa"
        )
        lines.append(
            f"    E = 6 (C1 + C2) (paper)   = {self.paper_modulus / 1e6:.5g} +/- "
            f"{self.paper_modulus_stderr / 1e6:.2g} MPa"
        )
        if self.correlations:
            lines.append("[[Correlations]] (|C| > 0.1)")
            for k, v in sorted(self.correlations.items(), key=lambda kv: -abs(kv[1])):
                if abs(v) > 0.1:
                    lines.append(f"    C({k}) = {v:+.4f}")
        if self.profiles:
            lines.append("[[Bulges]]")
            for p, res in zip(self.profiles, self.profile_residuals, strict=True):
                rms = float(np.sqrt(np.mean(res**2)))
                lines.append(
                    f"    {p.label or 'bulge'}: a = {p.radius * 1e6:.4g} um, Vtilde = {p.vtilde:.4g}, "
                    f"{p.r.size} points, rms distance {rms * 1e6:.3g} um"
                )
        if not self.errorbars:
            lines.append("    warning: uncertainties could not be estimated (singular covariance)")
        at_bound = "jm" in self.params and self.params["jm"] < self.jm_lower_bound * 1.01
        if np.isfinite(self.jm_lower_bound) and at_bound:
            lines.append("    warning: jm is at its lower bound (the locking of the data)")
        if not self.success:
            lines.append(f"    warning: the fit did not converge: {self.message}")
        return "\n".join(lines)

    def to_dataset(self) -> xr.Dataset:
        """The data, model and fitted constants as an ``xarray.Dataset``.

        Uniaxial data over ``uniaxial``, picked points over ``point`` (with the
        index of their ``bulge``), constants on ``param`` as
        ``modelfit_coefficients`` / ``modelfit_stderr``.
        """
        names = list(self.params)
        pts_r = np.concatenate([p.r for p in self.profiles]) if self.profiles else np.empty(0)
        pts_z = np.concatenate([p.z for p in self.profiles]) if self.profiles else np.empty(0)
        bulge = np.concatenate([np.full(p.r.size, i) for i, p in enumerate(self.profiles)]) if self.profiles else (
            np.empty(0, int))
        dist = np.concatenate(self.profile_residuals) if self.profiles else np.empty(0)
        data = {
            "stress": ("uniaxial", self.stress, {"units": "Pa", "long_name": "measured nominal uniaxial stress"}),
            "stress_model": ("uniaxial", self.stress_model, {"units": "Pa", "long_name": "model nominal stress"}),
            "point_r": ("point", pts_r, {"units": "m", "long_name": "picked point distance from the axis"}),
            "point_z": ("point", pts_z, {"units": "m", "long_name": "picked point height above the rim"}),
            "point_bulge": ("point", bulge, {"units": "1", "long_name": "index of the bulge of each point"}),
            "point_distance": ("point", dist, {"units": "m",
                                               "long_name": "signed distance to the model profile (+ outside)"}),
            "bulge_vtilde": ("bulge", np.array([p.vtilde for p in self.profiles]),
                             {"units": "1", "long_name": "dimensionless bulge volume dV/(pi a^3)"}),
            "bulge_radius": ("bulge", np.array([p.radius for p in self.profiles]),
                             {"units": "m", "long_name": "chamber radius"}),
            "modelfit_coefficients": ("param", np.array([self.params[k] for k in names]),
                                      {"long_name": "fitted material constants"}),
            "modelfit_stderr": ("param", np.array([self.stderr[k] for k in names]),
                                {"long_name": "standard errors of the constants"}),
        }
        coords = {
            "stretch": ("uniaxial", self.stretch, {"units": "1", "long_name": "uniaxial stretch"}),
            "param": ("param", names),
            "param_units": ("param", [_UNITS[k] for k in names]),
        }
        attrs = {
            "title": f"material fit ({self.law})",
            "material_law": self.law,
            "youngs_modulus_Pa": float(self.youngs_modulus),
            "paper_modulus_Pa": float(self.paper_modulus),
            "stress_sigma_Pa": float(self.stress_sigma),
            "profile_sigma_m": float(self.profile_sigma),
            "chisqr": float(self.chisqr),
            "redchi": float(self.redchi),
            "nfev": int(self.nfev),
            "success": int(self.success),
            "osmobulge_version": __version__,
        }
        return xr.Dataset(data, coords=coords, attrs=attrs)


# --------------------------------------------------------------------------- fit


def _resolve_law(law):
    if isinstance(law, Material):
        for name, (cls, _) in LAWS.items():
            if type(law) is cls:
                return name, dict(law.constants)
        raise ValueError(f"law {type(law).__name__} cannot be fitted; choose one of {sorted(LAWS)}")
    if isinstance(law, str):
        key = law.strip().lower().replace("_", "-").replace(" ", "-")
        key = {"neohookean": "neo-hookean", "mooneyrivlin": "mooney-rivlin", "gentgent": "gent-gent",
               "gent3": "gent-gent"}.get(key.replace("-", ""), key)
        if key not in LAWS:
            raise ValueError(f"law must be one of {sorted(LAWS)} or a material instance, got {law!r}")
        return key, None
    raise TypeError(f"law must be a law name or an osmobulge material instance, got {type(law).__name__}")


def _initial_guess(name, stretch, stress, jm_min):
    """Small-strain (Mooney plot) estimate of the constants from uniaxial data."""
    lam = stretch
    sel = np.abs(lam - 1.0) > 1e-3
    if sel.sum() >= 2:
        y = stress[sel] / (2.0 * (lam[sel] - lam[sel] ** -2))  # W1 + W2 / lam
        x = 1.0 / lam[sel]
        slope, icpt = np.polyfit(x, y, 1) if np.ptp(x) > 1e-6 else (0.0, float(np.mean(y)))
        total = float(np.mean(y))
    else:
        slope, icpt, total = 0.0, 1e5, 1e5
    total = max(total, 1.0)
    if slope <= 0 or icpt <= 0:
        icpt, slope = 0.7 * total, 0.3 * total
    jm = max(10.0 * jm_min, 20.0)
    guess = {
        "neo-hookean": {"c1": total},
        "mooney-rivlin": {"c1": icpt, "c2": slope},
        "gent": {"c1": total, "jm": jm},
        "gent-gent": {"c1": icpt, "c2": 3.0 * slope, "jm": jm},
    }[name]
    return guess


def fit_material(
    law,
    *,
    stretch=None,
    stress=None,
    profiles: Sequence[BulgeProfilePoints] = (),
    stress_sigma=None,
    profile_sigma=None,
    initial: dict | None = None,
    weights: str = "auto",
    max_nfev: int = 200,
) -> MaterialFit:
    r"""Fit a hyperelastic law to uniaxial tension data and bulge profile points.

    Parameters
    ----------
    law : str or Material
        ``"neo-hookean"``, ``"mooney-rivlin"``, ``"gent"`` or ``"gent-gent"``
        (the paper's Gent 3-parameter law), or an instance of one of these
        laws whose constants are the starting values.
    stretch : array_like of shape (N,)
        Uniaxial stretches :math:`\lambda > 0`.
    stress : array_like of shape (N,), Pa
        Nominal (engineering) uniaxial stresses.
    profiles : sequence of BulgeProfilePoints
        Picked points on bulge profiles, each with its chamber radius and volume.
    stress_sigma : float, Pa, optional
        Standard deviation of the stresses; default 1 % of the largest stress.
    profile_sigma : float, m, optional
        Standard deviation of the picked coordinates; default 0.5 % of the
        chamber radius.
    initial : dict, optional
        Starting values by constant name (override those of ``law``).
    weights : {"auto", "given"}
        ``"auto"`` refits once with each data set weighted by the scatter of its
        own residuals (so that the uncertainties do not depend on guessed
        sigmas); ``"given"`` keeps ``stress_sigma`` and ``profile_sigma``.
    max_nfev : int
        Largest number of residual evaluations per pass.

    Returns
    -------
    MaterialFit

    Raises
    ------
    ValueError
        Mismatched lengths, stretches <= 0, non-finite values, profiles without
        uniaxial data (a profile does not depend on the stress scale), too few
        data for the constants, or an unknown option.
    MaterialFitError
        When the optimiser does not converge.

    Notes
    -----
    Supplement Sec. 6: Eqn 57 (law), Eqn 61 (uniaxial stress, replaced by the
    correct derivation), Eqns 60 and 62 (moduli).  :math:`J_m` is bounded below
    by the largest :math:`J_1 = \lambda^2 + 2/\lambda - 3` of the uniaxial data
    (the law must not lock within the data).  A trial law that cannot reach a
    bulge's volume (Gent locking) gets a large residual for that bulge.

    Examples
    --------
    >>> import numpy as np
    >>> from osmobulge.modeling.materials import Gent
    >>> lam = np.linspace(1.05, 3.0, 12)
    >>> fit = fit_material("gent", stretch=lam, stress=Gent(3e4, 20.0).uniaxial_stress(lam))
    >>> round(fit.params["c1"]), round(fit.params["jm"], 3)
    (30000, 20.0)
    """
    name, start = _resolve_law(law)
    cls, names = LAWS[name]
    if weights not in _WEIGHTS:
        raise ValueError(f"weights must be one of {_WEIGHTS}, got {weights!r}")
    if int(max_nfev) < 1:
        raise ValueError(f"max_nfev must be >= 1, got {max_nfev!r}")

    if stretch is None or stress is None:
        raise ValueError(
            "uniaxial data (stretch and stress) are required: a bulge profile does not depend on the "
            "stress scale, so profiles alone cannot fix C1"
        )
    lam = _finite_array("stretch", stretch, "1")
    sig = _finite_array("stress", stress, "Pa")
    if lam.size != sig.size:
        raise ValueError(f"stretch and stress must have the same length, got {lam.size} and {sig.size}")
    if np.any(lam <= 0):
        raise ValueError(f"stretch must be > 0, got min {lam.min():.6g}")
    profiles = tuple(profiles)
    for i, p in enumerate(profiles):
        if not isinstance(p, BulgeProfilePoints):
            raise TypeError(f"profiles[{i}] must be a BulgeProfilePoints, got {type(p).__name__}")
    n_data = lam.size + sum(p.r.size for p in profiles)
    if n_data <= len(names):
        raise ValueError(f"{n_data} data points cannot determine the {len(names)} constants {names} of {name}")

    j1 = lam * lam + 2.0 / lam - 3.0
    jm_min = float(max(j1.max(), 0.0)) * (1.0 + 1e-6) + 1e-9
    scale = float(np.max(np.abs(sig))) if sig.size else 1.0
    if stress_sigma is None:
        stress_sigma = 0.01 * scale if scale > 0 else 1.0
    stress_sigma = float(stress_sigma)
    if not math.isfinite(stress_sigma) or stress_sigma <= 0:
        raise ValueError(f"stress_sigma must be finite and > 0 (Pa), got {stress_sigma!r}")
    radii = np.array([p.radius for p in profiles])
    if profile_sigma is None:
        profile_sigma = 0.005 * float(np.mean(radii)) if profiles else 1e-6
    profile_sigma = float(profile_sigma)
    if not math.isfinite(profile_sigma) or profile_sigma <= 0:
        raise ValueError(f"profile_sigma must be finite and > 0 (m), got {profile_sigma!r}")

    guess = _initial_guess(name, lam, sig, jm_min)
    if start:
        guess.update(start)
    if initial:
        unknown = set(initial) - set(names)
        if unknown:
            raise ValueError(f"initial has constants {sorted(unknown)} not in {name} {names}")
        guess.update({k: float(v) for k, v in initial.items()})
    if "jm" in guess and guess["jm"] <= jm_min:
        guess["jm"] = max(2.0 * jm_min, jm_min + 1.0)

    params = lmfit.Parameters()
    for k in names:
        if k == "jm":
            params.add(k, value=guess[k], min=jm_min)
        else:
            params.add(k, value=max(guess[k], 1e-3), min=0.0)

    vts = np.array([p.vtilde for p in profiles])
    ells = np.array([p.lambda_pre for p in profiles])
    pts = [p.points for p in profiles]
    n_pts = [p.r.size for p in profiles]

    solver = _MeridianSolver(vts, ells)

    def distances(material):
        try:
            curves = solver(material)
        except NoSolutionError:
            return None
        return [profile_distances(q, c) for q, c in zip(pts, curves, strict=True)]

    def make(pv):
        return cls(**{k: pv[k] for k in names})

    def residual(pv, s_sigma, p_sigma):
        try:
            material = make(pv)
        except ValueError:
            return np.full(n_data, _LOCKED_PENALTY)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            model = material.uniaxial_stress(lam)
        r_uni = (model - sig) / s_sigma
        r_uni = np.where(np.isfinite(r_uni), r_uni, _LOCKED_PENALTY)
        if not profiles:
            return r_uni
        ds = distances(material)
        if ds is None:
            return np.r_[r_uni, np.full(sum(n_pts), _LOCKED_PENALTY)]
        return np.r_[r_uni, np.concatenate([d * a / p_sigma for d, a in zip(ds, radii, strict=True)])]

    def run(pars, s_sigma, p_sigma, tol=1e-8):
        mini = lmfit.Minimizer(residual, pars, fcn_args=(s_sigma, p_sigma))
        # diff_step 1e-4: the profile residuals are smooth to ~1e-9 a, far below the noise
        return mini.minimize(method="least_squares", max_nfev=int(max_nfev), diff_step=1e-4, x_scale="jac",
                             ftol=tol, xtol=tol)

    out = run(params, stress_sigma, profile_sigma)
    nfev = int(out.nfev)
    if weights == "auto" and profiles and out.success:
        # re-weight each data set by the scatter of its own residuals, then refine
        r = out.residual
        n_u = lam.size
        dof_frac = max(1.0 - len(names) / n_data, 0.1)
        s_new = stress_sigma * float(np.sqrt(np.mean(r[:n_u] ** 2) / dof_frac)) if n_u else stress_sigma
        p_new = profile_sigma * float(np.sqrt(np.mean(r[n_u:] ** 2) / dof_frac))
        ratio = (s_new / stress_sigma) / (p_new / profile_sigma) if s_new > 0 and p_new > 0 else 1.0
        if s_new > 0 and p_new > 0:
            stress_sigma, profile_sigma = s_new, p_new
        if abs(math.log(ratio)) > math.log(1.1):
            # the relative weight changed: refine (from the optimum; a loose tolerance is enough)
            out = run(out.params, stress_sigma, profile_sigma, tol=1e-6)
            nfev += int(out.nfev)
        elif s_new > 0 and p_new > 0:
            out = run(out.params, stress_sigma, profile_sigma, tol=1e-3)  # same optimum: new covariance
            nfev += int(out.nfev)
    if not out.success:
        raise MaterialFitError(f"the {name} fit did not converge: {out.message}")

    best = {k: float(out.params[k].value) for k in names}
    errs = {k: float(out.params[k].stderr) if out.params[k].stderr is not None else float("nan") for k in names}
    material = make(best)
    cov = out.covar if getattr(out, "covar", None) is not None else None
    corr = {}
    if cov is not None:
        sd = np.sqrt(np.diag(cov))
        for i in range(len(names)):
            for j in range(i + 1, len(names)):
                corr[f"{names[i]}:{names[j]}"] = float(cov[i, j] / (sd[i] * sd[j]))

    def lin_err(coef):
        if cov is None:
            return float("nan")
        g = np.array([coef.get(k, 0.0) for k in names])
        return float(np.sqrt(g @ cov @ g))

    # 3 mu: mu = 2 (W1 + W2) at rest; W2 = C2 (Mooney-Rivlin) or C2/3 (Gent 3-parameter)
    true_coef = {"c1": 6.0, "c2": 2.0 if name == "gent-gent" else 6.0}
    paper_coef = {"c1": 6.0, "c2": 6.0}
    ds = distances(material) if profiles else []
    if ds is None:
        raise MaterialFitError("the fitted law cannot reach the volume of every bulge")
    return MaterialFit(
        law=name,
        params=best,
        stderr=errs,
        material=material,
        youngs_modulus=material.youngs_modulus,
        youngs_modulus_stderr=lin_err(true_coef),
        paper_modulus=paper_modulus(material),
        paper_modulus_stderr=lin_err(paper_coef),
        stretch=lam,
        stress=sig,
        stress_model=np.asarray(material.uniaxial_stress(lam), float),
        profiles=profiles,
        profile_residuals=tuple(d * a for d, a in zip(ds, radii, strict=True)),
        stress_sigma=stress_sigma,
        profile_sigma=profile_sigma,
        correlations=corr,
        success=bool(out.success),
        errorbars=bool(out.errorbars),
        nfev=nfev,
        chisqr=float(out.chisqr),
        redchi=float(out.redchi),
        message=str(out.message),
        jm_lower_bound=jm_min if "jm" in names else float("nan"),
        lmfit_result=out,
    )
