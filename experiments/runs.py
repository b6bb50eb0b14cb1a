"""Batch runs: process (extract) -> fit -> report, resumable, in parallel.

Each experiment folder gets ``results/`` with

- ``extraction.nc``: the extraction dataset (:func:`osmobulge.imaging.extract.extract`);
- ``fits.json`` and ``fits.nc``: the permeability fits and the instantaneous permeability;
- ``report.html``: the self-contained report;
- ``state.json``: for each step the content hash of its inputs, the hashes of
  its outputs, its status, duration and error.

A step runs again only when the hash of its inputs changed: the frames'
content (hashed once, then cached by size and modification time), the
``experiment.toml`` content, the curation decisions that matter for that
step, the options, the upstream step's outputs and the code (the package
version and a hash of its source).  Outputs are written atomically and the
state only after them, so a crash or a kill leaves either the old or the new
file and the next run picks up where it stopped.  A failure in one experiment
is recorded in its state and in the batch result (failures are data in
batches, ``errors="ignore"``); the other experiments are not affected.

Parallelism: ``scheduler="processes"`` (default) uses a local process pool;
``"serial"`` runs in this process; an address (``"tcp://host:8786"``) or a
``distributed.Client`` sends one task per experiment to a dask.distributed
cluster (``client.map``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import json
import os
import socket
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from osmobulge.experiments._io import atomic_path, atomic_write_text
from osmobulge.experiments.metadata import MODELS, Experiment, MetadataError, load_experiment

__all__ = [
    "STEPS",
    "STATE_FILE",
    "EXIT_OK",
    "EXIT_FAILED",
    "EXIT_BAD_INPUT",
    "EXIT_ENVIRONMENT",
    "Step",
    "StepOutcome",
    "ExperimentOutcome",
    "BatchResult",
    "run_experiment",
    "run_batch",
    "read_state",
    "experiment_status",
    "code_version",
    "file_sha256",
    "atomic_path",
    "ExperimentLocked",
]

STATE_FILE = "state.json"
LOCK_FILE = ".lock"
FRAME_HASH_CACHE = ".frame-hashes.json"
RESULTS = "results"
#: the steps, in order
STEPS = ("process", "fit", "report")
#: exit codes of the batch commands
EXIT_OK = 0  # every experiment up to date
EXIT_FAILED = 1  # some experiments failed in a step (others are done; re-run to resume)
EXIT_BAD_INPUT = 2  # bad input: no experiment found, invalid experiment.toml, missing frames, bad option
EXIT_ENVIRONMENT = 3  # environment: dask.distributed missing or scheduler unreachable
SCHEDULERS = ("processes", "serial")
#: how long to try reaching a dask scheduler before giving up (exit code 3)
SCHEDULER_TIMEOUT = "10s"


class ExperimentLocked(RuntimeError):
    """Another live run holds the experiment's lock."""


# ---------------------------------------------------------------------------------------------
# hashing
# ---------------------------------------------------------------------------------------------
def file_sha256(path, *, chunk: int = 1 << 20) -> str:
    """SHA-256 of a file's content, read in chunks (constant memory)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def _json_hash(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """``"<version>+<hash>"``: the package version and a hash of its Python source.

    Any change of the code invalidates the results it produced.
    """
    import osmobulge

    root = Path(osmobulge.__file__).resolve().parent
    h = hashlib.sha256()
    for sub in ("modeling", "imaging", "experiments"):
        for p in sorted((root / sub).rglob("*.py")):
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
    h.update((root / "__init__.py").read_bytes())
    return f"{osmobulge.__version__}+{h.hexdigest()[:12]}"


def frames_fingerprint(exp: Experiment, files=None) -> list:
    """Content hashes of the experiment's frame files (or of ``files``), cached by size and mtime.

    Returns
    -------
    list of [str, str]
        ``[name relative to the folder (or absolute), sha256]`` per file.
    """
    cache_path = exp.results_dir / FRAME_HASH_CACHE
    try:
        cache = json.loads(cache_path.read_text())
    except (OSError, json.JSONDecodeError):
        cache = {}
    out, changed = [], False
    for f in (exp.frame_files() if files is None else files):
        st = f.stat()
        key = str(f.resolve())
        hit = cache.get(key)
        if hit and hit[0] == st.st_size and hit[1] == st.st_mtime_ns:
            digest = hit[2]
        else:
            digest = file_sha256(f)
            cache[key] = [st.st_size, st.st_mtime_ns, digest]
            changed = True
        try:
            name = str(f.resolve().relative_to(exp.path.resolve()))
        except ValueError:
            name = str(f.resolve())
        out.append([name, digest])
    if changed:
        with contextlib.suppress(OSError):
            atomic_write_text(cache_path, json.dumps(cache))
    return out


# ---------------------------------------------------------------------------------------------
# atomic outputs, lock, state
# ---------------------------------------------------------------------------------------------
def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@contextlib.contextmanager
def _lock(results: Path):
    """Exclusive lock of one experiment's results (stale locks of dead processes are broken)."""
    results.mkdir(parents=True, exist_ok=True)
    lock = results / LOCK_FILE
    me = {"pid": os.getpid(), "host": socket.gethostname(), "at": time.time()}
    for _ in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                other = json.loads(lock.read_text() or "{}")
            except (OSError, json.JSONDecodeError):
                other = {}
            stale = other.get("host") == me["host"] and not _pid_alive(int(other.get("pid", -1)))
            if stale or not other:
                with contextlib.suppress(OSError):
                    lock.unlink()
                continue
            raise ExperimentLocked(f"{results.parent}: another run holds the lock (pid {other.get('pid')} on "
                                   f"{other.get('host')}); remove {lock} if that run is gone") from None
        with os.fdopen(fd, "w") as fh:
            json.dump(me, fh)
        # temporary files of runs that were killed mid-write (nobody else writes here while we hold the lock)
        for tmp in results.glob(".*.tmp"):
            with contextlib.suppress(OSError):
                tmp.unlink()
        break
    else:  # pragma: no cover - lost a race twice
        raise ExperimentLocked(f"{results.parent}: could not take the lock {lock}")
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            lock.unlink()


def read_state(directory) -> dict:
    """The ``results/state.json`` of an experiment (empty dict when absent or unreadable)."""
    try:
        return json.loads((Path(directory) / RESULTS / STATE_FILE).read_text())
    except (OSError, json.JSONDecodeError):
        return {}


def _write_state(results: Path, state: dict) -> None:
    atomic_write_text(results / STATE_FILE, json.dumps(state, indent=1, sort_keys=True, default=str) + "\n")


# ---------------------------------------------------------------------------------------------
# steps
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Step:
    """One step of the pipeline.

    Attributes
    ----------
    name : str
    outputs : tuple of str
        File names under ``results/``, written atomically by ``compute``.
    after : tuple of str
        Upstream steps (their output hashes are inputs of this one).
    fingerprint : callable
        ``fingerprint(experiment, options) -> dict`` (JSON-safe) of everything
        besides upstream outputs and code that the step reads.
    compute : callable
        ``compute(experiment, results_dir, options) -> dict`` writes the
        outputs and returns a JSON-safe summary.
    """

    name: str
    outputs: tuple
    after: tuple
    fingerprint: Callable
    compute: Callable


