"""Expanding a spec into runs and executing them into the store.

Runs execute in worker processes (``concurrent.futures``), each limited to one
BLAS/torch thread so that N workers use N cores; only this (client) process
writes to the store, one transaction per finished run. Runs already in the
store are skipped, so an interrupted sweep resumes where it stopped.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import time
import uuid
from collections import Counter
from concurrent.futures import FIRST_COMPLETED, Executor, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import lru_cache

from tqdm.auto import tqdm

from codesign import Design, count_links
from codesign.scoring import evaluate

from .environment import environment
from .fingerprint import fingerprint_details
from .plugins import load_plugins
from .pool import WorkerPool
from .records import canonical_key
from .registry import get_method
from .spec import ExperimentSpec, Run
from .store import Store

__all__ = [
    "build_instance",
    "execute_run",
    "execute_task",
    "plan_tasks",
    "run_experiment",
    "RunSummary",
    "make_executor",
    "open_executor",
    "StoreBusy",
    "instance_facts",
    "failed_run",
]

# RAYON_NUM_THREADS: Clarabel's faer factorization runs on a rayon pool that otherwise takes every
# core (seen: SLS at N = 100 kept a second thread busy, so two workers ran three threads on 2 cores).
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS",
                "RAYON_NUM_THREADS")


def build_instance(instance_spec: dict):
    """The :class:`codesign.Instance` described by a run's instance spec."""
    from .families import get_family

    return get_family(instance_spec["family"]).build(instance_spec)


def instance_facts(instance) -> dict:
    """What a report needs to know about an instance without rebuilding it."""
    return {"n": int(instance.n), "plant_links": count_links(instance.plant_adj)[0],
            "comm_links": count_links(instance.comm_adj)[0]}


def _evaluated(instance, designs, evaluation) -> list[Design]:
    return [evaluate(instance, d, validation_size=evaluation.validation_size, noise_std=evaluation.noise_std)
            for d in designs]


def _failed(run: Run, exc: BaseException) -> list[Design]:
    if isinstance(exc, SystemExit):
        return failed_run(run, f"the method called sys.exit({exc.code!r})")
    return failed_run(run, f"{type(exc).__name__}: {exc}")


def failed_run(run: Run, message: str, extras: dict | None = None) -> list[Design]:
    """The designs recorded for a run that produced none: one ``failed`` design saying why."""
    return [Design.failure(run.method, run.params, "failed", message, extras=dict(extras or {}))]


def unsendable(run: Run, result: tuple, exc: Exception) -> tuple:
    """The result recorded for a run whose designs cannot leave its worker (they do not pickle)."""
    _, seconds, peak_mb = result
    return (failed_run(run, f"its design could not be sent back from the worker process "
                            f"({type(exc).__name__}: {exc}); a method's designs must pickle"), seconds, peak_mb)


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


def _peak_memory_mb() -> float | None:
    """This process's peak resident memory (MB) since the last reset, or None if unknown."""
    try:
        with open(_STATUS_FILE) as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return None


@contextmanager
def _measured():
    """Wall seconds and peak resident memory (MB, None if unknown) of the block: ``with _measured() as m``."""
    watch = {"peak_mb": None}
    tracked = _reset_peak_memory()
    start = time.perf_counter()
    try:
        yield watch
    finally:
        watch["seconds"] = time.perf_counter() - start
        watch["peak_mb"] = _peak_memory_mb() if tracked else None


def execute_run(run: Run) -> tuple[list[Design], float, float | None]:
    """Run one method on one instance and score its designs; any exception becomes a ``failed`` design.

    Returns the designs, the wall seconds and the process's peak resident memory
    during the run in MB (None where the platform cannot reset the peak: Linux's
    ``/proc/self/clear_refs`` is used). The peak includes what the worker process
    already held (the interpreter and the loaded libraries), not what earlier runs
    freed (returned to the system first, see :func:`_release_freed_memory`).
    """
    with _measured() as m:
        try:
            instance = build_instance(run.instance)
            designs = _evaluated(instance, get_method(run.method)(instance, **run.params), run.evaluation)
        except (Exception, SystemExit) as exc:  # a failing method is a recorded status, never a crashed sweep
            designs = _failed(run, exc)
    return designs, m["seconds"], m["peak_mb"]


