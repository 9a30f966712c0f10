import networkx as nx
import numpy as np
import pytest
import scipy.sparse.csgraph

from codesign import Instance, InstanceError, hop_distances, paper_instance


@pytest.mark.parametrize("a_norm", [0.995, 1.05])
@pytest.mark.parametrize("seed", [0, 7, 123])
def test_paper_instance_matches_design(seed, a_norm):
    inst = paper_instance(seed, a_norm=a_norm)
    comm = inst.comm_adj
    assert np.array_equal(comm, comm.T)
    assert set(np.unique(comm)) <= {0.0, 1.0}
    assert np.all(np.diag(comm) == 1)
    assert nx.is_connected(nx.from_numpy_array(comm))
    # each node's 6 nearest positions include itself: at least 5 neighbours
    assert np.all(comm.sum(axis=1) - 1 >= 5)
    far = hop_distances(comm) > 3
    assert np.all(inst.A[far] == 0) and np.all(inst.B[far] == 0)
    assert np.array_equal(inst.A, inst.A.T) and np.array_equal(inst.B, inst.B.T)
    assert np.linalg.norm(inst.A, 2) == pytest.approx(a_norm, rel=1e-12)
    assert np.linalg.norm(inst.B, 2) == pytest.approx(1.0, rel=1e-12)
    assert inst.open_loop_radius == pytest.approx(a_norm, rel=1e-9)  # symmetric: norm = radius
    # the plant graph is the support of A and B, inside the 3-hop closure
    assert np.array_equal(inst.plant_adj != 0, (inst.A != 0) | (inst.B != 0))
    assert not np.any((inst.plant_adj != 0) & far)
    # DARE: P solves the Riccati equation
    A, B, P = inst.A, inst.B, inst.P
    residual = A.T @ P @ A - P - A.T @ P @ B @ np.linalg.solve(B.T @ P @ B + inst.R, B.T @ P @ A) + inst.Q
    assert np.abs(residual).max() < 1e-9 * np.abs(P).max()


def test_eigenvectors_shared_with_normalized_adjacency_before_truncation():
    # With hops large enough nothing is cut, so A commutes with the graph shift operator.
    inst = paper_instance(3, hops=100)
    assert np.abs(inst.A @ inst.gso - inst.gso @ inst.A).max() < 1e-12
    assert np.abs(inst.B @ inst.gso - inst.gso @ inst.B).max() < 1e-12


def test_average_nonzeros_over_200_seeds():
    counts = [paper_instance(seed).comm_adj.sum() for seed in range(200)]
    assert 135 <= np.mean(counts) <= 145
    plant = [paper_instance(seed).plant_adj.sum() - 20 for seed in range(0, 200, 10)]
    assert 250 <= np.mean(plant) <= 310  # docs/problem.md: ~266-300 off-diagonal plant links


def test_same_seed_same_instance_and_different_seeds_differ():
    a, b, c = paper_instance(5), paper_instance(5), paper_instance(6)
    assert np.array_equal(a.A, b.A) and np.array_equal(a.comm_adj, b.comm_adj)
    assert not np.array_equal(a.A, c.A)
    assert a.key == b.key != c.key


def test_instance_arrays_are_read_only():
    inst = paper_instance(0)
    with pytest.raises(ValueError):
        inst.A[0, 0] = 1.0


