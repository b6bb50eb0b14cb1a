r"""Vectorised shooting solver for the axisymmetric membrane bulge (Eqns 19-24).

Pure numerics: dimensionless arrays in, dimensionless arrays out; no I/O.

Formulation
-----------
State along the reference radius :math:`\rho`:
``y = (lam_xi, alpha, lam_phi, z, V, A, L, B)`` with

* Eqn 19-22 for :math:`\lambda_\xi, \alpha, \lambda_\phi, \tilde z` (derived again
  in ``docs/paper-errata.md``; the paper's forms are right);
* :math:`d\tilde V/d\rho = \lambda_\phi^2 \rho^2\, d\tilde z/d\rho` (Eqn 23 corrected:
  discs of radius :math:`\tilde r = \lambda_\phi\rho`, squared);
* quadratures :math:`A' = \lambda_\xi\lambda_\phi\rho`, :math:`L' = (\lambda_\xi\lambda_\phi)^2\rho`,
  :math:`B' = (\lambda_\xi\lambda_\phi)^{3/2}\rho` for the area (Eqn 50), the mean inverse
  thickness (Eqn 52) and the area-averaged biaxial stretch (Eqn 55).

Here :math:`\tilde z` grows from the pole to the rim (the paper's membrane
deflects along :math:`-z`); the public API flips it so the dome height is positive.

Scaling trick
-------------
If :math:`y(\rho)` solves the equations with pressure :math:`\tilde P`, then
:math:`y(\rho^*\sigma)` solves them in :math:`\sigma` with pressure :math:`\rho^*\tilde P`
(only the pressure term of Eqn 20 lacks a :math:`1/\rho`).  So a single
integration from the pole with a trial pressure, stopped where
:math:`\lambda_\phi = \lambda_{pre}`, *is* an exact clamped solution after
rescaling lengths by :math:`\rho^*`.  The only unknown left per bulge volume is the
pole stretch :math:`\lambda_0`, found by a safeguarded secant iteration on the
monotone map :math:`\lambda_0 \mapsto \tilde V`, for all requested volumes at once.

The pole is a regular singular point; integration starts at a small
:math:`\rho_\epsilon` from the series solution derived in ``docs/paper-errata.md``
(S1) and uses a mesh graded geometrically away from the pole, so the explicit
fixed-step RK4 stays stable where the :math:`1/\rho` terms are stiff.
"""

from __future__ import annotations

import math

import numpy as np

N_STATE = 8
IXI, IAL, IPHI, IZ, IV, IA, IL, IB = range(N_STATE)

#: default number of uniform RK4 steps over the unit reference radius
DEFAULT_STEPS = 160
#: start of the integration, as a fraction of the (scaled) reference radius
RHO_START = 1e-5
#: geometric grading near the pole: h <= GRADING * rho
GRADING = 0.2


class ShootingError(RuntimeError):
    """No clamped solution was found for some rows."""


def _mesh(rho_end: float, steps: int) -> np.ndarray:
    """Mesh from RHO_START to ``rho_end`` graded at the pole, uniform (1/steps) after."""
    h = 1.0 / steps
    pts = [RHO_START]
    r = RHO_START
    while r < rho_end - 1e-15:
        r = min(r + min(h, GRADING * r), rho_end)
        pts.append(r)
    return np.asarray(pts)


def pole_series(material, lam0, pressure, rho):
    r"""State at small ``rho`` from the series solution about the pole.

    With :math:`k = \alpha'(0) = \tilde P\lambda_0 / (2 \tilde T_0)`,
    :math:`\lambda_\phi = \lambda_0 + b_2\rho^2`,
    :math:`\lambda_\xi = \lambda_0 + a_2\rho^2`,
    :math:`b_2 = -\lambda_0 k^2 (3 T_{11} - T_{12}) / (16 T_{11})`,
    :math:`a_2 = 3 b_2 + \lambda_0 k^2 / 2`, where :math:`T_{11} = \partial\tilde T_\xi/\partial\lambda_\xi`
    and :math:`T_{12} = \partial\tilde T_\xi/\partial\lambda_\phi` at the equibiaxial pole.
    """
    lam0 = np.asarray(lam0, float)
    pressure = np.asarray(pressure, float)
    t0, _, t11, t12 = material.membrane_tangent(lam0, lam0)
    k = pressure * lam0 / (2.0 * t0)
    b2 = -lam0 * k * k * (3.0 * t11 - t12) / (16.0 * t11)
    a2 = 3.0 * b2 + 0.5 * lam0 * k * k
    r2 = rho * rho
    y = np.empty((N_STATE,) + lam0.shape)
    y[IXI] = lam0 + a2 * r2
    y[IAL] = k * rho
    y[IPHI] = lam0 + b2 * r2
    y[IZ] = 0.5 * lam0 * k * r2
    y[IV] = 0.25 * lam0**3 * k * r2 * r2
    y[IA] = 0.5 * lam0**2 * r2
    y[IL] = 0.5 * lam0**4 * r2
    y[IB] = 0.5 * lam0**3 * r2
    return y