def execute_task(runs: list[Run], plugins=()) -> list[tuple[list[Design], float, float | None]]:
    """Run a group of runs of one method; a batched method designs them in one call.

    ``plugins`` are imported first (once per process), so that worker processes
    know the same user methods as the process that planned the runs. Returns
    ``(designs, seconds)`` per run, in order; the seconds of a batched call are
    shared equally. If the batched call fails as a whole, each run is retried
    alone so that one bad run cannot fail its neighbours. Each result is
    ``(designs, seconds, peak_mb)`` as :func:`execute_run` gives it; the runs of a
    batched call share its peak memory.
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
    with _measured() as m:
        try:
            instances = [build_instance(run.instance) for run in runs]
            results = method.run_batch([(inst, run.params) for inst, run in zip(instances, runs)])
            results = [_evaluated(inst, designs, run.evaluation) for inst, designs, run in zip(instances, results, runs)]
        except (Exception, SystemExit):
            results = None
    if results is None:
        return [execute_run(run) for run in runs]
    share = m["seconds"] / len(runs)
    return [(designs, share, m["peak_mb"]) for designs in results]


def plan_tasks(runs: list[Run]) -> list[list[Run]]:
    """Group runs into tasks: batched methods get up to ``batch_size`` runs per task.

    A task holds runs on instances of one family and size only: a batch's seconds are
    shared equally among its runs, so mixing sizes would blur the time per design at
    each N that the report's compute section draws.
    """
    tasks, groups = [], {}
    for run in runs:
        method = get_method(run.method)
        if method.batch is None:
            tasks.append([run])
        else:
            size_key = (run.instance.get("family"), run.instance.get("n"))
            groups.setdefault((run.method, json.dumps(size_key)), []).append(run)
    for (name, _), group in groups.items():
        size = get_method(name).batch_size
        tasks += [group[i:i + size] for i in range(0, len(group), size)]
    # Largest tasks first keeps workers busy to the end.
    return sorted(tasks, key=len, reverse=True)


_LIMITS = []  # the worker's threadpoolctl limits, kept for the process's lifetime


def _limit_threads() -> None:
    """Make this (worker) process single-threaded in every thread pool.

    Runs as the pool's initializer, after unpickling it imported this module and with
    it numpy: OpenBLAS has already started its threads by then, so the environment
    variables alone come too late for it (measured: two workers each ran 2-thread
    OpenBLAS on 2 cores, and numpy-bound methods at N = 100 took 3-20x their
    single-process time). threadpoolctl caps the pools already loaded; the variables
    cover those loaded later (MKL in SCS, rayon in Clarabel, OpenMP), and torch is
    set directly.
    """
    for var in _THREAD_VARS:
        os.environ[var] = "1"
    from threadpoolctl import threadpool_limits

    _LIMITS.append(threadpool_limits(limits=1))
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass


def make_executor(workers: int) -> Executor:
    """A process pool of ``workers`` single-threaded workers (spawned, not forked; see :func:`_limit_threads`)."""
    # The pool starts its processes when work is submitted, so the limits are set in each
    # worker by the initializer rather than through this process's environment.
    return ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_limit_threads,
    )


class ExecutorError(ValueError):
    """An executor address that cannot be used."""


class WorkerSetupError(ExecutorError):
    """A worker that cannot import the experiment's plug-ins (or find its method)."""


@contextmanager
def open_executor(address: str, workers: int):
    """An executor for ``address``, closed on exit.

    ``"process"`` (the default) is a local :class:`~compare.pool.WorkerPool` of ``workers``
    processes (a worker that dies or overruns its time fails its own run only);
    ``"dask-local"`` starts a local dask.distributed cluster of ``workers``
    single-threaded worker processes; ``"dask://HOST:PORT"`` (or ``tcp://``)
    connects to a running scheduler. Dask runs go through the client's
    ``concurrent.futures`` interface; only this process writes to the store.
    """
    if address == "process":
        with WorkerPool(workers) as pool:
            yield pool
        return
    if address == "dask-local" or address.startswith(("dask://", "tcp://")):
        try:
            from distributed import Client, LocalCluster
        except ImportError:  # pragma: no cover
            raise ExecutorError("dask.distributed is not installed: pip install 'dask[distributed]'") from None
        cluster = None
        if address == "dask-local":
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=40)
            client = Client(cluster)
        else:
            target = "tcp://" + address.split("://", 1)[1]
            try:
                client = Client(target, timeout="10s")
            except (OSError, TimeoutError) as exc:
                raise ExecutorError(f"cannot reach the dask scheduler at {target}: {exc}") from None
        try:
            client.run(_limit_threads)  # dask's nanny covers BLAS and OpenMP, not rayon
            yield client.get_executor(pure=False)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
        return
    raise ExecutorError(
        f"unknown executor {address!r}: use 'process', 'dask-local' or 'dask://HOST:PORT'"
    )


