"""Problem instances, evaluation, and the GRNN co-design.

Public names::

    from codesign import paper_instance, Instance, Design
    from codesign import static_gain_cost, simulate, validation_set
    from codesign import grnn, grnn_batch, GRNNController       # learned methods (codesign.learned)
    from codesign import gcnn, gcnn_batch, GCNNController
    from codesign import method, score          # register your own method, score a controller
"""

from .controllers import StaticGain, ZeroInput, controller_from_arrays, register_controller
from .design import (
    INACCURATE_RTOL,
    INFO_MODELS,
    SOLVER_STATUS,
    STATUSES,
    Design,
    count_links,
    solver_status,
    vet_solver_cost,
)
from .status import NO_DESIGN, STABILITY_TOL, USABLE
from .evaluation import (
    Rollout,
    compare_exact_and_simulated,
    control_variate_estimate,
    exact_cost,
    impulse_responses,
    response_cost,
    simulate,
    spectral_radius,
    static_gain_cost,
    static_gain_cost_and_grad,
    validation_set,
)
from .learned import GCNNController, GRNNController, gcnn, gcnn_batch, grnn, grnn_batch, grnn_defaults, paper_beta
from .instances import Instance, InstanceError, hop_distances, paper_instance
from .methods import Method, get_method, method, registered_methods
from .scoring import evaluate, score

__version__ = "0.1.0"

__all__ = [
    "Instance",
    "InstanceError",
    "paper_instance",
    "hop_distances",
    "Design",
    "STATUSES",
    "USABLE",
    "NO_DESIGN",
    "STABILITY_TOL",
    "SOLVER_STATUS",
    "INACCURATE_RTOL",
    "solver_status",
    "vet_solver_cost",
    "INFO_MODELS",
    "count_links",
    "StaticGain",
    "ZeroInput",
    "controller_from_arrays",
    "register_controller",
    "static_gain_cost",
    "static_gain_cost_and_grad",
    "response_cost",
    "validation_set",
    "simulate",
    "Rollout",
    "exact_cost",
    "impulse_responses",
    "control_variate_estimate",
    "compare_exact_and_simulated",
    "spectral_radius",
    "GRNNController",
    "grnn",
    "grnn_batch",
    "grnn_defaults",
    "paper_beta",
    "gcnn",
    "gcnn_batch",
    "GCNNController",
    "Method",
    "method",
    "get_method",
    "registered_methods",
    "score",
    "evaluate",
]
