"""Executing runs in this process: what a worker does with a task, and what it measures.

:func:`execute_task` runs a task (runs of one method; a batched method designs them
in one call) and returns, run by run, a :class:`RunResult`: the scored designs, the
wall seconds, the seconds spent scoring the designs, and the process's resident
memory at the start of the run and at its peak. Any exception, or a method's
``sys.exit``, becomes that run's ``failed`` design. Worker processes
(:mod:`compare.run.pool`, or a dask worker) call it after :func:`limit_threads`;
:mod:`compare.run.runner` calls it directly with one worker.
"""

from __future__ import annotations

import os
import pickle
import sys
import time
import warnings
from contextlib import contextmanager
from dataclasses import replace
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from codesign import Design, count_links
from codesign.design import Timer
from codesign.graphs import design_graph, graph_hash
from codesign.scoring import evaluate
from codesign.status import FAILED

from .plugins import load_plugins
from .registry import get_method
from .spec import Run

__all__ = ["build_instance", "instance_facts", "execute_run", "execute_task", "execute_task_sendable", "failed_run",
           "unsendable", "sendable_results", "reissue_warnings", "RunResult", "ExecutorError", "WorkerSetupError",
           "limit_threads", "THREAD_VARS"]

# RAYON_NUM_THREADS: Clarabel's faer factorization runs on a rayon pool that otherwise takes every
# core (seen: SLS at N = 100 kept a second thread busy, so two workers ran three threads on 2 cores).
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS",
               "RAYON_NUM_THREADS")


def build_instance(instance_spec: dict):
    """The :class:`codesign.Instance` described by a run's instance spec."""
    from .families import get_family

    return get_family(instance_spec["family"]).build(instance_spec)


def instance_facts(instance) -> dict:
    """What a report needs to know about an instance without rebuilding it.

    ``n`` (states), ``nodes``, ``inputs``, ``actuated`` (nodes with an input), ``radius`` (the
    open-loop spectral radius), ``plant_links``, ``comm_links`` and the ``drawing``
    its topology figure draws (:func:`compare.report.topologies.drawing_facts`), None for an
    instance of more than :data:`compare.report.topologies.DRAWN_NODES_AT_MOST` nodes.
    (Facts without a ``drawing`` key were stored before drawings were, without
    ``radius`` before the systems table.)
    """
    from .drawing import drawing_facts

    return {"n": int(instance.n), "nodes": int(instance.nodes), "inputs": int(instance.m),
            "actuated": int(np.unique(instance.input_nodes).size), "radius": float(instance.open_loop_radius),
            "plant_links": count_links(instance.plant_adj)[0], "comm_links": count_links(instance.comm_adj)[0],
            "drawing": drawing_facts(instance)}


class RunResult(NamedTuple):
    """What a run gives back: its designs and what the run cost.

    ``record(run, *result)`` passes the fields in this order (:mod:`compare.run.runner`,
    :mod:`compare.run.pool`). The measurements are None where unknown: a run that ended
    its worker or its time limit, or a platform without Linux's ``/proc`` for memory.

    Attributes
    ----------
    designs : list of Design
        The scored designs (or the one ``failed`` design saying why there are none).
    seconds : float
        Wall seconds of the run: building the instance, the method's call and the
        scoring. A batched run's is an equal share of its batch's.
    peak_mb : float or None
        The process's peak resident memory (MB) during the run, everything it held included.
    scoring_seconds : float or None
        Seconds spent scoring the designs (:func:`codesign.scoring.evaluate`), timed around
        those calls alone; 0 where the method failed before any design was scored.
    baseline_mb : float or None
        The process's resident memory (MB) when the run started, after the peak was reset:
        the interpreter and the libraries loaded so far. ``peak_mb - baseline_mb`` is what
        the run itself added.
    """

    designs: list
    seconds: float
    peak_mb: float | None = None
    scoring_seconds: float | None = None
    baseline_mb: float | None = None


def _with_graph(instance, design: Design) -> Design:
    """The design with ``extras["graph"]``, its graph's hash, where its graph can be recovered.

    A report joins a design to the refits of its graph (:mod:`compare.report.graph_gaps`) by
    this hash; a refit names the graph it was given already.
    """
    if "graph" in design.extras:
        return design
    adj = design_graph(instance, design)
    return design if adj is None else replace(design, extras={**design.extras, "graph": graph_hash(adj)})


def _evaluated(instance, designs, evaluation, watch: Timer) -> list[Design]:
    """The designs scored as the harness scores them; the time the scoring takes goes on ``watch``."""
    with watch:
        return [_with_graph(instance, evaluate(instance, d, validation_size=evaluation.validation_size,
                                               noise_std=evaluation.noise_std))
                for d in designs]


def _failed(run: Run, exc: BaseException) -> list[Design]:
    if isinstance(exc, SystemExit):
        return failed_run(run, f"the method called sys.exit({exc.code!r})")
    return failed_run(run, f"{type(exc).__name__}: {exc}")


