# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # A problem posed as its source poses it: disturbances through B1
#
# lqrsp (Lin, Fardad & Jovanović) designs sparse feedback for the H2 problem
#
#     minimize  J(K) = trace(B1' P_K B1),   P_K = A_cl' P_K A_cl + Q + K'RK,
#
# where disturbances enter through a few channels B1 (on its New England wide-area model,
# 9 channels into 75 states). The toolkit's cost is the expected cost from x(0) ~ N(0, Σ₀);
# with `x0_cov = B1 @ B1.T` it is that problem: every cost, gradient, training draw and the
# normalizer (LQR's cost, trace(B1' P B1)) read Σ₀. The model itself is not redistributable, so
# this notebook poses the same kind of problem on a stand-in: 8 nodes of two states (an
# oscillator each, one of them with a slow rotational mode, −5e-6 per second), a force input
# per node and a disturbance into every node's second state, sampled by zero-order hold.
# Run as a script (`python examples/disturbance_weighting.py`); `EXAMPLES_SMALL=1` runs a
# shorter version.

# %%
import os

import numpy as np
import scipy.linalg
from scipy.signal import cont2discrete

from baselines import decentralized, lqr, sparse_newton
from codesign import Instance

SMALL = os.environ.get("EXAMPLES_SMALL") == "1"
NODES, DT, SLOW = 8, 0.05, -5e-6

rng = np.random.default_rng(1)
blocks = [np.array([[SLOW, 0.6], [-0.6, SLOW]])]
for _ in range(1, NODES):
    s, w = -rng.uniform(0.2, 2.0), rng.uniform(0.5, 5.0)
    blocks.append(np.array([[s, w], [-w, s]]))
V = np.eye(2 * NODES) + 0.3 * rng.standard_normal((2 * NODES, 2 * NODES))
Ac = V @ scipy.linalg.block_diag(*blocks) @ np.linalg.inv(V)
Bc = np.zeros((2 * NODES, NODES))
Bc[2 * np.arange(NODES) + 1, np.arange(NODES)] = 1.0
A, B, *_ = cont2discrete((Ac, Bc, np.eye(2 * NODES), np.zeros((2 * NODES, NODES))), DT, method="zoh")
B1 = B.copy()  # disturbances enter where the inputs do: 8 channels into 16 states

common = dict(horizon=50, state_nodes=np.repeat(np.arange(NODES), 2), input_nodes=np.arange(NODES))
h2 = Instance.from_matrices(A, B, x0_cov=B1 @ B1.T, name="h2 stand-in", **common)
plain = Instance.from_matrices(A, B, name="identity stand-in", **common)
print(f"x0_cov has rank {h2.x0_factor.shape[1]} of {h2.n}; LQR's cost trace(B1' P B1) = {h2.trace_P:.6g}")

# %% [markdown]
# The cost of a static gain against the closed-form value: the horizon-T cost with terminal
# cost P is trace(B1' (P_K + A_cl'^T (P − P_K) A_cl^T) B1), with P_K from scipy's Lyapunov solver.

# %%
design = decentralized(h2)
K = design.controller.K
Acl = A + B @ K
PK = scipy.linalg.solve_discrete_lyapunov(Acl.T, h2.Q + K.T @ h2.R @ K)
AT = np.linalg.matrix_power(Acl, h2.horizon)
closed_form = np.trace(B1.T @ (PK + AT.T @ (h2.P - PK) @ AT) @ B1) / h2.trace_P
h2_norm = np.trace(B1.T @ PK @ B1) / h2.trace_P  # the infinite-horizon H2 cost, lqrsp's objective
print(f"decentralized: {design.status}, cost {design.cost:.6f} x LQR (closed form {closed_form:.6f}); "
      f"infinite-horizon H2 cost {h2_norm:.6f} x LQR")
print(f"the same plant weighted by x(0) ~ N(0, I): decentralized costs {decentralized(plain).cost:.6f} x LQR")

# %% [markdown]
# The ℓ1 path of sparse static gains (lqrsp's Newton method) under the B1 weighting: cost
# against node links, from the centralized gain to the decentralized one.

# %%
gammas = [1e-3, 1e-2, 1e-1] if SMALL else list(np.geomspace(1e-4, 1.0, 9))
path = sparse_newton(h2, gammas=gammas)
rows = np.array([(d.params["gamma"], d.links, d.cost) for d in path if np.isfinite(d.cost)])
for gamma, links, cost in rows:
    print(f"gamma {gamma:9.3g}: {int(links):3d} links, {cost:.6f} x LQR")
print(f"centralized LQR: {lqr(h2).cost:.12f} x LQR")