def test_from_matrices_defaults_and_roundtrip():
    inst0 = paper_instance(2)
    inst = Instance.from_matrices(inst0.A, inst0.B, comm_adj=inst0.comm_adj)
    assert np.allclose(inst.P, inst0.P)
    assert np.array_equal(inst.comm_adj, inst0.comm_adj)
    assert inst.spec["family"] == "matrices"
    # default communication graph: the plant graph (with self-loops)
    default = Instance.from_matrices(inst0.A, inst0.B)
    assert np.array_equal(default.comm_adj != 0, (inst0.plant_adj != 0) | np.eye(20, dtype=bool))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(A=np.ones((3, 2)), B=np.eye(3)), "A must be square"),
        (dict(A=np.eye(3), B=np.eye(2)), "B must have 3 rows to match A"),
        (dict(A=np.array([[np.nan, 0], [0, 1]]), B=np.eye(2)), "A has non-finite"),
        (dict(A=np.eye(2), B=np.array([[np.inf, 0], [0, 1]])), "B has non-finite"),
        (dict(A=np.eye(2), B=np.eye(2), Q=-np.eye(2)), "Q must be positive semidefinite"),
        (dict(A=np.eye(2), B=np.eye(2), R=np.zeros((2, 2))), "R must be positive definite"),
        (dict(A=np.eye(2), B=np.eye(2), Q=np.array([[1, 2], [0, 1]])), "Q must be symmetric"),
        (dict(A=np.eye(2), B=np.eye(2), R=np.eye(3)), "R must have shape"),
        (dict(A=np.diag([2.0, 0.5]), B=np.diag([0.0, 1.0])), "not stabilizable"),
        (dict(A=np.eye(2), B=np.eye(2), horizon=0), "horizon"),
        (dict(A=np.eye(2), B=np.eye(2), comm_adj=np.eye(3)), "comm_adj must have shape"),
        (dict(A="abc", B=np.eye(2)), "A must be"),
    ],
)
def test_from_matrices_rejects_bad_input(kwargs, match):
    A = kwargs.pop("A")
    B = kwargs.pop("B")
    with pytest.raises(InstanceError, match=match):
        Instance.from_matrices(A, B, **kwargs)


@pytest.mark.parametrize(
    "kwargs, match",
    [(dict(n=1), "n must be"), (dict(degree=30), "degree"), (dict(a_norm=-1.0), "a_norm"),
     (dict(a_norm=float("nan")), "a_norm"), (dict(horizon=0), "horizon")],
)
def test_paper_instance_rejects_bad_arguments(kwargs, match):
    with pytest.raises(InstanceError, match=match):
        paper_instance(0, **kwargs)


def test_paper_instance_rejects_negative_seed():
    with pytest.raises(InstanceError, match="seed"):
        paper_instance(-1)


@pytest.mark.parametrize("seed", [0, 3, 7])
def test_paper_instances_do_not_depend_on_the_lapack_basis(monkeypatch, seed):
    """Another LAPACK returns another basis of each repeated eigenvalue's eigenspace: same instance."""
    import codesign.instances as instances

    reference = paper_instance(seed, a_norm=1.05)
    original = np.linalg.eigh
    rng = np.random.default_rng(seed)

    def rotated_eigh(M):
        w, V = original(M)
        if M.shape[0] == reference.n:
            for value in np.unique(np.round(w, 9)):
                idx = np.where(np.abs(w - value) < 1e-9)[0]
                if idx.size > 1:
                    Q, _ = np.linalg.qr(rng.standard_normal((idx.size, idx.size)))
                    V[:, idx] = V[:, idx] @ Q
        return w, V

    monkeypatch.setattr(instances.np.linalg, "eigh", rotated_eigh)
    other = instances.paper_instance(seed, a_norm=1.05)
    monkeypatch.undo()
    np.testing.assert_allclose(other.A, reference.A, atol=1e-12)
    np.testing.assert_allclose(other.B, reference.B, atol=1e-12)
    assert np.array_equal(other.plant_adj, reference.plant_adj)


def test_bridge_connects_a_large_draw_with_one_link_per_gap():
    """At N = 600 the first draw's 6-NN graph is not connected; bridging adds one link per gap and keeps the rest."""
    import scipy.sparse.csgraph

    from codesign.instances import knn_graph

    rng = np.random.default_rng(0)
    positions = rng.uniform(0.0, 1.0, 600)
    knn = knn_graph(positions, 6)
    components, _ = scipy.sparse.csgraph.connected_components(knn, directed=False)
    assert components > 1  # the case the rule exists for
    instance = paper_instance(0, n=600, connect="bridge", horizon=5)
    comm = instance.comm_adj
    assert nx.is_connected(nx.from_numpy_array(comm))
    added = comm - ((knn != 0) | np.eye(600, dtype=bool))
    assert added.min() == 0 and np.array_equal(added, added.T)
    assert added.sum() / 2 == components - 1
    order = np.argsort(positions)
    rank = np.empty(600, dtype=int)
    rank[order] = np.arange(600)
    i, j = np.nonzero(np.triu(added))
    assert np.all(np.abs(rank[i] - rank[j]) == 1)  # each bridge joins neighbours in position
    assert instance.spec["connect"] == "bridge"


