import numpy as np

from compare.report import aggregate, budget_costs, pareto_front, plant_links, plot_cost_vs_links

INST = [{"family": "paper", "seed": s, "n": 8, "degree": 4, "a_norm": 1.05, "b_norm": 1.0, "hops": 3, "horizon": 10}
        for s in range(3)]


def _rec(inst, label, links, cost, status="optimal", params=None, info="instantaneous"):
    return {"instance": inst, "label": label, "method": label, "params": params or {}, "links": links,
            "self_loops": 8, "cost": cost, "status": status, "info_model": info, "run_key": "k", "idx": 0}


def test_aggregate_medians_and_failures():
    records = [_rec(INST[i], "m", 10 + i, 1.0 + i) for i in range(3)]
    records.append(_rec(INST[0], "m", 99, float("nan"), status="infeasible", params={}))
    (point,) = aggregate(records)
    assert point.designs == 4 and point.ok == 3
    assert point.links[1] == 11 and point.cost[1] == 2.0
    assert point.statuses == {"optimal": 3, "infeasible": 1}


def test_pareto_front_drops_dominated_settings():
    records = []
    for gamma, links, cost in ((1, 10, 2.0), (2, 20, 1.5), (3, 30, 1.6), (4, 40, 1.2)):
        records += [_rec(inst, "m", links, cost, params={"gamma": gamma}) for inst in INST]
    front = pareto_front(aggregate(records))
    assert [p.links[1] for p in front] == [10, 20, 40]


def test_budget_costs_take_best_design_within_budget_per_instance():
    records = [_rec(INST[0], "m", 10, 3.0), _rec(INST[0], "m", 50, 2.0), _rec(INST[1], "m", 100, 1.5)]
    ((panel, label), cells), = budget_costs(records, budgets=(20, 60, None)).items()
    assert label == "m"
    assert cells[0] == (3.0, 1) and cells[1] == (2.0, 1)
    assert cells[2] == (1.75, 2)  # median of the per-instance bests 2.0 and 1.5


def test_plant_boundary_and_plot_handles():
    records = [_rec(inst, "m", 5, 1.2, info="delayed") for inst in INST]
    boundary = plant_links(records)
    (panel, links), = boundary.items()
    assert 0 < links <= 8 * 7
    fig, axes = plot_cost_vs_links(aggregate(records), boundaries=boundary)
    assert len(axes) == 1 and axes[0].get_xscale() == "symlog"
    assert np.isclose(axes[0].lines[-1].get_xdata()[0], links)


def _vertical_lines(ax):
    return [line for line in ax.lines if len(set(line.get_xdata())) == 1 and len(line.get_xdata()) == 2]


def test_qi_boundary_only_with_a_delayed_method_and_linear_axis_for_a_narrow_range():
    records = [_rec(inst, "m", 5, 1.2) for inst in INST] + [_rec(inst, "lqr", 56, 1.0) for inst in INST]
    fig, axes = plot_cost_vs_links(aggregate(records), boundaries=plant_links(records))
    assert not _vertical_lines(axes[0])
    assert axes[0].get_yscale() == "linear"
    labels = [t.get_text() for t in axes[0].get_yticklabels() if t.get_text()]
    assert len(labels) >= 3  # a narrow range still gets several labelled ticks


def test_single_setting_methods_at_the_same_link_count_are_dodged():
    from compare.report import _dodge

    records = [_rec(inst, label, 0, 1.3) for inst in INST for label in ("autonomous", "decentralized")]
    points = aggregate(records)
    offsets = _dodge({p.label: [p] for p in points}, right=56)
    assert len(offsets) == 2 and len(set(offsets.values())) == 2


def test_dodged_markers_stay_inside_the_axes():
    """Methods that share a link count are drawn with an offset transform, which autoscaling ignores."""
    records = [_rec(inst, label, 56, 1.0 + 0.1 * k) for inst in INST for k, label in enumerate(("lqr", "dense"))]
    records += [_rec(inst, "path", links, 1.5 - 0.01 * links, params={"gamma": links})
                for inst in INST for links in (0, 2, 5)]
    fig, axes = plot_cost_vs_links(aggregate(records))
    assert axes[0].get_xlim()[1] > 56
    fig.clf()


def test_many_methods_get_distinct_colour_and_marker_pairs():
    from compare.figures import label_styles

    styles = label_styles([f"method {i}" for i in range(30)])
    assert len({(tuple(c), m) for c, m in styles.values()}) == 30


