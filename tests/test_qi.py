"""Quadratic invariance of the SLS delay constraints, checked against brute force.

The brute force takes the delay set from :func:`baselines.sls.support_hops` (the
supports SLS imposes, ``Φ[k]`` being K's tap k - 1), draws random controllers K on
it and looks for a tap of ``K G K`` outside it; it shares no code with the closed
form of :mod:`baselines.qi`.
"""

import itertools

import numpy as np
import pytest

from baselines import sls
from baselines.qi import (
    controller_delays,
    is_quadratically_invariant,
    propagation_delays,
    transmission_delays,
)
from baselines.sls import support_hops
from codesign import Instance, hop_distances

N = 6


def _undirected(edges, n=N):
    adj = np.eye(n)
    for i, j in edges:
        adj[i, j] = adj[j, i] = 1.0
    return adj


_PATH = [(i, i + 1) for i in range(N - 1)]
#: name -> (plant graph, communication graph). On "detour" the plant has a shortcut
#: 0-3 that the communication graph lacks: information goes the long way round.
GRAPHS = {
    "path": (_undirected(_PATH), _undirected(_PATH)),
    "ring": (_undirected(_PATH + [(N - 1, 0)]), _undirected(_PATH + [(N - 1, 0)])),
    "detour": (_undirected(_PATH + [(0, 3)]), _undirected(_PATH)),
}


def _instance(plant, comm, b, seed=0):
    rng = np.random.default_rng(seed)
    # Entries below 1/2 keep the taps A^k B of moderate size over the 3n + 3 taps checked.
    A = plant * rng.uniform(0.2, 0.4, plant.shape) * rng.choice([-1.0, 1.0], plant.shape)
    B = np.eye(len(plant)) if b == "local" else plant * rng.uniform(0.5, 1.0, plant.shape)
    return Instance.from_matrices(A, B, comm_adj=comm, horizon=5)


def _case(graph, b):
    plant, comm = GRAPHS[graph]
    return _instance(plant, comm, b), comm


def _taps(n):
    # A violation at (k, l) shows at tap M(k, l) < D(k, l); finite D are at most n
    # (n - 1 hops plus act_delay <= 2 here) and M <= D + p + D <= 3n, so 3n + 3 taps
    # cannot hide one by truncation.
    return 3 * n + 3


def sls_delays(comm, speed, act_delay):
    """First tap of K allowed at (i, j) by SLS's supports (inf if never)."""
    hops = hop_distances(comm)
    D = np.full(hops.shape, np.inf)
    for k in range(_taps(len(hops)), 0, -1):  # supports grow with k: the last write is the first tap
        D[hops <= support_hops(k, speed=speed, act_delay=act_delay)] = k - 1
    return D


def _convolve(X, Y):
    return np.array([np.einsum("aij,ajk->ik", X[: m + 1], Y[m::-1]) for m in range(len(X))])


def brute_force_qi(instance, D, *, draws=3, seed=0) -> bool:
    """True when no random K in the delay set D gives a tap of K G K outside it."""
    n, taps = instance.n, _taps(instance.n)
    G = np.zeros((taps, n, n))
    power = np.eye(n)
    for k in range(1, taps):
        G[k] = power @ instance.B
        power = instance.A @ power
    allowed = np.arange(taps)[:, None, None] >= D[None]
    rng = np.random.default_rng(seed)
    for _ in range(draws):
        K = np.where(allowed, rng.standard_normal((taps, n, n)), 0.0)
        KGK = _convolve(_convolve(K, G), K)
        # Structural zeros are exact in floating point; the tolerance only guards round-off.
        size = np.abs(KGK).max(axis=(1, 2), keepdims=True)
        if np.any((np.abs(KGK) > 1e-9 * size) & ~allowed):
            return False
    return True


CASES = list(itertools.product(GRAPHS, ("local", "spread"), (0, 1), (1, 1.5, 2)))


@pytest.mark.parametrize("graph, b, act_delay, speed", CASES)
def test_qi_matches_brute_force(graph, b, act_delay, speed):
    instance, comm = _case(graph, b)
    D = sls_delays(comm, speed, act_delay)
    np.testing.assert_array_equal(controller_delays(comm, speed, act_delay), D)
    result = is_quadratically_invariant(instance, comm, speed=speed, act_delay=act_delay)
    assert result.qi == brute_force_qi(instance, D), result.reason
    assert bool(result) == result.qi and (result.violations == 0) == result.qi


def test_cases_cover_both_answers_and_the_old_errors():
    answers = {case: is_quadratically_invariant(*_case(*case[:2]), speed=case[3], act_delay=case[2]).qi
               for case in CASES}
    assert 0 < sum(answers.values()) < len(CASES)
    # act_delay = 0 with B spreading over the plant graph: two instantaneous hops around
    # one plant step outrun the delay set, which the pairwise test missed.
    assert not answers["path", "spread", 0, 1] and not answers["ring", "spread", 0, 1]
    assert answers["path", "spread", 1, 1]
    # A local B reaches the far end of the shortcut one step later, in time at speed 2.
    assert answers["detour", "local", 1, 2] and not answers["detour", "spread", 1, 2]


