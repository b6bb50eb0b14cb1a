"""The osmobulge napari plugin: curation and manual profile picking.

Installed with the ``napari`` extra and discovered by napari through the npe2
manifest ``napari.yaml``: a reader for experiment folders (a folder holding
``experiment.toml``) and two dock widgets, *Curation* and *Profile picker*.
Open one experiment from a shell with::

    python -m osmobulge.plugins path/to/experiment

All logic is Qt-free and scriptable: :mod:`osmobulge.plugins._session`
(:class:`~osmobulge.plugins._session.CurationSession`),
:mod:`osmobulge.plugins._logic` (snapping, live fits, point ordering) and
:mod:`osmobulge.plugins.roi` (CSV and ImageJ ROI import/export).  Only
``_widget`` imports Qt.  See ``docs/napari-curation.md``.
"""