def rhs(material, rho, y, pressure):
    """Right-hand side of the bulge equations, vectorised over the last axis."""
    lxi, al, lphi = y[IXI], y[IAL], y[IPHI]
    t1, t2, t11, t12 = material.membrane_tangent(lxi, lphi)
    c, s = np.cos(al), np.sin(al)
    lxc = lxi * c
    dlphi = (lxc - lphi) / rho
    dlxi = (lxi * (t2 - t1) * c - lphi * t12 * (lxc - lphi)) / (rho * lphi * t11)
    dal = pressure * lxi / t1 - lxi * t2 * s / (rho * lphi * t1)
    dz = lxi * s
    j = lxi * lphi
    out = np.empty_like(y)
    out[IXI] = dlxi
    out[IAL] = dal
    out[IPHI] = dlphi
    out[IZ] = dz
    out[IV] = lphi * lphi * rho * rho * dz
    out[IA] = j * rho
    out[IL] = j * j * rho
    out[IB] = j * np.sqrt(j) * rho
    return out


def _hermite(y0, f0, y1, f1, h, theta):
    """Cubic Hermite interpolation on a step of length h at fraction theta."""
    t = theta
    h00 = (1 + 2 * t) * (1 - t) ** 2
    h10 = t * (1 - t) ** 2
    h01 = t * t * (3 - 2 * t)
    h11 = t * t * (t - 1)
    return h00 * y0 + h10 * h * f0 + h01 * y1 + h11 * h * f1


def shoot(material, lam0, ell, pressure, *, steps=DEFAULT_STEPS, rho_max=4.0, keep_path=False):
    r"""Integrate from the pole until :math:`\lambda_\phi` falls to ``ell``.

    Parameters
    ----------
    material : Material
        Constitutive law (supplies ``membrane_tangent``).
    lam0, ell, pressure : ndarray of shape (N,)
        Pole stretch, rim stretch :math:`\lambda_{pre}` and trial pressure
        :math:`\tilde P` (any positive value; ideally the solution's, so that the
        crossing falls near :math:`\rho = 1` and is resolved by ``steps`` steps).
    steps : int
        RK4 steps per unit reference radius.
    rho_max : float
        Give up on rows whose crossing lies beyond this radius.
    keep_path : bool
        Also return the states at every mesh node (for profiles).

    Returns
    -------
    dict of ndarray
        ``rho_star`` (NaN where no crossing), and the state at the crossing
        ``y_star`` of shape (8, N); with ``keep_path``, ``rho`` and ``path``.
    """
    lam0 = np.atleast_1d(np.asarray(lam0, float))
    ell = np.broadcast_to(np.asarray(ell, float), lam0.shape).copy()
    pressure = np.broadcast_to(np.asarray(pressure, float), lam0.shape).copy()
    n = lam0.size
    mesh = _mesh(rho_max, steps)
    y = pole_series(material, lam0, pressure, mesh[0])
    rho_star = np.full(n, np.nan)
    y_star = np.full((N_STATE, n), np.nan)
    active = np.arange(n)
    path = [y.copy()] if keep_path else None
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        f = rhs(material, mesh[0], y, pressure)
        for j in range(len(mesh) - 1):
            if active.size == 0:
                break
            r0, h = mesh[j], mesh[j + 1] - mesh[j]
            ya, fa, p = y[:, active], f[:, active], pressure[active]
            k2 = rhs(material, r0 + 0.5 * h, ya + 0.5 * h * fa, p)
            k3 = rhs(material, r0 + 0.5 * h, ya + 0.5 * h * k2, p)
            k4 = rhs(material, r0 + h, ya + h * k3, p)
            yb = ya + (h / 6.0) * (fa + 2.0 * k2 + 2.0 * k3 + k4)
            fb = rhs(material, r0 + h, yb, p)
            bad = ~np.all(np.isfinite(fb), axis=0) | ~np.all(np.isfinite(yb), axis=0)
            crossed = (yb[IPHI] <= ell[active]) & ~bad
            if np.any(crossed):
                idx = np.nonzero(crossed)[0]
                a, fa_c, b, fb_c = ya[:, idx], fa[:, idx], yb[:, idx], fb[:, idx]
                target = ell[active[idx]]
                lo = np.zeros(idx.size)
                hi = np.ones(idx.size)
                # bisection then Newton-free refinement on the Hermite cubic of lam_phi
                for _ in range(60):
                    mid = 0.5 * (lo + hi)
                    val = _hermite(a[IPHI], fa_c[IPHI], b[IPHI], fb_c[IPHI], h, mid)
                    above = val > target
                    lo = np.where(above, mid, lo)
                    hi = np.where(above, hi, mid)
                theta = 0.5 * (lo + hi)
                rows = active[idx]
                rho_star[rows] = r0 + theta * h
                y_star[:, rows] = _hermite(a, fa_c, b, fb_c, h, theta)
            y[:, active] = yb
            f[:, active] = fb
            if keep_path:
                path.append(y.copy())
            # rows that crossed are done; rows that broke down are dropped (NaN)
            keep = ~(crossed | bad)
            active = active[keep]
    out = {"rho_star": rho_star, "y_star": y_star}
    if keep_path:
        out["rho"] = mesh[: len(path)]
        out["path"] = np.stack(path, axis=1)  # (8, M, N)
    return out