@dataclass
class StepOutcome:
    """What happened to one step: ``status`` in done, skipped (up to date), failed, not_run."""

    name: str
    status: str
    seconds: float = 0.0
    error: str = ""
    summary: dict = field(default_factory=dict)


@dataclass
class ExperimentOutcome:
    """Result of :func:`run_experiment` (JSON-safe via :meth:`to_dict`).

    Attributes
    ----------
    path : str
    name : str
    status : str
        ``ok``, ``failed`` (a step raised) or ``invalid`` (bad experiment.toml,
        missing frames, locked).
    steps : list of StepOutcome
    error : str
    """

    path: str
    name: str = ""
    status: str = "ok"
    steps: list = field(default_factory=list)
    error: str = ""
    seconds: float = 0.0

    def __bool__(self) -> bool:
        return self.status == "ok"

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def step(self, name: str) -> StepOutcome | None:
        return next((s for s in self.steps if s.name == name), None)


def _outputs_ok(results: Path, rec: dict) -> bool:
    outs = rec.get("outputs", {})
    for name, digest in outs.items():
        p = results / name
        if not p.is_file() or file_sha256(p) != digest:
            return False
    return bool(outs)


def _pipeline(name_or_steps) -> dict[str, Step]:
    if name_or_steps is None or name_or_steps == "default":
        return dict(_DEFAULT_PIPELINE)
    if isinstance(name_or_steps, dict):
        return dict(name_or_steps)
    return {s.name: s for s in name_or_steps}


def _closure(wanted: Sequence[str], pipeline: dict[str, Step]) -> list[str]:
    need: list[str] = []

    def add(n):
        if n not in pipeline:
            raise ValueError(f"step {n!r}: expected one of {tuple(pipeline)}")
        for u in pipeline[n].after:
            add(u)
        if n not in need:
            need.append(n)

    for n in wanted:
        add(n)
    order = list(pipeline)
    return sorted(need, key=order.index)


def run_experiment(path, steps: Sequence[str] = STEPS, *, force: bool | Sequence[str] = False,
                   options: dict | None = None, pipeline=None, errors: str = "ignore",
                   progress: Callable | None = None) -> ExperimentOutcome:
    """Bring the requested steps of one experiment up to date.

    Steps whose prerequisites are missing or stale run those first; a step whose
    input hash matches its recorded state and whose outputs are intact is skipped.

    Parameters
    ----------
    path : path
        Experiment folder.
    steps : sequence of str
        Any of :data:`STEPS`.
    force : bool or sequence of str
        Re-run these steps (all requested ones when True) even if up to date.
    options : dict, optional
        Step options (``models``: tuple of :data:`MODELS` for the fit step).
    pipeline : optional
        Alternative steps (a sequence of :class:`Step`); default the real pipeline.
    errors : {"ignore", "raise"}
        ``ignore`` (batches): a failure is recorded in the outcome and in
        ``state.json``; ``raise``: re-raise it after recording.
    progress : callable, optional
        ``progress(description, done, total)``: called when a step starts
        (``total`` None) and for every frame the process step reads.

    Returns
    -------
    ExperimentOutcome
        ``status`` is ``invalid`` for bad input (``experiment.toml``, frames
        that cannot be opened as described: :class:`FramesError`), ``failed``
        when a step raised anything else.
    """
    if errors not in ("ignore", "raise"):
        raise ValueError(f"errors = {errors!r}: expected 'ignore' or 'raise'")
    t0 = time.perf_counter()
    options = dict(options or {})
    pipe = _pipeline(pipeline)
    todo = _closure(steps, pipe)
    forced = set(todo if force is True else () if force is False else force)
    out = ExperimentOutcome(path=str(path))
    try:
        exp = load_experiment(path)
    except (MetadataError, FileNotFoundError) as err:
        out.status, out.error = "invalid", str(err)
        out.steps = [StepOutcome(n, "not_run") for n in todo]
        if errors == "raise":
            raise
        return out
    out.name = exp.name
    results = exp.results_dir
    try:
        with _lock(results):
            state = read_state(exp.path)
            state.setdefault("steps", {})
            state["experiment"] = exp.name
            failed = False
            for name in todo:
                if failed:
                    out.steps.append(StepOutcome(name, "not_run"))
                    continue
                step = pipe[name]
                rec = state["steps"].get(name, {})
                s0 = time.perf_counter()
                try:
                    upstream = {u: state["steps"].get(u, {}).get("outputs", {}) for u in step.after}
                    key = _json_hash({"step": name, "inputs": step.fingerprint(exp, options),
                                      "upstream": upstream, "code": code_version()})
                    if (name not in forced and rec.get("status") == "done" and rec.get("key") == key
                            and _outputs_ok(results, rec)):
                        out.steps.append(StepOutcome(name, "skipped", summary=rec.get("summary", {})))
                        continue
                    if progress is not None:
                        progress(f"{exp.name}: {name}", 0, None)
                    opts = {**options, "_progress": progress} if progress is not None else options
                    summary = step.compute(exp, results, opts) or {}
                    outputs = {o: file_sha256(results / o) for o in step.outputs}
                    state["steps"][name] = {
                        "status": "done", "key": key, "outputs": outputs, "summary": summary,
                        "finished": time.strftime("%Y-%m-%dT%H:%M:%S"), "seconds": time.perf_counter() - s0,
                        "code": code_version(),
                    }
                    # downstream results are now stale: their keys will not match
                    _write_state(results, state)
                    out.steps.append(StepOutcome(name, "done", time.perf_counter() - s0, summary=summary))
                except Exception as err:  # noqa: BLE001 - failures are data in batches
                    failed = True
                    msg = f"{type(err).__name__}: {err}"
                    state["steps"][name] = {
                        "status": "failed", "error": msg, "traceback": traceback.format_exc(),
                        "finished": time.strftime("%Y-%m-%dT%H:%M:%S"), "seconds": time.perf_counter() - s0,
                    }
                    _write_state(results, state)
                    out.status = "invalid" if isinstance(err, FramesError) else "failed"
                    out.error = f"{name}: {msg}"
                    out.steps.append(StepOutcome(name, "failed", time.perf_counter() - s0, error=msg))
                    if errors == "raise":
                        raise
    except ExperimentLocked as err:
        out.status, out.error = "invalid", str(err)
        if errors == "raise":
            raise
    out.seconds = time.perf_counter() - t0
    return out


def experiment_status(directory) -> str:
    """``raw``, ``processed``, ``fitted``, ``reported`` (last step done), or ``failed``."""
    steps = read_state(directory).get("steps", {})
    if any(rec.get("status") == "failed" for rec in steps.values()):
        return "failed"
    status = "raw"
    for name, label in (("process", "processed"), ("fit", "fitted"), ("report", "reported")):
        if steps.get(name, {}).get("status") == "done":
            status = label
        else:
            break
    return status


