"""Expanding a spec into runs and executing them into the store.

Runs execute in worker processes (:mod:`compare.run.pool` locally, or a dask
cluster), each limited to one BLAS/torch thread so that N workers use N cores;
what a worker does with a task is :mod:`compare.run.execution`. Only this (client)
process writes to the store, one transaction per finished run. Runs already in
the store are skipped, so an interrupted sweep resumes where it stopped.
"""

from __future__ import annotations

import json
import multiprocessing
import pickle
import socket
import time
import uuid
from collections import Counter
from concurrent.futures import FIRST_COMPLETED, Executor, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass, field

from tqdm.auto import tqdm

from codesign.status import OPTIMAL

from .environment import environment
from .execution import (  # noqa: F401 - re-exported: the runner's public names
    THREAD_VARS,
    ExecutorError,
    RunResult,
    WorkerSetupError,
    build_instance,
    execute_run,
    execute_task,
    execute_task_sendable,
    failed_run,
    instance_facts,
    limit_threads,
    reissue_warnings,
    sendable_results,
)
from .families import get_family
from .fingerprint import fingerprint_details
from .meta import MetaKind, meta_key
from .pool import WorkerPool
from .records import canonical_key
from .refits import has_refits, refit_runs
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


def make_executor(workers: int) -> Executor:
    """A process pool of ``workers`` single-threaded workers (spawned, not forked; see :func:`limit_threads`)."""
    # The pool starts its processes when work is submitted, so the limits are set in each
    # worker by the initializer rather than through this process's environment.
    return ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=limit_threads,
    )


