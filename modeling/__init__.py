"""Membrane mechanics, transport and permeability fits (pure numerics, SI units)."""

from osmobulge.modeling import materials
from osmobulge.modeling.bulge import (
    NoSolutionError,
    bulge_mechanics,
    bulge_profile,
    locking_volume,
    turgor_ratio,
)
from osmobulge.modeling.prestretch import PreStretch, fit_prestretch
from osmobulge.modeling.table import MechanicsTable, mechanics_table

__all__ = [
    "materials",
    "bulge_profile",
    "bulge_mechanics",
    "locking_volume",
    "turgor_ratio",
    "NoSolutionError",
    "PreStretch",
    "fit_prestretch",
    "MechanicsTable",
    "mechanics_table",
]
