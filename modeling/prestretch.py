r"""Measured rim pre-stretch :math:`\lambda_{pre}(\tilde V)` (supplement Sec. 5.7).

The chamber rim widens slightly as the turgor pressure rises.  The paper fits
a second-order polynomial through :math:`(\tilde V, R/R_0) = (0, 1)`:

.. math:: \lambda_{pre}(\tilde V) = 1 + c_1 \tilde V + c_2 \tilde V^2 .
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PreStretch", "fit_prestretch", "check_prestretch"]


@dataclass(frozen=True)
class PreStretch:
    r"""Polynomial rim stretch :math:`1 + c_1\tilde V + c_2\tilde V^2`.

    Parameters
    ----------
    c1, c2 : float
        Linear and quadratic coefficients (dimensionless).

    Examples
    --------
    >>> PreStretch(0.01, 0.0)(2.0)
    1.02
    """

    c1: float = 0.0
    c2: float = 0.0

    def __call__(self, vtilde):
        v = np.asarray(vtilde, dtype=float)
        out = 1.0 + self.c1 * v + self.c2 * v * v
        return float(out) if out.ndim == 0 else out

    @property
    def cache_key(self) -> str:
        return f"PreStretch(c1={self.c1!r},c2={self.c2!r})"


def fit_prestretch(vtilde, stretch, *, weights=None) -> PreStretch:
    r"""Least-squares fit of :class:`PreStretch` to measured rim stretches.

    Parameters
    ----------
    vtilde : array_like of shape (N,)
        Dimensionless bulge volumes :math:`\tilde V` (>= 0).
    stretch : array_like of shape (N,)
        Measured rim radius ratios :math:`R(\tilde V)/R_0`.
    weights : array_like of shape (N,), optional
        Weights of the residuals (e.g. inverse standard errors).

    Returns
    -------
    PreStretch
        Constrained through (0, 1) as in supplement Sec. 5.7.

    Examples
    --------
    >>> v = np.linspace(0, 4, 9)
    >>> fit = fit_prestretch(v, 1 + 0.02 * v - 0.001 * v**2)
    >>> round(fit.c1, 6), round(fit.c2, 6)
    (0.02, -0.001)
    """
    v = np.asarray(vtilde, float).ravel()
    y = np.asarray(stretch, float).ravel() - 1.0
    if v.shape != y.shape:
        raise ValueError(f"vtilde and stretch must have the same length, got {v.size} and {y.size}")
    ok = np.isfinite(v) & np.isfinite(y)
    if ok.sum() < 2:
        raise ValueError("need at least 2 finite (vtilde, stretch) points to fit the pre-stretch")
    a = np.stack([v[ok], v[ok] ** 2], axis=1)
    rhs = y[ok]
    if weights is not None:
        w = np.asarray(weights, float).ravel()[ok]
        a, rhs = a * w[:, None], rhs * w
    (c1, c2), *_ = np.linalg.lstsq(a, rhs, rcond=None)
    return PreStretch(float(c1), float(c2))


def check_prestretch(lambda_pre, vtilde):
    """Evaluate ``lambda_pre`` (float or callable of vtilde) and validate it.

    Returns an array broadcast to ``vtilde``; raises ``ValueError`` naming the
    parameter when a value is below 1 (a compressed rim would wrinkle the
    membrane: no tension-field solution exists) or not finite.
    """
    v = np.asarray(vtilde, float)
    if callable(lambda_pre):
        ell = np.asarray(lambda_pre(v), float)
        what = "lambda_pre(vtilde)"
    else:
        try:
            ell = np.asarray(float(lambda_pre))
        except (TypeError, ValueError):
            raise TypeError(f"lambda_pre must be a number >= 1 or a callable of vtilde, got {lambda_pre!r}") from None
        what = "lambda_pre"
    ell = np.broadcast_to(ell, v.shape).astype(float)
    if not np.all(np.isfinite(ell)):
        raise ValueError(f"{what} must be finite")
    if np.any(ell < 1.0):
        raise ValueError(f"{what} must be >= 1 (rim pre-stretch), got min {ell.min():.6g}")
    return ell