def failed_run(run: Run, message: str, extras: dict | None = None) -> list[Design]:
    """The designs recorded for a run that produced none: one ``failed`` design saying why."""
    return [Design.failure(run.method, run.params, FAILED, message, extras=dict(extras or {}))]


def unsendable(run: Run, result: tuple, exc: Exception) -> RunResult:
    """The result recorded for a run whose designs cannot leave its worker (they do not pickle); its timings kept."""
    return RunResult(*result)._replace(designs=failed_run(
        run, f"its design could not be sent back from the worker process ({type(exc).__name__}: {exc}); "
             "a method's designs must pickle"))


def unstorable(run: Run, result: tuple, exc: Exception) -> RunResult:
    """The result recorded for a run whose designs the store cannot hold (params or extras not JSON)."""
    return RunResult(*result)._replace(designs=failed_run(
        run, f"its design could not be stored ({type(exc).__name__}: {exc}); a method's params "
             "and extras must hold numbers, strings, lists and dicts only"))


def _sendable(run: Run, result: tuple) -> bytes:
    try:
        data = pickle.dumps(result)
    except Exception as exc:  # noqa: BLE001 - any pickling error is this run's fault
        return pickle.dumps(unsendable(run, result, exc))
    try:
        for design in result[0]:
            design.to_record()  # what the store will write: its JSON fails here, not in the client
    except Exception as exc:  # noqa: BLE001 - whatever the extras' JSON raises is this run's fault
        return pickle.dumps(unstorable(run, result, exc))
    return data


def sendable_results(runs: list[Run], results: list[tuple]) -> list[bytes]:
    """Each run's result pickled once, in the process that computed it, ready to send back.

    A run whose designs do not pickle (:func:`unsendable`) or do not go into the store's
    JSON (:func:`unstorable`) gets its ``failed`` design instead. Checked here, run by
    run, so that such a fault is its own run's status on every executor: otherwise
    dask reschedules a task whose result it cannot serialize, again and again, and the
    client's store write raises.
    """
    return [_sendable(run, result) for run, result in zip(runs, results)]


def execute_task_sendable(runs: list[Run], plugins=()) -> tuple[list[bytes], list[tuple]]:
    """:func:`execute_task` in a worker: its results as :func:`sendable_results`, and the warnings it raised.

    The warnings (``(message, category, filename, lineno)``, see :func:`reissue_warnings`)
    go back to the client instead of the worker's stderr, where they would land in the
    middle of the progress bar, or above a one-line error the run ends with.
    """
    with warnings.catch_warnings(record=True) as caught:  # the process's filters: each place once
        results = sendable_results(runs, execute_task(runs, plugins))
    return results, [_warning_fields(w) for w in caught]


def _warning_fields(w: warnings.WarningMessage) -> tuple:
    category = w.category
    try:
        pickle.dumps(category)  # a plug-in's own class may not unpickle in the client
    except Exception:  # noqa: BLE001
        category = UserWarning
    return str(w.message), category, w.filename, w.lineno


def reissue_warnings(fields: list[tuple], registry: dict | None = None) -> None:
    """Raise again, in this (client) process, the warnings a worker sent back (:func:`execute_task_sendable`).

    They then go where this process's warnings go: the ``compare`` command holds them
    until it ends (:mod:`compare.cli`); ``registry`` shows each place's warning once.
    """
    for message, category, filename, lineno in fields:
        if not (isinstance(category, type) and issubclass(category, Warning)):
            category = UserWarning
        warnings.warn_explicit(message, category, filename, lineno, registry=registry)


_STATUS_FILE = "/proc/self/status"
_CLEAR_REFS = "/proc/self/clear_refs"


@lru_cache(maxsize=1)
def _malloc_trim():
    """glibc's ``malloc_trim``, or None where there is none (the peak then includes freed memory still held)."""
    try:
        import ctypes

        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None


def _release_freed_memory() -> None:
    """Hand memory that earlier runs freed back to the system (glibc), so that it is not counted again.

    Without it a worker that had run SLS at N = 100 (4.6 GB) kept about 1.2 GB in malloc's
    free lists, and every later run in it reported that as its peak (LQR: 1200 MB).
    """
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


def _reset_peak_memory() -> bool:
    """Start a new resident-memory high-water mark for this process (Linux); False where unsupported."""
    _release_freed_memory()
    try:
        with open(_CLEAR_REFS, "w") as f:
            f.write("5")  # proc(5): "5" resets the peak resident set size (VmHWM) to the current one
        return True
    except OSError:
        return False


def _status_mb(field: str) -> float | None:
    """A memory line of this process's ``/proc/self/status`` (``VmHWM``, ``VmRSS``) in MB, or None if unknown."""
    try:
        with open(_STATUS_FILE) as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return None


def _peak_memory_mb() -> float | None:
    """This process's peak resident memory (MB) since the last reset, or None if unknown."""
    return _status_mb("VmHWM")