def test_topology_path_prefers_the_papers_a_norm_then_the_longest_path_and_draws_each_design():
    from codesign import paper_instance
    from compare.topologies import plot_topology_path, topology_path_records

    records = []
    for seed, betas in ((0, (0.1, 1.0)), (1, (0.1, 1.0, 10.0))):
        inst = dict(INST[0], seed=seed, a_norm=1.1)
        for beta in betas:
            rec = _rec(inst, "GRNN-Sparse", 10, 1.2, params={"beta": beta})
            rec["method"] = "grnn_sparse"
            records.append(rec)
    path = topology_path_records(records)
    assert [r.params["beta"] for r in path] == [0.1, 1.0, 10.0]
    assert all(r.instance.seed == 1 for r in path)
    # A longer path elsewhere, and a run with other settings on the preferred
    # instance, do not displace or join the preferred a_norm's path.
    for beta in (0.01, 0.1, 1.0, 10.0):
        rec = _rec(dict(INST[0], seed=0, a_norm=0.995), "GRNN-Sparse", 10, 1.2, params={"beta": beta})
        rec["method"] = "grnn_sparse"
        records.append(rec)
    other = _rec(dict(INST[0], seed=1, a_norm=1.1), "GRNN-Sparse", 10, 1.2, params={"beta": 2.0, "steps": 750})
    other["method"] = "grnn_sparse"
    path = topology_path_records(records + [other])
    assert [r.params["beta"] for r in path] == [0.1, 1.0, 10.0]
    assert all(r.instance.seed == 1 and r.instance.a_norm == 1.1 for r in path)
    # The linear ablation's path, even a longer one on the same instance, gives way to the paper's tanh GRNN.
    linear = []
    for beta in (0.01, 0.1, 1.0, 10.0, 100.0):
        rec = _rec(dict(INST[0], seed=0, a_norm=1.1), "Linear GRNN-Sparse", 10, 1.2,
                   params={"beta": beta, "activation": "identity"})
        rec["method"] = "grnn_sparse"
        linear.append(rec)
    path = topology_path_records(records + linear)
    assert [r.params["beta"] for r in path] == [0.1, 1.0, 10.0]
    assert all("activation" not in r.params for r in path)
    inst = paper_instance(1, n=8, degree=4, a_norm=1.1, horizon=10)
    supports = [np.eye(8) + np.diag(np.ones(7), 1) * (k > 0) for k in range(3)]
    fig, axes = plot_topology_path(inst, [(b, 7 * (k > 0), 1.2, s) for k, (b, s) in enumerate(zip((0.1, 1, 10), supports))])
    assert len(axes) == 4 and axes[1].get_title().startswith("β = 0.1")


def test_report_counts_runs_and_shows_how_to_regenerate(tmp_path):
    from compare.report import write_report

    records = []
    for i, inst in enumerate(INST):
        for label, links, cost in (("a", 0, 2.0), ("b", 10, 1.1)):
            rec = _rec(inst, label, links, cost)
            rec.update(run_key=f"{label}{i}", cost_stderr=0.0, cost_kind="exact", message="", seconds=0.1,
                       controller_kind=None, extras={}, experiment="x")
            records.append(rec)
    commands = ["compare run x --out o", "compare run y --out o", "compare report --out o"]
    files = write_report(records, tmp_path, title="T", commands=commands)
    text = files["md"].read_text()
    assert "6 runs on 3 instances, 6 designs." in text
    assert ("Regenerate with `compare run x --out o` then `compare run y --out o` (runs already in the store "
            "are skipped), or from the stored results alone with `compare report --out o`.") in text
    alone = write_report(records, tmp_path, title="T", commands=["compare report --out o"])["md"].read_text()
    assert "Regenerate from the stored results with `compare report --out o`." in alone


def test_params_column_rounds_grid_values_and_keeps_the_rest():
    from compare.report import _params_text

    text = _params_text({"gamma": 0.0021544346900318843, "reweight": 3, "rho": 100.0, "end": float("inf"),
                         "g": "plant"})
    assert text == "end=inf, g=plant, gamma=0.002154, reweight=3, rho=100"
    assert _params_text({}) == "—"


def test_sections_come_from_declarations_not_names(tmp_path):
    """Table 1 appears for any experiment that asks for it, whatever its name; not otherwise."""
    from compare import Store, parse_spec, run_experiment
    from compare.cli import _write_report

    spec = """
name = "{name}"
{report}
[instances]
n = [8]
a_norms = [0.995, 1.05]
seeds = 2
degree = 4
horizon = 10
[[methods]]
method = "lqr"
[[methods]]
method = "autonomous"
"""
    for name, report, expected in (("renamed-table", '[report]\nsections = ["table1"]', True),
                                   ("table1-lookalike", "", False)):
        out = tmp_path / name
        with Store(out / "results.sqlite") as store:
            run_experiment(parse_spec(spec.format(name=name, report=report)), store, progress=False)
            _write_report(store, out)
        assert ("## Table 1" in (out / "report.md").read_text()) is expected


def test_delayed_section_says_when_the_paired_result_reverses_the_median_ranking(tmp_path):
    from compare.figures import label_styles
    from compare.report import _delayed_section

    insts = [dict(INST[0], seed=s) for s in range(8)]
    records = [_rec(inst, "A", 10, 1.0 if s < 4 else 1.2, info="delayed") for s, inst in enumerate(insts)]
    # B ran on instances 2..7 only and beats A on each of them by 0.01.
    records += [_rec(inst, "B", 10, (1.0 if s < 4 else 1.2) - 0.01, info="delayed")
                for s, inst in enumerate(insts) if s >= 2]
    lines = _delayed_section(records, tmp_path, {}, label_styles(["A", "B"]), {})
    text = "\n".join(lines)
    assert "at ≤ 20 links A (1.1) against B (1.19)" in text
    assert "B significantly better on the 6 common instances" in text


