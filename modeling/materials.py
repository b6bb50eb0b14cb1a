r"""Incompressible isotropic constitutive laws for thin elastomer membranes.

Every law is a strain-energy density :math:`W(I_1, I_2)` in pascals of the
invariants of the left Cauchy-Green tensor of an incompressible deformation
with principal stretches :math:`\lambda_1, \lambda_2, \lambda_3 = 1/(\lambda_1\lambda_2)`:

.. math::

    I_1 = \lambda_1^2 + \lambda_2^2 + \lambda_3^2, \qquad
    I_2 = \lambda_1^{-2} + \lambda_2^{-2} + \lambda_3^{-2}.

The paper writes the third terms as :math:`1/(\lambda_1\lambda_2)` (main text
Eqns 15-16, supplement Eqns 58-59); that is :math:`\lambda_3`, not
:math:`\lambda_3^2`, and makes the reference state carry stress. See
``docs/paper-errata.md`` (E1).

A law only supplies :math:`W` and its first and second partial derivatives in
:math:`(I_1, I_2)`; membrane line tensions, their derivatives, the uniaxial
nominal stress and the small-strain moduli follow from the chain rule in this
base class, so they are right for every law at once.

Units: all constants and stresses in Pa.  Membrane line tensions are returned
per unit *reference* thickness (Pa); multiply by :math:`l_0` for N/m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "Material",
    "NeoHookean",
    "MooneyRivlin",
    "Gent",
    "GentGent",
    "LinearElastic",
    "PDMS",
    "PEO_PDMS",
    "get_material",
    "PRESETS",
]


def _check_constant(name: str, value: float, *, allow_zero: bool = False) -> float:
    """Validate a material constant: finite and positive (or non-negative)."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"material constant {name!r} must be a real number, got {value!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"material constant {name!r} must be finite, got {value!r}")
    if value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"material constant {name!r} must be {bound} (Pa), got {value!r}")
    return value


def _is_zero(value) -> bool:
    """True for the scalar 0.0 that laws return for identically vanishing terms."""
    return isinstance(value, float) and value == 0.0


