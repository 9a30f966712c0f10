"""On one-state-one-input nodes every method gives the numbers it gave before nodes could hold blocks.

``data/p1_reference.json`` was written by the code at the commit it names (before
``state_nodes``/``input_nodes`` existed), with the settings it lists. Exact costs
must agree to rounding; learned controllers (5 training steps in float64) to 1e-6,
which allows for BLAS differences between machines and nothing more.
"""

import json
from pathlib import Path

import numpy as np
import pytest

import compare.run.registry  # noqa: F401  (the built-ins)
from codesign import get_method, paper_instance, simulate, validation_set

REFERENCE = json.loads((Path(__file__).parent / "data" / "p1_reference.json").read_text())
LEARNED = {"grnn", "grnn_sparse", "gcnn"}


@pytest.fixture(scope="module")
def instance():
    spec = {k: v for k, v in REFERENCE["instance"].items() if k != "family"}
    return paper_instance(**spec)


@pytest.mark.parametrize("name", sorted(REFERENCE["designs"]))
def test_numbers_are_unchanged(instance, name):
    designs = get_method(name)(instance, **REFERENCE["settings"].get(name, {}))
    expected = REFERENCE["designs"][name]
    assert len(designs) == len(expected)
    rtol = 1e-6 if name in LEARNED else 1e-9
    for got, want in zip(designs, expected):
        assert (got.status, got.links, got.self_loops, got.cost_kind) == (
            want["status"], want["links"], want["self_loops"], want["cost_kind"])
        cost = got.cost
        if name in LEARNED:
            # The reference scored on the first 2000 validation draws; rollouts now continue on
            # further draws until precise, so the trained controller is compared on those 2000.
            cost = simulate(instance, got.controller, validation_set(instance, 2000), control_variates=True).cost
        np.testing.assert_allclose(cost, want["cost"], rtol=rtol)
