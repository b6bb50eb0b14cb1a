"""osmobulge: deformation-dependent membrane permeability from osmotic microactuators.

The toolkit turns time-lapse cross-section micrographs of bulging, salt-filled
micro-chambers into measured water permeability of the sealing membrane,
following Spitzer & Hutchens (see ``docs/``).

Subpackages
-----------
modeling
    Constitutive laws, the axisymmetric membrane bulge problem, the flux ODE and
    permeability fits.  Pure numerics: SI floats and numpy arrays in, xarray out.
imaging
    Readers, the synthetic micrograph renderer and profile extraction.
experiments
    Experiment folders, curation, batch runs, reports and the command line.
plugins
    The napari plugin (curation and manual profile picking).
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