class Material:
    """Base class of the incompressible hyperelastic laws.

    Subclasses implement :meth:`_energy_derivatives`.  Everything else
    (membrane tensions, uniaxial stress, moduli) is derived here.
    """

    #: short law name used in cache keys, reports and error messages
    law: str = "material"

    # -- to be provided by subclasses ------------------------------------------
    def _energy_derivatives(self, i1, i2):
        """Return ``(W, W1, W2, W11, W12, W22)`` at invariants ``(i1, i2)``.

        Values outside the law's domain (Gent locking) are NaN.
        """
        raise NotImplementedError

    @property
    def constants(self) -> dict[str, float]:
        """Material constants (Pa, or dimensionless for Jm) as a plain dict."""
        raise NotImplementedError

    @property
    def stress_scale(self) -> float:
        """Stress (Pa) that makes the bulge problem dimensionless.

        :math:`C_1` for every law here, the paper's choice for the Gent
        3-parameter law (supplement Sec. 5.6: :math:`\\tilde P_t = P_t a / (C_1 l_0)`).
        """
        raise NotImplementedError

    # -- derived quantities ----------------------------------------------------
    @property
    def shear_modulus(self) -> float:
        r"""Small-strain shear modulus :math:`\mu = 2(W_1 + W_2)` at the reference state (Pa)."""
        _, w1, w2, *_ = self._energy_derivatives(3.0, 3.0)
        return float(2.0 * (w1 + w2))

    @property
    def youngs_modulus(self) -> float:
        r"""Small-strain Young's modulus :math:`3\mu` of the incompressible solid (Pa)."""
        return 3.0 * self.shear_modulus

    @property
    def E(self) -> float:  # noqa: N802 - the paper's symbol
        """Modulus (Pa) that nondimensionalises the turgor pressure, f_p = P_t / E.

        The small-strain Young's modulus unless the material was built with an
        explicit ``reference_modulus`` (the presets keep the paper's values,
        which do not equal 3 mu; see ``docs/paper-errata.md``).  E only scales
        f_p: the flux ODE uses E * f_p = P_t, so the choice never changes a result.
        """
        ref = getattr(self, "reference_modulus", None)
        return float(ref) if ref is not None else self.youngs_modulus

    @property
    def locking_stretch(self) -> float:
        """Equibiaxial stretch at which W diverges (``inf`` for laws that never lock)."""
        return math.inf

    def invariants(self, l1, l2):
        """Invariants ``(I1, I2)`` of the incompressible state with in-plane stretches."""
        l1 = np.asarray(l1, dtype=float)
        l2 = np.asarray(l2, dtype=float)
        l3sq = 1.0 / (l1 * l1 * l2 * l2)
        i1 = l1 * l1 + l2 * l2 + l3sq
        i2 = 1.0 / (l1 * l1) + 1.0 / (l2 * l2) + 1.0 / l3sq
        return i1, i2

    def strain_energy(self, l1, l2):
        """Strain-energy density W (Pa) for in-plane principal stretches ``l1, l2``."""
        i1, i2 = self.invariants(l1, l2)
        return self._energy_derivatives(i1, i2)[0]

    def _reduced_derivatives(self, l1, l2, *, second_yy=True):
        """First and second derivatives of the reduced energy W(l1, l2).

        Returns ``(Wx, Wy, Wxx, Wxy, Wyy)`` in Pa, with ``x = l1``, ``y = l2`` and
        ``l3 = 1/(l1 l2)`` eliminated by incompressibility (``Wyy`` is None when
        ``second_yy`` is false).  Laws may return the Python float ``0.0`` for
        second derivatives that vanish identically; those terms are skipped.
        """
        x = np.asarray(l1, dtype=float)
        y = np.asarray(l2, dtype=float)
        x2, y2 = x * x, y * y
        ix2, iy2 = 1.0 / x2, 1.0 / y2
        l3sq = ix2 * iy2
        i1 = x2 + y2 + l3sq
        i2 = ix2 + iy2 + x2 * y2
        _, w1, w2, w11, w12, w22 = self._energy_derivatives(i1, i2)
        # invariant derivatives
        i1x = 2.0 * (x - l3sq / x)
        i1y = 2.0 * (y - l3sq / y)
        i2x = 2.0 * (x * y2 - ix2 / x)
        i2y = 2.0 * (x2 * y - iy2 / y)
        wx = w1 * i1x + w2 * i2x
        wy = w1 * i1y + w2 * i2y
        wxx = w1 * (2.0 + 6.0 * ix2 * l3sq) + w2 * (6.0 * ix2 * ix2 + 2.0 * y2)
        wxy = w1 * (4.0 * l3sq / (x * y)) + w2 * (4.0 * x * y)
        wyy = None
        if second_yy:
            wyy = w1 * (2.0 + 6.0 * iy2 * l3sq) + w2 * (6.0 * iy2 * iy2 + 2.0 * x2)
        if not _is_zero(w11):
            wxx = wxx + w11 * i1x * i1x
            wxy = wxy + w11 * i1x * i1y
            if second_yy:
                wyy = wyy + w11 * i1y * i1y
        if not _is_zero(w12):
            wxx = wxx + 2.0 * w12 * i1x * i2x
            wxy = wxy + w12 * (i1x * i2y + i1y * i2x)
            if second_yy:
                wyy = wyy + 2.0 * w12 * i1y * i2y
        if not _is_zero(w22):
            wxx = wxx + w22 * i2x * i2x
            wxy = wxy + w22 * i2x * i2y
            if second_yy:
                wyy = wyy + w22 * i2y * i2y
        return wx, wy, wxx, wxy, wyy

    def membrane_tensions(self, l1, l2):
        r"""Principal membrane line tensions per unit reference thickness (Pa).

        .. math:: T_1 / l_0 = \frac{1}{\lambda_2}\frac{\partial W}{\partial\lambda_1},\quad
                  T_2 / l_0 = \frac{1}{\lambda_1}\frac{\partial W}{\partial\lambda_2}

        (main text Eqn 24 before the division by :math:`C_1`).  Equal to the
        Cauchy stress times the current thickness :math:`l = l_0\lambda_3`.
        """
        wx, wy, *_ = self._reduced_derivatives(l1, l2)
        return wx / np.asarray(l2, float), wy / np.asarray(l1, float)

    def membrane_tangent(self, l1, l2):
        """Dimensionless tensions and derivatives used by the bulge equations.

        Returns ``(t1, t2, dt1_dl1, dt1_dl2)`` with ``t = T / (stress_scale * l0)``,
        the :math:`\\tilde T_\\xi, \\tilde T_\\phi` of Eqn 24 and the partial
        derivatives that appear in Eqn 19.
        """
        x = np.asarray(l1, dtype=float)
        y = np.asarray(l2, dtype=float)
        wx, wy, wxx, wxy, _ = self._reduced_derivatives(x, y, second_yy=False)
        s = 1.0 / self.stress_scale
        t1 = s * wx / y
        t2 = s * wy / x
        dt1_dl1 = s * wxx / y
        dt1_dl2 = s * (wxy / y - wx / (y * y))
        return t1, t2, dt1_dl1, dt1_dl2

    def uniaxial_stress(self, stretch):
        r"""Nominal (engineering) uniaxial stress :math:`T_{11}(\lambda)` in Pa.

        With :math:`\lambda_2 = \lambda_3 = \lambda^{-1/2}`:

        .. math:: T_{11} = 2\left(\lambda - \lambda^{-2}\right)
                  \left(W_1 + \lambda^{-1} W_2\right)

        This replaces supplement Eqn 61, which does not follow from Eqn 57
        (``docs/paper-errata.md``, E5).
        """
        lam = np.asarray(stretch, dtype=float)
        if np.any(~np.isfinite(lam)) or np.any(lam <= 0):
            raise ValueError("stretch must be finite and > 0")
        i1 = lam * lam + 2.0 / lam
        i2 = 2.0 * lam + 1.0 / (lam * lam)
        _, w1, w2, *_ = self._energy_derivatives(i1, i2)
        return 2.0 * (lam - 1.0 / (lam * lam)) * (w1 + w2 / lam)

    def equibiaxial_tension(self, stretch):
        """Membrane tension per reference thickness (Pa) in equibiaxial stretch."""
        lam = np.asarray(stretch, dtype=float)
        return self.membrane_tensions(lam, lam)[0]

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.constants.items())
        return f"{type(self).__name__}({args})"


