"""Membrane mechanics, transport and permeability fits (pure numerics, SI units).

Mechanics (main text Sec. 3.3-3.5): :mod:`~osmobulge.modeling.materials`,
:func:`bulge_profile`, :func:`bulge_mechanics`, :func:`mechanics_table`.
Transport (Sec. 3.2): :class:`Chamber`, :func:`simulate`.
Fits (Sec. 3.6-3.7, supplement Secs 6-7): :func:`fit_permeability`,
:func:`instantaneous_permeability`, :func:`fit_material`.
"""

from osmobulge.modeling import materials
from osmobulge.modeling.bulge import (
    NoSolutionError,
    ProfileBatch,
    bulge_mechanics,
    bulge_profile,
    bulge_profiles,
    locking_volume,
    turgor_ratio,
)
from osmobulge.modeling.fitting import FitError, PermeabilityFit, fit_permeability, register_model, registered_models
from osmobulge.modeling.instantaneous import (
    InstantaneousAnalysis,
    analyze_instantaneous,
    bin_by_stretch,
    collapse_spread,
    dimensionless_collapse,
    fit_eqn27,
    instantaneous_permeability,
    volume_rates,
)
from osmobulge.modeling.material_fit import BulgeProfilePoints, MaterialFit, MaterialFitError, fit_material
from osmobulge.modeling.permeability import Constant, DoubleExponential, Firpo
from osmobulge.modeling.prestretch import PreStretch, fit_prestretch
from osmobulge.modeling.simulate import MechanicsRangeError, simulate
from osmobulge.modeling.table import MechanicsTable, mechanics_table
from osmobulge.modeling.transport import (
    CHAMBER_ATTRS,
    PAPER_CHAMBERS,
    Chamber,
    mobility,
    paper_chamber,
    permeability_from_mobility,
    time_constant,
    volume_ratio_from_vtilde,
    vtilde_from_volume_ratio,
)

__all__ = [
    "materials",
    "bulge_profile",
    "bulge_profiles",
    "ProfileBatch",
    "bulge_mechanics",
    "locking_volume",
    "turgor_ratio",
    "NoSolutionError",
    "PreStretch",
    "fit_prestretch",
    "MechanicsTable",
    "mechanics_table",
    "Chamber",
    "paper_chamber",
    "PAPER_CHAMBERS",
    "CHAMBER_ATTRS",
    "mobility",
    "permeability_from_mobility",
    "time_constant",
    "vtilde_from_volume_ratio",
    "volume_ratio_from_vtilde",
    "simulate",
    "MechanicsRangeError",
    "Constant",
    "DoubleExponential",
    "Firpo",
    "fit_permeability",
    "PermeabilityFit",
    "FitError",
    "register_model",
    "registered_models",
    "instantaneous_permeability",
    "analyze_instantaneous",
    "InstantaneousAnalysis",
    "bin_by_stretch",
    "collapse_spread",
    "dimensionless_collapse",
    "fit_eqn27",
    "volume_rates",
    "fit_material",
    "MaterialFit",
    "MaterialFitError",
    "BulgeProfilePoints",
]
