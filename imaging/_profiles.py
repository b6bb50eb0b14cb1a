r"""Batched bulge profiles for the synthetic renderer (many volumes in one solve).

:func:`osmobulge.modeling.bulge_profile` solves one volume per call (about 0.5 s,
dominated by Python-level loop overhead of the shooting integrator).  A
time-lapse series needs one profile per frame, so :func:`profiles` reproduces
the same computation for many volumes at once: the volume solve and the final
profile integration are vectorised over rows, exactly as
:func:`osmobulge.modeling.bulge_mechanics` does for the mechanics functions.
The result matches ``bulge_profile`` to rounding (checked in the tests); no
interpolation between volumes is involved, so there is no interpolation error.

Pure numerics: dimensionless arrays in and out, no I/O.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from osmobulge.modeling import _shooting
from osmobulge.modeling.bulge import _check_material, _check_vtilde, _solve
from osmobulge.modeling.materials import LinearElastic
from osmobulge.modeling.prestretch import check_prestretch

__all__ = ["ProfileBatch", "profiles"]


@dataclass(frozen=True)
class ProfileBatch:
    """Deformed midlines of several bulges, in units of the chamber radius ``a``.

    Attributes
    ----------
    vtilde : ndarray of shape (N,)
        Dimensionless bulge volumes :math:`\\tilde V`.
    lambda_pre : ndarray of shape (N,)
        Rim pre-stretch of each row.
    rho : ndarray of shape (M,)
        Reference radii in [0, 1] (pole to rim).
    r, z : ndarray of shape (N, M)
        Deformed midline, r/a and z/a (height above the rim plane).
    thickness : ndarray of shape (N, M)
        Thickness ratio l/l0 (Eqn 18).
    area_ratio, bulge_height, pressure : ndarray of shape (N,)
        :math:`f_A`, :math:`\\delta/a` and :math:`P_t a/(C_1 l_0)`.
    """

    vtilde: np.ndarray
    lambda_pre: np.ndarray
    rho: np.ndarray
    r: np.ndarray
    z: np.ndarray
    thickness: np.ndarray
    area_ratio: np.ndarray
    bulge_height: np.ndarray
    pressure: np.ndarray


def _hermite_rows(mesh, path, deriv, rho_ref):
    """Cubic Hermite interpolation of ``path`` (8, M, N) at ``rho_ref`` (N, K) per row."""
    n, k = rho_ref.shape
    j = np.clip(np.searchsorted(mesh, rho_ref, side="right") - 1, 0, mesh.size - 2)
    h = mesh[j + 1] - mesh[j]
    theta = (rho_ref - mesh[j]) / h
    cols = np.broadcast_to(np.arange(n)[:, None], (n, k))
    y0, y1 = path[:, j, cols], path[:, j + 1, cols]
    f0, f1 = deriv[:, j, cols], deriv[:, j + 1, cols]
    return _shooting._hermite(y0, f0, y1, f1, h, theta)


def profiles(material, vtilde, lambda_pre=1.0, *, n=401) -> ProfileBatch:
    r"""Bulge midlines for many dimensionless volumes in one vectorised solve.

    Parameters
    ----------
    material : Material
        Hyperelastic law, e.g. ``osmobulge.modeling.materials.PDMS``.
    vtilde : array_like of shape (N,)
        Dimensionless bulge volumes :math:`\tilde V = \Delta V/(\pi a^3) \geq 0`,
        any order, repeats allowed (each distinct value is solved once).
    lambda_pre : float or callable
        Rim pre-stretch, constant or a function of :math:`\tilde V`.
    n : int
        Number of reference radii ``rho`` in [0, 1].

    Returns
    -------
    ProfileBatch
        Rows in the order of ``vtilde``.  A flat row (:math:`\tilde V = 0`) has
        ``r = rho * lambda_pre``, ``z = 0`` and thickness :math:`\lambda_{pre}^{-2}`.

    Raises
    ------
    osmobulge.modeling.NoSolutionError
        For a volume at or beyond the law's locking limit.

    Notes
    -----
    Memoised (last 32 calls) when the material and ``lambda_pre`` are
    hashable; the returned arrays are then read-only.

    Same equations and the same interpolation of the shot as
    :func:`osmobulge.modeling.bulge_profile` (main text Eqns 17-24).
    """
    v_all = _check_vtilde(vtilde)
    levels, inverse = np.unique(v_all, return_inverse=True)
    key = tuple(levels.tolist())
    try:
        out = _profiles_cached(material, key, lambda_pre, int(n))
    except TypeError as err:  # unhashable material or lambda_pre
        if "unhashable" not in str(err):
            raise
        out = _profiles(material, levels, lambda_pre, n=n)
    if levels.size == v_all.size and np.all(inverse == np.arange(v_all.size)):
        return out
    return ProfileBatch(
        vtilde=out.vtilde[inverse],
        lambda_pre=out.lambda_pre[inverse],
        rho=out.rho,
        r=out.r[inverse],
        z=out.z[inverse],
        thickness=out.thickness[inverse],
        area_ratio=out.area_ratio[inverse],
        bulge_height=out.bulge_height[inverse],
        pressure=out.pressure[inverse],
    )


@functools.lru_cache(maxsize=32)
def _profiles_cached(material, v, lambda_pre, n):
    out = _profiles(material, np.asarray(v, float), lambda_pre, n=n)
    for f in ("vtilde", "lambda_pre", "rho", "r", "z", "thickness", "area_ratio", "bulge_height", "pressure"):
        getattr(out, f).setflags(write=False)
    return out


def _profiles(material, vtilde, lambda_pre=1.0, *, n=401) -> ProfileBatch:
    """Uncached :func:`profiles`."""
    _check_material(material)
    if isinstance(material, LinearElastic):
        raise TypeError("profiles need a hyperelastic law; LinearElastic has no profile")
    v_all = _check_vtilde(vtilde)
    if int(n) < 3:
        raise ValueError(f"n must be >= 3, got {n!r}")
    ell_all = check_prestretch(lambda_pre, v_all)
    rho = np.linspace(0.0, 1.0, int(n))
    keys, inverse = np.unique(np.stack([v_all, ell_all], axis=1), axis=0, return_inverse=True)
    inverse = np.asarray(inverse).ravel()
    v, ell = keys[:, 0], keys[:, 1]
    m = v.size
    r = rho[None, :] * ell[:, None]
    z = np.zeros((m, rho.size))
    thick = np.broadcast_to(ell[:, None] ** -2.0, (m, rho.size)).copy()
    area = ell**2
    height = np.zeros(m)
    press = np.zeros(m)
    pos = v > 0
    if np.any(pos):
        vp, lp = v[pos], ell[pos]
        res = _solve(material, vp, lp)
        lam0, p = res["lam0"], res["pressure"]
        shot = _shooting.shoot(material, lam0, lp, p, keep_path=True, rho_max=1.05)
        rs = shot["rho_star"]
        if not np.all(np.isfinite(rs)):
            i = int(np.argmin(np.isfinite(rs)))
            from osmobulge.modeling.bulge import NoSolutionError

            raise NoSolutionError(f"final profile integration failed at vtilde={vp[i]:.6g}")
        mesh, path = shot["rho"], shot["path"]
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            deriv = _shooting.rhs(material, mesh[:, None], path, p[None, :])
        rho_ref = rho[None, :] * rs[:, None]
        ys = _hermite_rows(mesh, path, deriv, np.maximum(rho_ref, mesh[0]))
        near = rho_ref < mesh[0]
        if np.any(near):  # within RHO_START of the pole: the series is exact to rounding
            rows, cols = np.nonzero(near)
            ys[:, rows, cols] = _shooting.pole_series(material, lam0[rows], p[rows], rho_ref[rows, cols])
        y_end = shot["y_star"]
        lxi, lphi = ys[_shooting.IXI], ys[_shooting.IPHI]
        r[pos] = lphi * rho[None, :]
        z[pos] = (y_end[_shooting.IZ][:, None] - ys[_shooting.IZ]) / rs[:, None]
        thick[pos] = 1.0 / (lxi * lphi)
        area[pos] = res["area_ratio"]
        height[pos] = res["height"]
        press[pos] = p
    return ProfileBatch(
        vtilde=v_all,
        lambda_pre=ell_all,
        rho=rho,
        r=r[inverse],
        z=z[inverse],
        thickness=thick[inverse],
        area_ratio=area[inverse],
        bulge_height=height[inverse],
        pressure=press[inverse],
    )
