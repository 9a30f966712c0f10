import os

import pytest

# One BLAS thread per test process keeps the suite predictable on 2 cores.
for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")


class InstanceBuilt(BaseException):
    """Raised by any instance build a test forbids: a BaseException, so that no ``except Exception`` hides it."""


@pytest.fixture
def forbid_instance_builds(monkeypatch):
    """A function that makes every way of building an instance raise :class:`InstanceBuilt` from then on.

    Covers the runner's helper and each registered family's build; for tests that a report
    (or a folder rebuild) draws from stored facts alone.
    """

    def forbid():
        from dataclasses import replace

        from compare.run import execution, families

        def refuse(spec):
            raise InstanceBuilt(f"an instance was built: {spec}")

        monkeypatch.setattr(execution, "build_instance", refuse)
        for name in families.family_names():
            monkeypatch.setitem(families._FAMILIES, name, replace(families.get_family(name), build=refuse))

    return forbid


@pytest.fixture(scope="module")
def uneven():
    """Four nodes: node 0 has three states, node 2 one, the others two; node 1 has two inputs, node 3 none.

    Shared by the GRNN node-block tests (shared and per-node readout).
    """
    import numpy as np

    from codesign import Instance

    rng = np.random.default_rng(11)
    state_nodes = np.array([0, 1, 2, 3, 0, 1, 3, 0])
    input_nodes = np.array([0, 1, 1, 2])
    A = 0.3 * rng.standard_normal((8, 8)) + 0.6 * np.eye(8)
    B = rng.standard_normal((8, 4))
    ring = np.eye(4) + np.roll(np.eye(4), 1, axis=1) + np.roll(np.eye(4), -1, axis=1)
    return Instance.from_matrices(A, B, Q=np.diag(rng.uniform(0.5, 2, 8)), R=np.diag(rng.uniform(0.5, 2, 4)),
                                  comm_adj=ring, state_nodes=state_nodes, input_nodes=input_nodes, horizon=15)
