"""``osmobulge demo``: a small synthetic campaign, run end to end to reports.

The paper's five conditions (main text Sec. 3.1, Fig. 2c and 7), a few
chambers each:

==================  ==========  =====  =====  ======  =======
condition           material    a um   h um   l0 um   C0 M
==================  ==========  =====  =====  ======  =======
reference           PDMS        200    110    20      3
small_radius        PDMS        100    110    20      3
thick_membrane      PDMS        200    110    26      3
low_concentration   PDMS        200    110    20      1
peo_pdms            PEO_PDMS    200    110    20      3
==================  ==========  =====  =====  ======  =======

Each chamber's V/V0(t) is simulated with the paper's stretch-dependent
permeability (main text Eqn 27, Table 3 constants for the material,
:func:`osmobulge.modeling.simulate.simulate`) and rendered as cross-section
micrographs (:func:`osmobulge.imaging.synthetic.render_simulation`) with mild,
seeded nuisances (noise, blur, tilt, drift).  Smaller than real data so the
whole demo runs in a few minutes on 2 cores: 400 x 448 px frames at
2.5 um/px (real: 1024-2048 px at ~1 um/px), 34 frames per chamber over 24 h
(every 15 min for the first 3 h, then hourly; real: every 15 min throughout).

One frame of the first reference chamber is rendered delaminated and
excluded in its ``curation.json`` (reason ``delaminated``), as a person would.

Layout::

    DIR/README.txt, truth.json, demo-summary.json
    DIR/<condition>/chamber-<k>/experiment.toml, curation.json, frames/*.tif, truth.nc, results/
    DIR/campaign/  campaign.json, campaign.nc, report.html  (fits per material)
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from osmobulge.experiments._io import atomic_write_bytes, atomic_write_text

__all__ = ["CONDITIONS", "DEMO_TIMES", "PIXEL_SIZE", "FRAME_SHAPE", "write_demo_campaign", "run_demo"]

#: condition -> (material, radius, depth, thickness (m), concentration (mol/m^3))
CONDITIONS = {
    "reference": ("PDMS", 200e-6, 110e-6, 20e-6, 3000.0),
    "small_radius": ("PDMS", 100e-6, 110e-6, 20e-6, 3000.0),
    "thick_membrane": ("PDMS", 200e-6, 110e-6, 26e-6, 3000.0),
    "low_concentration": ("PDMS", 200e-6, 110e-6, 20e-6, 1000.0),
    "peo_pdms": ("PEO_PDMS", 200e-6, 110e-6, 20e-6, 3000.0),
}
#: frame times, s: every 15 min for 3 h, then hourly to 24 h
DEMO_TIMES = np.r_[np.arange(0.0, 3 * 3600.0, 900.0), np.arange(3 * 3600.0, 24 * 3600.0 + 1.0, 3600.0)]
PIXEL_SIZE = 2.5e-6
FRAME_SHAPE = (400, 448)
DELAMINATED = ("reference", 1, 20)  # condition, chamber number, frame index


def _law(material: str):
    from osmobulge.modeling.permeability import DoubleExponential

    return DoubleExponential.PEO_PDMS if material == "PEO_PDMS" else DoubleExponential.PDMS


def _toml(name, condition, material, a, h, l0, c0, times) -> str:
    tm = ", ".join(f"{t / 60.0:g}" for t in times)
    return f'''# osmobulge demo experiment (synthetic; truth in truth.nc).  Keys: docs/experiment-folder.md
[experiment]
name = "{name}"
condition = "{condition}"
material = "{material}"
date = 2024-01-01
operator = "osmobulge demo"
notes = "synthetic frames rendered from the model with the paper's Table 3 permeability"

[chamber]
radius_um = {a * 1e6:g}
depth_um = {h * 1e6:g}
membrane_thickness_um = {l0 * 1e6:g}
concentration_M = {c0 / 1e3:g}
feed_concentration_M = 0.0
temperature_K = 298.15

[imaging]
frames = "frames/*.tif"
pixel_size_um = {PIXEL_SIZE * 1e6:g}
timestamps_min = [{tm}]
bulge_direction = "up"

[analysis]
models = ["constant_linear", "constant_hyperelastic", "double_exponential"]
linear_window_volume_ratio = 1.3
instantaneous = true
rate_method = "spline"
'''


def _write_chamber(folder: Path, condition: str, k: int, seed: int) -> dict:
    import tifffile

    from osmobulge.imaging.synthetic import Nuisances, render_simulation
    from osmobulge.modeling.materials import get_material
    from osmobulge.modeling.simulate import simulate
    from osmobulge.modeling.transport import Chamber

    material_name, a, h, l0, c0 = CONDITIONS[condition]
    material = get_material(material_name)
    chamber = Chamber(a, h, l0, c0)
    sim = simulate(chamber, material, _law(material_name), DEMO_TIMES, on_limit="truncate")
    rng = np.random.default_rng(seed)
    delaminated = (DELAMINATED[2],) if (condition, k) == DELAMINATED[:2] and sim.sizes["time"] > DELAMINATED[2] else ()
    nuis = Nuisances(noise_sigma=0.01, blur_sigma=1.0, tilt=float(rng.uniform(-1.5, 1.5)), drift_sigma=0.5,
                     bit_depth=16, delaminated_frames=delaminated)
    series = render_simulation(sim, chamber=chamber, material=material, pixel_size=PIXEL_SIZE, shape=FRAME_SHAPE,
                               nuisances=nuis, seed=seed)
    frames_dir = folder / "frames"
    frames_dir.mkdir(parents=True, exist_ok=True)
    for i, frame in enumerate(series.frames):
        import io

        buf = io.BytesIO()
        tifffile.imwrite(buf, frame)
        atomic_write_bytes(frames_dir / f"frame_{i:03d}.tif", buf.getvalue())
    truth = series.truth
    truth.attrs["permeability_law"] = repr(_law(material_name))
    from osmobulge.experiments.runs import atomic_path

    with atomic_path(folder / "truth.nc") as tmp:
        truth.to_netcdf(tmp, engine="h5netcdf")
    name = f"{condition}-{k}"
    if delaminated:
        from osmobulge.experiments.curation import exclude_frame

        exclude_frame(folder, delaminated[0], "delaminated", "membrane lifted off the rim (demo: rendered so)",
                      by="osmobulge demo", force=True)
    # written last: a chamber without experiment.toml is rendered again by the next run
    atomic_write_text(folder / "experiment.toml",
                      _toml(name, condition, material_name, a, h, l0, c0, truth["time"].values))
    return {"name": name, "path": str(folder), "frames": int(series.frames.shape[0]),
            "vtilde_end": float(truth["vtilde"].values[-1])}


def write_demo_campaign(directory, *, chambers: int = 2, force: bool = False, progress: bool = False,
                        workers: int | None = 1) -> list[Path]:
    """Write the synthetic campaign (frames, experiment.toml, curation, truth) into ``directory``.

    Parameters
    ----------
    directory : path
    chambers : int
        Chambers per condition (1-10).
    force : bool
        Rewrite chambers that exist already (otherwise they are kept, so a
        second ``osmobulge demo`` only re-runs what changed: nothing).
    progress : bool
        A progress bar (stderr).
    workers : int, optional
        Chambers rendered in parallel (local processes; None: one per CPU).

    Returns
    -------
    list of pathlib.Path
        The experiment folders.
    """
    if not isinstance(chambers, int) or not 1 <= chambers <= 10:
        raise ValueError(f"chambers = {chambers!r}: expected an integer from 1 to 10")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    jobs = []
    for ci, condition in enumerate(CONDITIONS):
        for k in range(1, chambers + 1):
            folder = directory / condition / f"chamber-{k}"
            jobs.append((folder, condition, k, 1000 * ci + k))
    folders = [job[0] for job in jobs]
    todo = [job for job in jobs if force or not (job[0] / "experiment.toml").exists()]
    from contextlib import nullcontext

    bar = nullcontext()
    if progress:
        from rich.console import Console
        from rich.progress import Progress

        bar = Progress(console=Console(stderr=True), transient=True)
    with bar as prog:
        task = prog.add_task("rendering demo frames", total=len(todo)) if progress else None
        n = max(1, min(workers or os.cpu_count() or 1, len(todo)))
        if n == 1:
            for job in todo:
                _write_chamber(*job)
                if progress:
                    prog.update(task, advance=1)
        else:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor, as_completed

            with ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn")) as pool:
                for fut in as_completed([pool.submit(_write_chamber, *job) for job in todo]):
                    fut.result()
                    if progress:
                        prog.update(task, advance=1)
    truth = {}
    for m in ("PDMS", "PEO_PDMS"):
        law = _law(m)
        truth[m] = {"law": "double_exponential", "c1": law.c1, "c2": law.c2, "c3": law.c3, "c4": law.c4,
                    "P_w1": float(law(1.0))}
    atomic_write_text(directory / "truth.json", json.dumps(truth, indent=1) + "\n")
    atomic_write_text(directory / "README.txt", __doc__ or "")
    return folders


def run_demo(directory, *, chambers: int = 2, workers: int | None = None, scheduler="processes",
             force: bool = False, progress: bool = False) -> dict:
    """Write the demo campaign, run every experiment, fit per material, compare with the truth.

    Parameters
    ----------
    directory : path
    chambers : int
        Chambers per condition.
    workers : int, optional
        Local worker processes.
    scheduler : str or distributed.Client
        As in :func:`osmobulge.experiments.runs.run_batch`.
    force : bool
        Re-render the frames and recompute everything.
    progress : bool
        Progress bars.

    Returns
    -------
    dict
        ``n_experiments``, ``seconds`` (wall time), ``exit_code``,
        ``steps_done``/``steps_skipped`` (up-to-date steps are skipped),
        ``campaign_report`` (path), ``recovery``: per material the campaign's
        P_w(1) (double-exponential fit through the ODE), the truth and the
        relative error; also written to ``DIR/demo-summary.json``.
    """
    from osmobulge.experiments.runs import check_scheduler, run_batch, run_campaign

    check_scheduler(scheduler)  # before minutes of rendering
    t0 = time.perf_counter()
    directory = Path(directory)
    folders = write_demo_campaign(directory, chambers=chambers, force=force, progress=progress,
                                  workers=1 if scheduler == "serial" else workers)
    t_write = time.perf_counter() - t0
    batch = run_batch(folders, ("process", "fit", "report"), scheduler=scheduler, workers=workers, force=force,
                      progress=progress)
    ok = [Path(o.path) for o in batch.outcomes if o.status == "ok"]
    camp = run_campaign(ok, directory / "campaign", group_by="material", progress=progress) if ok else \
        {"groups": [], "report": None}
    truth = json.loads((directory / "truth.json").read_text())
    recovery = []
    for g in camp["groups"]:
        m = g["group"]
        fit = g["models"].get("double_exponential", {})
        p = fit.get("P_w1") if fit.get("ok") else None
        true = truth.get(m, {}).get("P_w1")
        recovery.append({"material": m, "n_experiments": g["n_experiments"], "P_w1": p,
                         "P_w1_stderr": fit.get("P_w1_stderr"), "P_w1_true": true,
                         "rel_error": None if p is None or true is None else (p - true) / true})
    summary = {
        "n_experiments": len(folders), "n_ok": len(ok), "exit_code": batch.exit_code,
        "seconds": time.perf_counter() - t0, "seconds_rendering": t_write, "seconds_batch": batch.seconds,
        "scheduler": batch.scheduler, "campaign_report": camp.get("report"), "recovery": recovery,
        "steps_done": sum(st.status == "done" for o in batch.outcomes for st in o.steps),
        "steps_skipped": sum(st.status == "skipped" for o in batch.outcomes for st in o.steps),
        "failed": [{"path": o.path, "error": o.error} for o in batch.outcomes if o.status != "ok"],
    }
    atomic_write_text(directory / "demo-summary.json", json.dumps(summary, indent=1, default=str) + "\n")
    return summary