@contextmanager
def open_executor(address: str, workers: int):
    """An executor for ``address``, closed on exit.

    ``"process"`` (the default) is a local :class:`~compare.run.pool.WorkerPool` of ``workers``
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
            from distributed.comm import parse_host_port
        except ImportError:  # pragma: no cover
            raise ExecutorError("dask.distributed is not installed: pip install 'dask[distributed]'") from None
        cluster = None
        if address == "dask-local":
            import logging

            import dask

            # A worker that dies fails its task at once, as in the local pool: dask's default retries it
            # on three more workers (each restarted by its nanny), and under load such a round of
            # restarts hung 2 of 8 tries of a plug-in calling os._exit. The scheduler runs in this
            # process, so its log of that failure would reach the terminal of a successful run.
            with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=logging.CRITICAL)
            client = Client(cluster)
        else:
            target = "tcp://" + address.split("://", 1)[1]
            try:
                # A refused connection answers at once; dask's client would retry it until its timeout.
                socket.create_connection(parse_host_port(target[len("tcp://"):]), timeout=10).close()
                client = Client(target, timeout="10s")
            except (OSError, TimeoutError, ValueError) as exc:
                raise ExecutorError(f"cannot reach the dask scheduler at {target}: {exc}") from None
        try:
            client.run(limit_threads)  # dask's nanny covers BLAS and OpenMP, not rayon
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
    #: Source designs a refit stage could not refit: no graph recovered (compare.run.refits).
    graphless: int = 0

    def __str__(self) -> str:
        failed = {k: v for k, v in self.statuses.items() if k != OPTIMAL}
        parts = [f"{self.total} runs: {self.computed} computed, {self.already_stored} already stored"]
        if self.by_others:
            parts[0] += f", {self.by_others} computed by another process"
        if failed:
            parts.append("non-optimal designs: " + ", ".join(f"{v} {k}" for k, v in sorted(failed.items())))
        if self.graphless:
            parts.append(f"{self.graphless} source designs with no graph to refit")
        parts.append(f"{self.seconds:.1f} s")
        return "; ".join(parts)


class StoreBusy(RuntimeError):
    """Runs of the experiment are being computed by another process and ``wait`` is False."""


def _drain(pool: Executor, tasks: list[list[Run]], plugins, record) -> None:
    """Run ``tasks`` on a ``concurrent.futures`` executor (dask's, or the caller's).

    A task whose future fails (its results would not unpickle, its worker died) is
    recorded as failed, run by run; a worker that cannot load the methods stops all.
    Results travel pickled by the worker (:func:`compare.run.execution.sendable_results`), so
    that a design which cannot be serialized is its run's failure, not a task the
    executor retries for ever. Per-run time limits need the local
    :class:`~compare.run.pool.WorkerPool`.
    """
    futures = {pool.submit(execute_task_sendable, task, plugins): task for task in tasks}
    warned: dict = {}
    try:
        remaining = set(futures)
        while remaining:
            finished, remaining = wait(remaining, return_when=FIRST_COMPLETED)
            for future in finished:
                task, caught = futures[future], []
                try:
                    sent, caught = future.result()
                    results = [pickle.loads(result) for result in sent]
                except WorkerSetupError:
                    raise
                except Exception as exc:  # noqa: BLE001 - the executor's failure is these runs' status
                    message = f"the executor could not run it: {type(exc).__name__}: {exc}"
                    if type(exc).__name__ == "KilledWorker":  # dask's: the process running it exited or was killed
                        message = (f"its dask worker died while running it (the process exited or was killed; "
                                   f"KilledWorker: {exc})")
                    results = [RunResult(failed_run(run, message), 0.0) for run in task]
                for run, result in zip(task, results):
                    record(run, *result)
                reissue_warnings(caught, warned)  # after recording: a warning filtered to "error" loses no run
    except BaseException:
        for future in futures:
            future.cancel()
        raise


#: Instance facts written per transaction while planning: few commits, and an interrupted plan keeps its batches.
PLAN_BATCH = 1000
#: Instances above this many states take seconds or more to build (paper family with connect = "bridge":
#: 36 s at n = 600, 240 s at n = 3000 on 2 cores): planning then shows its bar from the start.
SLOW_PLAN_STATES = 100


def _record_meta(spec: ExperimentSpec, runs: list[Run], store: Store, progress: bool = False) -> None:
    """Store what the report needs beside the runs: the spec, methods, fingerprints and instance facts.

    Each instance is built once here, in this process, for its facts (a few ms each at
    small sizes); a bar shows it when that takes more than a couple of seconds, and the
    facts are written :data:`PLAN_BATCH` instances per transaction, not one commit each.
    """
    entries = {meta_key(MetaKind.SPEC, spec.name): spec.source,
               meta_key(MetaKind.SECTIONS, spec.name): list(spec.sections),
               meta_key(MetaKind.PAIRS, spec.name): [list(pair) for pair in spec.pairs]}
    for name in dict.fromkeys(run.method for run in runs):
        m = get_method(name)
        details = fingerprint_details(m.modules)
        entries[meta_key(MetaKind.METHOD, name)] = {
            "label": m.label, "summary": m.summary, "produces": list(m.produces), "path_param": m.path_param,
            "fingerprint": details["fingerprint"]}
        entries[meta_key(MetaKind.FINGERPRINT, details["fingerprint"])] = {
            "modules": details["modules"], "versions": details["versions"]}
    store.set_metas(entries)
    store.set_members(spec.name, [run.key for run in runs])
    known = store.instance_facts()
    # "radius" missing: new, or stored before the systems table's facts.
    todo = [spec_dict for key, spec_dict in {canonical_key(run.instance): run.instance for run in runs}.items()
            if "radius" not in known.get(key, {})]
    batch = []
    # tqdm checks its delay only when an item finishes: one slow build showed nothing at all.
    slow = any((get_family(s["family"]).states(s) or 0) > SLOW_PLAN_STATES for s in todo)
    with tqdm(todo, desc=f"{spec.name}: planning", unit="instance", disable=not progress,
              delay=0.0 if slow else 2.0) as bar:
        for spec_dict in bar:
            if slow:
                bar.set_postfix_str(f"building {spec_dict['family']} n = {spec_dict.get('n')}", refresh=True)
            try:
                batch.append((spec_dict, instance_facts(build_instance(spec_dict))))
            except Exception:  # the instance's runs record the failure; the report draws without its facts
                pass
            if len(batch) >= PLAN_BATCH:
                store.set_metas(store.instance_facts_entries(batch))
                batch = []
    if batch:
        store.set_metas(store.instance_facts_entries(batch))


def _pending_runs(runs: list[Run], store: Store) -> list[Run]:
    """The runs of ``runs`` still to compute; those already stored take the spec's labels and instance specs."""
    limits = store.timed_out()
    # A run stored as stopped at its time limit is tried again when the spec now gives it longer.
    store.forget(run.key for run in runs if run.key in limits
                 and (getattr(run, "timeout", None) or float("inf")) > limits[run.key])
    done = store.done_keys()
    pending = [run for run in runs if run.key not in done]
    store.relabel({run.key: run.label for run in runs if run.key in done})
    store.redescribe({run.key: run.instance for run in runs if run.key in done})
    return pending


def _record_environment(spec: ExperimentSpec, store: Store, executor, workers: int) -> None:
    """Store the machine and executor that compute this call's runs, for the report's compute section."""
    executor_name = (executor if isinstance(executor, str)
                     else "process" if executor is None or isinstance(executor, WorkerPool)
                     else type(executor).__name__)
    store.set_meta(meta_key(MetaKind.ENVIRONMENT, spec.name),
                   environment(1 if executor is None and workers <= 1 else workers, executor_name))