# ---------------------------------------------------------------------------------------------
# batches
# ---------------------------------------------------------------------------------------------
@dataclass
class BatchResult:
    """Outcomes of a batch, in the order of the inputs.

    Attributes
    ----------
    outcomes : list of ExperimentOutcome
    seconds : float
        Wall time.
    scheduler : str
    """

    outcomes: list
    seconds: float = 0.0
    scheduler: str = "serial"

    @property
    def exit_code(self) -> int:
        """:data:`EXIT_OK`, :data:`EXIT_FAILED` or :data:`EXIT_BAD_INPUT` (bad input wins)."""
        if not self.outcomes or any(o.status == "invalid" for o in self.outcomes):
            return EXIT_BAD_INPUT
        if any(o.status == "failed" for o in self.outcomes):
            return EXIT_FAILED
        return EXIT_OK

    @property
    def ok(self) -> bool:
        return self.exit_code == EXIT_OK

    def to_dict(self) -> dict:
        return {"exit_code": self.exit_code, "seconds": self.seconds, "scheduler": self.scheduler,
                "experiments": [o.to_dict() for o in self.outcomes]}


def _run_one(path, steps, force, options, pipeline, progress=None):
    """Task body (module level: picklable for process pools and dask)."""
    return run_experiment(path, steps, force=force, options=options, pipeline=pipeline, errors="ignore",
                          progress=progress)


def _crashed(path, err) -> ExperimentOutcome:
    return ExperimentOutcome(path=str(path), status="failed", error=f"worker crashed: {type(err).__name__}: {err}")


def run_batch(paths: Sequence, steps: Sequence[str] = STEPS, *, scheduler="processes", workers: int | None = None,
              force: bool | Sequence[str] = False, options: dict | None = None, pipeline=None,
              progress: bool | Callable = False) -> BatchResult:
    """Run the steps on many experiments, in parallel.

    Parameters
    ----------
    paths : sequence of path
        Experiment folders.
    steps : sequence of str
        Any of :data:`STEPS`.
    scheduler : str or distributed.Client
        ``"processes"`` (local process pool, default), ``"serial"``, a
        dask.distributed scheduler address (``"tcp://..."``) or a ``Client``.
    workers : int, optional
        Local pool size (default: the number of CPUs, at most the number of experiments).
    force, options, pipeline
        As in :func:`run_experiment`.
    progress : bool or callable
        True: a rich progress bar on stderr (experiments done; when the
        experiments run in this process -- ``"serial"``, or a single
        experiment -- also the current step and its frames); a callable is
        called with each :class:`ExperimentOutcome` as it finishes.

    Returns
    -------
    BatchResult
        Never raises for a failing experiment: see its ``exit_code``.

    Raises
    ------
    ImportError
        A scheduler address was given but dask.distributed is not installed.
    OSError
        The scheduler cannot be reached.
    """
    t0 = time.perf_counter()
    check_scheduler(scheduler)
    paths = [Path(p) for p in paths]
    if pipeline not in (None, "default"):
        _closure(steps, _pipeline(pipeline))  # validate step names early
    else:
        _closure(steps, dict(_DEFAULT_PIPELINE))
    results: dict[int, ExperimentOutcome] = {}
    label = scheduler if isinstance(scheduler, str) else "dask"

    with _progress(progress, len(paths)) as tick:
        def done(i, outcome):
            results[i] = outcome
            tick(outcome)

        if not paths:
            pass
        elif scheduler == "serial" or (scheduler == "processes" and len(paths) == 1):
            # in this process (a pool of one buys nothing): the bar can follow the steps and frames
            for i, p in enumerate(paths):
                done(i, _run_one(p, steps, force, options, pipeline, getattr(tick, "detail", None)))
            if scheduler == "processes":
                label = "processes(in-process)"
        elif scheduler == "processes":
            n = max(1, min(workers or os.cpu_count() or 1, len(paths)))
            _run_pool(paths, n, done, (steps, force, options, pipeline))
            label = f"processes({n})"
        else:
            client, own = _dask_client(scheduler)
            try:
                from distributed import as_completed as dask_completed

                futs = client.map(_run_one, [str(p) for p in paths], steps=list(steps), force=force,
                                  options=options, pipeline=pipeline, pure=False)
                index = {f.key: i for i, f in enumerate(futs)}
                for fut in dask_completed(futs):
                    i = index[fut.key]
                    try:
                        done(i, fut.result())
                    except Exception as err:  # noqa: BLE001
                        done(i, _crashed(paths[i], err))
                label = f"dask({client.scheduler.address})"
            finally:
                if own:
                    client.close()
    return BatchResult([results[i] for i in range(len(paths))], time.perf_counter() - t0, label)


