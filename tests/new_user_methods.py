"""Plug-in methods for tests/test_new_user_faults.py: designs that cannot leave their worker.

Loaded by file path; each is otherwise a correct LQR design.
"""

import threading

import numpy as np

from codesign import StaticGain, method, score


def _lqr(instance):
    return score(instance, StaticGain(np.asarray(instance.K_lqr)))


@method("newuser_lock_extras", label="Lock in extras")
def lock_extras(instance, *, seed: int = 0):
    """A design whose extras hold a ``threading.Lock``: it neither pickles nor goes into JSON."""
    design = _lqr(instance)
    design.extras["lock"] = threading.Lock()
    return design


@method("newuser_set_extras", label="Set in extras")
def set_extras(instance, *, seed: int = 0):
    """A design whose extras hold a set: it pickles, but the store's JSON cannot hold it."""
    design = _lqr(instance)
    design.extras["labels"] = {"a", "b"}
    return design


@method("newuser_warns", label="Warns")
def warns(instance, *, seed: int = 0):
    """A correct design whose computation raises a RuntimeWarning (as numpy's overflow does)."""
    import warnings

    warnings.warn("newuser: overflow in a rollout", RuntimeWarning)
    return _lqr(instance)