class _Sweep:
    """The state one call of :func:`run_experiment` shares with the executors' callbacks.

    Results are recorded as they arrive, each in its own transaction under this call's
    claim ``owner``; the bar shows how many runs of each method are running.
    """

    def __init__(self, spec: ExperimentSpec, store: Store, summary: RunSummary, bar, executor, workers: int):
        self.spec, self.store, self.summary, self.bar = spec, store, summary, bar
        self.executor, self.workers = executor, workers
        self.owner = uuid.uuid4().hex
        self.running: Counter = Counter()

    def record(self, run, designs, seconds, peak_mb=None, scoring_seconds=None, baseline_mb=None):
        # The fields of a compare.run.execution.RunResult, in its order.
        self.store.add_run(run, designs, experiment=self.spec.name, seconds=seconds, peak_mb=peak_mb,
                           scoring_seconds=scoring_seconds, baseline_mb=baseline_mb, owner=self.owner)
        self.summary.computed += 1
        self.summary.statuses.update(d.status for d in designs)
        self.bar.update(1)

    def show(self, runs, sign):
        for run in runs:
            self.running[run.method] += sign
        self.bar.set_postfix_str(", ".join(f"{m} ×{k}" for m, k in sorted(self.running.items()) if k > 0),
                                 refresh=True)

    def compute(self, todo: list[Run]) -> None:
        """Compute ``todo`` (runs this call has claimed): in this process, or on the executor asked for."""
        tasks = plan_tasks(todo)
        if self.executor is None and self.workers <= 1:
            for task in tasks:
                self.show(task, 1)
                # Through pickle as in a worker: a design that could not leave one fails here too.
                for run, result in zip(task, sendable_results(task, execute_task(task))):
                    self.record(run, *pickle.loads(result))
                self.show(task, -1)
        elif isinstance(self.executor, (Executor, WorkerPool)):
            self.drain(self.executor, tasks)
        else:
            with open_executor(self.executor or "process", self.workers) as pool:
                self.drain(pool, tasks)

    def drain(self, pool, tasks: list[list[Run]]) -> None:
        if isinstance(pool, WorkerPool):
            pool.drain(tasks, self.spec.plugins, self.record, on_start=lambda runs: self.show(runs, 1),
                       on_finish=lambda runs: self.show(runs, -1))
        else:
            _drain(pool, tasks, self.spec.plugins, self.record)

    def until_stored(self, pending: list[Run], wait_for_others: bool, poll: float) -> None:
        """Claim and compute ``pending`` until every run is stored, by this process or by others."""
        told = False
        while pending:
            mine = set(self.store.claim([run.key for run in pending], self.owner))
            if mine:
                self.compute([run for run in pending if run.key in mine])
            stored = self.store.done_keys()
            left = [run for run in pending if run.key not in stored]
            by_others = len(pending) - len(left) - len(mine & stored)
            self.summary.by_others += by_others
            self.bar.update(by_others)
            pending = left
            if not pending:
                break
            where = _claimants(self.store, pending)
            if not wait_for_others:
                raise StoreBusy(f"{len(pending)} runs are being computed by another process ({where}) "
                                f"on {self.store.path}; run again when it has finished")
            if not told:
                self.bar.write(f"waiting for {len(pending)} runs being computed by another process ({where})")
                told = True
            time.sleep(poll)


def _claimants(store: Store, runs: list[Run]) -> str:
    """"pid 123 on host, ...": the processes whose claims hold ``runs``."""
    others = {store.claims().get(run.key, (None, "?", 0))[1:] for run in runs}
    return ", ".join(f"pid {pid} on {host}" for host, pid in sorted(others))


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
    summary = RunSummary(total=0, already_stored=0)
    try:
        _run_stage(spec, store, runs, summary, spec.name, executor, workers, progress, wait_for_others, poll)
        if has_refits(spec):
            # The second stage: refits of the graphs the first stage's designs chose (compare.run.refits).
            plan = refit_runs(spec, store, runs)
            summary.graphless = plan.graphless
            _run_stage(spec, store, runs + plan.runs, summary, f"{spec.name}: refits", executor, workers, progress,
                       wait_for_others, poll, new=plan.runs)
    finally:
        summary.seconds = time.perf_counter() - start
    return summary


def _run_stage(spec, store, runs, summary, desc, executor, workers, progress, wait_for_others, poll, new=None):
    """Record ``runs`` as the experiment's members and compute those of ``new`` (all by default) not stored."""
    new = runs if new is None else new
    _record_meta(spec, runs, store, progress)
    pending = _pending_runs(new, store)
    summary.total += len(new)
    summary.already_stored += len(new) - len(pending)
    bar = tqdm(total=len(pending), desc=desc, unit="run", disable=not progress or not pending)
    sweep = _Sweep(spec, store, summary, bar, executor, workers)
    if pending:
        _record_environment(spec, store, executor, workers)
    try:
        sweep.until_stored(pending, wait_for_others, poll)
    finally:
        # Released even when interrupted: another process may then take the runs left.
        store.release(sweep.owner)
        bar.close()