def _run_pool(paths, n, done, args):
    """Local process pool; if a worker dies (the pool breaks), the unfinished experiments are
    re-run each in its own single-process pool, so only the culprit is marked crashed."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("spawn")
    finished: set[int] = set()
    broken = False
    with ProcessPoolExecutor(max_workers=n, mp_context=ctx) as pool:
        futs = {pool.submit(_run_one, p, *args): i for i, p in enumerate(paths)}
        for fut in as_completed(futs):
            i = futs[fut]
            try:
                outcome = fut.result()
            except BrokenProcessPool:
                broken = True
                continue
            except Exception as err:  # noqa: BLE001 - e.g. an unpicklable result
                outcome = _crashed(paths[i], err)
            finished.add(i)
            done(i, outcome)
    if not broken:
        return

    def isolated(i):
        with ProcessPoolExecutor(max_workers=1, mp_context=ctx) as one:
            try:
                return i, one.submit(_run_one, paths[i], *args).result()
            except Exception as err:  # noqa: BLE001 - this experiment kills its worker
                return i, _crashed(paths[i], err)

    rest = [i for i in range(len(paths)) if i not in finished]
    with ThreadPoolExecutor(max_workers=n) as threads:
        for fut in as_completed([threads.submit(isolated, i) for i in rest]):
            done(*fut.result())


def check_scheduler(scheduler) -> None:
    """Raise ValueError unless ``scheduler`` is 'processes', 'serial', an address or a distributed Client."""
    if isinstance(scheduler, str) and scheduler not in SCHEDULERS and "://" not in scheduler and ":" not in scheduler:
        raise ValueError(f"scheduler = {scheduler!r}: expected 'processes', 'serial' or a dask scheduler address "
                         "such as tcp://127.0.0.1:8786")


def _dask_client(scheduler):
    if not isinstance(scheduler, str):
        return scheduler, False
    if scheduler in SCHEDULERS:  # pragma: no cover - handled by the caller
        raise ValueError(scheduler)
    check_scheduler(scheduler)
    try:
        from distributed import Client
    except ImportError as err:
        raise ImportError("scheduler address given but dask.distributed is not installed: "
                          "pip install 'osmobulge[cluster]'") from err
    return Client(scheduler, timeout=SCHEDULER_TIMEOUT), True


@contextlib.contextmanager
def _progress(progress, total: int):
    if callable(progress):
        yield progress
        return
    if not progress:
        yield lambda outcome: None
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=Console(stderr=True), transient=False) as bar:
        task = bar.add_task("experiments", total=total)
        sub: list = []

        def tick(outcome):
            mark = "ok" if outcome.status == "ok" else outcome.status.upper()
            bar.update(task, advance=1, description=f"{outcome.name or Path(outcome.path).name}: {mark}")

        def detail(description, done, total_):
            """Current step (``total_`` None: an indeterminate bar) / frames of an experiment run in this process."""
            if total_ is None or not sub:  # a new step: a fresh task (rich cannot set a total back to None)
                if sub:
                    bar.remove_task(sub.pop())
                sub.append(bar.add_task(description, total=total_))
            bar.update(sub[0], description=description, completed=done)

        tick.detail = detail
        try:
            yield tick
        finally:
            if sub:
                bar.remove_task(sub[0])


# ---------------------------------------------------------------------------------------------
# the real steps
# ---------------------------------------------------------------------------------------------
def _toml_content(exp: Experiment, *sections) -> dict:
    raw = exp.raw
    return {s: raw.get(s) for s in sections} if sections else raw


def _fp_process(exp: Experiment, options: dict) -> dict:
    from osmobulge.experiments.curation import curation_fingerprint, load_curation

    ref = exp.imaging.reference_frame
    return {
        "frames": frames_fingerprint(exp),
        "toml": _toml_content(exp, "imaging", "chamber"),
        "curation": curation_fingerprint(load_curation(exp.path), "extraction"),
        "extract_options": options.get("extract", {}),
        # the flat frame the chamber is found in: its content as much as its name
        **({"reference_frame": frames_fingerprint(exp, [exp.reference_path])} if ref else {}),
    }


def _fp_fit(exp: Experiment, options: dict) -> dict:
    from osmobulge.experiments.curation import curation_fingerprint, load_curation

    return {
        "toml": _toml_content(exp, "experiment", "material", "chamber", "analysis"),
        "curation": curation_fingerprint(load_curation(exp.path), "fit"),
        "models": list(options.get("models") or exp.analysis.models),
    }


def _fp_report(exp: Experiment, options: dict) -> dict:
    from osmobulge.experiments.curation import curation_fingerprint, load_curation

    return {"toml": exp.raw, "curation": curation_fingerprint(load_curation(exp.path), "all"),
            "frames": frames_fingerprint(exp)}


def _compute_process(exp: Experiment, results: Path, options: dict) -> dict:
    return process_experiment(exp, results, progress=options.get("_progress"), **options.get("extract", {}))


def _compute_fit(exp: Experiment, results: Path, options: dict) -> dict:
    models = tuple(options.get("models") or exp.analysis.models)
    bad = [m for m in models if m not in MODELS]
    if bad:
        raise ValueError(f"models = {bad}: expected any of {MODELS}")
    return fit_experiment(exp, results, models=models)


def _compute_report(exp: Experiment, results: Path, options: dict) -> dict:
    from osmobulge.experiments.report import write_experiment_report

    path = write_experiment_report(exp, results / "report.html")
    return {"report": str(path.name)}


# ---- process -----------------------------------------------------------------------------------
class FramesError(ValueError):
    """The frames cannot be opened as the experiment describes them (bad input, exit code 2)."""


def _netcdf_safe_attrs(attrs: dict) -> dict:
    out = {}
    for k, v in attrs.items():
        if v is None:
            continue
        if isinstance(v, bool):
            v = int(v)
        if isinstance(v, dict):
            v = json.dumps(v, default=str)
        out[str(k)] = v
    return out


def experiment_attrs(exp: Experiment) -> dict:
    """netCDF-safe attrs describing the experiment (nested metadata stays in experiment.toml)."""
    meta = exp.summary()
    attrs = {f"experiment_{k}": v for k, v in meta.items() if v is not None and k not in
             ("radius_um", "depth_um", "membrane_thickness_um", "concentration_M", "feed_concentration_M",
              "temperature_K", "pixel_size_um", "frame_interval_min", "frame_times")}
    attrs.update(exp.chamber.to_attrs())
    attrs["osmobulge_code"] = code_version()
    return _netcdf_safe_attrs(attrs)


def _write_netcdf(ds, path: Path) -> None:
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine="h5netcdf")


@dataclass
class ExperimentFrames:
    """The frames of an experiment, opened lazily (:func:`open_experiment_frames`).

    Attributes
    ----------
    frames : dask.array.Array of shape (T, H, W)
        One chunk per frame, read when computed.
    pixel_size : float, m
    times : ndarray of shape (T,), s
        Frame clock (from ``experiment.toml`` or the files).
    frame_index : ndarray of int of shape (T,)
        Index of each frame in the experiment's frame order
        (:meth:`~osmobulge.experiments.metadata.Experiment.frame_files`): the
        frame numbers of ``curation.json``.  Differs from ``arange(T)`` only
        when unreadable files were skipped.
    source : str
    bad_frames : list of (str, str)
        Files skipped by the reader, with the reason.
    time_source : str
        ``"experiment.toml"`` or ``"files"``.
    """

    frames: object
    pixel_size: float
    times: object
    frame_index: object
    source: str
    bad_frames: list
    time_source: str


def _lazy_stack(read, n: int, shape, dtype):
    import dask
    import dask.array as da

    parts = [da.from_delayed(dask.delayed(read, pure=False)(j), shape=tuple(shape), dtype=dtype) for j in range(n)]
    return da.stack(parts)


def open_experiment_frames(exp: Experiment, *, on_frame: Callable | None = None) -> ExperimentFrames:
    """Open the frames of an experiment with :func:`osmobulge.imaging.io.open_series`.

    The pixel size and frame times of ``experiment.toml`` are checked against
    the files' own metadata (they must agree); ``timestamps = "files"`` takes
    the times from the files (relative to the first frame).  A glob's
    matches are one series, in natural file-name order.

    Parameters
    ----------
    exp : Experiment
    on_frame : callable, optional
        Called with no argument each time a frame is read (progress).

    Returns
    -------
    ExperimentFrames

    Raises
    ------
    FramesError
        No readable frame, pixel size or times missing or in conflict with the
        files, a wrong number of ``timestamps_min``.
    """
    import warnings

    import numpy as np

    from osmobulge.imaging.io import open_series

    im = exp.imaging
    kw: dict = {"pixel_size": im.pixel_size}
    if not im.timestamps_from_files:
        if im.timestamps is not None:
            kw["timestamps"] = np.asarray(im.timestamps, float)
        elif im.frame_interval is not None:
            kw["frame_interval"] = float(im.frame_interval)
    files = exp.frame_files()
    source = exp.frames_source()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # skipped files are listed in bad_frames
            series = open_series(source, order="name", **kw)
    except (ValueError, FileNotFoundError) as err:  # io.MetadataError is a ValueError
        raise FramesError(f"{exp.path}: frames {im.frames!r}: {err}") from err
    times = np.asarray(series.timestamps, float)
    names = list(series.names) if hasattr(series, "names") else []
    by_name = {f.name: i for i, f in enumerate(files)}
    if names and len(set(names)) == len(names) and all(n in by_name for n in names):
        index = np.array([by_name[n] for n in names], int)
    else:
        index = np.arange(len(series))
    shape, dtype = series.shape[1:], series.dtype

    def read(j):
        frame = np.asarray(series[j])
        if on_frame is not None:
            on_frame()
        return frame

    if times.shape != (len(series),) or not np.all(np.isfinite(times)):
        raise FramesError(f"{exp.path}: frame times unknown: set [imaging] frame_interval_min or timestamps_min")
    p = float(series.pixel_size) if series.pixel_size is not None else float("nan")
    if not np.isfinite(p):
        raise FramesError(f"{exp.path}: pixel size unknown: set [imaging] pixel_size_um")
    return ExperimentFrames(
        frames=_lazy_stack(read, len(series), shape, dtype), pixel_size=p, times=times, frame_index=index,
        source=str(exp.path / im.frames) if not Path(im.frames).is_absolute() else im.frames,
        bad_frames=list(getattr(series, "bad_frames", [])),
        time_source="files" if im.timestamps_from_files else "experiment.toml")


def _manual_for_region(manual: dict, regions, p: float, what: str = "manual profile") -> list[dict]:
    """Split the manual profiles (or priors) by chamber region; points shifted into each region's crop (m)."""
    import numpy as np

    if not regions:
        return [{f: np.asarray(v["points"], float) for f, v in manual.items()}]
    out = [{} for _ in regions]
    names = [r["name"] for r in regions]
    for f, v in manual.items():
        pts = np.asarray(v["points"], float)
        if v.get("chamber") is not None:
            if v["chamber"] not in names:
                raise FramesError(f"{what} of frame {f}: chamber {v['chamber']!r} is not one of the "
                                  f"chamber regions {names}")
            k = names.index(v["chamber"])
        else:  # the region holding the points' centre
            col, row = pts.mean(axis=0) / p
            hits = [i for i, r in enumerate(regions) if r["rows"][0] <= row < r["rows"][1]
                    and r["cols"][0] <= col < r["cols"][1]]
            if len(hits) != 1:
                setter = "set_prior" if what == "prior" else "set_manual_profile"
                raise FramesError(f"{what} of frame {f} lies in {len(hits)} chamber regions: name its "
                                  f"chamber ({setter}(..., chamber=NAME))")
            k = hits[0]
        r = regions[k]
        out[k][f] = pts - np.array([r["cols"][0], r["rows"][0]], float) * p
    return out