@dataclass(frozen=True, repr=False)
class NeoHookean(Material):
    r"""Neo-Hookean solid, :math:`W = C_1 (I_1 - 3)`, shear modulus :math:`2C_1`.

    Parameters
    ----------
    c1 : float, Pa
        Half the shear modulus.
    """

    c1: float
    reference_modulus: float | None = field(default=None, compare=True)
    law = "neo-hookean"

    def __post_init__(self):
        object.__setattr__(self, "c1", _check_constant("c1", self.c1))

    @property
    def constants(self):
        return {"c1": self.c1}

    @property
    def stress_scale(self):
        return self.c1

    def _energy_derivatives(self, i1, i2):
        i1 = np.asarray(i1, dtype=float)
        return self.c1 * (i1 - 3.0), self.c1 + 0.0 * i1, 0.0, 0.0, 0.0, 0.0


@dataclass(frozen=True, repr=False)
class MooneyRivlin(Material):
    r"""Mooney-Rivlin solid, :math:`W = C_1 (I_1 - 3) + C_2 (I_2 - 3)`.

    Parameters
    ----------
    c1, c2 : float, Pa
        Constants; the shear modulus is :math:`2 (C_1 + C_2)`.
    """

    c1: float
    c2: float
    reference_modulus: float | None = None
    law = "mooney-rivlin"

    def __post_init__(self):
        object.__setattr__(self, "c1", _check_constant("c1", self.c1))
        object.__setattr__(self, "c2", _check_constant("c2", self.c2))

    @property
    def constants(self):
        return {"c1": self.c1, "c2": self.c2}

    @property
    def stress_scale(self):
        return self.c1

    def _energy_derivatives(self, i1, i2):
        i1 = np.asarray(i1, dtype=float)
        i2 = np.asarray(i2, dtype=float)
        zero = np.zeros(np.broadcast(i1, i2).shape)
        w = self.c1 * (i1 - 3.0) + self.c2 * (i2 - 3.0)
        return w, self.c1 + zero, self.c2 + zero, 0.0, 0.0, 0.0


