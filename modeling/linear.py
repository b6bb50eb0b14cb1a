r"""Linear-elastic (small-deflection) membrane bulge, main text Eqns 11-13 corrected.

A spherical cap of height :math:`\delta` over a rim of radius :math:`a` has
volume :math:`\pi\delta(3a^2+\delta^2)/6 \approx \pi a^2\delta/2` (Nix's small-deflection
approximation), so :math:`\delta = 2\tilde V a`, and area :math:`\pi(a^2 + \delta^2)`, so

.. math::

    f_A = 1 + 4\tilde V^2 \quad\text{(not } 1 + 4\pi\tilde V^2\text{, errata E3)},\qquad
    f_l = 1,\qquad
    f_p = \frac{P_t}{E} = \frac{128}{3}\frac{l_0}{a}\tilde V^3 ,

the last from Timoshenko's :math:`P_t = 8 Y l_0\delta^3/(3a^4)` with the biaxial
modulus :math:`Y = E/(1-\nu) = 2E` for an incompressible membrane.
"""

from __future__ import annotations

import numpy as np

__all__ = ["linear_area_ratio", "linear_inverse_thickness", "linear_pressure"]


def linear_area_ratio(vtilde):
    r"""Area ratio :math:`f_A = A/A_0 = 1 + 4\tilde V^2` of the spherical-cap approximation."""
    v = np.asarray(vtilde, float)
    return 1.0 + 4.0 * v * v


def linear_inverse_thickness(vtilde):
    """Mean inverse thickness ratio f_l = 1 (thickness change neglected, Eqn 13)."""
    return np.ones_like(np.asarray(vtilde, float))


def linear_pressure(vtilde):
    r"""Dimensionless turgor pressure :math:`P_t a / (E l_0) = 128\tilde V^3/3` (Eqn 11)."""
    v = np.asarray(vtilde, float)
    return 128.0 / 3.0 * v**3