def process_experiment(exp: Experiment, results: Path, *, progress: Callable | None = None,
                       **extract_options) -> dict:
    """The process step: extract the frames -> ``results/extraction.nc``.

    The frames are read lazily (:func:`open_experiment_frames`); each chamber
    region (``curation.json`` or ``[imaging] chamber_regions``) is cropped and
    extracted on its own and the datasets are stacked along a ``chamber``
    dimension; a rim (``curation.json``'s, else ``[imaging] rim_px``) locates
    the chamber instead.  Manual profiles of ``curation.json`` replace the automatic
    trace of their frames (``profile_source = "manual"``); its priors (points
    picked on a few frames, the semi-automatic mode) are passed to the tracer
    as ``priors=`` and their frame numbers recorded in the ``prior_frames``
    attribute.  The curation file itself is only read.

    Parameters
    ----------
    exp : Experiment
    results : pathlib.Path
        The results folder.
    progress : callable, optional
        ``progress(description, done, total)`` after every frame read.
    **extract_options
        Passed to :func:`osmobulge.imaging.extract.extract` (``settings``,
        ``errors``, ``n_profile``, ...).  ``priors`` here (frame position ->
        ``(N, 2)`` points ``(x, y)`` in m of the full frame) are added to the
        curation's, replacing them on the same frames (a preview of unsaved picks).

    Returns
    -------
    dict
        ``n_frames``, ``n_flagged``, ``flags`` (count per flag), ``n_manual``,
        ``n_priors``, ``n_chambers``.
    """
    import dask
    import numpy as np

    from osmobulge.experiments.curation import load_curation
    from osmobulge.imaging.extract import extract, stack_chambers

    cur = load_curation(exp.path)
    im = exp.imaging
    regions = list(cur.chamber_regions) if cur.chamber_regions is not None else [dict(r) for r in im.chamber_regions]
    rim = cur.rim if cur.rim is not None else im.rim  # (the curation's replaces experiment.toml's)
    if rim is not None and regions:  # (experiment.toml's own pair is refused by the metadata check)
        raise FramesError(f"a rim ({'curation.json' if cur.rim is not None else '[imaging] rim_px'}) and chamber "
                          f"regions are both set: the rim locates one chamber in the whole field; clear one of them")
    count = [0, 0]

    def on_frame():
        count[0] += 1
        if progress is not None:
            progress(f"{exp.name}: extracting", count[0], count[1])

    ef = open_experiment_frames(exp, on_frame=on_frame)
    count[1] = len(ef.times) * max(1, len(regions))
    p = ef.pixel_size
    n = len(ef.times)
    # curation frame numbers -> positions in the series
    pos = {int(f): i for i, f in enumerate(ef.frame_index)}
    missing = [f for f in cur.manual_profiles if int(f) not in pos]
    if missing:
        raise FramesError(f"manual profiles of frames {missing}: no such frame (the series has {n})")
    manual = {pos[int(f)]: v for f, v in cur.manual_profiles.items()}
    per_region = _manual_for_region(manual, regions, p)
    missing = [f for f in cur.priors if int(f) not in pos]
    if missing:
        raise FramesError(f"priors of frames {missing}: no such frame (the series has {n})")
    priors = {pos[int(f)]: v for f, v in cur.priors.items()}
    extra = extract_options.pop("priors", None) or {}
    priors.update({int(i): {"points": np.asarray(v, float), "chamber": None} for i, v in extra.items()})
    bad = [i for i in priors if not 0 <= i < n]
    if bad:
        raise FramesError(f"priors at frame positions {bad}: outside 0..{n - 1}")
    priors_region = _manual_for_region(priors, regions, p, "prior")
    options = {"progress": False, **extract_options}
    ref, ref_name = None, None
    if im.reference_frame:  # the frames start bulged: the chamber is found in this file's first frame
        from osmobulge.imaging.io import read_first_frame

        try:
            ref, _ = read_first_frame(exp.reference_path, pixel_size=p)  # (a pixel-size conflict is said there)
        except (ValueError, OSError) as err:
            raise FramesError(f"[imaging] reference_frame {im.reference_frame!r}: {err}") from err
        if ref.shape != ef.frames.shape[1:]:  # before any region crops both alike
            raise FramesError(f"[imaging] reference_frame {im.reference_frame!r} is {ref.shape[0]} x {ref.shape[1]} "
                              f"px, the frames {ef.frames.shape[1]} x {ef.frames.shape[2]} px: one field of view")
        ref_name = str(im.reference_frame)
    parts = []
    for k, region in enumerate(regions or [None]):
        arr = ef.frames
        r0 = c0 = 0
        ref_k = ref
        if region is not None:
            (r0, r1), (c0, c1) = region["rows"], region["cols"]
            if r1 > arr.shape[1] or c1 > arr.shape[2]:
                raise FramesError(f"chamber region {region['name']!r} rows {region['rows']} cols {region['cols']} "
                                  f"exceeds the frames ({arr.shape[1]} x {arr.shape[2]} px)")
            arr = arr[:, r0:r1, c0:c1]
            ref_k = None if ref is None else ref[r0:r1, c0:c1]
        kwargs = {"pixel_size": p, "frame_interval": 1.0, "chamber": exp.chamber,
                  "bulge_direction": im.bulge_direction, "metadata": None, **options}
        if ref_k is not None:
            kwargs["reference_frame"] = ref_k
        if rim is not None:
            kwargs["rim"] = np.reshape(rim, (2, 2)) * p
        if per_region[k]:
            kwargs["manual_profiles"] = per_region[k]
        if priors_region[k]:
            kwargs["priors"] = priors_region[k]
        with dask.config.set(scheduler="synchronous"):  # frames read here, one at a time, never on a cluster
            ds = extract(arr, **kwargs)
        # the real frame clock (extract was given a unit interval: it has no timestamps= argument)
        ds = ds.assign_coords(time=("time", ef.times, {"units": "s", "long_name": "time since the first frame"}),
                              frame=("time", ef.frame_index, {"long_name": "frame index (curation.json)"}))
        for v, off in (("profile_col", c0), ("profile_row", r0), ("axis_col", c0), ("axis_row", r0)):
            if v in ds and off:
                ds[v] = ds[v] + off
        if ref_name is not None:
            ds.attrs["reference_frame"] = ref_name  # (extract saw an array)
        if region is not None:
            ds.attrs.update(region_name=region["name"], region_rows=list(region["rows"]),
                            region_cols=list(region["cols"]))
        parts.append(ds)
    if regions:
        ds = stack_chambers(parts, [r["name"] for r in regions])
        ds["chamber"].attrs["long_name"] = "chamber region"
        for key in ("region_name", "region_rows", "region_cols"):
            ds.attrs.pop(key, None)
        ds["region_rows"] = (("chamber", "bound"), np.array([r["rows"] for r in regions]), {"units": "px"})
        ds["region_cols"] = (("chamber", "bound"), np.array([r["cols"] for r in regions]), {"units": "px"})
        ds = ds.transpose("time", "chamber", ...)
    else:
        ds = parts[0]
    ds.attrs.update(frame_interval=float(np.median(np.diff(ef.times))) if n > 1 else 0.0, source=ef.source,
                    time_source=ef.time_source,
                    bad_frames="; ".join(f"{a}: {b}" for a, b in ef.bad_frames) or "none")
    # frame numbers of curation.json (extract records positions in its own series)
    ds.attrs["prior_frames"] = (np.array(sorted(int(ef.frame_index[i]) for i in priors), np.int64) if priors
                                else "none")
    ds.attrs.update(experiment_attrs(exp))
    _write_netcdf(ds, results / "extraction.nc")
    flags = np.asarray(ds["flag"].values).astype(str).ravel()
    counts = {str(k): int(v) for k, v in zip(*np.unique(flags, return_counts=True), strict=True)}
    return {"n_frames": int(ds.sizes["time"]), "n_flagged": int(np.sum(flags != "ok")), "flags": counts,
            "n_manual": len(manual), "n_priors": len(priors), "n_chambers": max(1, len(regions))}


