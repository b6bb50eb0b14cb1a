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
import tempfile
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from osmobulge.experiments._io import atomic_write_text
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


def frames_fingerprint(exp: Experiment) -> list:
    """Content hashes of the experiment's frame files (cached by size and mtime).

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
    for f in exp.frame_files():
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
@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; on success move it onto ``path`` (``os.replace``).

    For writers that want a file name (netCDF, matplotlib).  On an exception, or
    when the process dies, ``path`` keeps its old content (or stays absent) and
    the temporary file is removed (or left as a hidden ``.*.tmp`` file that is
    never read).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        yield Path(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


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
                   options: dict | None = None, pipeline=None, errors: str = "ignore") -> ExperimentOutcome:
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

    Returns
    -------
    ExperimentOutcome
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
                    summary = step.compute(exp, results, options) or {}
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
                    out.status, out.error = "failed", f"{name}: {msg}"
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


def _run_one(path, steps, force, options, pipeline):
    """Task body (module level: picklable for process pools and dask)."""
    return run_experiment(path, steps, force=force, options=options, pipeline=pipeline, errors="ignore")


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
        True: a rich progress bar on stderr; a callable is called with each
        :class:`ExperimentOutcome` as it finishes.

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
        elif scheduler == "serial":
            for i, p in enumerate(paths):
                done(i, _run_one(p, steps, force, options, pipeline))
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


def _dask_client(scheduler):
    if not isinstance(scheduler, str):
        return scheduler, False
    if scheduler in SCHEDULERS:  # pragma: no cover - handled by the caller
        raise ValueError(scheduler)
    if "://" not in scheduler and ":" not in scheduler:
        raise ValueError(f"scheduler = {scheduler!r}: expected 'processes', 'serial' or a dask scheduler address "
                         "such as tcp://127.0.0.1:8786")
    try:
        from distributed import Client
    except ImportError as err:
        raise ImportError("scheduler address given but dask.distributed is not installed: "
                          "pip install 'osmobulge[cluster]'") from err
    return Client(scheduler, timeout="10s"), True


@contextlib.contextmanager
def _progress(progress, total: int):
    if callable(progress):
        yield progress
        return
    if not progress:
        yield lambda outcome: None
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  transient=False) as bar:
        task = bar.add_task("experiments", total=total)

        def tick(outcome):
            mark = "ok" if outcome.status == "ok" else outcome.status.upper()
            bar.update(task, advance=1, description=f"{outcome.name or Path(outcome.path).name}: {mark}")

        yield tick


# ---------------------------------------------------------------------------------------------
# the real steps
# ---------------------------------------------------------------------------------------------
def _toml_content(exp: Experiment, *sections) -> dict:
    raw = exp.raw
    return {s: raw.get(s) for s in sections} if sections else raw


def _fp_process(exp: Experiment, options: dict) -> dict:
    from osmobulge.experiments.curation import curation_fingerprint, load_curation

    return {
        "frames": frames_fingerprint(exp),
        "toml": _toml_content(exp, "imaging", "chamber"),
        "curation": curation_fingerprint(load_curation(exp.path), "extraction"),
        "extract_options": options.get("extract", {}),
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
    return process_experiment(exp, results, **options.get("extract", {}))


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


def process_experiment(exp: Experiment, results: Path, **extract_options) -> dict:
    """Extraction step (wired to osmobulge.imaging.extract once it lands)."""
    raise NotImplementedError("osmobulge.imaging.extract is not available yet")


def fit_experiment(exp: Experiment, results: Path, *, models=MODELS) -> dict:
    """Fit step (wired to osmobulge.modeling.fitting once it lands)."""
    raise NotImplementedError("osmobulge.modeling.fitting is not available yet")


_DEFAULT_PIPELINE = {
    "process": Step("process", ("extraction.nc",), (), _fp_process, _compute_process),
    "fit": Step("fit", ("fits.json", "fits.nc"), ("process",), _fp_fit, _compute_fit),
    "report": Step("report", ("report.html",), ("process", "fit"), _fp_report, _compute_report),
}