def _resident_memory_mb() -> float | None:
    """This process's resident memory (MB) now, or None if unknown."""
    return _status_mb("VmRSS")


@contextmanager
def _measured():
    """Wall seconds, and resident memory (MB, None if unknown) at the start and at the peak, of the block.

    ``with _measured() as m``: then ``m["seconds"]``, ``m["baseline_mb"]`` (what the process
    held when the block started, read just after the peak was reset to it) and ``m["peak_mb"]``.
    """
    watch = {"peak_mb": None, "baseline_mb": None}
    tracked = _reset_peak_memory()
    if tracked:
        watch["baseline_mb"] = _resident_memory_mb()
    start = time.perf_counter()
    try:
        yield watch
    finally:
        watch["seconds"] = time.perf_counter() - start
        watch["peak_mb"] = _peak_memory_mb() if tracked else None


def execute_run(run: Run) -> RunResult:
    """Run one method on one instance and score its designs; any exception becomes a ``failed`` design.

    Returns the :class:`RunResult`: the designs, the wall seconds, the seconds spent
    scoring the designs (timed around the scoring calls, apart from the method's), and
    the process's resident memory in MB at the start of the run and at its peak (None
    where the platform cannot reset the peak: Linux's ``/proc/self/clear_refs`` is
    used). Both include what the worker process already held (the interpreter and the
    libraries loaded so far), not what earlier runs freed (returned to the system
    first, see :func:`_release_freed_memory`); their difference is what the run added.
    """
    scoring = Timer()
    with _measured() as m:
        try:
            instance = build_instance(run.instance)
            designs = _evaluated(instance, get_method(run.method)(instance, **run.params), run.evaluation, scoring)
        except (Exception, SystemExit) as exc:  # a failing method is a recorded status, never a crashed sweep
            designs = _failed(run, exc)
    return RunResult(designs, m["seconds"], m["peak_mb"], scoring.seconds, m["baseline_mb"])


def execute_task(runs: list[Run], plugins=()) -> list[RunResult]:
    """Run a group of runs of one method; a batched method designs them in one call.

    ``plugins`` are imported first (once per process), so that worker processes
    know the same user methods as the process that planned the runs. Returns a
    :class:`RunResult` per run, in order, as :func:`execute_run` gives it. If the
    batched call fails as a whole, each run is retried alone so that one bad run
    cannot fail its neighbours. The runs of a batched call share its wall seconds
    equally (the method designs them together) and its memory baseline and peak;
    each run's scoring seconds are its own, since its designs are scored apart.
    """
    try:
        load_plugins(plugins)
        method = get_method(runs[0].method)
    except Exception as exc:  # the worker's environment, not the run: stop with a message, store nothing
        names = ", ".join(str(getattr(p, "ref", p)) for p in plugins) or "(none)"
        raise WorkerSetupError(
            f"a worker could not load method {runs[0].method!r} (plug-ins: {names}): {exc}; install the plug-ins, "
            "or make their files reachable at the same paths, on every worker"
        ) from None
    if len(runs) == 1 or method.batch is None:
        return [execute_run(run) for run in runs]
    scoring = [Timer() for _ in runs]
    with _measured() as m:
        try:
            instances = [build_instance(run.instance) for run in runs]
            results = method.run_batch([(inst, run.params) for inst, run in zip(instances, runs)])
            results = [_evaluated(inst, designs, run.evaluation, watch)
                       for inst, designs, run, watch in zip(instances, results, runs, scoring)]
        except (Exception, SystemExit):
            results = None
    if results is None:
        return [execute_run(run) for run in runs]
    share = m["seconds"] / len(runs)
    return [RunResult(designs, share, m["peak_mb"], watch.seconds, m["baseline_mb"])
            for designs, watch in zip(results, scoring)]


_LIMITS = []  # the worker's threadpoolctl limits, kept for the process's lifetime


def limit_threads() -> None:
    """Make this (worker) process single-threaded in every thread pool.

    Runs as the pool's initializer, after unpickling it imported this module and with
    it numpy: OpenBLAS has already started its threads by then, so the environment
    variables alone come too late for it (measured: two workers each ran 2-thread
    OpenBLAS on 2 cores, and numpy-bound methods at N = 100 took 3-20x their
    single-process time). threadpoolctl caps the pools already loaded; the variables
    cover those loaded later (MKL in SCS, rayon in Clarabel, OpenMP, and torch, which
    sizes its pool from OMP_NUM_THREADS when it is imported). A torch loaded already
    is set directly; one not loaded is not imported here (1.5 s per worker, for the
    many workers that never train).
    """
    for var in THREAD_VARS:
        os.environ[var] = "1"
    from threadpoolctl import threadpool_limits

    _LIMITS.append(threadpool_limits(limits=1))
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(1)


class ExecutorError(ValueError):
    """An executor address that cannot be used."""


class WorkerSetupError(ExecutorError):
    """A worker that cannot import the experiment's plug-ins (or find its method)."""
