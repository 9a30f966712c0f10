"""Classical baselines: centralized LQR, autonomous, decentralized static gains.

Public names::

    from baselines import lqr, autonomous, decentralized, polish_gain, gcnn
"""

from .gcnn import GCNNController, gcnn, gcnn_batch
from .lqr import autonomous, decentralized, lqr
from .polish import PolishResult, polish_gain

__all__ = ["lqr", "autonomous", "decentralized", "polish_gain", "PolishResult", "gcnn", "gcnn_batch",
           "GCNNController"]
