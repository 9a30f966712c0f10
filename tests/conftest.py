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

        from compare import execution, families

        def refuse(spec):
            raise InstanceBuilt(f"an instance was built: {spec}")

        monkeypatch.setattr(execution, "build_instance", refuse)
        for name in families.family_names():
            monkeypatch.setitem(families._FAMILIES, name, replace(families.get_family(name), build=refuse))

    return forbid
