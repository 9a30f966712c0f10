"""A plug-in as a user would write it: one decorated method and one plain function.

Used by the method contract test and the plug-in tests (loaded by file path).
"""

import numpy as np

from codesign import StaticGain, method, score


@method("plugin_scaled_lqr", label="Scaled LQR (plug-in)")
def scaled_lqr(instance, *, scale: float = 0.9, seed: int = 0):
    """The LQR gain scaled by ``scale``: a registered plug-in method."""
    return score(instance, StaticGain(scale * np.asarray(instance.K_lqr)))


def trunc10(instance, *, links: int = 10):
    """LQR truncated to its ``links`` largest off-diagonal entries (not polished)."""
    K = np.array(instance.K_lqr)
    off = np.abs(K) * (1 - np.eye(instance.n))
    keep = np.argsort(off, axis=None)[::-1][:links]
    mask = np.eye(instance.n, dtype=bool)
    mask.flat[keep] = True
    return score(instance, StaticGain(np.where(mask, K, 0.0)))