def _gent_term(c1, jm, i1):
    """Gent first-invariant term and its derivatives; NaN beyond locking."""
    j1 = np.asarray(i1, dtype=float) - 3.0
    gap = jm - j1
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = gap > 0
        safe = np.where(ok, gap, np.nan)
        w = -c1 * jm * np.log(safe / jm)
        w1 = c1 * jm / safe
        w11 = c1 * jm / (safe * safe)
    return w, w1, w11


def _check_jm(jm: float) -> float:
    try:
        jm = float(jm)
    except (TypeError, ValueError):
        raise TypeError(f"material constant 'jm' must be a real number, got {jm!r}") from None
    if not math.isfinite(jm) or jm <= 0:
        raise ValueError(f"material constant 'jm' (locking limit of I1 - 3) must be finite and > 0, got {jm!r}")
    return jm


def _equibiaxial_locking(jm: float) -> float:
    """Stretch lam with 2 lam^2 + lam^-4 - 3 = jm (lam > 1)."""
    lo, hi = 1.0, 2.0
    f = lambda lam: 2 * lam * lam + lam**-4 - 3.0 - jm  # noqa: E731
    while f(hi) < 0:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if f(mid) < 0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@dataclass(frozen=True, repr=False)
class Gent(Material):
    r"""Classic Gent solid, :math:`W = -C_1 J_m \ln(1 - J_1/J_m)`, :math:`J_1 = I_1 - 3`.

    Shear modulus :math:`2 C_1`; stiffens without bound as :math:`J_1 \to J_m`.

    Parameters
    ----------
    c1 : float, Pa
        Half the shear modulus.
    jm : float
        Locking value of :math:`I_1 - 3` (dimensionless, > 0).
    """

    c1: float
    jm: float
    reference_modulus: float | None = None
    law = "gent"

    def __post_init__(self):
        object.__setattr__(self, "c1", _check_constant("c1", self.c1))
        object.__setattr__(self, "jm", _check_jm(self.jm))

    @property
    def constants(self):
        return {"c1": self.c1, "jm": self.jm}

    @property
    def stress_scale(self):
        return self.c1

    @property
    def locking_stretch(self):
        return _equibiaxial_locking(self.jm)

    def _energy_derivatives(self, i1, i2):
        w, w1, w11 = _gent_term(self.c1, self.jm, i1)
        zero = np.zeros(np.broadcast(np.asarray(i1), np.asarray(i2)).shape)
        return w + zero, w1 + zero, zero, w11 + zero, 0.0, 0.0


