"""Classical baselines: centralized LQR, autonomous, decentralized static gains, SLS.

Public names::

    from baselines import lqr, autonomous, decentralized, polish_gain
    from baselines import sls, sls_topologies, sls_local, is_quadratically_invariant
    from baselines import sparse_admm, sparse_newton, sparse_sdp, truncated_lqr, sparse_delayed
    from baselines import sparse_budget, best_pattern     # exact link budgets, exhaustive search
    from baselines import refit, refit_design             # the best controller of one class on a given graph
    from baselines import gcnn, gcnn_batch, GCNNController   # the learned baseline, from codesign.learned
    from baselines import grnn, grnn_batch      # the GRNN trainer with its warm starts' static designs
"""

from codesign.learned.gcnn import GCNNController, gcnn, gcnn_batch
from .lqr import autonomous, decentralized, lqr
from .polish import PolishResult, polish_gain
from .qi import QIResult, is_quadratically_invariant
from .sls import TOPOLOGY_FAMILY, SLSController, sls, sls_topologies, topology
from .sls_local import sls_local
from .sparse_admm import ADMM_GAMMAS, sparse_admm
from .sparse_delayed import DelayedStaticGain, sparse_delayed
from .sparse_newton import sparse_newton
from .sparse_sdp import SDP_GAMMAS, SparseSDP, sparse_sdp
from .truncation import truncated_lqr
from .sparse_budget import sparse_budget
from .best_pattern import best_pattern
from .refit import refit, refit_design
from .grnn import grnn, grnn_batch

__all__ = [
    "lqr",
    "autonomous",
    "decentralized",
    "polish_gain",
    "PolishResult",
    "sls",
    "sls_topologies",
    "sls_local",
    "SLSController",
    "topology",
    "TOPOLOGY_FAMILY",
    "is_quadratically_invariant",
    "QIResult",
    "sparse_admm",
    "sparse_newton",
    "sparse_delayed",
    "DelayedStaticGain",
    "ADMM_GAMMAS",
    "sparse_sdp",
    "SparseSDP",
    "SDP_GAMMAS",
    "truncated_lqr",
    "sparse_budget",
    "best_pattern",
    "refit",
    "refit_design",
    "gcnn",
    "gcnn_batch",
    "grnn",
    "grnn_batch",
    "GCNNController",
]
