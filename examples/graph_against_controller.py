# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # Graph against controller
#
# Every co-design picks a communication graph and fits a controller on it. Here one paper
# instance's delayed ℓ1 path picks graphs; each graph is refit with the delayed static gain,
# SLS and a warm-started GRNN (`baselines.refit_design`), and each design's excess over the
# best graph found within its budget splits into its **graph gap** (its graph's value V(G)
# minus the best value within the budget) and its **controller gap** (its cost minus V(G)).
# Run as a script (`python examples/graph_against_controller.py`); `EXAMPLES_SMALL=1` runs a
# shorter version.

# %%
import os

import numpy as np

from baselines import refit_design, sparse_delayed
from codesign import paper_instance
from codesign.graphs import design_graph, graph_hash

SMALL = os.environ.get("EXAMPLES_SMALL") == "1"
inst = paper_instance(0, n=6, a_norm=1.05)
path = [d for d in sparse_delayed(inst, gammas=[0.0, 1e-3, 1e-2, 0.1] if SMALL else None) if d.ok]

# %% [markdown]
# ## Each graph of the path, refit per class
#
# V(G) is the lowest cost of any controller found on exactly G in the delayed information model:
# the source design itself and its refits. The GRNN refit starts from the delayed refit (exactly
# embedded) and is kept only where training ends below that start, so it never costs more.

# %%
steps = 30 if SMALL else 150
value, links = {}, {}
for design in path:
    graph = design_graph(inst, design)
    key = graph_hash(graph)
    if key in value:
        continue
    refits = [refit_design(inst, graph, "delayed", starts=[design]), refit_design(inst, graph, "sls"),
              refit_design(inst, graph, "grnn", starts=[design], activation="identity", steps=steps)]
    value[key] = min([design.cost] + [r.cost for r in refits if r.ok])
    links[key] = int(graph.sum())
    print(f"{links[key]:3d} links: static {design.cost:.4f}, "
          + ", ".join(f"{r.params['controller']} {r.cost:.4f}" if r.ok else f"{r.params['controller']} {r.status}"
                      for r in refits))

# %% [markdown]
# ## The two gaps of each design
#
# Within a budget b, the best value is the lowest V over every graph found with at most b links.
# For the path's design with L links: graph gap = V(G) − best(L), controller gap = cost − V(G).

# %%
rows = []
for design in path:
    key = graph_hash(design_graph(inst, design))
    best = min(v for k, v in value.items() if links[k] <= design.links)
    rows.append((design.links, design.cost - best, value[key] - best, design.cost - value[key]))
    print(f"{design.links:3d} links: excess {design.cost - best:+.4f} = graph {value[key] - best:+.4f} "
          f"+ controller {design.cost - value[key]:+.4f}")
gaps = np.array(rows)
assert np.allclose(gaps[:, 1], gaps[:, 2] + gaps[:, 3])  # the two gaps add up to the excess, design by design
