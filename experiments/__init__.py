"""Experiment folders, curation, batch runs, reports and the ``osmobulge`` command line.

See ``docs/experiment-folder.md`` for every ``experiment.toml`` key.
"""

from osmobulge.experiments.catalog import catalog, group_catalog
from osmobulge.experiments.curation import (
    Curation,
    CurationConflict,
    apply_curation,
    exclude_frame,
    include_frame,
    keep_flagged_frame,
    load_curation,
    remove_manual_profile,
    save_curation,
    set_chamber_regions,
    set_manual_profile,
    set_rim,
    set_time_origin,
)
from osmobulge.experiments.demo import run_demo, write_demo_campaign
from osmobulge.experiments.metadata import (
    Experiment,
    MetadataError,
    find_experiments,
    load_experiment,
    validate_metadata,
    write_template,
)
from osmobulge.experiments.runs import BatchResult, run_batch, run_campaign, run_experiment

__all__ = [
    "Experiment",
    "MetadataError",
    "find_experiments",
    "load_experiment",
    "validate_metadata",
    "write_template",
    "Curation",
    "CurationConflict",
    "apply_curation",
    "exclude_frame",
    "include_frame",
    "keep_flagged_frame",
    "load_curation",
    "remove_manual_profile",
    "save_curation",
    "set_chamber_regions",
    "set_rim",
    "set_manual_profile",
    "set_time_origin",
    "BatchResult",
    "run_batch",
    "run_campaign",
    "run_experiment",
    "catalog",
    "group_catalog",
    "run_demo",
    "write_demo_campaign",
]