def shoot_refined(material, lam0, ell, pressure, *, steps=DEFAULT_STEPS, rho_max=4.0):
    """:func:`shoot`, with rows close to Gent locking integrated on finer meshes.

    Near locking the pole region becomes very stiff; rows whose pole stretch lies within
    1e-3 (1e-4) of the locking stretch use 4x (16x) the steps, which keeps the error of the
    volume and pressure below ~1e-8 relative down to 1e-5 from the lock.
    """
    lam0 = np.atleast_1d(np.asarray(lam0, float))
    ell = np.broadcast_to(np.asarray(ell, float), lam0.shape)
    pressure = np.broadcast_to(np.asarray(pressure, float), lam0.shape)
    lock = material.locking_stretch
    gap = (lock - lam0) / lock if math.isfinite(lock) else np.full(lam0.shape, np.inf)
    factor = np.where(gap < 1e-4, 16, np.where(gap < 1e-3, 4, 1))
    out = {"rho_star": np.full(lam0.shape, np.nan), "y_star": np.full((N_STATE, lam0.size), np.nan)}
    for f in np.unique(factor):
        rows = np.nonzero(factor == f)[0]
        shot = shoot(material, lam0[rows], ell[rows], pressure[rows], steps=int(f) * steps, rho_max=rho_max)
        out["rho_star"][rows] = shot["rho_star"]
        out["y_star"][:, rows] = shot["y_star"]
    return out


def scaled_results(lam0, pressure, shot):
    """Dimensionless results for the unit-radius membrane from a shot.

    Returns a dict of arrays: ``vtilde``, ``pressure``, ``area_ratio``,
    ``inverse_thickness``, ``mean_stretch``, ``height``, ``edge_lam_xi``,
    ``edge_alpha``, ``lam0``.
    """
    rs = shot["rho_star"]
    y = shot["y_star"]
    area = 2.0 * y[IA] / rs**2
    return {
        "lam0": np.asarray(lam0, float),
        "vtilde": y[IV] / rs**3,
        "pressure": np.asarray(pressure, float) * rs,
        "area_ratio": area,
        "inverse_thickness": 2.0 * y[IL] / rs**2 / area,
        "mean_stretch": 2.0 * y[IB] / rs**2 / area,
        "height": y[IZ] / rs,
        "edge_lam_xi": y[IXI],
        "edge_alpha": y[IAL],
    }


