# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # First steps: one instance, five designs, one figure, then your own system and method
#
# This notebook is a [jupytext](https://jupytext.readthedocs.io) script: open it in
# Jupyter (with jupytext installed) or run it as `python examples/first_steps.py`
# (from the checkout: the figure is then saved as `results/first_steps.png`, which git ignores).
# `EXAMPLES_SMALL=1` runs a reduced version (shorter training; CI runs it so).
#
# Every method takes an `Instance` and keyword-only hyperparameters and returns a
# frozen `Design` (or a list of them along a regularization path): controller,
# normalized cost E[J]/trace(P) (centralized LQR = 1), directed off-diagonal links,
# information model, status.

# %%
import os

import matplotlib.pyplot as plt
import numpy as np

from baselines import lqr, sls, sparse_admm, sparse_delayed
from codesign import Instance, StaticGain, get_method, grnn, method, paper_instance, score
from compare.report.styles import style_for

SMALL = os.environ.get("EXAMPLES_SMALL") == "1"
STEPS = 40 if SMALL else 150

# %% [markdown]
# ## An instance of the paper's family
# N = 20 nodes, ‖A‖₂ = 1.05 (open-loop unstable), horizon 50. The seed fixes everything.

# %%
inst = paper_instance(0, a_norm=1.05)
print(inst)
print("plant-graph links:", int((inst.plant_adj != 0).sum() - np.trace(inst.plant_adj != 0)))

# %% [markdown]
# ## Classical designs
# Centralized LQR (380 links, instantaneous), the ℓ1 ADMM path of sparse static gains
# (instantaneous links), the delayed ℓ1 path (neighbours' states one step late, the
# GRNN's information model for one hop), and SLS on the plant graph (one hop per step).

# %%
designs = {
    "LQR": [lqr(inst)],
    "Sparse K (ℓ1 ADMM)": sparse_admm(inst),
    "Sparse delayed K (ℓ1)": sparse_delayed(inst),
    "SLS (plant graph)": [sls(inst, graph="plant")],
}
for name, path in designs.items():
    best = min(path, key=lambda d: d.cost)
    print(f"{name:24s} {len(path):3d} designs, best cost {best.cost:.4f} with {best.links} links "
          f"({best.info_model}, {best.status})")

# %% [markdown]
# ## GRNN co-design: a short β path
# The ℓ1 weight β trades cost for links; each design is a trained GRNN whose
# communication graph is the support of S. Its cost is simulated on the instance's
# validation set with control variates: the standard error is printed beside it.

# %%
designs["GRNN-Sparse (β path)"] = [
    grnn(inst, variant="sparse", beta=beta, steps=STEPS, ensemble=1, refine_ensemble=1, lr=0.03, l1_lr=0.03,
         stability_steps=0)
    for beta in (0.03, 0.3, 3.0)
]
for d in designs["GRNN-Sparse (β path)"]:
    print(f"β = {d.params['beta']:<5g} links {d.links:3d}  cost {d.cost:.4f} ± {d.cost_stderr:.1e}")

# %% [markdown]
# ## All on one figure

# %%
def plot_designs(designs, ax=None):
    """Cost against links, one line per method (exact or simulated cost; failed designs left out).

    Each method in the colour, marker and line style (its information model) it has in every report.
    """
    ax = ax or plt.gca()
    for name, path in designs.items():
        ok = sorted((d.links, d.cost) for d in path if d.status in ("optimal", "inaccurate"))
        if ok:
            x, y = zip(*ok)
            style = style_for(path[0].method, path[0].params, path[0].info_model)
            single = len(ok) == 1  # a one-design method: a larger marker, drawn on top
            ax.plot(x, y, color=style.colour, marker=style.marker, markerfacecolor=style.face,
                    linestyle=style.linestyle, markersize=9 if single else 5, zorder=3 if single else 2, label=name)
    ax.set_xscale("symlog", linthresh=1)
    ax.xaxis.set_major_formatter(plt.FuncFormatter(lambda value, _: f"{value:g}"))
    ax.set_xlabel("directed off-diagonal links")
    ax.set_ylabel("E[J] / trace(P)")
    ax.axhline(1.0, color="0.6", linewidth=0.8)
    ax.legend(fontsize=8)
    return ax


fig, ax = plt.subplots(figsize=(7, 4.5))
plot_designs(designs, ax=ax)
fig.tight_layout()
# In a notebook the figure shows below the cell. Run as a script, nothing shows, so it is
# saved into results/ (which git ignores) under the working folder, as `compare run` does.
if "__file__" in globals():
    os.makedirs("results", exist_ok=True)
    fig.savefig(os.path.join("results", "first_steps.png"), dpi=110)
    print("figure: results/first_steps.png")

# %% [markdown]
# ## Your own system
# Any linear system with one state and one input per node: here a ring of 12
# coupled, slightly unstable scalar subsystems where each node feels its two
# neighbours. `Instance.from_matrices` validates shapes, finiteness and
# stabilizability, and derives the plant graph from the supports of A and B.

# %%
n = 12
ring = np.eye(n) * 1.02 + 0.2 * (np.roll(np.eye(n), 1, axis=1) + np.roll(np.eye(n), -1, axis=1))
mine = Instance.from_matrices(ring, np.eye(n), horizon=30)
print(mine, "LQR:", lqr(mine).cost, "best delayed sparse:", min(d.cost for d in sparse_delayed(mine)))

# %% [markdown]
# ## Your own method
# A method is a function `f(instance, *, ...) -> Design`; `score` turns any controller
# into a scored `Design` (exact cost for linear ones). The `@method` decorator
# registers it, so `compare run` can name it in a spec
# (`method = "nearest_lqr"`, with the module listed under `plugins = [...]`).
# Called through the registry, its hyperparameters are checked and its name is
# stamped into the design, as the harness does.

# %%
@method("nearest_lqr", label="LQR restricted to plant neighbours")
def nearest_lqr(instance, *, seed: int = 0):
    """The LQR gain with every entry outside the plant graph set to zero (not re-optimized)."""
    K = np.where(instance.plant_adj != 0, instance.K_lqr, 0.0)
    return score(instance, StaticGain(K))


for system in (inst, mine):
    (d,) = get_method("nearest_lqr")(system)  # the registry always answers with a list of designs
    print(f"{d.method}: cost {d.cost:.4f} with {d.links} links, status {d.status}")