@dataclass
class RunSummary:
    """What a call of :func:`run_experiment` did."""

    total: int
    already_stored: int
    computed: int = 0
    by_others: int = 0
    statuses: Counter = field(default_factory=Counter)
    seconds: float = 0.0

    def __str__(self) -> str:
        failed = {k: v for k, v in self.statuses.items() if k != "optimal"}
        parts = [f"{self.total} runs: {self.computed} computed, {self.already_stored} already stored"]
        if self.by_others:
            parts[0] += f", {self.by_others} computed by another process"
        if failed:
            parts.append("non-optimal designs: " + ", ".join(f"{v} {k}" for k, v in sorted(failed.items())))
        parts.append(f"{self.seconds:.1f} s")
        return "; ".join(parts)


class StoreBusy(RuntimeError):
    """Runs of the experiment are being computed by another process and ``wait`` is False."""


def _drain(pool: Executor, tasks: list[list[Run]], plugins, record) -> None:
    """Run ``tasks`` on a ``concurrent.futures`` executor (dask's, or the caller's).

    A task whose future fails (its results would not unpickle, its worker died) is
    recorded as failed, run by run; a worker that cannot load the methods stops all.
    Per-run time limits need the local :class:`~compare.pool.WorkerPool`.
    """
    futures = {pool.submit(execute_task, task, plugins): task for task in tasks}
    try:
        remaining = set(futures)
        while remaining:
            finished, remaining = wait(remaining, return_when=FIRST_COMPLETED)
            for future in finished:
                task = futures[future]
                try:
                    results = future.result()
                except WorkerSetupError:
                    raise
                except Exception as exc:  # noqa: BLE001 - the executor's failure is these runs' status
                    message = f"the executor could not run it: {type(exc).__name__}: {exc}"
                    results = [(failed_run(run, message), 0.0, None) for run in task]
                for run, result in zip(task, results):
                    record(run, *result)
    except BaseException:
        for future in futures:
            future.cancel()
        raise


def _record_meta(spec: ExperimentSpec, runs: list[Run], store: Store) -> None:
    """Store what the report needs beside the runs: the spec, methods, fingerprints and instance facts."""
    store.set_meta(f"spec:{spec.name}", spec.source)
    store.set_meta(f"sections:{spec.name}", list(spec.sections))
    store.set_meta(f"pairs:{spec.name}", [list(pair) for pair in spec.pairs])
    store.set_members(spec.name, [run.key for run in runs])
    for name in dict.fromkeys(run.method for run in runs):
        m = get_method(name)
        details = fingerprint_details(m.modules)
        store.set_meta(f"method:{name}", {"label": m.label, "summary": m.summary, "produces": list(m.produces),
                                          "path_param": m.path_param, "fingerprint": details["fingerprint"]})
        store.set_meta(f"fingerprint:{details['fingerprint']}", {"modules": details["modules"],
                                                                 "versions": details["versions"]})
    known = store.instance_facts()
    for key, spec_dict in {canonical_key(run.instance): run.instance for run in runs}.items():
        if key not in known:
            try:
                facts = instance_facts(build_instance(spec_dict))
            except Exception:  # the instance's runs record the failure; the report draws without its facts
                continue
            store.set_instance_facts(spec_dict, facts)