def pressure_guess(material, lam0, ell):
    """Trial pressure putting the rim crossing near rho = 1 (small-deflection series)."""
    lam0 = np.asarray(lam0, float)
    t0, _, t11, t12 = material.membrane_tangent(lam0, lam0)
    k2 = 16.0 * t11 * (lam0 - ell) / (lam0 * (3.0 * t11 - t12))
    return 2.0 * t0 * np.sqrt(np.maximum(k2, 0.0)) / lam0


def family(material, lam0, ell, *, steps=DEFAULT_STEPS, passes=2, refine=True):
    """Exact clamped solutions for given pole stretches (no root finding).

    Two passes: the second re-runs each row with the pressure found by the
    first, so that every crossing falls at rho ~ 1 and is fully resolved.
    ``refine=False`` skips the finer meshes near locking (for initial guesses).
    """
    lam0 = np.asarray(lam0, float)
    ell = np.broadcast_to(np.asarray(ell, float), lam0.shape)
    p = pressure_guess(material, lam0, ell)
    res = None
    for i in range(passes):
        integrate = shoot_refined if refine else shoot
        shot = integrate(material, lam0, ell, p, steps=steps, rho_max=8.0 if i == 0 else 1.5)
        res = scaled_results(lam0, p, shot)
        ok = np.isfinite(res["pressure"])
        p = np.where(ok, res["pressure"], p)
    return res


class RowCurves:
    """Per-row monotone curves ``q -> (ln V, ln P)`` from coarse exact families.

    ``q = ln(lam0 - lambda_pre)``.  Used for initial guesses, secant slopes and
    trial pressures, so that every shot crosses the rim near rho = 1.
    """

    def __init__(self, q, lnv, lnp):
        self.q, self.lnv, self.lnp = (np.asarray(a, float) for a in (q, lnv, lnp))

    def _interp(self, x, xs, ys):
        # vectorised per-row linear interpolation with linear extrapolation
        n, m = xs.shape
        idx = np.clip((xs < x[:, None]).sum(axis=1), 1, m - 1)
        rows = np.arange(n)
        x0, x1 = xs[rows, idx - 1], xs[rows, idx]
        y0, y1 = ys[rows, idx - 1], ys[rows, idx]
        w = (x - x0) / (x1 - x0)
        return y0 + w * (y1 - y0), (y1 - y0) / (x1 - x0)

    def q_of_lnv(self, lnv):
        return self._interp(lnv, self.lnv, self.q)[0]

    def lnp_of_q(self, q):
        return self._interp(q, self.q, self.lnp)[0]

    def slope(self, q):
        return self._interp(q, self.q, self.lnv)[1]


