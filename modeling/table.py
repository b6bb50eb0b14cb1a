r"""Cached, interpolated mechanics tables :math:`f_A, f_l, \tilde P(\tilde V)`.

The flux ODE evaluates the mechanics functions thousands of times; it must
never re-solve the bulge problem.  :func:`mechanics_table` solves once on a
Chebyshev-Lobatto grid in :math:`\tilde V` (dense at both ends: the
small-deflection start and the stiffening near Gent locking), fits cubic
splines, and keeps the solved nodes in an on-disk cache keyed by law,
constants, pre-stretch, grid and code version.

Cache location: ``$OSMOBULGE_CACHE_DIR`` if set, else the user cache directory
(``platformdirs.user_cache_dir("osmobulge")``).  Set ``cache=False`` to bypass.
The cache is the only file I/O in :mod:`osmobulge.modeling`; writes are atomic.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import math
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import xarray as xr
from scipy.interpolate import CubicSpline

from osmobulge import __version__
from osmobulge.modeling.bulge import MECHANICS_ATTRS, _check_material, bulge_mechanics, locking_volume
from osmobulge.modeling.materials import LinearElastic

__all__ = ["MechanicsTable", "mechanics_table", "cache_dir", "TABLE_SCHEMA"]

#: bump when the solver or the table layout changes, to invalidate old caches
TABLE_SCHEMA = 2
_QUANTITIES = ("area_ratio", "inverse_thickness", "pressure", "lambda_bar", "pole_thickness_ratio", "lambda_pre")


def cache_dir() -> Path:
    """Directory of the on-disk mechanics cache."""
    env = os.environ.get("OSMOBULGE_CACHE_DIR")
    if env:
        return Path(env)
    import platformdirs

    return Path(platformdirs.user_cache_dir("osmobulge"))


@functools.lru_cache(maxsize=1)
def _solver_code_hash() -> str:
    """Hash of the solver sources, so a changed solver never reuses stale cached tables."""
    here = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for name in ("materials.py", "_shooting.py", "bulge.py", "linear.py", "prestretch.py", "table.py"):
        h.update((here / name).read_bytes())
    return h.hexdigest()[:16]


def _prestretch_key(lambda_pre, vtilde_end: float) -> str:
    if not callable(lambda_pre):
        return f"const:{float(lambda_pre)!r}"
    key = getattr(lambda_pre, "cache_key", None)
    if key is not None:
        return str(key)
    # arbitrary callable: identify it by its values on a fixed sample
    sample = np.asarray(lambda_pre(np.linspace(0.0, vtilde_end, 97)), float)
    return "samples:" + hashlib.sha256(sample.tobytes()).hexdigest()


class MechanicsTable:
    r"""Spline interpolant of the bulge mechanics over :math:`[0, \tilde V_{max}]`.

    Build with :func:`mechanics_table`.  Calling the quantity methods outside
    the table raises ``ValueError`` (never extrapolates).

    Attributes
    ----------
    vtilde : ndarray of shape (N,)
        Solved nodes.
    data : dict of ndarray
        Solved values at the nodes (keys as in :func:`bulge_mechanics`).
    vtilde_max : float
        Upper end of the table.
    vtilde_lock : float
        Locking volume of the law (``inf`` if it never locks).
    """

    def __init__(self, vtilde, data, *, material, lambda_pre_key, vtilde_lock):
        self.vtilde = np.asarray(vtilde, float)
        self.data = {k: np.asarray(v, float) for k, v in data.items()}
        self.material = material
        self.lambda_pre_key = lambda_pre_key
        self.vtilde_lock = float(vtilde_lock)
        self.vtilde_max = float(self.vtilde[-1])
        # quantities that are not defined for a law (NaN, e.g. the pole of the linear membrane) get no spline
        self._splines = {
            k: CubicSpline(self.vtilde, v) for k, v in self.data.items() if k != "pressure" and np.all(np.isfinite(v))
        }
        # The pressure rises like V^3 for a slack rim (Foppl-Hencky) but like V for a pre-stretched one,
        # and diverges at Gent locking: a cubic spline of ln P against ln V is smooth in every regime.
        pos = self.vtilde > 0
        lv, lp = np.log(self.vtilde[pos]), np.log(self.data["pressure"][pos])
        self._lnv_first = lv[0]
        self._lnp_spline = CubicSpline(lv, lp)
        self._lnp_slope0 = float((lp[1] - lp[0]) / (lv[1] - lv[0]))  # local power law at the smallest nodes

    def _eval(self, name, vtilde):
        v = np.asarray(vtilde, float)
        if np.any(v < 0) or np.any(v > self.vtilde_max * (1 + 1e-12)) or np.any(~np.isfinite(v)):
            bad = v[(v < 0) | (v > self.vtilde_max) | ~np.isfinite(v)]
            raise ValueError(
                f"vtilde={bad.flat[0]!r} outside the mechanics table [0, {self.vtilde_max:.6g}]"
                + (f" (the {self.material.law} law locks at {self.vtilde_lock:.6g})"
                   if math.isfinite(self.vtilde_lock) else "")
            )
        if name == "pressure":
            with np.errstate(divide="ignore"):
                lv = np.log(v)
            below = lv < self._lnv_first
            # below the smallest node: the power law of the two smallest nodes (small-deflection limit)
            lnp = np.where(
                below,
                self._lnp_spline(self._lnv_first) + self._lnp_slope0 * (lv - self._lnv_first),
                self._lnp_spline(np.maximum(lv, self._lnv_first)),
            )
            out = np.where(v > 0, np.exp(lnp), 0.0)
        elif name in self._splines:
            out = self._splines[name](v)
        else:
            raise ValueError(f"{name} is not defined for the {self.material.law} law")
        return float(out) if out.ndim == 0 else out

    def area_ratio(self, vtilde):
        """:math:`f_A(\\tilde V) = A/A_0`."""
        return self._eval("area_ratio", vtilde)

    def inverse_thickness(self, vtilde):
        """:math:`f_l(\\tilde V) = \\langle l_0/l\\rangle`."""
        return self._eval("inverse_thickness", vtilde)

    def pressure(self, vtilde):
        """Dimensionless pressure :math:`P_t a/(C_1 l_0)`."""
        return self._eval("pressure", vtilde)

    def lambda_bar(self, vtilde):
        """Average biaxial stretch :math:`\\sqrt{A/A_0}`."""
        return self._eval("lambda_bar", vtilde)

    def turgor_pressure(self, vtilde, *, thickness, radius):
        """Turgor pressure in Pa for a membrane of thickness ``l0`` (m) over radius ``a`` (m)."""
        return self.pressure(vtilde) * self.material.stress_scale * thickness / radius

    def to_dataset(self) -> xr.Dataset:
        """The solved nodes as an ``xarray.Dataset`` over ``vtilde``."""
        return xr.Dataset(
            {k: ("vtilde", v, dict(MECHANICS_ATTRS[k])) for k, v in self.data.items()},
            coords={"vtilde": ("vtilde", self.vtilde,
                               {"units": "1", "long_name": "dimensionless bulge volume dV/(pi a^3)"})},
            attrs={"material_law": self.material.law, "lambda_pre": self.lambda_pre_key},
        )

    def __repr__(self):
        return (f"MechanicsTable({self.material!r}, lambda_pre={self.lambda_pre_key}, "
                f"vtilde in [0, {self.vtilde_max:.4g}], {self.vtilde.size} nodes)")


def _grid(vtilde_end: float, n: int) -> np.ndarray:
    """Chebyshev-Lobatto nodes on [0, vtilde_end], plus 20 log-spaced nodes from 1e-5 to 2 % of it.

    The log-spaced nodes resolve the small-deflection power laws of the pressure (P ~ V^3
    for a slack rim, ~ V or V^2 with pre-stretch, and the crossover between them) for the
    log-log spline.
    """
    k = np.arange(n)
    cheb = vtilde_end * 0.5 * (1.0 - np.cos(np.pi * k / (n - 1)))
    low = np.geomspace(min(1e-5, cheb[1] / 10.0), 0.02 * vtilde_end, 20)
    return np.unique(np.r_[cheb, low])


def mechanics_table(material, lambda_pre=1.0, *, vtilde_max=None, n=160, cache=True) -> MechanicsTable:
    r"""Solve (or load from cache) an interpolated mechanics table.

    Parameters
    ----------
    material : Material or LinearElastic
        Constitutive law.
    lambda_pre : float or callable
        Rim pre-stretch, constant or a function of :math:`\tilde V`.
    vtilde_max : float, optional
        Upper end; default 99 % of the locking volume (Gent laws) or 12.
    n : int
        Number of Chebyshev nodes (>= 8); 20 log-spaced nodes at small volumes are added.
    cache : bool
        Use the on-disk cache.

    Returns
    -------
    MechanicsTable

    Examples
    --------
    >>> from osmobulge.modeling.materials import PDMS
    >>> t = mechanics_table(PDMS, vtilde_max=4.0, cache=False)
    >>> round(float(t.area_ratio(2.0)), 3)
    4.475
    """
    _check_material(material)
    if int(n) < 8:
        raise ValueError(f"n must be >= 8, got {n!r}")
    n = int(n)
    if vtilde_max is not None:
        vtilde_max = float(vtilde_max)
        if not math.isfinite(vtilde_max) or vtilde_max <= 0:
            raise ValueError(f"vtilde_max must be finite and > 0, got {vtilde_max!r}")
    key_fields = {
        "law": material.law,
        "constants": material.constants,
        "E": float(material.E),
        "lambda_pre": _prestretch_key(lambda_pre, vtilde_max or 12.0),
        "vtilde_max": "auto" if vtilde_max is None else vtilde_max,
        "n": n,
        "version": __version__,
        "schema": TABLE_SCHEMA,
        "code": _solver_code_hash(),
    }
    key = hashlib.sha256(json.dumps(key_fields, sort_keys=True).encode()).hexdigest()[:32]
    path = cache_dir() / f"mechanics-{key}.npz"
    data = None
    if cache and path.exists():
        try:
            with np.load(path, allow_pickle=False) as f:
                grid = f["vtilde"]
                vlock = float(f["vtilde_lock"])
                data = {q: f[q] for q in _QUANTITIES}
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
            data = None  # corrupt or truncated cache entry: recompute and overwrite
    if data is None:
        if isinstance(material, LinearElastic):
            vlock = math.inf
        else:
            # for a callable pre-stretch, the lock at its rest value bounds the default range
            vlock = locking_volume(material, lambda_pre(0.0) if callable(lambda_pre) else lambda_pre)
        if vtilde_max is None:
            vend = 0.99 * vlock if math.isfinite(vlock) else 12.0
        else:
            vend = vtilde_max
        grid = _grid(vend, n)
        ds = bulge_mechanics(material, grid, lambda_pre=lambda_pre)
        data = {q: ds[q].values for q in _QUANTITIES}
        if cache:
            _atomic_save(path, grid, data, vlock)
    return MechanicsTable(grid, data, material=material, lambda_pre_key=key_fields["lambda_pre"], vtilde_lock=vlock)


def _atomic_save(path: Path, grid, data, vlock) -> None:
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".npz")
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, vtilde=grid, vtilde_lock=np.float64(vlock), **data)
        os.replace(tmp, path)
    except OSError:
        # a read-only cache directory must not break the computation
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
