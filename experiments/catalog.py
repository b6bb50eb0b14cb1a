"""Catalog: one row per experiment under a folder (metadata, status, key results).

Reads only ``experiment.toml``, ``curation.json`` and ``results/state.json``
(the summaries each step records), so it is fast on any number of
experiments and never touches the frames.
"""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from osmobulge.experiments.curation import load_curation
from osmobulge.experiments.metadata import MetadataError, find_experiments, load_experiment
from osmobulge.experiments.runs import experiment_status, read_state

__all__ = ["CATALOG_COLUMNS", "GROUP_KEYS", "catalog", "group_catalog", "condition_groups"]

#: grouping keys: chamber geometry, loading (concentrations, temperature), material
GROUP_KEYS = ("geometry", "loading", "material")
#: columns of :func:`catalog`, in order
CATALOG_COLUMNS = (
    "name", "condition", "status", "material", "date", "operator",
    "radius_um", "depth_um", "membrane_thickness_um", "concentration_M", "feed_concentration_M", "temperature_K",
    "n_frames", "n_kept", "n_excluded", "n_flagged", "n_manual",
    "P_w1", "P_w1_stderr", "P_w_constant_linear", "P_w_constant_hyperelastic", "fit_rms", "fit_model",
    "n_warnings", "geometry", "loading", "error", "path",
)


def _row(path: Path) -> dict:
    row: dict = dict.fromkeys(CATALOG_COLUMNS)
    row["path"] = str(path)
    try:
        exp = load_experiment(path, check_frames=False)
    except (MetadataError, FileNotFoundError) as err:
        row.update(name=path.name, status="invalid", error=str(err).splitlines()[0])
        return row
    meta = exp.summary()
    for k in CATALOG_COLUMNS:
        if k in meta:
            row[k] = meta[k]
    row.update(exp.groups())
    row["status"] = experiment_status(path)
    try:
        cur = load_curation(path)
        row["n_excluded"] = len(cur.excluded)
        row["n_manual"] = len(cur.manual_profiles)
    except ValueError as err:
        row["error"] = str(err)
    steps = read_state(path).get("steps", {})
    proc = steps.get("process", {})
    if proc.get("status") == "done":
        s = proc.get("summary", {})
        row["n_frames"] = s.get("n_frames")
        row["n_flagged"] = s.get("n_flagged")
    fit = steps.get("fit", {})
    if fit.get("status") == "done":
        s = fit.get("summary", {})
        for k in ("n_kept", "n_frames", "P_w1", "P_w1_stderr", "fit_rms", "fit_model", "n_warnings",
                  "P_w_constant_linear", "P_w_constant_hyperelastic"):
            if s.get(k) is not None:
                row[k] = s[k]
    failed = [f"{n}: {r.get('error', '')}" for n, r in steps.items() if r.get("status") == "failed"]
    if failed:
        row["error"] = "; ".join(failed)
    return row


def catalog(root) -> pd.DataFrame:
    """Every experiment at or under ``root`` as a table.

    Parameters
    ----------
    root : path or sequence of paths
        Folder(s) searched recursively for ``experiment.toml`` (``results/`` and
        hidden folders skipped).

    Returns
    -------
    pandas.DataFrame
        One row per experiment, columns :data:`CATALOG_COLUMNS`: metadata in
        the file's units (um, M, K), ``status`` (raw, processed, fitted,
        reported, failed, invalid), frame counts (``n_kept`` used by the fits,
        ``n_excluded`` by a person, ``n_flagged`` automatically), key results
        (``P_w1`` = P_w at lambda_bar = 1 in m**2/s from the best fitted model
        ``fit_model``, ``fit_rms`` its RMS residual in V/V0), and the grouping
        keys ``geometry``, ``loading``, ``material``.
    """
    roots = [root] if isinstance(root, str | Path) else list(root)
    paths = []
    for r in roots:
        paths.extend(find_experiments(r))
    rows = [_row(p) for p in paths]
    return pd.DataFrame(rows, columns=list(CATALOG_COLUMNS))


def group_catalog(df: pd.DataFrame, by=GROUP_KEYS) -> pd.DataFrame:
    """Summary per condition: number of experiments, how many fitted, mean and std of P_w(1).

    Parameters
    ----------
    df : pandas.DataFrame
        From :func:`catalog`.
    by : str or sequence of str
        Any of :data:`GROUP_KEYS` or other columns (``condition``).

    Returns
    -------
    pandas.DataFrame
        Indexed by the group keys; columns ``n``, ``n_fitted``, ``P_w1_mean``,
        ``P_w1_std``, ``fit_rms_mean``.
    """
    by = [by] if isinstance(by, str) else list(by)
    bad = [b for b in by if b not in df.columns]
    if bad:
        raise ValueError(f"by = {bad}: expected columns of the catalog such as {GROUP_KEYS} or 'condition'")
    d = df.copy()
    d["P_w1"] = pd.to_numeric(d["P_w1"], errors="coerce")
    d["fit_rms"] = pd.to_numeric(d["fit_rms"], errors="coerce")
    g = d.groupby(by, dropna=False, sort=True)
    out = pd.DataFrame({
        "n": g.size(),
        "n_fitted": g["P_w1"].count(),
        "P_w1_mean": g["P_w1"].mean(),
        "P_w1_std": g["P_w1"].std(),
        "fit_rms_mean": g["fit_rms"].mean(),
    })
    return out


def condition_groups(df: pd.DataFrame, by="material") -> dict[str, list[str]]:
    """Experiment folders per group, e.g. per material for campaign fits.

    Parameters
    ----------
    df : pandas.DataFrame
        From :func:`catalog` (invalid experiments are left out).
    by : str or sequence of str

    Returns
    -------
    dict of str -> list of str
        Group label -> experiment paths.
    """
    by = [by] if isinstance(by, str) else list(by)
    ok = df[df["status"] != "invalid"]
    groups: dict[str, list[str]] = {}
    for key, sub in ok.groupby(by, sort=True, dropna=False):
        key = key if isinstance(key, tuple) else (key,)
        label = " | ".join("" if (isinstance(k, float) and math.isnan(k)) else str(k) for k in key)
        groups[label] = list(sub["path"])
    return groups
