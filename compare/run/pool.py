"""Local worker processes for ``compare run``: one run's fault is that run's status.

:class:`WorkerPool` keeps ``workers`` long-lived spawned processes and hands each one
task (a list of runs) at a time over its own pipe, so the pool always knows which
runs a process holds. That is what ``concurrent.futures.ProcessPoolExecutor``
cannot give: when one of its workers dies, every pending future fails with
``BrokenProcessPool`` and nothing says whose run killed it. Here:

- a worker that dies (segfault, ``os._exit``) or a task over its time limit
  (the runs' ``timeout``) fails that task only; a task of several runs is retried
  run by run, so that the failure lands on the run that caused it, recorded as a
  ``failed`` design whose message says what happened; a new worker takes the
  dead one's place;
- a design that cannot be pickled, or whose extras the store cannot hold, fails its
  own run (checked in the worker, run by run: :func:`compare.run.execution.sendable_results`),
  not the sweep;
- workers die with the process that started them, however it ends: Linux's
  ``PR_SET_PDEATHSIG`` kills them when it dies (even by SIGKILL), a watchdog thread
  covers other platforms, and an idle worker exits when its pipe closes; they
  ignore SIGINT, so Ctrl-C in a terminal interrupts the run once, without
  tracebacks from idle workers.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
import threading
import time
from collections import deque
from multiprocessing.connection import wait as wait_ready

__all__ = ["WorkerPool", "death_message", "timeout_failure"]

_PR_SET_PDEATHSIG = 1  # linux/prctl.h
#: The longest one wait for the workers lasts, in seconds; the loop then checks the time limits again.
#: A limit of 1e10 s would otherwise reach the operating system's wait, which cannot hold it
#: (OverflowError "timestamp too large to convert to C _PyTime_t" past about 9.2e9 s).
_LONGEST_WAIT = 3600.0


def _die_with_parent(parent_pid: int) -> None:
    """Make this process end when ``parent_pid`` does (SIGKILL from the kernel where it can)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):  # not Linux: the watchdog alone
        pass
    if os.getppid() != parent_pid:  # the parent died before the request took effect
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True, name="parent-watchdog").start()


def _watch_parent(parent_pid: int) -> None:
    while True:
        time.sleep(1.0)
        if os.getppid() != parent_pid:
            os._exit(1)


_HELD = {signal.SIGINT, signal.SIGTERM}