def test_redraw_is_the_default_and_stays_out_of_the_spec():
    assert "connect" not in paper_instance(0).spec
    assert paper_instance(0, connect="redraw").spec == paper_instance(0).spec
    bridged = paper_instance(0, connect="bridge")  # at N = 20 the first draw may already be connected
    assert bridged.spec["connect"] == "bridge"
    with pytest.raises(InstanceError, match="connect must be one of redraw, bridge, got 'glue'"):
        paper_instance(0, connect="glue")


def test_redrawing_gives_up_with_an_error_that_names_the_bridge(monkeypatch):
    import codesign.instances as instances

    # 6 neighbours on 1000 nodes: no draw in thousands is connected, and redrawing used to run forever
    monkeypatch.setattr(instances, "MAX_REDRAWS", 3)
    with pytest.raises(InstanceError, match=r"no connected 6-nearest-neighbour graph on 1000 nodes in 3 draws "
                                            r"\(seed 4\); pass connect='bridge'"):
        paper_instance(4, n=1000)
    assert paper_instance(4, n=1000, connect="bridge").n == 1000


@pytest.mark.parametrize("kind", ["uniform", "ties", "rounded"])
def test_the_sorted_line_gives_the_dense_sort_nearest_neighbours_ties_included(kind):
    """Every draw's neighbour sets are the dense stable argsort's, also where positions repeat or distances tie."""
    from codesign.instances import is_connected, knn_graph, knn_neighbours

    rng = np.random.default_rng(["uniform", "ties", "rounded"].index(kind))
    for _ in range(300):
        n = int(rng.integers(2, 60))
        degree = int(rng.integers(2, n + 1))
        positions = {"uniform": lambda: rng.uniform(0.0, 1.0, n), "ties": lambda: rng.integers(0, 6, n) / 7.0,
                     "rounded": lambda: np.round(rng.uniform(0.0, 1.0, n), 2)}[kind]()
        dense = np.argsort(np.abs(positions[:, None] - positions[None, :]), axis=1, kind="stable")[:, :degree]
        window = knn_neighbours(positions, degree)
        assert np.array_equal(np.sort(window, axis=1), np.sort(dense, axis=1))
        graph = knn_graph(positions, degree)
        components = scipy.sparse.csgraph.connected_components(graph, directed=False, return_labels=False)
        assert is_connected(window) == (components == 1)


def test_a_hopeless_redraw_ends_with_the_default_limit():
    """1500 nodes: no draw of 1000 is connected; each draw used to sort the dense distance matrix (197 s in all)."""
    with pytest.raises(InstanceError, match=r"on 1500 nodes in 1000 draws \(seed 0\); pass connect='bridge'"):
        paper_instance(0, n=1500)


def test_large_instances_use_the_doubling_dare_and_it_agrees_with_scipy(monkeypatch):
    import scipy.linalg

    import codesign.instances as instances

    reference = paper_instance(4, n=30)
    calls = []
    original = scipy.linalg.solve_discrete_are
    monkeypatch.setattr(scipy.linalg, "solve_discrete_are", lambda *a: calls.append(1) or original(*a))
    monkeypatch.setattr(instances, "FAST_DARE_ABOVE", 10)
    fast = paper_instance(4, n=30)
    assert not calls  # scipy's solver was not used above the threshold
    assert np.linalg.norm(fast.P - reference.P) <= 1e-12 * np.linalg.norm(reference.P)
    with pytest.raises(InstanceError, match="not stabilizable"):
        Instance.from_matrices(np.diag(np.r_[1.5 * np.ones(11), 0.5]), np.diag(np.r_[np.zeros(11), 1.0]))


def test_haar_orthogonal_is_scipys_ortho_group_draw_to_the_last_bit():
    """The instances' basis rotation without scipy.stats: the same draw on the same stream."""
    scipy_stats = pytest.importorskip("scipy.stats")
    from codesign.instances import haar_orthogonal

    for dim in (1, 2, 3, 5, 11, 40):
        for seed in range(5):
            ours = haar_orthogonal(dim, np.random.default_rng([seed, dim]))
            theirs = scipy_stats.ortho_group.rvs(dim, random_state=np.random.default_rng([seed, dim]))
            assert ours.shape == (dim, dim)
            np.testing.assert_array_equal(ours, theirs)
            np.testing.assert_allclose(ours @ ours.T, np.eye(dim), atol=1e-13)
