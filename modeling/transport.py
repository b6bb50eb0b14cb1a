r"""Osmotic water transport into a membrane-capped chamber (main text Sec. 3.2).

Water crosses the membrane by solution-diffusion.  With the chamber well mixed
and no salt leakage, the chamber volume obeys main text Eqn 8 with the feed
term of supplement Eqn 32:

.. math::

    \frac{d(V/V_0)}{dt} = -\frac{L \Pi_0 A_0}{l_0 V_0}\, f_A f_l
        \left(\frac{1}{V/V_0} - \frac{C_{feed}}{C_0} + \frac{P_t}{\Pi_0}\right),
    \qquad L = \frac{P_w V_m}{R T},\qquad \Pi_0 = -i C_0 R T .

Everything here is SI: metres, seconds, pascals, mol/m**3 (1 M = 1000 mol/m**3),
kelvin.  The physical constants of water live in this module only
(:data:`GAS_CONSTANT`, :data:`WATER_MOLAR_MASS`, :data:`WATER_DENSITY`,
:data:`WATER_MOLAR_VOLUME`, :data:`WATER_CONCENTRATION`).

The mechanics of the flux ODE (:math:`f_A, f_l, P_t` as functions of
:math:`\tilde V`) come from :func:`mechanics_model`: the cached hyperelastic
table of :func:`osmobulge.modeling.mechanics_table` or the closed-form
linear-elastic membrane (main text Eqns 11-13, area corrected, errata E3).
"""

from __future__ import annotations

import math
from dataclasses import MISSING, asdict, dataclass, fields

import numpy as np

__all__ = [
    "GAS_CONSTANT",
    "WATER_MOLAR_MASS",
    "WATER_DENSITY",
    "WATER_MOLAR_VOLUME",
    "WATER_CONCENTRATION",
    "MOLAR",
    "MICROMETRE",
    "CHAMBER_ATTRS",
    "PLAUSIBLE_RANGES",
    "Chamber",
    "paper_chamber",
    "PAPER_CHAMBERS",
    "mobility",
    "permeability_from_mobility",
    "time_constant",
    "vtilde_from_volume_ratio",
    "volume_ratio_from_vtilde",
    "osmotic_term",
    "LinearMechanics",
    "mechanics_model",
    "MECHANICS_KINDS",
    "volume_rate",
]

# ---------------------------------------------------------------------------
# Physical constants (the only place they are defined)
# ---------------------------------------------------------------------------
#: Molar gas constant R, J/(mol K) (exact, SI 2019).
GAS_CONSTANT = 8.314462618
#: Molar mass of water M_w, kg/mol.
WATER_MOLAR_MASS = 18.01528e-3
#: Density of liquid water at 298.15 K and 1 atm, kg/m**3 (IAPWS-95: 997.047).
WATER_DENSITY = 997.047
#: Molar volume of liquid water V_m = M_w / rho_w at 298.15 K, m**3/mol (1.8069e-5).
WATER_MOLAR_VOLUME = WATER_MOLAR_MASS / WATER_DENSITY
#: Molar concentration of pure water C_w = 1 / V_m, mol/m**3 (55.34 M).
WATER_CONCENTRATION = 1.0 / WATER_MOLAR_VOLUME

#: 1 mol/L in SI (mol/m**3).
MOLAR = 1000.0
#: 1 um in metres.
MICROMETRE = 1e-6

