"""The exhaustive best pattern (baselines.best_pattern) is a floor for every sparse heuristic on small systems."""

from __future__ import annotations

import pytest

import compare.run.registry  # noqa: F401  (the built-ins: importing a family registers no method)
from codesign import get_method, paper_instance
from codesign.status import USABLE
from compare.run.families.chain import chain_instance

HEURISTICS = {"instantaneous": ["sparse_admm", "sparse_sdp", "truncated_lqr", "sparse_budget"],
              "delayed": ["sparse_delayed", "sparse_budget"]}


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("info_model", ["instantaneous", "delayed"])
def test_the_best_pattern_is_at_or_below_every_heuristic(seed, info_model):
    inst = paper_instance(seed, n=3, degree=2, a_norm=1.1, horizon=20)
    best = {d.params["budget"]: d for d in get_method("best_pattern")(inst, info_model=info_model)}
    assert sorted(best) == list(range(7)) and all(d.status == "optimal" for d in best.values())
    assert all(d.links <= b for b, d in best.items())
    for name in HEURISTICS[info_model]:
        params = {"info_model": info_model} if name == "sparse_budget" else {}
        for d in get_method(name)(inst, **params):
            if d.status in USABLE:
                assert best[d.links].cost <= d.cost * (1 + 1e-9), (name, d.links, d.cost, best[d.links].cost)
    costs = [best[b].cost for b in range(7)]
    assert all(a >= b - 1e-9 for a, b in zip(costs, costs[1:]))  # more links never cost more
    assert abs(best[6].cost - (1.0 if info_model == "instantaneous" else best[6].cost)) < 1e-9


def test_symmetric_instances_polish_one_pattern_per_orbit():
    chain = chain_instance(4, rho=1.05, alpha=0.3, horizon=15)  # reversal maps the chain onto itself
    from baselines.best_pattern import automorphisms

    perms = automorphisms(chain)
    assert len(perms) == 2 and list(perms[1]) == [3, 2, 1, 0]
    designs = {d.params["budget"]: d for d in get_method("best_pattern")(chain, links=[1, 2])}
    assert designs[1].extras["patterns"] == 6  # 12 single links, in mirror pairs
    assert designs[2].extras["patterns"] < 66 and designs[1].extras["symmetries"] == 2
    assert designs[2].cost <= designs[1].cost


def test_too_many_patterns_are_refused_at_once():
    inst = paper_instance(0, n=6, degree=2, horizon=10)
    with pytest.raises(ValueError, match=r"best_pattern: budgets \[15\] on 30 admissible links take 155117520 "
                                         r"patterns, more than max_patterns = 20000"):
        get_method("best_pattern")(inst, links=[15])


def test_the_report_gives_each_methods_gap_to_the_best_pattern(tmp_path):
    from click.testing import CliRunner

    from compare.cli import main

    (tmp_path / "s.toml").write_text(
        'name = "s"\n[instances]\nfamily = "paper"\nn = [3]\ndegree = 2\na_norms = [1.1]\nseeds = 2\nhorizon = 20\n'
        '[[methods]]\nmethod = "best_pattern"\n[[methods]]\nmethod = "truncated_lqr"\nparams = { links = [4, 2, 0] }\n'
        '[[methods]]\nmethod = "sparse_admm"\n[[methods]]\nmethod = "sls"\n')
    result = CliRunner().invoke(main, ["run", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out"),
                                       "--workers", "1", "--no-progress"])
    assert result.exit_code == 0, result.output
    report = (tmp_path / "out" / "report.md").read_text()
    section = report.split("## Gap to the best pattern found", 1)[1].split("\n## ", 1)[0]
    assert "instantaneous information" in section and "| ≤ 0 links | ≤ 1 link |" in section
    rows = {line.split(" | ")[0].lstrip("| "): line for line in section.splitlines() if line.startswith("| ")}
    truncation = rows["Truncated LQR K"].split(" | ")[2:]
    assert all(cell.strip(" |") in ("0", "—") or cell.startswith("+") for cell in truncation)  # never below
    assert "Starts per pattern: 3" in section