def run_experiment(
    spec: ExperimentSpec,
    store: Store,
    *,
    workers: int = 1,
    executor: Executor | str | None = None,
    progress: bool = True,
    wait_for_others: bool = True,
    poll: float = 1.0,
) -> RunSummary:
    """Execute every run of ``spec`` not yet in ``store``.

    Parameters
    ----------
    spec : ExperimentSpec
    store : Store
        Finished runs are committed one by one as they complete.
    workers : int
        Worker processes; 1 runs everything in this process.
    executor : concurrent.futures.Executor or str, optional
        An executor to submit runs to, or an address for :func:`open_executor`
        (``"process"``, ``"dask-local"``, ``"dask://HOST:PORT"``). By default a
        local process pool of ``workers`` processes (none when ``workers == 1``).
    progress : bool
        Show a tqdm progress bar.
    wait_for_others : bool
        Runs that another live process has claimed on the same store are left to
        it; True waits for them (so the report is complete), False raises
        :class:`StoreBusy` once this process has computed its own share.
    poll : float
        Seconds between looks at the store while waiting.
    """
    start = time.perf_counter()
    runs = list({run.key: run for run in spec.runs()}.values())
    _record_meta(spec, runs, store)
    limits = store.timed_out()
    # A run stored as stopped at its time limit is tried again when the spec now gives it longer.
    store.forget(run.key for run in runs if run.key in limits
                 and (getattr(run, "timeout", None) or float("inf")) > limits[run.key])
    done = store.done_keys()
    pending = [run for run in runs if run.key not in done]
    store.relabel({run.key: run.label for run in runs if run.key in done})
    summary = RunSummary(total=len(runs), already_stored=len(runs) - len(pending))
    bar = tqdm(total=len(pending), desc=f"{spec.name}", unit="run", disable=not progress or not pending)
    owner = uuid.uuid4().hex

    def record(run, designs, seconds, peak_mb=None):
        store.add_run(run, designs, experiment=spec.name, seconds=seconds, peak_mb=peak_mb, owner=owner)
        summary.computed += 1
        summary.statuses.update(d.status for d in designs)
        bar.update(1)

    running: Counter = Counter()

    def show(runs, sign):
        running.update({run.method: sign for run in runs})
        bar.set_postfix_str(", ".join(f"{m} ×{k}" for m, k in sorted(running.items()) if k > 0), refresh=True)

    def drain(pool, tasks):
        if isinstance(pool, WorkerPool):
            pool.drain(tasks, spec.plugins, record, on_start=lambda runs: show(runs, 1),
                       on_finish=lambda runs: show(runs, -1))
        else:
            _drain(pool, tasks, spec.plugins, record)

    def compute(todo):
        tasks = plan_tasks(todo)
        if executor is None and workers <= 1:
            for task in tasks:
                show(task, 1)
                for run, result in zip(task, execute_task(task)):
                    record(run, *result)
                show(task, -1)
        elif isinstance(executor, (Executor, WorkerPool)):
            drain(executor, tasks)
        else:
            with open_executor(executor or "process", workers) as pool:
                drain(pool, tasks)

    if pending:
        executor_name = (executor if isinstance(executor, str)
                         else "process" if executor is None or isinstance(executor, WorkerPool)
                         else type(executor).__name__)
        store.set_meta(f"environment:{spec.name}", environment(1 if executor is None and workers <= 1 else workers,
                                                               executor_name))
    told = False
    try:
        while pending:
            mine = set(store.claim([run.key for run in pending], owner))
            if mine:
                compute([run for run in pending if run.key in mine])
            stored = store.done_keys()
            left = [run for run in pending if run.key not in stored]
            summary.by_others += len(pending) - len(left) - len(mine & stored)
            bar.update(len(pending) - len(left) - len(mine & stored))
            pending = left
            if not pending:
                break
            others = {store.claims().get(run.key, (None, "?", 0))[1:] for run in pending}
            where = ", ".join(f"pid {pid} on {host}" for host, pid in sorted(others))
            if not wait_for_others:
                raise StoreBusy(f"{len(pending)} runs are being computed by another process ({where}) "
                                f"on {store.path}; run again when it has finished")
            if not told:
                bar.write(f"waiting for {len(pending)} runs being computed by another process ({where})")
                told = True
            time.sleep(poll)
    finally:
        store.release(owner)
        bar.close()
        summary.seconds = time.perf_counter() - start
    return summary