# ---- fit ---------------------------------------------------------------------------------------
#: fit step models -> (fit_permeability model, mechanics)
MODEL_SPECS = {
    "constant_linear": ("constant", "linear"),
    "constant_hyperelastic": ("constant", "hyperelastic"),
    "double_exponential": ("double_exponential", "hyperelastic"),
}


def observations_from_extraction(ds, exp: Experiment) -> list:
    """Curated per-chamber observations for the fits.

    Parameters
    ----------
    ds : xarray.Dataset
        Extraction dataset after :func:`osmobulge.experiments.curation.apply_curation`.
    exp : Experiment

    Returns
    -------
    list of xarray.Dataset
        One per chamber: ``volume_ratio`` over ``time`` (s) on the kept frames
        with a finite volume, attrs = the chamber (SI) and ``label``.
    """
    import numpy as np
    import xarray as xr

    from osmobulge.imaging.extract import OWN_FIRST_FRAME

    chamber = exp.chamber
    kept = np.asarray(ds["kept"].values, bool) if "kept" in ds else np.ones(ds.sizes["time"], bool)
    if "volume_ratio" in ds:
        vr = ds["volume_ratio"]
    elif "volume" in ds:
        vr = 1.0 + ds["volume"] / chamber.volume
    else:
        raise ValueError("extraction dataset has neither 'volume_ratio' nor 'volume'")
    if "chamber" in vr.dims:
        labels = [str(c) for c in ds["chamber"].values] if "chamber" in ds.coords else \
            [str(i) for i in range(ds.sizes["chamber"])]
        series = [(f"{exp.name}/{lab}", vr.isel(chamber=i).values) for i, lab in enumerate(labels)]
    else:
        series = [(exp.name, vr.values)]
    t = np.asarray(ds["time"].values, float)
    out = []
    for label, v in series:
        v = np.asarray(v, float)
        use = kept & np.isfinite(v) & np.isfinite(t)
        if use.sum() < 3:
            raise ValueError(f"{label}: only {int(use.sum())} usable frames (kept, with a volume); need >= 3")
        attrs = {**chamber.to_attrs(), "label": label}
        tu, vu = t[use], v[use]
        if str(ds.attrs.get("reference_frame", OWN_FIRST_FRAME)) != OWN_FIRST_FRAME:
            # a later file of a split series (the chamber found in a reference frame): its clock starts long
            # after the actuation did, so the flux ODE (main text Eqn 8; autonomous: dV/dt depends on V alone)
            # starts from the state measured at its first usable frame, v0 = that V/V0 at t = 0, not from 1
            attrs["v0"] = float(vu[0])
            tu = tu - tu[0]
        out.append(xr.Dataset({"volume_ratio": ("time", vu, {"units": "1", "long_name": "V/V0"})},
                              coords={"time": ("time", tu, {"units": "s"})}, attrs=attrs))
    return out


def _call_fit(observations, material, model: str, analysis):
    from osmobulge.modeling.fitting import fit_permeability

    fam, mech = MODEL_SPECS[model]
    window = {"volume_ratio_max": analysis.linear_window_volume_ratio} if model == "constant_linear" else None
    return fit_permeability(observations, material, model=fam, mechanics=mech, window=window, errors="raise")


def fit_experiment(exp: Experiment, results: Path, *, models=MODELS) -> dict:
    """The fit step: curated extraction -> ``results/fits.json`` and ``results/fits.nc``.

    Parameters
    ----------
    exp : Experiment
    results : pathlib.Path
    models : sequence of str
        Any of :data:`~osmobulge.experiments.metadata.MODELS`.

    Returns
    -------
    dict
        Summary for ``state.json`` and the catalog: ``n_frames``, ``n_kept``,
        ``P_w1`` (m**2/s) and ``P_w1_stderr`` of the best model ``fit_model``,
        ``fit_rms`` (RMS residual of V/V0), the constant fits, ``n_warnings``.
    """
    import xarray as xr

    from osmobulge.experiments.curation import apply_curation, load_curation

    ds = xr.load_dataset(results / "extraction.nc", engine="h5netcdf")
    cds = apply_curation(ds, load_curation(exp.path))
    obs = observations_from_extraction(cds, exp)
    result = fit_observations(obs, exp.material, models=models, analysis=exp.analysis, label=exp.name)
    data = cds[["kept", "excluded", "exclusion_reason"]].copy()
    out = result["dataset"].merge(data.rename({"time": "frame_time"}), compat="override")
    out.attrs.update(experiment_attrs(exp))
    out.attrs["n_kept"] = int(cds["kept"].sum())
    _write_netcdf(out, results / "fits.nc")
    js = result["json"]
    js["experiment"] = exp.name
    js["n_frames"] = int(cds.sizes["time"])
    js["n_kept"] = int(cds["kept"].sum())
    js["n_excluded"] = int(cds["excluded"].sum())
    atomic_write_text(results / "fits.json", json.dumps(js, indent=1, default=_json_default) + "\n")
    return _fit_summary(js)