def _start_with_signals_held(process) -> None:
    """Start ``process`` with Ctrl-C and SIGTERM held back in this thread until it is started.

    Otherwise an interrupt inside ``start()`` could leave a half-started worker that the pool
    does not know and cannot stop. The child inherits the held mask, so a Ctrl-C reaching it
    before :func:`_serve` ignores SIGINT waits there, and is then dropped.
    """
    hold = hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD) if hold else None
    try:
        process.start()
    finally:
        if hold:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _serve(conn, parent_pid: int) -> None:
    """A worker's life: take a task, run it, send back its results; end when the pipe closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _HELD)  # held while it was started
    _die_with_parent(parent_pid)
    from .execution import WorkerSetupError, execute_task_sendable, limit_threads

    limit_threads()
    while True:
        try:
            task_id, runs, plugins = conn.recv()
        except (EOFError, OSError):
            return
        conn.send(("started", task_id, None))
        try:
            reply = ("done", task_id, execute_task_sendable(runs, plugins))
        except WorkerSetupError as exc:
            reply = ("setup", task_id, str(exc))
        except BaseException as exc:  # noqa: BLE001 - whatever escaped the runs' own guards
            reply = ("crashed", task_id, f"{type(exc).__name__}: {exc}")
        conn.send(reply)


def death_message(exitcode: int | None) -> str:
    """Why a worker process ended, in words."""
    if exitcode is None:
        return "its worker process ended"
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        return f"its worker process was killed by {name}"
    return f"its worker process exited with code {exitcode}"


def timeout_failure(limit: float) -> str:
    return f"stopped at its time limit of {limit:g} s (timeout = {limit:g}); a larger timeout reruns it"


class _Worker:
    def __init__(self, context):
        self.conn, child = context.Pipe()
        self.process = context.Process(target=_serve, args=(child, os.getpid()), daemon=True,
                                       name="compare-worker")
        _start_with_signals_held(self.process)
        child.close()
        self.task = None  # (task id, runs, started, deadline)

    def stop(self, *, kill: bool = False) -> None:
        if kill and self.process.is_alive():
            self.process.kill()
        self.conn.close()
        self.process.join(timeout=5)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()


def _deadline(runs, now: float) -> float | None:
    limits = [getattr(run, "timeout", None) for run in runs]
    if any(limit is None for limit in limits):
        return None
    return now + sum(limits)


class WorkerPool:
    """``workers`` spawned worker processes, started when the first task comes.

    Use as a context manager; leaving it (normally or by an exception, Ctrl-C
    included) ends every worker.

    Parameters
    ----------
    workers : int
        Processes running tasks at once.
    """

    def __init__(self, workers: int):
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.workers = workers
        self._context = multiprocessing.get_context("spawn")
        self._idle: list[_Worker] = []
        self._busy: list[_Worker] = []
        self._next_id = 0
        self._warned: dict = {}  # the workers' warnings already shown (warnings' registry)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(kill=exc_type is not None)

    def close(self, *, kill: bool = False) -> None:
        """End every worker: idle ones exit when their pipe closes; ``kill`` stops busy ones at once."""
        for worker in self._idle + self._busy:
            worker.stop(kill=kill or worker in self._busy)
        self._idle, self._busy = [], []

    def drain(self, tasks, plugins, record, *, on_start=None, on_finish=None) -> None:
        """Run ``tasks`` (lists of runs); ``record(run, *result)`` for each run as it ends.

        ``result`` is the run's :class:`compare.run.execution.RunResult` (designs, seconds,
        peak_mb, scoring_seconds, baseline_mb); a run that ended its worker or its time
        limit has only its designs and seconds, its memory and scoring seconds unknown.

        ``on_start(runs)`` and ``on_finish(runs)`` are told when a worker takes and
        ends a task (for progress). Raises :class:`compare.run.runner.WorkerSetupError`
        when a worker cannot load the experiment's methods.
        """
        from .execution import WorkerSetupError, reissue_warnings

        queue = deque(tasks)
        while queue or self._busy:
            while queue and len(self._busy) < self.workers:
                self._give(queue.popleft(), plugins)
            timeout = self._wait_time()
            ready = wait_ready([w.conn for w in self._busy] + [w.process.sentinel for w in self._busy], timeout)
            now = time.monotonic()
            for worker in list(self._busy):
                task_id, runs, started, deadline = worker.task
                if worker.conn in ready or worker.process.sentinel in ready:
                    try:
                        kind, _, payload = worker.conn.recv()
                    except (EOFError, OSError):
                        kind, payload = "died", None
                    if kind == "started":
                        if on_start is not None:
                            on_start(runs)
                        continue
                    if kind == "died":
                        worker.process.join(timeout=5)
                        self._retire(worker)
                        self._fail(runs, death_message(worker.process.exitcode), now - started, queue, record)
                    elif kind == "setup":
                        self._release(worker)
                        raise WorkerSetupError(payload)
                    elif kind == "crashed":
                        self._release(worker)
                        self._fail(runs, f"the task raised {payload}", now - started, queue, record)
                    else:
                        self._release(worker)
                        results, caught = payload
                        for run, pickled in zip(runs, results):
                            record(run, *pickle.loads(pickled))
                        reissue_warnings(caught, self._warned)  # after recording: none lost to an "error" filter
                    if on_finish is not None:
                        on_finish(runs)
                elif deadline is not None and now > deadline:
                    self._retire(worker, kill=True)
                    limit = sum(run.timeout for run in runs)
                    self._fail(runs, timeout_failure(limit), now - started, queue, record,
                               extras={"timeout_s": limit})
                    if on_finish is not None:
                        on_finish(runs)

    def _give(self, runs, plugins) -> None:
        while self._idle and not self._idle[-1].process.is_alive():  # died idle (e.g. the OOM killer): not this run's
            self._idle.pop().stop()
        worker = self._idle.pop() if self._idle else _Worker(self._context)
        self._next_id += 1
        now = time.monotonic()
        worker.task = (self._next_id, runs, now, _deadline(runs, now))
        try:
            worker.conn.send((self._next_id, runs, plugins))
        except (BrokenPipeError, OSError):  # died while idle: replace it and try again once
            worker.stop(kill=True)
            worker = _Worker(self._context)
            worker.task = (self._next_id, runs, now, _deadline(runs, now))
            worker.conn.send((self._next_id, runs, plugins))
        self._busy.append(worker)

    def _wait_time(self) -> float | None:
        deadlines = [w.task[3] for w in self._busy if w.task[3] is not None]
        if not deadlines:
            return None
        return min(_LONGEST_WAIT, max(0.0, min(deadlines) - time.monotonic()) + 0.05)

    def _release(self, worker: _Worker) -> None:
        self._busy.remove(worker)
        worker.task = None
        self._idle.append(worker)

    def _retire(self, worker: _Worker, *, kill: bool = False) -> None:
        self._busy.remove(worker)
        worker.stop(kill=kill)

    @staticmethod
    def _fail(runs, message: str, seconds: float, queue: deque, record, extras: dict | None = None) -> None:
        """A task that ended its worker or its time: one run is recorded failed; several are retried one by one."""
        from .execution import RunResult, failed_run

        if len(runs) > 1:
            queue.extendleft([run] for run in reversed(runs))
            return
        record(runs[0], *RunResult(failed_run(runs[0], message, extras), seconds))
