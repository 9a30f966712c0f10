"""SLS on the complete graph at one hop per step bounds every delayed design from below.

With communication at least as fast as the plant, the information pattern is
partially nested, so the optimal controller for it is linear (Ho & Chu 1972;
Rotkowitz & Lall 2006) and the finite-horizon SLS optimum on that graph is the
best cost *any* controller with that information reaches. On the complete graph
with one step of delay per hop (act_delay = 1), every delayed design in the
toolkit has at most that information: the GRNN variants, tanh and linear (one hop
per step over a subgraph), and the delayed sparse gains (own state now, others one
step late).
"""

import numpy as np
import pytest

from baselines import lqr, polish_gain, sls, sparse_delayed
from codesign import StaticGain, grnn, paper_instance, score

EXACT_TOL = 1e-9


def _bound(instance) -> float:
    design = sls(instance, graph="complete", act_delay=1)
    assert design.status == "optimal", design.message
    return design.cost


def _violations(bound, designs) -> list:
    """Designs whose cost is below the bound by more than their error allows."""
    out = []
    for d in designs:
        if d.status not in ("optimal", "inaccurate"):
            continue
        slack = EXACT_TOL if d.cost_kind == "exact" else 3 * d.cost_stderr + EXACT_TOL
        if d.cost < bound - slack:
            out.append((d.method, d.params, d.cost, bound))
    return out


def _delayed_designs(instance, steps, seed):
    designs = list(sparse_delayed(instance))
    designs.append(grnn(instance, variant="given", steps=steps, ensemble=1, stability_steps=0, seed=seed))
    designs.append(grnn(instance, variant="dense", steps=steps, ensemble=1, stability_steps=0, seed=seed))
    designs.append(grnn(instance, variant="sparse", beta=0.1, steps=steps, ensemble=1, stability_steps=0,
                        seed=seed))
    designs.append(grnn(instance, variant="sparse", beta=0.1, steps=steps, ensemble=1, stability_steps=0,
                        seed=seed, activation="identity"))  # linear GRNN, scored exactly
    return designs


@pytest.mark.parametrize("a_norm", [0.995, 1.05])
def test_no_delayed_design_beats_the_complete_graph_sls(a_norm):
    instance = paper_instance(1, a_norm=a_norm)
    bound = _bound(instance)
    designs = _delayed_designs(instance, steps=60, seed=0)
    assert all(d.info_model == "delayed" for d in designs)
    assert designs[-1].cost_kind == "exact" and designs[-1].status == "optimal"
    assert not _violations(bound, designs)


@pytest.mark.parametrize("a_norm", [0.995, 1.05])
def test_the_check_catches_designs_scored_without_the_delay(a_norm):
    # Negative controls, a method whose cost ignores the delay: the instantaneous LQR,
    # and sparse static gains with the links of the delayed path's densest designs used
    # without delay (the same links, information one step earlier), beat the bound.
    instance = paper_instance(1, a_norm=a_norm)
    bound = _bound(instance)
    assert _violations(bound, [lqr(instance)])
    path = [d for d in sparse_delayed(instance) if d.status == "optimal" and d.links]
    densest = max(path, key=lambda d: d.links)
    support = (densest.controller.K_delayed != 0) | np.eye(instance.n, dtype=bool)
    polished = polish_gain(instance, instance.K_lqr, support)
    assert _violations(bound, [score(instance, StaticGain(polished.K))])


@pytest.mark.slow
@pytest.mark.parametrize("a_norm", [0.995, 1.05])
def test_no_delayed_design_beats_the_bound_on_ten_instances(a_norm):
    for seed in range(10):
        instance = paper_instance(seed, a_norm=a_norm)
        bound = _bound(instance)
        designs = _delayed_designs(instance, steps=750, seed=seed)
        assert not _violations(bound, designs), seed
