"""A static gain at every exact link budget (baselines.sparse_budget)."""

from __future__ import annotations

import pytest

import compare.run.registry  # noqa: F401  (the built-ins: importing a family registers no method)
from codesign import get_method, paper_instance
from compare.run.families.swing_grid import swing_grid_instance


@pytest.fixture(scope="module")
def paper():
    return paper_instance(1, n=10, a_norm=1.05)


@pytest.mark.parametrize("info_model", ["instantaneous", "delayed"])
def test_every_budget_gets_a_design_within_it(paper, info_model):
    budgets = [90, 40, 17, 9, 3, 1, 0]
    designs = get_method("sparse_budget")(paper, links=budgets, info_model=info_model)
    assert [d.params["budget"] for d in designs] == budgets
    for d in designs:
        assert d.status == "optimal" and d.links <= d.params["budget"] and d.info_model == info_model
        assert d.cost_kind == "exact" and d.cost >= 1.0 - 1e-9
    costs = [d.cost for d in designs]
    assert costs == sorted(costs)  # more links never cost more here
    decentralized = get_method("decentralized")(paper)[0]
    assert abs(designs[-1].cost - decentralized.cost) < 1e-9 and designs[-1].links == 0


def test_at_or_below_truncation_and_the_l1_paths_at_their_link_counts(paper):
    l1 = [d for d in get_method("sparse_admm")(paper) if d.status == "optimal" and 0 < d.links < 90]
    counts = sorted({d.links for d in l1}, reverse=True)
    budget = {d.params["budget"]: d for d in get_method("sparse_budget")(paper, links=counts)}
    truncated = {d.params["links"]: d for d in get_method("truncated_lqr")(paper, links=counts)}
    for d in l1:
        assert budget[d.links].cost <= min(d.cost, truncated[d.links].cost) * (1 + 1e-9)
    delayed = [d for d in get_method("sparse_delayed")(paper) if d.status == "optimal" and 0 < d.links < 90]
    counts = sorted({d.links for d in delayed}, reverse=True)
    budget = {d.params["budget"]: d for d in get_method("sparse_budget")(paper, links=counts, info_model="delayed")}
    for d in delayed:
        assert budget[d.links].cost <= d.cost * (1 + 1e-9)


@pytest.mark.parametrize("info_model", ["instantaneous", "delayed"])
def test_node_blocks_and_unactuated_nodes(info_model):
    grid = swing_grid_instance(3, seed=2, actuation=0.5)  # 9 buses, 5 actuated, two states each
    designs = get_method("sparse_budget")(grid, info_model=info_model)
    most = 5 * 8  # links only from actuated buses
    assert designs[0].params["budget"] == most
    assert all(d.status == "optimal" and d.links <= d.params["budget"] for d in designs)
    with pytest.raises(ValueError, match=r"links must be integers between 0 and 40 \(the admissible links\), got 41"):
        get_method("sparse_budget")(grid, links=[41])


def test_a_pair_named_by_method_compares_each_of_its_labels(tmp_path):
    """report.pairs = [["sparse_budget", "sparse_admm"]] pairs every label of sparse_budget with the ADMM path."""
    from click.testing import CliRunner

    from compare.cli import main

    (tmp_path / "p.toml").write_text(
        'name = "p"\n[report]\npairs = [["sparse_budget", "sparse_admm"]]\n'
        '[instances]\nfamily = "paper"\nn = [6]\ndegree = 3\na_norms = [1.05]\nseeds = 2\nhorizon = 15\n'
        '[[methods]]\nmethod = "sparse_admm"\n[[methods]]\nmethod = "sparse_budget"\n'
        '[[methods]]\nmethod = "sparse_budget"\nlabel = "Budget, delayed"\nparams = { info_model = "delayed" }\n')
    result = CliRunner().invoke(main, ["run", str(tmp_path / "p.toml"), "--out", str(tmp_path / "out"),
                                       "--workers", "1", "--no-progress"])
    assert result.exit_code == 0, result.output
    report = (tmp_path / "out" / "report.md").read_text()
    assert "### Sparse K at exact budgets (GraSP) against Sparse K (l1 ADMM), " in report
    assert "| Budget, delayed − Sparse K (l1 ADMM)<br>information: delayed vs instantaneous |" in report