@dataclass(frozen=True, repr=False)
class GentGent(Material):
    r"""Gent 3-parameter ("Gent-Gent") solid of main text Eqn 14 / supplement Eqn 57.

    .. math:: W = -C_1 J_m \ln\left(1 - \frac{J_1}{J_m}\right)
                  + C_2 \ln\left(\frac{J_2 + 3}{3}\right),
              \quad J_1 = I_1 - 3,\ J_2 = I_2 - 3.

    The small-strain shear modulus is :math:`\mu = 2 C_1 + 2 C_2 / 3`
    (:math:`W_2 = C_2 / I_2 = C_2/3` at rest), not :math:`2(C_1 + C_2)` as in
    supplement Eqn 60 (``docs/paper-errata.md``, E4).

    Parameters
    ----------
    c1, c2 : float, Pa
        The Gent constants.
    jm : float
        Locking value of :math:`J_1` (dimensionless).
    reference_modulus : float, Pa, optional
        Modulus used for :math:`f_p = P_t/E`; defaults to :math:`3\mu`.
    """

    c1: float
    c2: float
    jm: float
    reference_modulus: float | None = None
    law = "gent-gent"

    def __post_init__(self):
        object.__setattr__(self, "c1", _check_constant("c1", self.c1))
        object.__setattr__(self, "c2", _check_constant("c2", self.c2))
        object.__setattr__(self, "jm", _check_jm(self.jm))
        if self.reference_modulus is not None:
            object.__setattr__(
                self, "reference_modulus", _check_constant("reference_modulus", self.reference_modulus)
            )

    @property
    def constants(self):
        return {"c1": self.c1, "c2": self.c2, "jm": self.jm}

    @property
    def stress_scale(self):
        return self.c1

    @property
    def locking_stretch(self):
        return _equibiaxial_locking(self.jm)

    def _energy_derivatives(self, i1, i2):
        w_a, w1, w11 = _gent_term(self.c1, self.jm, i1)
        i2 = np.asarray(i2, dtype=float)
        w_b = self.c2 * np.log(i2 / 3.0)
        w2 = self.c2 / i2
        w22 = -self.c2 / (i2 * i2)
        return w_a + w_b, w1, w2, w11, 0.0, w22


@dataclass(frozen=True, repr=False)
class LinearElastic:
    """Small-strain (linear-elastic) membrane of Young's modulus ``E``.

    Not a strain-energy law: it selects the closed-form small-deflection bulge
    functions of main text Eqns 11-13 (corrected, ``docs/paper-errata.md``)
    behind the same :func:`osmobulge.modeling.bulge_mechanics` interface.

    Parameters
    ----------
    E : float, Pa
        Young's modulus (incompressible, Poisson ratio 1/2).
    """

    E: float  # noqa: N815
    law = "linear"

    def __post_init__(self):
        object.__setattr__(self, "E", _check_constant("E", self.E))

    @property
    def constants(self):
        return {"E": self.E}

    @property
    def shear_modulus(self) -> float:
        return self.E / 3.0

    @property
    def youngs_modulus(self) -> float:
        return self.E

    @property
    def stress_scale(self) -> float:
        """:math:`C_1 = \\mu/2 = E/6`, the neo-Hookean constant of the same modulus."""
        return self.E / 6.0

    @property
    def locking_stretch(self) -> float:
        return math.inf

    @classmethod
    def equivalent_to(cls, material) -> LinearElastic:
        """The linear membrane with the same nondimensionalising modulus ``material.E``."""
        return cls(material.E)


# Supplement Table 1 (MPa -> Pa).  E is the paper's value, 6 (C1 + C2), kept as
# the nondimensionalising modulus; the true small-strain modulus is
# material.youngs_modulus.
PDMS = GentGent(c1=0.0316e6, c2=0.0297e6, jm=26.0, reference_modulus=0.37e6)
PEO_PDMS = GentGent(c1=0.0714e6, c2=0.0536e6, jm=45.0, reference_modulus=0.75e6)

PRESETS = {"PDMS": PDMS, "PEO_PDMS": PEO_PDMS, "PEO-PDMS": PEO_PDMS}


def get_material(name: str):
    """Look up a preset by name (case-insensitive): ``"PDMS"`` or ``"PEO_PDMS"``."""
    key = str(name).strip().upper().replace(" ", "_")
    for preset, material in PRESETS.items():
        if preset.upper() == key:
            return material
    raise ValueError(f"unknown material preset {name!r}; choose one of {sorted(set(PRESETS) - {'PEO-PDMS'})}")