def solve_volumes(
    material,
    vtilde,
    ell,
    *,
    curves,
    lam0_max,
    steps=DEFAULT_STEPS,
    rtol=1e-11,
    maxiter=80,
):
    r"""Find the pole stretch for each target volume; return the scaled results.

    Safeguarded secant iteration on :math:`\ln\tilde V` against
    :math:`q = \ln(\lambda_0 - \lambda_{pre})`, vectorised over targets, with a
    bracket kept for every row so that it cannot leave
    :math:`(\lambda_{pre}, \lambda_{max})`.  ``curves`` (:class:`RowCurves`)
    supplies the initial guess, first slope and trial pressures.
    """
    vt = np.asarray(vtilde, float)
    ell = np.broadcast_to(np.asarray(ell, float), vt.shape).astype(float)
    lam_max = np.broadcast_to(np.asarray(lam0_max, float), vt.shape).astype(float)
    target = np.log(vt)
    q_lo = np.log(1e-14 * ell)
    q_hi = np.log(lam_max - ell)
    q = np.clip(curves.q_of_lnv(target), q_lo, q_hi)
    converged = np.zeros(vt.shape, bool)
    q_prev = np.full(vt.shape, np.nan)
    g_prev = np.full(vt.shape, np.nan)
    result = {k: np.full(vt.shape, np.nan) for k in (
        "lam0", "vtilde", "pressure", "area_ratio", "inverse_thickness",
        "mean_stretch", "height", "edge_lam_xi", "edge_alpha")}
    for _ in range(maxiter):
        todo = np.nonzero(~converged)[0]
        if todo.size == 0:
            break
        qt, et = q[todo], ell[todo]
        lam0 = et + np.exp(qt)
        p = np.exp(curves.lnp_of_q(q)[todo])
        shot = shoot_refined(material, lam0, et, p, steps=steps, rho_max=3.0)
        res = scaled_results(lam0, p, shot)
        ok = np.isfinite(res["vtilde"]) & (res["vtilde"] > 0)
        # Rows without a crossing had a poor trial pressure (the crossing lies beyond rho_max):
        # retry with the small-deflection series pressure, then with a generous radius.
        for p_retry, rmax in ((pressure_guess(material, lam0, et), 3.0), (p, 8.0)):
            if ok.all():
                break
            redo = np.nonzero(~ok)[0]
            shot2 = shoot_refined(material, lam0[redo], et[redo], p_retry[redo], steps=steps, rho_max=rmax)
            res2 = scaled_results(lam0[redo], p_retry[redo], shot2)
            for k in res:
                res[k][redo] = res2[k]
            ok = np.isfinite(res["vtilde"]) & (res["vtilde"] > 0)
        g = np.where(ok, np.log(np.where(ok, res["vtilde"], 1.0)) - target[todo], np.inf)
        # rows that broke down are past locking: shrink the bracket from above
        q_hi[todo] = np.where(g > 0, np.minimum(q_hi[todo], qt), q_hi[todo])
        q_lo[todo] = np.where(g < 0, np.maximum(q_lo[todo], qt), q_lo[todo])
        for k, v in res.items():
            result[k][todo] = np.where(ok, v, result[k][todo])
        # ln V cannot be resolved better than the round-off of lam0 = ell + exp(q) allows
        floor = 16.0 * np.finfo(float).eps * lam0 / np.exp(qt) * np.abs(curves.slope(q)[todo])
        conv_t = ok & (np.abs(g) < np.maximum(rtol, floor))
        converged[todo] = conv_t
        # secant slope, falling back to the coarse family's slope
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = (g - g_prev[todo]) / (qt - q_prev[todo])
        fallback = curves.slope(q)[todo]
        slope = np.where(np.isfinite(slope) & (slope > 1e-9), slope, fallback)
        slope = np.where(slope > 1e-9, slope, 0.5)
        q_new = qt - np.where(np.isfinite(g), g, 0.0) / slope
        bisect = 0.5 * (q_lo[todo] + q_hi[todo])
        outside = ~np.isfinite(q_new) | (q_new <= q_lo[todo]) | (q_new >= q_hi[todo]) | ~ok
        q_new = np.where(outside, bisect, q_new)
        q_prev[todo] = np.where(ok, qt, np.nan)
        g_prev[todo] = np.where(ok, g, np.nan)
        q[todo] = np.where(conv_t, qt, q_new)
    result["converged"] = converged
    return result


#: distances below the locking stretch (relative) used to extrapolate the locking volume
_LOCK_EPS = np.array([1e-2, 5e-3, 2.5e-3, 1.25e-3])


def locking_volumes(material, ell, *, steps=DEFAULT_STEPS):
    """Largest bulge volume reachable before the pole locks, for each rim stretch in ``ell``.

    ``inf`` for laws that never lock.  Near locking the pressure diverges like
    ``1/(V_lock - V)`` (checked in the tests), so V is a smooth function of 1/P: a cubic
    through four exact solutions 1e-2 ... 1.25e-3 (relative) below the locking stretch is
    extrapolated to 1/P = 0.  Agrees with solutions 1e-5 from the lock to ~1e-8.
    """
    ell = np.atleast_1d(np.asarray(ell, float))
    lam_lock = material.locking_stretch
    if not math.isfinite(lam_lock):
        return np.full(ell.shape, np.inf)
    k = _LOCK_EPS.size
    res = family(material, np.tile(lam_lock * (1 - _LOCK_EPS), ell.size), np.repeat(ell, k), steps=steps)
    v = res["vtilde"].reshape(ell.size, k)
    x = 1.0 / res["pressure"].reshape(ell.size, k)
    if not np.all(np.isfinite(v) & np.isfinite(x)):
        raise ShootingError("could not integrate close to the locking stretch")
    return np.array([np.polyval(np.polyfit(xi, vi, k - 1), 0.0) for xi, vi in zip(x, v, strict=True)])


def locking_volume(material, ell, *, steps=DEFAULT_STEPS) -> float:
    """Scalar version of :func:`locking_volumes`."""
    return float(locking_volumes(material, [float(ell)], steps=steps)[0])
