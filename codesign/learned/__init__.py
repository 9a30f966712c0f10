"""Learned controllers: one trainer (:mod:`.trainer`), and one model per learned method.

Public names::

    from codesign.learned import grnn, grnn_batch, GRNNController, GRNNSettings
    from codesign.learned import embed_delayed_gain      # a delayed static gain as a per-node-readout GRNN
    grnn(instance, readout="per_node", init="delayed", start=design)  # a warm start from your delayed design
    # (init="diagonal" and the variants' own delayed designs: baselines.grnn, which computes them)
    from codesign.learned import gcnn, gcnn_batch, GCNNController, GCNNSettings
    from codesign.learned import TrainingSettings, takes_settings      # your own learned method
    from codesign.learned import AutogradModel, StackModel, Member, Loop, TrainingJob
    from codesign.learned import train_stack, train_jobs, best_member, selection_set, simulated_design

A learned method of your own is one file: a settings type, a
:class:`StackModel` (or an :class:`AutogradModel`, whose gradient autograd
takes), a controller, and a method that trains its members with
:func:`train_jobs` and builds designs with :func:`simulated_design`
(docs/extending.md shows one).
"""

from .embedding import delayed_gain_parts, embed_delayed_gain
from .gcnn import GCNNController, GCNNSettings, gcnn, gcnn_batch
from .grnn import GRNNController, GRNNSettings, LinearGRNNController, grnn, grnn_batch, grnn_defaults, paper_beta
from .settings import TrainingSettings, takes_settings
from .trainer import (DTYPES, AutogradModel, Loop, Member, StackModel, TrainingJob, TrainResult, best_member, curve,
                      diverged_members_message, selection_costs, selection_set, simulated_design, train_jobs,
                      train_stack)

__all__ = ["grnn", "grnn_batch", "grnn_defaults", "paper_beta", "GRNNController", "LinearGRNNController",
           "GRNNSettings", "gcnn", "gcnn_batch", "GCNNController", "GCNNSettings", "TrainingSettings",
           "takes_settings", "StackModel", "AutogradModel", "Member", "Loop", "TrainingJob", "TrainResult",
           "train_stack", "train_jobs", "best_member", "selection_costs", "selection_set", "curve", "simulated_design",
           "diverged_members_message", "DTYPES", "embed_delayed_gain", "delayed_gain_parts"]
