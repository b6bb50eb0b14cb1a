r"""Axisymmetric hyperelastic membrane bulge: profiles and mechanics functions.

Public entry points (main text Sec. 3.3-3.5, supplement Secs 4-5):

* :func:`bulge_profile` -- the deformed membrane at one dimensionless bulge volume
  :math:`\tilde V = \Delta V/(\pi a^3)`;
* :func:`bulge_mechanics` -- :math:`f_A, f_l`, the pressure and related functions
  over many :math:`\tilde V`;
* :func:`locking_volume` -- the largest :math:`\tilde V` a locking (Gent) law reaches;
* :func:`turgor_ratio` -- :math:`f_p = P_t/E` for a chamber's :math:`l_0/a`.

All lengths are in units of the chamber radius :math:`a`, the pressure in units of
:math:`C l_0/a` where :math:`C` is ``material.stress_scale`` (:math:`C_1`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import xarray as xr

from osmobulge import __version__
from osmobulge.modeling import _shooting
from osmobulge.modeling.linear import linear_area_ratio, linear_pressure
from osmobulge.modeling.materials import LinearElastic, Material
from osmobulge.modeling.prestretch import check_prestretch

__all__ = [
    "bulge_profile",
    "bulge_profiles",
    "ProfileBatch",
    "bulge_mechanics",
    "locking_volume",
    "turgor_ratio",
    "NoSolutionError",
    "MECHANICS_ATTRS",
]


class NoSolutionError(ValueError):
    """The bulge problem has no solution for the requested input."""


MECHANICS_ATTRS = {
    "area_ratio": {"units": "1", "long_name": "membrane area ratio f_A = A/A0"},
    "inverse_thickness": {"units": "1", "long_name": "mean inverse thickness ratio f_l = <l0/l>"},
    "pressure": {"units": "1", "long_name": "dimensionless turgor pressure P_t a/(C1 l0)"},
    "lambda_bar": {"units": "1", "long_name": "average biaxial stretch sqrt(A/A0)"},
    "mean_stretch": {"units": "1", "long_name": "area-averaged biaxial stretch <sqrt(lam_xi lam_phi)> (supp. Eqn 55)"},
    "pole_thickness_ratio": {"units": "1", "long_name": "pole thickness ratio l_pole/l0"},
    "pole_stretch": {"units": "1", "long_name": "equibiaxial stretch at the pole"},
    "bulge_height": {"units": "1", "long_name": "dome height over the rim plane delta/a"},
    "lambda_pre": {"units": "1", "long_name": "rim pre-stretch lambda_pre"},
}


def _material_attrs(material) -> dict:
    attrs = {"material_law": material.law, "stress_scale_Pa": float(material.stress_scale)}
    for k, v in material.constants.items():
        attrs[f"material_{k}"] = float(v)
    attrs["nondimensionalising_modulus_Pa"] = float(material.E)
    attrs["osmobulge_version"] = __version__
    return attrs


def _check_material(material):
    if not isinstance(material, Material | LinearElastic):
        raise TypeError(
            "material must be an osmobulge.modeling.materials law (e.g. materials.PDMS), "
            f"got {type(material).__name__}"
        )


def _check_vtilde(vtilde, *, sorted_=False, name="vtilde"):
    v = np.atleast_1d(np.asarray(vtilde, dtype=float))
    if v.ndim != 1:
        raise ValueError(f"{name} must be a scalar or 1-D array, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite")
    if np.any(v < 0):
        raise ValueError(
            f"{name} must be >= 0 (bulge volume over pi a^3), got min {v.min():.6g}; "
            "an inward bulge is the mirror image of an outward one"
        )
    if sorted_ and np.any(np.diff(v) <= 0):
        raise ValueError(f"{name} must be strictly increasing")
    return v


def locking_volume(material, lambda_pre=1.0) -> float:
    r"""Largest dimensionless bulge volume :math:`\tilde V` the law can reach.

    For a Gent-type law the pole stretch approaches the equibiaxial locking
    stretch and the pressure diverges at a finite :math:`\tilde V`; for laws
    that never lock the result is ``inf``.

    Parameters
    ----------
    material : Material
        Constitutive law.
    lambda_pre : float
        Constant rim pre-stretch (>= 1).

    Returns
    -------
    float
        :math:`\tilde V_{lock}`.

    Examples
    --------
    >>> from osmobulge.modeling.materials import PDMS
    >>> round(locking_volume(PDMS), 2)
    7.21
    """
    _check_material(material)
    if isinstance(material, LinearElastic):
        return math.inf
    ell = float(check_prestretch(lambda_pre, 0.0))
    if not math.isfinite(material.locking_stretch):
        return math.inf
    return _lock_volume_cached(material, ell)


@functools.lru_cache(maxsize=256)
def _lock_volume_cached(material, ell: float) -> float:
    return float(_lock_volumes_uncached(material, np.array([ell]))[0])


def _lock_volumes(material, ell):
    """Locking volume for each rim stretch in ``ell``, memoised per (law, value)."""
    lam_lock = material.locking_stretch
    if not math.isfinite(lam_lock):
        return np.full(ell.shape, np.inf), np.full(ell.shape, np.inf)
    levels, inverse = np.unique(ell, return_inverse=True)
    if levels.size <= 4:
        vlock = np.array([_lock_volume_cached(material, float(lv)) for lv in levels])
    else:
        vlock = _lock_volumes_uncached(material, levels)
    return vlock[inverse], np.full(ell.shape, lam_lock)


def _lock_volumes_uncached(material, levels):
    return _shooting.locking_volumes(material, levels)


#: pole-stretch samples of the coarse families, as fractions of the reachable range
_FAMILY_U = np.unique(np.r_[np.geomspace(1e-9, 0.5, 28), 1.0 - np.geomspace(0.5, 1e-5, 24)])


_FAMILY_CACHE: dict = {}


def _family_curves(material, levels, top: float):
    """Coarse exact families ``q -> (ln V, ln P)`` at several rim stretches.

    Memoised per (law, level, top); the levels not yet known are solved in one vectorised call.
    """
    keys = [(material, float(lv), top) for lv in levels]
    todo = [k for k in keys if k not in _FAMILY_CACHE]
    if todo:
        lvs = np.array([k[1] for k in todo])
        lam0 = np.concatenate([lv + _FAMILY_U * (top - lv) for lv in lvs])
        fam = _shooting.family(material, lam0, np.repeat(lvs, _FAMILY_U.size), steps=80, refine=False)
        for i, key in enumerate(todo):
            sl = slice(i * _FAMILY_U.size, (i + 1) * _FAMILY_U.size)
            v, p, l0 = fam["vtilde"][sl], fam["pressure"][sl], lam0[sl]
            ok = np.isfinite(v) & (v > 0) & np.isfinite(p)
            if ok.sum() < 4:
                raise NoSolutionError(f"the {material.law} law gives no bulge solutions at lambda_pre={key[1]:.6g}")
            if len(_FAMILY_CACHE) > 2048:
                _FAMILY_CACHE.clear()
            _FAMILY_CACHE[key] = (np.log(l0[ok] - key[1]), np.log(v[ok]), np.log(p[ok]))
    return [_FAMILY_CACHE[k] for k in keys]


def _row_curves(material, ell, lam_top):
    """Coarse exact families at up to nine rim stretches, interpolated to every row."""
    # a varying pre-stretch changes the small-deflection scaling: sample it at up to 9 quantiles
    levels = np.unique(np.round(np.quantile(ell, np.linspace(0.0, 1.0, 9)), 12))
    top = float(np.min(lam_top))
    curves = _family_curves(material, levels, top)
    m = min(c[0].size for c in curves)
    qs, lnvs, lnps = (np.array([c[i][:m] for c in curves]) for i in range(3))
    if levels.size == 1:
        idx = np.zeros(ell.size, int)
        pick = lambda arr: arr[idx]  # noqa: E731
    else:
        j = np.clip(np.searchsorted(levels, ell) - 1, 0, levels.size - 2)
        w = ((ell - levels[j]) / (levels[j + 1] - levels[j]))[:, None]
        pick = lambda arr: arr[j] * (1 - w) + arr[j + 1] * w  # noqa: E731
    return _shooting.RowCurves(pick(qs), pick(lnvs), pick(lnps))


def _solve(material, vt, ell):
    """Solve for every positive target volume; return the scaled result dict."""
    vlock, lam_lock = _lock_volumes(material, ell)
    too_big = vt >= vlock
    if np.any(too_big):
        i = int(np.argmax(too_big))
        raise NoSolutionError(
            f"vtilde={vt[i]:.6g} is beyond the largest volume the {material.law} law reaches "
            f"(locking limit vtilde_lock={vlock[i]:.6g} at lambda_pre={ell[i]:.6g}); "
            "the pressure diverges there"
        )
    lam_top = np.where(np.isfinite(lam_lock), lam_lock * (1 - 1e-7), 50.0 * ell)
    curves = _row_curves(material, ell, lam_top)
    res = _shooting.solve_volumes(material, vt, ell, curves=curves, lam0_max=lam_top)
    if not np.all(res["converged"]):
        i = int(np.argmin(res["converged"]))
        raise NoSolutionError(
            f"no clamped bulge solution found for vtilde={vt[i]:.6g} at lambda_pre={ell[i]:.6g} "
            f"with the {material.law} law (shooting did not converge)"
        )
    return res


def bulge_mechanics(material, vtilde, lambda_pre=1.0) -> xr.Dataset:
    r"""Mechanics functions of the bulging membrane over dimensionless volumes.

    Parameters
    ----------
    material : Material or LinearElastic
        Constitutive law, e.g. ``materials.PDMS``; ``LinearElastic`` gives the
        closed forms of Eqns 11-13 (corrected).
    vtilde : array_like of shape (N,)
        Strictly increasing dimensionless bulge volumes
        :math:`\tilde V = \Delta V / (\pi a^3) \geq 0`.
    lambda_pre : float or callable
        Rim pre-stretch :math:`\lambda_{pre} \geq 1`, constant or a function of
        :math:`\tilde V` (e.g. :class:`~osmobulge.modeling.prestretch.PreStretch`).

    Returns
    -------
    xarray.Dataset
        Over ``vtilde``: ``area_ratio`` (:math:`f_A`), ``inverse_thickness``
        (:math:`f_l`), ``pressure`` (:math:`P_t a/(C_1 l_0)`), ``lambda_bar``
        (:math:`\sqrt{A/A_0}`), ``mean_stretch``, ``pole_thickness_ratio``,
        ``pole_stretch``, ``bulge_height`` (:math:`\delta/a`), ``lambda_pre``.

    Raises
    ------
    NoSolutionError
        For a volume at or beyond the law's locking limit (the message gives it).

    Notes
    -----
    Solves main text Eqns 19-24 with Eqn 23 corrected (disc radius squared) and
    the invariants of Eqns 15-16 corrected; see ``docs/paper-errata.md``.

    Examples
    --------
    >>> from osmobulge.modeling.materials import PDMS
    >>> ds = bulge_mechanics(PDMS, [0.5, 1.0, 2.0])
    >>> ds.area_ratio.values.round(3)
    array([1.589, 2.69 , 4.818])
    """
    _check_material(material)
    vt = _check_vtilde(vtilde, sorted_=True)
    ell = check_prestretch(lambda_pre, vt)
    n = vt.size
    out = {k: np.empty(n) for k in MECHANICS_ATTRS}
    out["lambda_pre"] = ell.copy()
    if isinstance(material, LinearElastic):
        out["area_ratio"] = linear_area_ratio(vt) * ell**2
        out["inverse_thickness"] = ell**2
        # P a / (C1 l0) with C1 = E/6
        out["pressure"] = 6.0 * linear_pressure(vt)
        out["mean_stretch"] = np.sqrt(out["area_ratio"])
        out["pole_stretch"] = np.full(n, np.nan)
        out["pole_thickness_ratio"] = np.full(n, np.nan)
        out["bulge_height"] = 2.0 * vt
    else:
        flat = vt == 0
        for k in ("area_ratio", "inverse_thickness"):
            out[k][flat] = ell[flat] ** 2
        out["pressure"][flat] = 0.0
        out["mean_stretch"][flat] = ell[flat]
        out["pole_stretch"][flat] = ell[flat]
        out["pole_thickness_ratio"][flat] = ell[flat] ** -2
        out["bulge_height"][flat] = 0.0
        if np.any(~flat):
            res = _solve(material, vt[~flat], ell[~flat])
            out["area_ratio"][~flat] = res["area_ratio"]
            out["inverse_thickness"][~flat] = res["inverse_thickness"]
            out["pressure"][~flat] = res["pressure"]
            out["mean_stretch"][~flat] = res["mean_stretch"]
            out["pole_stretch"][~flat] = res["lam0"]
            out["pole_thickness_ratio"][~flat] = res["lam0"] ** -2
            out["bulge_height"][~flat] = res["height"]
    out["lambda_bar"] = np.sqrt(out["area_ratio"])
    ds = xr.Dataset(
        {k: ("vtilde", v, dict(MECHANICS_ATTRS[k])) for k, v in out.items()},
        coords={"vtilde": ("vtilde", vt, {"units": "1", "long_name": "dimensionless bulge volume dV/(pi a^3)"})},
        attrs=_material_attrs(material)
        | {"lambda_pre": _prestretch_label(lambda_pre), "title": "membrane bulge mechanics"},
    )
    return ds


def _prestretch_label(lambda_pre) -> str:
    if callable(lambda_pre):
        return getattr(lambda_pre, "cache_key", repr(lambda_pre))
    return repr(float(lambda_pre))


def bulge_profile(material, vtilde, lambda_pre=1.0, *, n=201) -> xr.Dataset:
    r"""Deformed membrane profile at one dimensionless bulge volume.

    Parameters
    ----------
    material : Material
        Hyperelastic law (``LinearElastic`` has no profile; use a law).
    vtilde : float
        :math:`\tilde V = \Delta V/(\pi a^3) > 0`.
    lambda_pre : float or callable
        Rim pre-stretch (>= 1), constant or a function of :math:`\tilde V`.
    n : int
        Number of reference radii ``rho`` in [0, 1].

    Returns
    -------
    xarray.Dataset
        Over ``rho`` (reference radius / a): ``r`` (r/a), ``z`` (z/a, height
        above the rim plane, positive into the dome), ``lambda_xi``,
        ``lambda_phi``, ``thickness_ratio`` (l/l0), ``alpha`` (tangent angle of
        the paper's Fig. 3a, rad; > pi/2 where the dome overhangs its rim).
        attrs: ``pressure`` (:math:`P_t a/(C_1 l_0)`), ``vtilde``, ``lambda_pre``,
        ``area_ratio``, ``inverse_thickness``, ``bulge_height``, ``pole_stretch``.

    Examples
    --------
    >>> from osmobulge.modeling.materials import PDMS
    >>> p = bulge_profile(PDMS, 2/3)
    >>> float(p.z[0]) > float(p.r[-1]) * 0.9   # about a hemisphere
    True
    """
    v = _check_vtilde(vtilde)
    if v.size != 1 or v[0] <= 0:
        raise ValueError(f"vtilde must be a single positive number, got {vtilde!r}")
    if int(n) < 3:
        raise ValueError(f"n must be >= 3, got {n!r}")
    b = _profiles(material, v, lambda_pre, n=int(n))
    dims = ("rho",)
    ds = xr.Dataset(
        {
            "r": (dims, b.r[0], {"units": "1", "long_name": "radial position r/a"}),
            "z": (dims, b.z[0], {"units": "1", "long_name": "height above the rim plane z/a"}),
            "lambda_xi": (dims, b.lambda_xi[0], {"units": "1", "long_name": "meridional stretch"}),
            "lambda_phi": (dims, b.lambda_phi[0], {"units": "1", "long_name": "hoop stretch"}),
            "thickness_ratio": (dims, b.thickness[0], {"units": "1", "long_name": "thickness ratio l/l0"}),
            "alpha": (dims, b.alpha[0], {"units": "rad", "long_name": "meridian tangent angle"}),
        },
        coords={"rho": (dims, b.rho, {"units": "1", "long_name": "reference radius rho/a"})},
        attrs=_material_attrs(material)
        | {
            "vtilde": float(v[0]),
            "lambda_pre": float(b.lambda_pre[0]),
            "pressure": float(b.pressure[0]),
            "area_ratio": float(b.area_ratio[0]),
            "inverse_thickness": float(b.inverse_thickness[0]),
            "bulge_height": float(b.bulge_height[0]),
            "pole_stretch": float(b.pole_stretch[0]),
            "title": "membrane bulge profile",
        },
    )
    return ds


def _refine_factor(material, lam0):
    """Mesh refinement of the final profile shot: 4x everywhere near Gent locking."""
    lock = material.locking_stretch
    return 4 if math.isfinite(lock) and np.any((lock - np.asarray(lam0)) / lock < 1e-3) else 1


_BATCH_FIELDS = (
    "vtilde", "lambda_pre", "rho", "r", "z", "thickness", "lambda_xi", "lambda_phi", "alpha",
    "area_ratio", "bulge_height", "pressure", "pole_stretch", "inverse_thickness",
)


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
    lambda_xi, lambda_phi, alpha : ndarray of shape (N, M)
        Meridional and hoop stretches and the tangent angle of Fig. 3a (rad).
    area_ratio, bulge_height, pressure : ndarray of shape (N,)
        :math:`f_A`, :math:`\\delta/a` and :math:`P_t a/(C_1 l_0)`.
    """

    vtilde: np.ndarray
    lambda_pre: np.ndarray
    rho: np.ndarray
    r: np.ndarray
    z: np.ndarray
    thickness: np.ndarray
    lambda_xi: np.ndarray
    lambda_phi: np.ndarray
    alpha: np.ndarray
    area_ratio: np.ndarray
    bulge_height: np.ndarray
    pressure: np.ndarray
    pole_stretch: np.ndarray
    inverse_thickness: np.ndarray


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


def bulge_profiles(material, vtilde, lambda_pre=1.0, *, n=401) -> ProfileBatch:
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

    :func:`bulge_profile` is the one-volume view of this function, as an
    ``xarray.Dataset`` (main text Eqns 17-24).
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
    return ProfileBatch(**{f: (out.rho if f == "rho" else getattr(out, f)[inverse]) for f in _BATCH_FIELDS})


@functools.lru_cache(maxsize=32)
def _profiles_cached(material, v, lambda_pre, n):
    out = _profiles(material, np.asarray(v, float), lambda_pre, n=n)
    for f in _BATCH_FIELDS:
        getattr(out, f).setflags(write=False)
    return out


def _profiles(material, vtilde, lambda_pre=1.0, *, n=401) -> ProfileBatch:
    """Uncached :func:`bulge_profiles`."""
    _check_material(material)
    if isinstance(material, LinearElastic):
        raise TypeError("bulge_profile needs a hyperelastic law; LinearElastic has only closed-form f_A, f_l, f_p")
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
    lxi_all = np.broadcast_to(ell[:, None], (m, rho.size)).copy()
    lphi_all = lxi_all.copy()
    alpha = np.zeros((m, rho.size))
    area = ell**2
    inv_thick = ell**2
    pole = ell.copy()
    height = np.zeros(m)
    press = np.zeros(m)
    pos = v > 0
    if np.any(pos):
        vp, lp = v[pos], ell[pos]
        res = _solve(material, vp, lp)
        lam0, p = res["lam0"], res["pressure"]
        shot = _shooting.shoot(material, lam0, lp, p, keep_path=True, rho_max=1.05,
                               steps=_shooting.DEFAULT_STEPS * _refine_factor(material, lam0))
        rs = shot["rho_star"]
        if not np.all(np.isfinite(rs)):
            i = int(np.argmin(np.isfinite(rs)))
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
        lxi_all[pos], lphi_all[pos], alpha[pos] = lxi, lphi, ys[_shooting.IAL]
        area[pos] = res["area_ratio"]
        inv_thick[pos] = res["inverse_thickness"]
        pole[pos] = lam0
        height[pos] = res["height"]
        press[pos] = p
    return ProfileBatch(
        vtilde=v_all,
        lambda_pre=ell_all,
        rho=rho,
        r=r[inverse],
        z=z[inverse],
        thickness=thick[inverse],
        lambda_xi=lxi_all[inverse],
        lambda_phi=lphi_all[inverse],
        alpha=alpha[inverse],
        area_ratio=area[inverse],
        bulge_height=height[inverse],
        pressure=press[inverse],
        pole_stretch=pole[inverse],
        inverse_thickness=inv_thick[inverse],
    )


def turgor_ratio(pressure, material, thickness_over_radius):
    r"""Convert the dimensionless pressure to :math:`f_p = P_t / E` for a chamber.

    :math:`f_p = \tilde P\, C_1 (l_0/a) / E`, with ``material.E`` the
    nondimensionalising modulus (the paper's E for the presets).

    Parameters
    ----------
    pressure : array_like
        :math:`P_t a/(C_1 l_0)` from :func:`bulge_mechanics`.
    material : Material or LinearElastic
    thickness_over_radius : float
        :math:`l_0/a` of the chamber.
    """
    r = float(thickness_over_radius)
    if not math.isfinite(r) or r <= 0:
        raise ValueError(f"thickness_over_radius (l0/a) must be finite and > 0, got {thickness_over_radius!r}")
    return np.asarray(pressure, float) * material.stress_scale * r / material.E