@pytest.mark.parametrize("seed", range(12))
def test_qi_matches_brute_force_on_random_digraphs(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 6))
    plant = (rng.random((n, n)) < 0.35) | np.eye(n, dtype=bool)
    comm = rng.random((n, n)) < 0.45
    A = 0.3 * plant * rng.uniform(0.5, 1.0, (n, n))
    B = ((rng.random((n, n)) < 0.3) | np.eye(n, dtype=bool)) * rng.uniform(0.5, 1.0, (n, n))
    instance = Instance.from_matrices(A, B, comm_adj=comm, horizon=3)
    for act_delay, speed in ((0, 1), (1, 1.5), (2, 1), (0, 2)):
        D = sls_delays(instance.comm_adj, speed, act_delay)
        result = is_quadratically_invariant(instance, instance.comm_adj, speed=speed, act_delay=act_delay)
        assert result.qi == brute_force_qi(instance, D), (act_delay, speed, result.reason)


def test_delays():
    plant, comm = GRAPHS["detour"]
    hops = hop_distances(comm)
    np.testing.assert_array_equal(transmission_delays(comm, 2), np.ceil(hops / 2))
    D = controller_delays(comm, 1, act_delay=0)
    assert D[0, 0] == 0 and D[0, 1] == 0 and D[0, 3] == 2  # the first hop is instantaneous
    D = controller_delays(comm, 1, act_delay=2)
    assert D[0, 0] == 0 and D[0, 1] == 2 and D[0, 3] == 4
    assert np.all(np.isinf(controller_delays(np.eye(3), 1)[~np.eye(3, dtype=bool)]))
    local, spread = _case("detour", "local")[0], _case("detour", "spread")[0]
    # u_3 -> x_0 directly through a spreading B, through x_3 and the shortcut with a local one.
    assert propagation_delays(spread.A, spread.B)[0, 3] == 1
    assert propagation_delays(local.A, local.B)[0, 3] == 2
    np.testing.assert_array_equal(np.diag(propagation_delays(local.A, local.B)), 1)
    with pytest.raises(ValueError, match="act_delay"):
        is_quadratically_invariant(local, comm, act_delay=-1)


def test_message_gives_the_right_delays():
    # Direct violation, act_delay = 0: 3 hops at speed 1 are 2 steps (not 3).
    instance, comm = _case("detour", "spread")
    result = is_quadratically_invariant(instance, comm, act_delay=0)
    assert not result.qi and result.pair == (0, 3) and result.via == (0, 3)
    assert (result.transmission, result.propagation) == (2, 1)
    assert "node 0 may use node 3's state only after 2 step(s) (3 hop(s) at speed 1, act_delay 0)" in result.reason
    assert "node 3's input moves node 0's state through the plant after 1 step(s)" in result.reason
    # A local B: the input moves the state one step later than the plant graph's hop distance.
    instance, comm = _case("detour", "local")
    result = is_quadratically_invariant(instance, comm)
    assert result.pair == (0, 3) and (result.transmission, result.propagation) == (3, 2)
    assert "only after 3 step(s) (3 hop(s) at speed 1, act_delay 1)" in result.reason
    assert "through the plant after 2 step(s)" in result.reason
    # Violation through the loop: x_3 -> u_2 at once, u_2 -> x_1 in one step, x_1 -> u_0 at once.
    instance, comm = _case("path", "spread")
    result = is_quadratically_invariant(instance, comm, act_delay=0)
    assert result.pair == (0, 3) and result.via == (1, 2)
    assert (result.transmission, result.propagation) == (2, 1)
    assert "node 3's state reaches node 0's input after 1 step(s) through the loop" in result.reason
    assert "node 2's input moves node 1's state after 1 step(s) through the plant" in result.reason


def _controller_taps(controller, taps):
    """K[m][:, j]: the inputs the controller answers x(0) = e_j (and x = 0 after) with."""
    n = controller.n
    state = controller.reset(n)
    out = []
    for t in range(taps):
        u, state = controller.step(state, np.eye(n) if t == 0 else np.zeros((n, n)))
        out.append(u.T)
    return np.array(out)


@pytest.mark.parametrize("act_delay, speed", [(0, 1), (1, 1), (1, 2)])
def test_sls_controller_lies_in_the_delay_set(act_delay, speed):
    # On a QI case the SLS controller's own taps fill exactly the delay set the check uses.
    instance, comm = _case("path", "local")
    design = sls(instance, comm_adj=comm, speed=speed, act_delay=act_delay)
    assert design.status == "optimal" and design.extras["qi"] is True
    taps = design.controller.length
    K = _controller_taps(design.controller, taps)
    D = controller_delays(comm, speed, act_delay)
    early = np.arange(taps)[:, None, None] < D[None]
    assert np.abs(K[early]).max() <= 1e-9 * np.abs(K).max()
    first = [K[int(D[i, j]), i, j] for i in range(N) for j in range(N) if D[i, j] < taps]
    assert np.all(np.abs(first) > 1e-9 * np.abs(K).max())


def test_sls_qi_flag_follows_act_delay():
    instance, comm = _case("path", "spread")
    assert sls(instance, comm_adj=comm, act_delay=1).extras["qi"] is True
    design = sls(instance, comm_adj=comm, act_delay=0)
    assert design.extras["qi"] is False and design.extras["qi_pair"] == [0, 3]
