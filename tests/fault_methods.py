"""Plug-in methods that misbehave the ways a user's code can: each fault must stay its own run's status.

Loaded by file path from tests/test_faults.py; every method is otherwise a correct LQR design.
"""

import ctypes
import os
import sys
import time
from pathlib import Path

import numpy as np

from codesign import StaticGain, method, score


def _lqr(instance):
    return score(instance, StaticGain(np.asarray(instance.K_lqr)))


@method("fault_unpicklable", label="Unpicklable")
def unpicklable(instance, *, seed: int = 0):
    """A design whose controller is an instance of a local class (pickle cannot send it between processes)."""

    class Local(StaticGain):
        pass

    return score(instance, Local(np.asarray(instance.K_lqr)))


@method("fault_segfault", label="Segfault")
def segfault(instance, *, seed: int = 0):
    """Dereferences a null pointer: the process dies by SIGSEGV."""
    ctypes.string_at(0)
    return _lqr(instance)


@method("fault_os_exit", label="os._exit")
def os_exit(instance, *, seed: int = 0):
    """Ends its process without cleanup."""
    os._exit(5)


@method("fault_sys_exit", label="sys.exit")
def sys_exit(instance, *, seed: int = 0):
    """Raises SystemExit(3), which ``except Exception`` does not catch."""
    sys.exit(3)


@method("fault_hang", label="Hang")
def hang(instance, *, seed: int = 0):
    """Never returns; with FAULT_HANG_STARTED set, first leaves a file named after its process there."""
    started = os.environ.get("FAULT_HANG_STARTED")
    if started:  # so a test can wait for the run itself rather than a guessed time
        (Path(started) / str(os.getpid())).touch()
    time.sleep(3600)
    return _lqr(instance)


@method("fault_empty", label="Empty")
def empty(instance, *, seed: int = 0):
    """Returns no design at all."""
    return []