def _json_default(o):
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def _finite(x):
    import math

    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _fit_summary(js: dict) -> dict:
    models = js.get("models", {})
    best = next((m for m in ("double_exponential", "constant_hyperelastic", "constant_linear")
                 if models.get(m, {}).get("ok")), None)
    s = {"n_frames": js.get("n_frames"), "n_kept": js.get("n_kept"), "n_excluded": js.get("n_excluded"),
         "fit_model": best, "n_warnings": len(js.get("warnings", []))}
    if best:
        s["P_w1"] = models[best].get("P_w1")
        s["P_w1_stderr"] = models[best].get("P_w1_stderr")
        s["fit_rms"] = models[best].get("rms")
    for m in ("constant_linear", "constant_hyperelastic"):
        if models.get(m, {}).get("ok"):
            s[f"P_w_{m}"] = models[m].get("P_w1")
    return s


def _model_curves(fit, observations, n_fine=200):
    """Fitted V/V0 at the data times and on a fine time grid, per observation."""
    import numpy as np

    at_data, fine = [], []
    for i, o in enumerate(observations):
        t = np.asarray(o["time"].values, float)
        tf = np.linspace(max(0.0, min(t[0], 0.0)), t[-1], n_fine)
        at_data.append(np.asarray(fit.curve(i, t), float))
        fine.append((tf, np.asarray(fit.curve(i, tf), float)))
    return at_data, fine


def fit_observations(observations, material, *, models=MODELS, analysis=None, label: str = "") -> dict:
    """Fit each model to the observations together, plus the instantaneous permeability.

    Parameters
    ----------
    observations : list of xarray.Dataset
        From :func:`observations_from_extraction` (one or many chambers).
    material
        Membrane law.
    models : sequence of str
    analysis : AnalysisSpec, optional
    label : str

    Returns
    -------
    dict
        ``json`` (JSON-safe: per model ``ok``, ``params``, ``stderr``,
        ``P_w1``, ``P_w1_stderr``, ``rms``, ``report``, ``summary`` or
        ``error``; ``instantaneous``; ``warnings``) and ``dataset`` (data,
        model curves, residuals, ``modelfit_coefficients``/``modelfit_stderr``
        over (``model``, ``param``), instantaneous values and bins).
    """
    import numpy as np
    import xarray as xr

    from osmobulge.experiments.metadata import AnalysisSpec

    analysis = analysis or AnalysisSpec()
    warnings: list[str] = []
    n_obs = len(observations)
    # data, flattened over chambers (dim "point")
    t_all = np.concatenate([o["time"].values for o in observations])
    v_all = np.concatenate([o["volume_ratio"].values for o in observations])
    c_all = np.concatenate([np.full(o.sizes["time"], i) for i, o in enumerate(observations)])
    labels = [str(o.attrs.get("label", i)) for i, o in enumerate(observations)]
    js: dict = {"label": label, "code": code_version(), "material": repr(material), "models": {},
                "analysis": dataclasses.asdict(analysis), "chambers": labels}
    params_all: dict[str, dict] = {}
    stderr_all: dict[str, dict] = {}
    curves, fines = {}, {}
    for model in models:
        rec: dict = {"ok": False, "family": MODEL_SPECS[model][0], "mechanics": MODEL_SPECS[model][1]}
        try:
            fit = _call_fit(observations, material, model, analysis)
            params = {k: float(v) for k, v in fit.params.items() if not k.startswith("ln_")}
            stderr = {k: _finite(fit.stderr.get(k)) for k in params}
            at_data, fine = _model_curves(fit, observations)
            resid = v_all - np.concatenate(at_data)
            used = np.isfinite(resid)
            if model == "constant_linear":
                used &= v_all <= analysis.linear_window_volume_ratio
            rms = float(np.sqrt(np.nanmean(resid[used] ** 2))) if used.any() else None
            rel_rms = float(np.sqrt(np.nanmean((resid[used] / v_all[used]) ** 2))) if used.any() else None
            rec.update(ok=True, params=params, stderr=stderr, P_w1=_finite(fit.p_at_rest),
                       P_w1_stderr=_finite(fit.p_at_rest_stderr), rms=rms, rel_rms=rel_rms, n_points=int(used.sum()),
                       redchi=_finite(fit.redchi), nfev=int(fit.nfev), seconds=_finite(fit.elapsed),
                       report=str(fit.report()) if hasattr(fit, "report") else "",
                       summary=_plain(fit.summary()) if hasattr(fit, "summary") else {})
            params_all[model], stderr_all[model] = params, stderr
            curves[model], fines[model] = np.concatenate(at_data), fine
            warnings.extend(_fit_warnings(model, rec, fit))
        except Exception as err:  # noqa: BLE001 - a model that fails is reported, the others go on
            rec["error"] = f"{type(err).__name__}: {err}"
            warnings.append(f"{model}: fit failed ({rec['error']})")
        js["models"][model] = rec
    # instantaneous permeability
    inst_ds = None
    if analysis.instantaneous:
        try:
            from osmobulge.modeling.instantaneous import analyze_instantaneous

            opts = {"bin_width": analysis.bin_width} if analysis.rate_method == "bins" else {}
            inst = analyze_instantaneous(observations, material, method=analysis.rate_method, direct=False, **opts)
            js["instantaneous"] = _plain(inst.summary()) if hasattr(inst, "summary") else {}
            js["instantaneous"]["P_w1"] = _finite(inst.eqn27.params.get("p_at_rest"))
            js["instantaneous"]["P_w1_stderr"] = _finite(inst.eqn27.stderr.get("p_at_rest"))
            inst_ds = inst.to_dataset()
            d = js["models"].get("double_exponential", {})
            if d.get("ok") and js["instantaneous"]["P_w1"] and d.get("P_w1"):
                ratio = js["instantaneous"]["P_w1"] / d["P_w1"]
                js["instantaneous"]["ratio_to_direct"] = ratio
                if abs(ratio - 1) > 0.2:
                    warnings.append(f"instantaneous P_w(1) differs from the direct Eqn 27 fit by "
                                    f"{(ratio - 1) * 100:+.0f} %")
        except Exception as err:  # noqa: BLE001
            js["instantaneous"] = {"error": f"{type(err).__name__}: {err}"}
            warnings.append(f"instantaneous permeability failed ({js['instantaneous']['error']})")
    if len(t_all) < 8:
        warnings.append(f"only {len(t_all)} usable frames")
    js["warnings"] = warnings
    # dataset
    ds = xr.Dataset(
        {"time": ("point", t_all, {"units": "s", "long_name": "time since the time origin"}),
         "volume_ratio": ("point", v_all, {"units": "1", "long_name": "observed V/V0"}),
         "chamber_index": ("point", c_all, {"units": "1", "long_name": "index of the chamber"})},
        coords={"chamber_label": ("chamber_index_dim", labels)},
    )
    fitted = [m for m in models if m in curves]
    if fitted:
        names = sorted({k for m in fitted for k in params_all[m]})
        ds = ds.assign_coords(model=fitted, param=names)
        ds["model_volume_ratio"] = (("model", "point"), np.array([curves[m] for m in fitted]),
                                    {"units": "1", "long_name": "model V/V0 at the data times"})
        ds["residual"] = (("model", "point"), v_all[None, :] - ds["model_volume_ratio"].values,
                          {"units": "1", "long_name": "observed minus model V/V0"})
        ds["modelfit_coefficients"] = (("model", "param"), np.array(
            [[params_all[m].get(k, np.nan) for k in names] for m in fitted]), {"long_name": "fitted parameters"})
        ds["modelfit_stderr"] = (("model", "param"), np.array(
            [[(stderr_all[m].get(k) if stderr_all[m].get(k) is not None else np.nan) for k in names]
             for m in fitted]), {"long_name": "standard errors"})
        nf = len(fines[fitted[0]][0][0])
        ds["fine_time"] = (("chamber", "fine"), np.array([f[0] for f in fines[fitted[0]]]), {"units": "s"})
        ds["fine_volume_ratio"] = (("model", "chamber", "fine"),
                                   np.array([[f[1] for f in fines[m]] for m in fitted]),
                                   {"units": "1", "long_name": "model V/V0 (fine time grid)"})
        del nf
    if inst_ds is not None:
        names = set(inst_ds.variables) | set(inst_ds.dims)
        inst_ds = inst_ds.rename({n: f"inst_{n}" for n in names if not str(n).startswith("inst_")})
        inst_ds.attrs = {}
        ds = ds.merge(inst_ds, compat="override")
    ds.attrs.update({"title": f"permeability fits of {label}", "osmobulge_code": code_version(),
                     "models": ",".join(models), "n_chambers": n_obs,
                     "linear_window_volume_ratio": float(analysis.linear_window_volume_ratio)})
    return {"json": js, "dataset": ds}