# ---------------------------------------------------------------------------
# Chamber
# ---------------------------------------------------------------------------
#: Plausible ranges ``(low, high, unit, hint)`` used to catch unit mistakes.
PLAUSIBLE_RANGES = {
    "radius": (1e-6, 1e-2, "m", "give metres, e.g. 200e-6 for 200 um"),
    "depth": (1e-7, 1e-2, "m", "give metres, e.g. 110e-6 for 110 um"),
    "thickness": (1e-8, 1e-3, "m", "give metres, e.g. 20e-6 for 20 um"),
    "concentration": (1e-1, 1e4, "mol/m^3", "give mol/m^3, e.g. 3000 for 3 M"),
    "feed_concentration": (0.0, 1e4, "mol/m^3", "give mol/m^3, e.g. 3000 for 3 M (0 for pure water)"),
    "temperature": (250.0, 400.0, "K", "give kelvin, e.g. 298.15 for 25 C"),
    "vant_hoff": (1e-3, 10.0, "1", "the van 't Hoff factor i of the solute, e.g. 2 for NaCl"),
}

#: netCDF attribute names ``(attr name, unit, description)`` under which a chamber is stored (all SI).
CHAMBER_ATTRS = {
    "radius": ("chamber_radius", "m", "chamber (membrane) radius a"),
    "depth": ("chamber_depth", "m", "chamber depth h"),
    "thickness": ("membrane_thickness", "m", "initial membrane thickness l0"),
    "concentration": ("concentration", "mol/m^3", "initial osmolyte concentration C0"),
    "feed_concentration": ("feed_concentration", "mol/m^3", "feed (bath) osmolyte concentration"),
    "temperature": ("temperature", "K", "temperature T"),
    "vant_hoff": ("vant_hoff", "1", "van 't Hoff factor i"),
}


def _check_field(name: str, value) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a real number, got {value!r}") from None
    low, high, unit, hint = PLAUSIBLE_RANGES[name]
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {x!r} {unit}")
    if name == "feed_concentration":
        if x < 0:
            raise ValueError(f"{name} must be >= 0 mol/m^3, got {x!r}")
    elif x <= 0:
        raise ValueError(f"{name} must be > 0 {unit}, got {x!r}")
    if not (low <= x <= high):
        raise ValueError(
            f"{name}={x!r} {unit} is implausible for a micro-chamber (expected {low:g}..{high:g} {unit}): {hint}"
        )
    return x


