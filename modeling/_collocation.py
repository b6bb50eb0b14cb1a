r"""Second, independent solver of the membrane bulge: collocation with ``solve_bvp``.

This module exists to validate :mod:`osmobulge.modeling._shooting` (the production
solver).  It shares nothing with it but the constitutive law
(``material.membrane_tangent``): the right-hand side, the pole series, the initial
guess and the continuation are written again here from the paper's equations.

Formulation
-----------
On :math:`\rho \in [\rho_\epsilon, 1]` the state is
``y = (lam_xi, alpha, lam_phi, z, V, A, L, B)`` with main text Eqns 19-22,

.. math::

    \tilde V' = \lambda_\phi^2\rho^2\tilde z' \quad\text{(Eqn 23 corrected, errata E2)},\qquad
    A' = \lambda_\xi\lambda_\phi\rho,\quad L' = (\lambda_\xi\lambda_\phi)^2\rho,\quad
    B' = (\lambda_\xi\lambda_\phi)^{3/2}\rho ,

so that :math:`f_A = 2A(1)`, :math:`f_l = 2L(1)/f_A` (supplement Eqns 50, 52) and
the area-averaged stretch is :math:`2B(1)/f_A` (Eqn 55).  Here :math:`\tilde z`
grows from the pole to the rim, as in the paper (the membrane deflects along
:math:`-z`).  The unknown parameters are the pole stretch :math:`\lambda_0` and the
pressure :math:`\tilde P = P_t a/(C_1 l_0)`.

Boundary conditions (10 = 8 states + 2 parameters):

* at :math:`\rho_\epsilon`: :math:`\lambda_\xi, \alpha, \lambda_\phi, \tilde V, A, L, B`
  equal the pole series (errata S1) evaluated with :math:`(\lambda_0, \tilde P)`;
* at :math:`\rho = 1`: :math:`\lambda_\phi = \lambda_{pre}`, :math:`\tilde V = \tilde V_{target}`,
  :math:`\tilde z = 0`.

The solver is seeded with a spherical cap of the target volume over the rim
(uniform meridional stretch) and a Laplace-law pressure; where that fails it
continues in :math:`\tilde V` from a small volume, each step seeded by the last.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import cumulative_trapezoid, solve_bvp

from osmobulge.modeling.materials import Material

__all__ = ["solve_collocation", "pole_series", "bulge_rhs", "CollocationError"]

#: start of the collocation interval (the pole series covers [0, RHO_EPS])
RHO_EPS = 1e-4
#: tolerance of the first, cheap pass from a rough guess
LOOSE_TOL = 1e-5


class CollocationError(RuntimeError):
    """``solve_bvp`` did not converge for the requested bulge volume.

    Attributes
    ----------
    vtilde_reached : float
        Largest volume solved along the continuation path (NaN if none); at a
        Gent law's locking limit this is the locking volume.
    """

    def __init__(self, message, vtilde_reached=math.nan):
        super().__init__(message)
        self.vtilde_reached = float(vtilde_reached)


def pole_series(material, lam0, pressure, rho):
    r"""Series solution at the pole (errata S1), state ``(8, ...)`` at ``rho``.

    .. math::

        k = \frac{\tilde P\lambda_0}{2\tilde T_0},\quad
        b_2 = -\frac{\lambda_0 k^2 (3T_{11} - T_{12})}{16 T_{11}},\quad
        a_2 = 3 b_2 + \frac{\lambda_0 k^2}{2},

    :math:`\lambda_\xi = \lambda_0 + a_2\rho^2`, :math:`\lambda_\phi = \lambda_0 + b_2\rho^2`,
    :math:`\alpha = k\rho`, :math:`\tilde z = \lambda_0 k\rho^2/2`,
    :math:`\tilde V = \lambda_0^3 k\rho^4/4`, :math:`A = \lambda_0^2\rho^2/2`,
    :math:`L = \lambda_0^4\rho^2/2`, :math:`B = \lambda_0^3\rho^2/2`.

    Parameters
    ----------
    material : Material
        Constitutive law.
    lam0, pressure : float
        Pole stretch and dimensionless pressure :math:`P_t a/(C_1 l_0)`.
    rho : float or ndarray
        Reference radii (small).

    Returns
    -------
    ndarray of shape (8,) + shape of rho
    """
    rho = np.asarray(rho, float)
    t0, _, t11, t12 = (float(v) for v in material.membrane_tangent(lam0, lam0))
    k = pressure * lam0 / (2.0 * t0)
    b2 = -lam0 * k * k * (3.0 * t11 - t12) / (16.0 * t11)
    a2 = 3.0 * b2 + 0.5 * lam0 * k * k
    r2 = rho * rho
    return np.stack(
        [
            lam0 + a2 * r2,
            k * rho,
            lam0 + b2 * r2,
            0.5 * lam0 * k * r2,
            0.25 * lam0**3 * k * r2 * r2,
            0.5 * lam0**2 * r2,
            0.5 * lam0**4 * r2,
            0.5 * lam0**3 * r2,
        ]
    )


def bulge_rhs(material, rho, y, pressure):
    r"""Right-hand side of main text Eqns 19-22 plus the volume and area quadratures.

    Parameters
    ----------
    material : Material
    rho : ndarray of shape (M,)
        Reference radii (> 0).
    y : ndarray of shape (8, M)
        States ``(lam_xi, alpha, lam_phi, z, V, A, L, B)``.
    pressure : float
        :math:`P_t a/(C_1 l_0)`.

    Returns
    -------
    ndarray of shape (8, M)
    """
    lxi, al, lphi = y[0], y[1], y[2]
    t_xi, t_phi, dtxi_dlxi, dtxi_dlphi = material.membrane_tangent(lxi, lphi)
    cos_a, sin_a = np.cos(al), np.sin(al)
    dz = lxi * sin_a
    jac = lxi * lphi
    return np.stack(
        [
            # Eqn 19
            (lxi * (t_phi - t_xi) * cos_a - lphi * dtxi_dlphi * (lxi * cos_a - lphi)) / (rho * lphi * dtxi_dlxi),
            # Eqn 20
            (pressure * rho * lphi * lxi - lxi * t_phi * sin_a) / (rho * lphi * t_xi),
            # Eqn 21
            (lxi * cos_a - lphi) / rho,
            # Eqn 22
            dz,
            # Eqn 23 corrected: discs of radius lam_phi rho, squared
            lphi * lphi * rho * rho * dz,
            jac * rho,
            jac * jac * rho,
            jac * np.sqrt(jac) * rho,
        ]
    )


def _cap_guess(material, vtilde, ell, mesh):
    """Spherical cap of volume ``vtilde`` over a rim of radius ``ell``; Laplace-law pressure."""
    # cap height: h^3 + 3 ell^2 h - 6 V = 0 (one positive root)
    roots = np.roots([1.0, 0.0, 3.0 * ell * ell, -6.0 * vtilde])
    h = float(max(r.real for r in roots if abs(r.imag) < 1e-9 and r.real > 0))
    rs = (ell * ell + h * h) / (2.0 * h)
    theta = math.asin(min(ell / rs, 1.0))
    if h > ell:
        theta = math.pi - theta
    s_total = rs * theta  # uniform meridional stretch
    alpha = mesh * theta
    r = rs * np.sin(alpha)
    hh = rs * (1.0 - np.cos(alpha))
    lxi = np.full(mesh.shape, s_total)
    lphi = r / mesh
    jac = lxi * lphi
    y = np.empty((8, mesh.size))
    y[0], y[1], y[2] = lxi, alpha, lphi
    y[3] = hh - h
    y[4] = hh * hh * (3.0 * rs - hh) / 3.0
    # quadratures, started from the equibiaxial pole values (A = lam0^2 rho^2 / 2 etc.)
    for i, integrand, power in ((5, jac * mesh, 2), (6, jac * jac * mesh, 4), (7, jac * np.sqrt(jac) * mesh, 3)):
        y[i] = cumulative_trapezoid(integrand, mesh, initial=0.0) + 0.5 * s_total**power * mesh[0] ** 2
    lam_bar = math.sqrt(2.0 * rs * h)  # sqrt(cap area / A0)
    lam_lock = material.locking_stretch
    if math.isfinite(lam_lock):
        lam_bar = min(lam_bar, 1.0 + 0.95 * (lam_lock - 1.0))
    tension = float(material.membrane_tangent(lam_bar, lam_bar)[0])
    pressure = 2.0 * tension / rs
    return y, np.array([s_total, pressure])


def _default_mesh():
    return np.unique(np.r_[np.geomspace(RHO_EPS, 0.05, 25), np.linspace(0.05, 1.0, 40)])


def _solve_once(material, vtilde, ell, x, y, p, tol, max_nodes):
    """One ``solve_bvp`` call; returns the result or None if it failed."""

    def fun(rho, yy, pp):
        return bulge_rhs(material, rho, yy, pp[1])

    def bc(ya, yb, pp):
        lam0, pressure = pp
        s = pole_series(material, lam0, pressure, RHO_EPS)
        return np.array(
            [
                ya[0] - s[0],
                ya[1] - s[1],
                ya[2] - s[2],
                ya[4] - s[4],
                ya[5] - s[5],
                ya[6] - s[6],
                ya[7] - s[7],
                yb[2] - ell,
                yb[4] - vtilde,
                yb[3],
            ]
        )

    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        try:
            res = solve_bvp(fun, bc, x, y, p=p, tol=tol, bc_tol=tol * 1e-2, max_nodes=max_nodes)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            return None
    if res.status != 0 or not np.all(np.isfinite(res.p)) or not np.all(np.isfinite(res.y)):
        return None
    lam0, pressure = res.p
    if lam0 < ell or pressure <= 0:
        return None  # converged to an unphysical branch
    return res


def _solve_staged(material, vtilde, ell, x, y, p, tol, max_nodes):
    """Converge loosely first (cheap, robust from a rough guess), then refine to ``tol``."""
    res = _solve_once(material, vtilde, ell, x, y, p, max(tol, LOOSE_TOL), min(max_nodes, 5000))
    if res is None or tol >= LOOSE_TOL:
        return res
    return _solve_once(material, vtilde, ell, res.x, res.y, res.p, tol, max_nodes)


def _evaluate_ell(lambda_pre, vtilde):
    ell = float(lambda_pre(vtilde)) if callable(lambda_pre) else float(lambda_pre)
    if not math.isfinite(ell) or ell < 1.0:
        raise ValueError(f"lambda_pre must be a finite number >= 1 (rim pre-stretch), got {ell!r} at vtilde={vtilde!r}")
    return ell


def solve_collocation(material, vtilde, lambda_pre=1.0, *, tol=1e-8, n=201, max_nodes=50_000):
    r"""Solve the clamped bulge at one volume by collocation (``scipy.integrate.solve_bvp``).

    An independent check of :func:`osmobulge.modeling.bulge_mechanics` and
    :func:`osmobulge.modeling.bulge_profile` (which use shooting).

    Parameters
    ----------
    material : Material
        Hyperelastic law (``NeoHookean``, ``Gent``, ``GentGent``, ...).
    vtilde : float
        Dimensionless bulge volume :math:`\tilde V = \Delta V/(\pi a^3) > 0`.
    lambda_pre : float or callable
        Rim pre-stretch :math:`\lambda_{pre} \geq 1`, or a callable of :math:`\tilde V`
        (evaluated at ``vtilde``; along a continuation path at each step's volume).
    tol : float
        ``solve_bvp`` residual tolerance (> 0); boundary conditions are met to ``tol/100``.
        The default 1e-8 reproduces the shooting results to about 1e-9 relative
        (1e-8 for the pole stretch at very large volumes); 1e-10 needs meshes of
        several thousand nodes and seconds per volume.
    n : int
        Number of reference radii in the returned profile (>= 3).
    max_nodes : int
        Mesh-size limit handed to ``solve_bvp``.

    Returns
    -------
    dict
        Scalars ``pressure`` (:math:`P_t a/(C_1 l_0)`), ``area_ratio`` (:math:`f_A`),
        ``inverse_thickness`` (:math:`f_l`), ``mean_stretch``, ``lam0`` (pole stretch),
        ``bulge_height`` (:math:`\delta/a`), ``vtilde``, ``lambda_pre``, ``nodes``
        (final mesh size), ``continuation_steps``; arrays over ``rho`` (n points in
        [0, 1]): ``rho``, ``r``, ``z`` (height above the rim plane, > 0 in the dome),
        ``lambda_xi``, ``lambda_phi``, ``thickness_ratio``, ``alpha``; and ``sol``,
        the ``solve_bvp`` result (continuous solution ``sol.sol`` on
        :math:`[\rho_\epsilon, 1]`, paper's sign of :math:`\tilde z`).

    Raises
    ------
    ValueError
        For invalid arguments.
    CollocationError
        If ``solve_bvp`` does not converge even with continuation (e.g. at or
        beyond a Gent law's locking volume).

    Notes
    -----
    Main text Eqns 19-22 with the corrected volume equation
    :math:`d\tilde V/d\rho = \lambda_\phi^2\rho^2 d\tilde z/d\rho` (Eqn 23/48, errata E2),
    the area and inverse-thickness integrals of supplement Eqns 50 and 52, and the
    pole series S1 of ``docs/paper-errata.md`` on :math:`[0, 10^{-4}]`.

    Examples
    --------
    >>> from osmobulge.modeling.materials import NeoHookean
    >>> out = solve_collocation(NeoHookean(1.0), 0.5)
    >>> round(out["area_ratio"], 4) > 1
    True
    """
    if not isinstance(material, Material):
        raise TypeError(f"material must be a hyperelastic osmobulge law (Material), got {type(material).__name__}")
    try:
        v_target = float(vtilde)
    except (TypeError, ValueError):
        raise TypeError(f"vtilde must be a single positive number, got {vtilde!r}") from None
    if not math.isfinite(v_target) or v_target <= 0:
        raise ValueError(f"vtilde must be finite and > 0 (bulge volume over pi a^3), got {vtilde!r}")
    if not (isinstance(tol, int | float) and math.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a finite number > 0, got {tol!r}")
    if int(n) < 3:
        raise ValueError(f"n must be >= 3, got {n!r}")
    ell_target = _evaluate_ell(lambda_pre, v_target)

    mesh = _default_mesh()
    y0, p0 = _cap_guess(material, v_target, ell_target, mesh)
    res = _solve_staged(material, v_target, ell_target, mesh, y0, p0, tol, max_nodes)
    steps = 0
    if res is None:
        # continuation in vtilde (loose tolerance), seeded by a spherical cap at a smaller
        # volume (halved until the cap seed converges, e.g. when the cap would exceed a
        # Gent law's locking stretch)
        v = v_target
        while res is None:
            v *= 0.5
            if v < 1e-3:
                raise CollocationError(f"collocation failed to start from a spherical cap with the {material.law} law")
            ell = _evaluate_ell(lambda_pre, v)
            y0, p0 = _cap_guess(material, v, ell, mesh)
            res = _solve_once(material, v, ell, mesh, y0, p0, LOOSE_TOL, 5000)
        factor = 1.5
        while v < v_target:
            v_next = min(v * factor, v_target)
            ell_next = _evaluate_ell(lambda_pre, v_next)
            # re-seed on the coarse mesh so that nodes do not pile up along the path
            nxt = _solve_once(material, v_next, ell_next, mesh, res.sol(mesh), res.p, LOOSE_TOL, 5000)
            steps += 1
            if nxt is None:
                factor = 1.0 + 0.5 * (factor - 1.0)
                if factor < 1.0 + 1e-6 or steps > 400:
                    raise CollocationError(
                        f"collocation continuation stalled at vtilde={v:.6g} (target {v_target:.6g}) with the "
                        f"{material.law} law; the target may be at or beyond the locking volume",
                        vtilde_reached=v,
                    )
                continue
            res, v = nxt, v_next
            factor = min(2.0, 1.0 + 1.5 * (factor - 1.0))
        if tol < LOOSE_TOL:
            res = _solve_once(material, v_target, ell_target, res.x, res.y, res.p, tol, max_nodes)
            if res is None:
                raise CollocationError(
                    f"collocation did not reach tol={tol:.3g} at vtilde={v_target:.6g} with the {material.law} law",
                    vtilde_reached=v_target,
                )

    lam0, pressure = (float(q) for q in res.p)
    y_end = res.y[:, -1]
    area = 2.0 * y_end[5]
    z_pole = float(pole_series(material, lam0, pressure, RHO_EPS)[3])  # z(eps) - z(0)
    z0 = res.y[3, 0] - z_pole  # paper's z at the pole (negative: the dome points along -z)
    rho = np.linspace(0.0, 1.0, int(n))
    ys = np.empty((8, rho.size))
    inside = rho >= RHO_EPS
    ys[:, inside] = res.sol(rho[inside])
    ys[:, ~inside] = pole_series(material, lam0, pressure, rho[~inside])
    ys[3, ~inside] += z0
    lxi, al, lphi = ys[0], ys[1], ys[2]
    return {
        "vtilde": v_target,
        "lambda_pre": ell_target,
        "pressure": pressure,
        "lam0": lam0,
        "area_ratio": float(area),
        "inverse_thickness": float(2.0 * y_end[6] / area),
        "mean_stretch": float(2.0 * y_end[7] / area),
        "bulge_height": float(-z0),
        "nodes": int(res.x.size),
        "continuation_steps": steps,
        "rho": rho,
        "r": lphi * rho,
        "z": -ys[3],
        "lambda_xi": lxi,
        "lambda_phi": lphi,
        "thickness_ratio": 1.0 / (lxi * lphi),
        "alpha": al,
        "sol": res,
    }