def _plain(obj):
    """JSON-safe copy (numpy scalars -> floats, NaN -> None)."""
    import math

    import numpy as np

    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if obj is None or isinstance(obj, str | int | float | bool):
        return obj
    return str(obj)


def _fit_warnings(model: str, rec: dict, fit) -> list[str]:
    out = []
    if rec.get("rel_rms") is not None and rec["rel_rms"] > 0.05:
        out.append(f"{model}: relative RMS residual {rec['rel_rms'] * 100:.2g} % of V/V0 (> 5 %): the model does "
                   "not follow the data")
    for k, v in rec.get("stderr", {}).items():
        val = rec["params"].get(k)
        if v is None:
            out.append(f"{model}: no uncertainty for {k} (at a bound or not identifiable)")
        elif val and abs(v / val) > 0.5:
            out.append(f"{model}: {k} = {val:.3g} +/- {v:.2g} is poorly determined (> 50 %)")
    if model == "constant_linear" and rec.get("n_points", 0) < 4:
        out.append(f"constant_linear: only {rec.get('n_points')} points in the linear window")
    for w in getattr(fit, "warnings", ()) or ():
        out.append(f"{model}: {w}")
    return out


# ---- campaign ------------------------------------------------------------------------------------
def run_campaign(paths, out, *, group_by="material", models=MODELS, progress: bool = False) -> dict:
    """Simultaneous fits across experiments, per group, with their own report.

    Each group (by default one per material: the paper's Table 3) is fitted with
    every model at once over all its chambers' curated V/V0(t) curves, and the
    instantaneous permeability is binned by stretch across the chambers (Fig. 6a).

    Parameters
    ----------
    paths : sequence of path
        Experiment folders with a done ``process`` step.
    out : path
        Output folder: ``campaign.json``, ``campaign.nc`` (one netCDF group per
        experiment group) and ``report.html``.
    group_by : str or sequence of str
        Catalog columns: ``material`` (default), ``condition``, ``geometry``, ``loading``.
    models : sequence of str
    progress : bool

    Returns
    -------
    dict
        JSON-safe summary: ``groups`` (each with ``group``, ``n_experiments``,
        ``experiments``, ``models`` -> ``ok``, ``P_w1``, ``P_w1_stderr``,
        ``rms``, ``params``, ``stderr``; ``instantaneous``; ``warnings``) and ``report``.

    Raises
    ------
    ValueError
        No experiment, an unknown grouping key, or a group mixing materials.
    """
    import xarray as xr

    from osmobulge.experiments.curation import apply_curation, load_curation
    from osmobulge.experiments.metadata import load_experiment

    keys = [group_by] if isinstance(group_by, str) else list(group_by)
    valid = ("material", "condition", "geometry", "loading")
    bad = [k for k in keys if k not in valid]
    if bad:
        raise ValueError(f"group_by = {bad}: expected any of {valid}")
    exps = [load_experiment(p, check_frames=False) for p in paths]
    if not exps:
        raise ValueError("campaign: no experiment with results to fit")
    groups: dict[str, list] = {}
    for e in exps:
        g = {**e.groups(), "condition": e.condition}
        groups.setdefault(" | ".join(str(g[k]) for k in keys), []).append(e)
    out = Path(out)
    summary = {"group_by": keys, "code": code_version(), "groups": []}
    datasets = {}
    with _progress(progress, len(groups)) as tick:
        for label, members in sorted(groups.items()):
            mats = {m.material_name for m in members}
            if len(mats) > 1:
                raise ValueError(f"group {label!r} mixes materials {sorted(mats)}: group by material too")
            obs, frames = [], {}
            for e in members:
                ds = xr.load_dataset(e.results_dir / "extraction.nc", engine="h5netcdf")
                cds = apply_curation(ds, load_curation(e.path))
                o = observations_from_extraction(cds, e)
                for item in o:
                    item.attrs["condition"] = e.condition
                obs.extend(o)
                frames[e.name] = int(cds["kept"].sum())
            res = fit_observations(obs, members[0].material, models=models, analysis=members[0].analysis,
                                   label=label)
            js = res["json"]
            js.update(group=label, n_experiments=len(members), experiments=[str(e.path) for e in members],
                      conditions=sorted({e.condition for e in members}), kept_frames=frames,
                      material=members[0].material_name)
            summary["groups"].append(js)
            datasets[label] = res["dataset"]
            tick(ExperimentOutcome(path=str(out), name=label))
    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / "campaign.nc") as tmp:
        mode = "w"
        for i, (label, ds) in enumerate(sorted(datasets.items())):
            ds.attrs["group"] = label
            ds.to_netcdf(tmp, mode=mode, group=f"group{i}", engine="h5netcdf")
            mode = "a"
    from osmobulge.experiments.report import write_campaign_report

    report = write_campaign_report(summary, datasets, out / "report.html")
    summary["report"] = str(report)
    atomic_write_text(out / "campaign.json", json.dumps(_plain(summary), indent=1) + "\n")
    return _plain(summary)


_DEFAULT_PIPELINE = {
    "process": Step("process", ("extraction.nc",), (), _fp_process, _compute_process),
    "fit": Step("fit", ("fits.json", "fits.nc"), ("process",), _fp_fit, _compute_fit),
    "report": Step("report", ("report.html",), ("process", "fit"), _fp_report, _compute_report),
}