def test_delayed_section_claims_no_significance_from_three_instances(tmp_path):
    """Three paired instances that all favour A: their range covers the median with 75 %, not 95 %."""
    from compare.figures import label_styles
    from compare.report import _delayed_section

    insts = [dict(INST[0], seed=s) for s in range(3)]
    records = [_rec(inst, "A", 10, 1.0 + 0.1 * s, info="delayed") for s, inst in enumerate(insts)]
    records += [_rec(inst, "B", 10, 1.05 + 0.1 * s, info="delayed") for s, inst in enumerate(insts)]
    text = "\n".join(_delayed_section(records, tmp_path, {}, label_styles(["A", "B"]), {}))
    assert "significantly" not in text
    assert "[-0.0500, -0.0500] (75%)" in text
    assert "A better on every common instance; too few instances for a 95 % interval" in text


def test_off_scale_values_get_one_label_per_value_and_neighbours_go_a_row_lower():
    """Costs above the axis: methods sharing a link count and value share a label; close labels do not overlap."""
    from types import SimpleNamespace

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from compare.report import _mark_off_scale

    fig, ax = plt.subplots(figsize=(4, 3))
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set_xlim(-0.2, 400)
    ax.set_ylim(0.9, 2.0)

    def point(label, links, cost):
        return SimpleNamespace(label=label, links=(links, links, links), cost=(cost, cost, cost))

    styles = {name: (colour, "o") for name, colour in (("a", "red"), ("b", "blue"), ("c", "green"))}
    rows = _mark_off_scale(ax, [point("a", 0, 2.3), point("b", 0, 2.3), point("c", 0, 1e26), point("a", 300, 5.0),
                                point("b", 10, 3.0)], 2.0, styles)
    texts = {t.get_text(): t for t in ax.texts}
    assert sorted(texts) == ["1e+26", "2.3", "3", "5"]
    assert texts["2.3"].get_color() == "0.25"  # shared by two methods
    assert texts["1e+26"].xyann[1] != texts["2.3"].xyann[1]  # same link count: stacked, not overlapping
    assert texts["5"].xyann[1] == -4  # far from the others: first row
    assert rows == 2
    # At the axes' edges a label extends inwards instead of past the frame.
    assert texts["5"].get_ha() == "right" and texts["2.3"].get_ha() == "left" and texts["3"].get_ha() == "center"

    from compare.figures import draw_boundary

    draw_boundary(ax, 300, below=9.0 * rows)  # its label starts under the off-scale labels
    boundary = next(t for t in ax.texts if "QI boundary" in t.get_text())
    assert boundary.xyann[1] < min(t.xyann[1] for t in texts.values()) - 7
    plt.close(fig)


def test_report_says_how_many_simulated_costs_were_refined_on_importance_draws():
    from compare.records import Records
    from compare.report import _precision_text

    def row(stderr, estimator, importance):
        return {"cost": 2.0, "cost_stderr": stderr, "cost_kind": "simulated", "status": "optimal",
                "extras": {"cost_estimator": estimator, "plain_cost": 2.0, "plain_cost_stderr": 0.02,
                           "validation_size": 2000 + importance, "importance_draws": importance}}

    records = Records.from_rows([row(2e-4, "control variates: all 210 quadratic monomials", 0),
                                 row(1.6e-3, "importance sampling tilted along ...", 62000)])
    text = _precision_text(records)
    assert text.startswith(" (control variates; 1 heavy-tailed costs re-estimated on up to 62,000")
    assert "largest 0.080%" in text and "median of 1.00%" in text
    plain = _precision_text(Records.from_rows([row(2e-4, "control variates: ...", 0)]))
    assert "re-estimated" not in plain and plain.startswith(" (control variates; relative")


def test_report_warns_about_costs_that_stay_imprecise_after_refinement():
    from compare.records import Records
    from compare.report import _uncertain_text

    def row(label, stderr, a_norm):
        return {"label": label, "cost": 2.0, "cost_stderr": stderr, "cost_kind": "simulated", "status": "optimal",
                "instance": {"family": "paper", "n": 20, "a_norm": a_norm, "seed": 0},
                "extras": {"cost_estimator": "importance sampling ...", "importance_draws": 126000}}

    assert _uncertain_text(Records.from_rows([row("GRNN", 1.9e-3, 1.2)])) == ""  # 0.1 %: imprecise, not unresolved
    text = _uncertain_text(Records.from_rows([row("GRNN", 0.3, 1.2), row("GRNN", 0.1, 1.2), row("GCNN", 0.03, 1.05),
                                              row("GCNN", 1e-3, 1.2)]))
    assert text.startswith(" 3 simulated costs keep a relative standard error above 1%")
    assert "(1 of GCNN on N = 20, ‖A‖₂ = 1.05; 2 of GRNN on N = 20, ‖A‖₂ = 1.2)" in text
    assert "rare initial states" in text and "docs/evaluation.md" in text