@dataclass(frozen=True)
class Chamber:
    r"""A cylindrical micro-chamber capped by a membrane, in SI units.

    Parameters
    ----------
    radius : float, m
        Chamber (membrane) radius :math:`a`; plausible range 1 um .. 10 mm.
    depth : float, m
        Chamber depth :math:`h`; plausible range 0.1 um .. 10 mm.
    thickness : float, m
        Initial membrane thickness :math:`l_0`; 10 nm .. 1 mm and thinner than ``radius``.
    concentration : float, mol/m**3
        Initial osmolyte concentration :math:`C_0` (1 M = 1000 mol/m**3); 0.1 .. 1e4.
    feed_concentration : float, mol/m**3
        Osmolyte concentration of the bath, 0 (pure water, default) .. 1e4.
    temperature : float, K
        Temperature, 250 .. 400 K (default 298.15 K).
    vant_hoff : float
        Van 't Hoff factor :math:`i` (default 2, NaCl); 1e-3 .. 10.

    Raises
    ------
    ValueError
        A non-finite, zero or negative value, or one outside the plausible range
        (a unit mistake such as ``radius=200`` meaning um): the message names the
        field, the value and the unit expected.

    Notes
    -----
    The chamber is a cylinder, :math:`V_0 = \pi a^2 h`, :math:`A_0 = \pi a^2`, so
    :math:`V_0/(A_0 a) = h/a` and Eqn 4 reads :math:`\tilde V = (V/V_0 - 1) h/a`.

    Examples
    --------
    >>> c = Chamber(radius=200e-6, depth=110e-6, thickness=20e-6, concentration=3000.0)
    >>> round(c.osmotic_potential / 1e6, 3)
    -14.874
    >>> Chamber(radius=200, depth=110e-6, thickness=20e-6, concentration=3000.0)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: radius=200.0 m is implausible for a micro-chamber (expected 1e-06..0.01 m): give metres, ...
    """

    radius: float
    depth: float
    thickness: float
    concentration: float
    feed_concentration: float = 0.0
    temperature: float = 298.15
    vant_hoff: float = 2.0

    def __post_init__(self):
        for f in fields(self):
            object.__setattr__(self, f.name, _check_field(f.name, getattr(self, f.name)))
        if self.thickness >= self.radius:
            raise ValueError(
                f"thickness={self.thickness!r} m must be smaller than radius={self.radius!r} m (a thin membrane)"
            )

    # -- derived quantities ---------------------------------------------------
    @property
    def volume(self) -> float:
        r"""Initial chamber volume :math:`V_0 = \pi a^2 h`, m**3."""
        return math.pi * self.radius**2 * self.depth

    @property
    def area(self) -> float:
        r"""Initial membrane area :math:`A_0 = \pi a^2`, m**2."""
        return math.pi * self.radius**2

    @property
    def aspect(self) -> float:
        r""":math:`V_0/(A_0 a) = h/a`, the factor of Eqn 4 (dimensionless)."""
        return self.depth / self.radius

    @property
    def osmotic_potential(self) -> float:
        r"""Initial osmotic potential :math:`\Pi_0 = -i C_0 R T`, Pa (negative)."""
        return -self.vant_hoff * self.concentration * GAS_CONSTANT * self.temperature

    @property
    def feed_ratio(self) -> float:
        r""":math:`C_{feed}/C_0` (dimensionless)."""
        return self.feed_concentration / self.concentration

    def vtilde(self, volume_ratio):
        """Dimensionless bulge volume of a volume ratio, see :func:`vtilde_from_volume_ratio`."""
        return vtilde_from_volume_ratio(volume_ratio, self)

    def volume_ratio(self, vtilde):
        """Volume ratio of a dimensionless bulge volume, see :func:`volume_ratio_from_vtilde`."""
        return volume_ratio_from_vtilde(vtilde, self)

    def time_constant(self, permeability) -> float:
        """Time constant tau (s) of Eqn 9 for a permeability (m**2/s), see :func:`time_constant`."""
        return time_constant(self, permeability)

    def replace(self, **changes) -> Chamber:
        """A copy with some fields changed (validated again)."""
        return Chamber(**{**asdict(self), **changes})

    # -- netCDF attrs ------------------------------------------------------------
    def to_attrs(self) -> dict:
        """The chamber as netCDF-safe Dataset attrs (names of :data:`CHAMBER_ATTRS`, SI floats)."""
        return {CHAMBER_ATTRS[f.name][0]: float(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_attrs(cls, attrs) -> Chamber:
        """Build a chamber from Dataset attrs written by :meth:`to_attrs` (or the imaging pipeline).

        Parameters
        ----------
        attrs : mapping
            Must hold ``chamber_radius``, ``chamber_depth``, ``membrane_thickness`` (m) and
            ``concentration`` (mol/m**3); ``feed_concentration`` (mol/m**3),
            ``temperature`` (K) and ``vant_hoff`` are optional.

        Returns
        -------
        Chamber
        """
        kwargs = {}
        missing = []
        for f in fields(cls):
            key = CHAMBER_ATTRS[f.name][0]
            if key in attrs:
                kwargs[f.name] = attrs[key]
            elif f.default is MISSING:  # no default: required
                missing.append(key)
        if missing:
            raise ValueError(f"attrs lack the chamber field(s) {missing} (SI units; see CHAMBER_ATTRS)")
        return cls(**kwargs)


#: The chamber configurations of the paper (main text Sec. 3.1, Fig. 2c), all h = 110 um, NaCl.
PAPER_CHAMBERS = {
    "reference": {"radius": 200e-6, "depth": 110e-6, "thickness": 20e-6, "concentration": 3.0 * MOLAR},
    "small_radius": {"radius": 100e-6, "depth": 110e-6, "thickness": 20e-6, "concentration": 3.0 * MOLAR},
    "thick_membrane": {"radius": 200e-6, "depth": 110e-6, "thickness": 26e-6, "concentration": 3.0 * MOLAR},
    "low_concentration": {"radius": 200e-6, "depth": 110e-6, "thickness": 20e-6, "concentration": 1.0 * MOLAR},
}


def paper_chamber(name: str = "reference", **changes) -> Chamber:
    """One of the paper's chamber presets.

    Parameters
    ----------
    name : {"reference", "small_radius", "thick_membrane", "low_concentration"}
        Reference: a = 200 um, l0 = 20 um, h = 110 um, C0 = 3 M; the others change
        one of them (a = 100 um; l0 = 26 um; C0 = 1 M).
    **changes
        Fields to override (e.g. ``feed_concentration=3000.0`` for the reverse
        actuation of Fig. 2b).

    Returns
    -------
    Chamber

    Examples
    --------
    >>> paper_chamber("small_radius").radius
    0.0001
    """
    if name not in PAPER_CHAMBERS:
        raise ValueError(f"unknown paper chamber {name!r}; choose one of {tuple(PAPER_CHAMBERS)}")
    return Chamber(**{**PAPER_CHAMBERS[name], **changes})


# ---------------------------------------------------------------------------
# Conversions
# ---------------------------------------------------------------------------
def mobility(permeability, temperature=298.15):
    r"""Volumetric water mobility :math:`L` from the permeability :math:`P_w`.

    Parameters
    ----------
    permeability : float or ndarray, m**2/s
        Water permeability :math:`P_w`.
    temperature : float, K

    Returns
    -------
    float or ndarray, m**2/(Pa s)

    Notes
    -----
    Main text Eqn 2 / supplement Eqn 26,
    :math:`L = \frac{P_w C_w}{RT}\frac{V_m M_w}{\rho_w}`.  With :math:`C_w V_m = 1`
    (pure-water concentration) and :math:`M_w/\rho_w = V_m` this is
    :math:`L = P_w V_m/(RT)`.

    Examples
    --------
    >>> f"{mobility(2e-12):.4e}"
    '1.4578e-20'
    """
    out = np.asarray(permeability, float) * WATER_MOLAR_VOLUME / (GAS_CONSTANT * float(temperature))
    return float(out) if out.ndim == 0 else out


def permeability_from_mobility(mobility_value, temperature=298.15):
    r"""Inverse of :func:`mobility`: :math:`P_w = L R T / V_m`.

    Parameters
    ----------
    mobility_value : float or ndarray, m**2/(Pa s)
    temperature : float, K

    Returns
    -------
    float or ndarray, m**2/s
    """
    out = np.asarray(mobility_value, float) * GAS_CONSTANT * float(temperature) / WATER_MOLAR_VOLUME
    return float(out) if out.ndim == 0 else out


def time_constant(chamber: Chamber, permeability):
    r"""Time constant :math:`\tau = -l_0 V_0/(L \Pi_0 A_0)` of Eqn 9, s.

    Parameters
    ----------
    chamber : Chamber
    permeability : float or ndarray, m**2/s

    Returns
    -------
    float or ndarray, s

    Notes
    -----
    With :math:`L = P_w V_m/(RT)` and :math:`\Pi_0 = -iC_0RT` the temperature
    cancels: :math:`\tau = l_0 h/(P_w V_m i C_0)`.

    Examples
    --------
    >>> round(time_constant(paper_chamber("reference"), 2e-12))
    10146
    """
    if not isinstance(chamber, Chamber):
        raise TypeError(f"chamber must be a Chamber, got {type(chamber).__name__}")
    p = np.asarray(permeability, float)
    if np.any(~np.isfinite(p)) or np.any(p <= 0):
        raise ValueError(f"permeability must be finite and > 0 m^2/s, got {permeability!r}")
    L = mobility(p, chamber.temperature)
    tau = -chamber.thickness * chamber.volume / (L * chamber.osmotic_potential * chamber.area)
    return float(tau) if np.ndim(tau) == 0 else tau


def vtilde_from_volume_ratio(volume_ratio, chamber: Chamber):
    r"""Dimensionless bulge volume :math:`\tilde V = (V/V_0 - 1)\,V_0/(A_0 a) = (V/V_0-1)\,h/a` (Eqn 4).

    Parameters
    ----------
    volume_ratio : float or ndarray
        :math:`V/V_0`.
    chamber : Chamber

    Returns
    -------
    float or ndarray
    """
    v = np.asarray(volume_ratio, float)
    out = (v - 1.0) * chamber.aspect
    return float(out) if out.ndim == 0 else out


def volume_ratio_from_vtilde(vtilde, chamber: Chamber):
    r"""Volume ratio :math:`V/V_0 = 1 + \tilde V a/h`, inverse of Eqn 4.

    Parameters
    ----------
    vtilde : float or ndarray
    chamber : Chamber

    Returns
    -------
    float or ndarray
    """
    vt = np.asarray(vtilde, float)
    out = 1.0 + vt / chamber.aspect
    return float(out) if out.ndim == 0 else out


def osmotic_term(volume_ratio, feed_ratio=0.0):
    r"""Dimensionless osmotic driving term :math:`\Delta\Pi/\Pi_0 = 1/(V/V_0) - C_{feed}/C_0`.

    Parameters
    ----------
    volume_ratio : float or ndarray
    feed_ratio : float
        :math:`C_{feed}/C_0`.

    Returns
    -------
    float or ndarray

    Notes
    -----
    Supplement Eqn 32 (an ideal, non-leaking solute diluted by the inflow).
    """
    v = np.asarray(volume_ratio, float)
    out = 1.0 / v - float(feed_ratio)
    return float(out) if out.ndim == 0 else out


# ---------------------------------------------------------------------------
# Mechanics for the flux ODE
# ---------------------------------------------------------------------------
MECHANICS_KINDS = ("hyperelastic", "linear")


class LinearMechanics:
    r"""Closed-form linear-elastic membrane (main text Eqns 11-13, Eqn 12 corrected).

    :math:`f_A = 1 + 4\tilde V^2` (errata E3), :math:`f_l = 1`,
    :math:`P_t = E\,\frac{128}{3}\frac{l_0}{a}\tilde V^3`, with ``E`` the
    nondimensionalising modulus of the paper (``material.E``).  Same interface
    as :class:`osmobulge.modeling.MechanicsTable`; it never runs out of range
    for :math:`\tilde V \ge 0`.

    Parameters
    ----------
    E : float, Pa
    """

    vtilde_max = math.inf
    vtilde_lock = math.inf

    def __init__(self, E: float):
        E = float(E)
        if not math.isfinite(E) or E <= 0:
            raise ValueError(f"E must be finite and > 0 Pa, got {E!r}")
        self.E = E

    @staticmethod
    def _v(vtilde):
        v = np.asarray(vtilde, float)
        if np.any(v < 0) or np.any(~np.isfinite(v)):
            raise ValueError("vtilde must be finite and >= 0 (inward deflection is not modelled)")
        return v

    @staticmethod
    def _out(x):
        return float(x) if np.ndim(x) == 0 else x

    def area_ratio(self, vtilde):
        r""":math:`f_A = 1 + 4\tilde V^2`."""
        v = self._v(vtilde)
        return self._out(1.0 + 4.0 * v * v)

    def inverse_thickness(self, vtilde):
        """:math:`f_l = 1`."""
        return self._out(np.ones_like(self._v(vtilde)))

    def lambda_bar(self, vtilde):
        r""":math:`\sqrt{f_A}`."""
        v = self._v(vtilde)
        return self._out(np.sqrt(1.0 + 4.0 * v * v))

    def turgor_pressure(self, vtilde, *, thickness, radius):
        r""":math:`P_t = E (128/3)(l_0/a)\tilde V^3`, Pa."""
        v = self._v(vtilde)
        return self._out(self.E * 128.0 / 3.0 * (thickness / radius) * v**3)

    def __repr__(self):
        return f"LinearMechanics(E={self.E!r})"


def mechanics_model(material, lambda_pre=1.0, mechanics: str = "hyperelastic"):
    """The membrane mechanics used by the flux ODE.

    Parameters
    ----------
    material : Material or LinearElastic
        Constitutive law (e.g. ``materials.PDMS``).
    lambda_pre : float or callable
        Rim pre-stretch (hyperelastic mechanics only; must be 1 for ``"linear"``).
    mechanics : {"hyperelastic", "linear"}
        ``"hyperelastic"``: the cached spline table of
        :func:`osmobulge.modeling.mechanics_table` (valid up to its ``vtilde_max``,
        99 % of Gent locking).  ``"linear"``: :class:`LinearMechanics` with
        ``E = material.E``.  A ``LinearElastic`` material always gives linear mechanics.

    Returns
    -------
    MechanicsTable or LinearMechanics
        Objects with ``area_ratio``, ``inverse_thickness``, ``lambda_bar``,
        ``turgor_pressure(vtilde, thickness=, radius=)`` and ``vtilde_max``.
    """
    if mechanics not in MECHANICS_KINDS:
        raise ValueError(f"mechanics must be one of {MECHANICS_KINDS}, got {mechanics!r}")
    from osmobulge.modeling.materials import LinearElastic

    if mechanics == "linear" or isinstance(material, LinearElastic):
        if callable(lambda_pre) or float(lambda_pre) != 1.0:
            raise ValueError(f"lambda_pre must be 1 for linear mechanics, got {lambda_pre!r}")
        if not hasattr(material, "E"):
            raise TypeError(f"material must have a modulus E, got {type(material).__name__}")
        return LinearMechanics(material.E)
    from osmobulge.modeling.table import mechanics_table

    return mechanics_table(material, lambda_pre)


def volume_rate(volume_ratio, chamber: Chamber, mechanics, permeability):
    r"""Right-hand side of the flux ODE, :math:`d(V/V_0)/dt` in 1/s (Eqn 8 with feed).

    Parameters
    ----------
    volume_ratio : float or ndarray
        :math:`V/V_0` (>= 1: the model has no inward deflection).
    chamber : Chamber
    mechanics : MechanicsTable or LinearMechanics
        From :func:`mechanics_model`.
    permeability : float or callable, m**2/s
        A constant, or a function of ``lambda_bar`` (and optionally ``thickness=``,
        the mean thickness :math:`l_0/f_l` in m).

    Returns
    -------
    float or ndarray, 1/s

    Notes
    -----
    .. math::

        \frac{d(V/V_0)}{dt} = \frac{P_w V_m\, i C_0}{l_0 h}\, f_A f_l
        \left(\frac{1}{V/V_0} - \frac{C_{feed}}{C_0} + \frac{P_t}{\Pi_0}\right)

    which is Eqn 8 with :math:`-L\Pi_0A_0/(l_0V_0) = 1/\tau` and
    :math:`E f_p = P_t`.
    """
    from osmobulge.modeling.permeability import evaluate_permeability

    v = np.asarray(volume_ratio, float)
    vt = vtilde_from_volume_ratio(v, chamber)
    fa = mechanics.area_ratio(vt)
    fl = mechanics.inverse_thickness(vt)
    pt = mechanics.turgor_pressure(vt, thickness=chamber.thickness, radius=chamber.radius)
    drive = osmotic_term(v, chamber.feed_ratio) + pt / chamber.osmotic_potential
    pw = evaluate_permeability(permeability, mechanics.lambda_bar(vt), chamber.thickness / np.asarray(fl))
    rate = pw * fa * fl * drive / time_constant(chamber, 1.0)
    return float(rate) if np.ndim(rate) == 0 else rate
