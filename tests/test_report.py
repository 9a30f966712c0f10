import numpy as np
import pytest
from tiny_specs import tiny_spec  # tests/tiny_specs.py

from compare.report.write import aggregate, budget_costs, pareto_front, plant_links, plot_cost_vs_links

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
    from compare.run.records import Records, canonical_key

    facts = {canonical_key(inst): {"n": 8, "plant_links": 20 + i, "comm_links": 30} for i, inst in enumerate(INST)}
    records = Records.from_rows([_rec(inst, "m", 5, 1.2, info="delayed") for inst in INST], facts)
    boundary = plant_links(records)
    (panel, links), = boundary.items()
    assert links == 21.0  # the median of the stored counts; no instance is rebuilt
    fig, axes = plot_cost_vs_links(aggregate(records), boundaries=boundary)
    (ax,) = axes.values()
    assert ax.get_xscale() == "symlog"
    assert np.isclose(ax.lines[-1].get_xdata()[0], links)


def _vertical_lines(ax):
    return [line for line in ax.lines if len(set(line.get_xdata())) == 1 and len(line.get_xdata()) == 2]


def test_qi_boundary_only_with_a_delayed_method_and_an_excess_cost_axis_in_percent():
    records = [_rec(inst, "m", 5, 1.2) for inst in INST] + [_rec(inst, "lqr", 56, 1.0) for inst in INST]
    fig, axes = plot_cost_vs_links(aggregate(records), boundaries=plant_links(records))
    (ax,) = axes.values()
    assert not _vertical_lines(ax)
    assert ax.get_yscale() == "log"
    fig.canvas.draw()
    labels = [t.get_text() for t in ax.get_yticklabels() if t.get_text()]
    assert len(labels) >= 2 and all(text.endswith("%") for text in labels)
    assert "20 %" in labels  # the cost 1.2 is 20 % above LQR
    assert ax.get_ylim()[0] < 0.2  # and the axis reaches below it, LQR (0 %) on the bottom edge


def test_single_setting_methods_at_the_same_link_count_are_dodged():
    from compare.report.cost_links import _dodge

    records = [_rec(inst, label, 0, 1.3) for inst in INST for label in ("autonomous", "decentralized")]
    points = aggregate(records)
    offsets = _dodge({p.label: [(p.x, p.cost[1])] for p in points})
    assert len(offsets) == 2 and sorted(offsets.values()) == [-3.5, 3.5]  # symmetric about the true count
    # A method alone at its link count stays there, even where a path ends (LQR at N(N - 1) links).
    assert _dodge({"lqr": [(56, 1.0)], "path": [(0, 1.5), (56, 1.0)]}) == {}


def test_dodged_markers_stay_inside_the_axes():
    """Methods that share a link count are drawn with an offset transform, which autoscaling ignores."""
    records = [_rec(inst, label, 56, 1.0 + 0.1 * k) for inst in INST for k, label in enumerate(("lqr", "dense"))]
    records += [_rec(inst, "path", links, 1.5 - 0.01 * links, params={"gamma": links})
                for inst in INST for links in (0, 2, 5)]
    fig, axes = plot_cost_vs_links(aggregate(records))
    assert axes[INST[0]["family"], 8, 1.05].get_xlim()[1] > 56
    fig.clf()


def test_a_summary_marker_is_drawn_only_on_or_above_its_methods_front():
    """Medians of links and of cost taken separately can describe no typical instance: then there is no marker."""
    insts = [dict(INST[0], seed=s) for s in range(6)]

    def setting(links, costs):
        return [_rec(inst, "m", k, c, params={"beta": 1.0}) for inst, k, c in zip(insts, links, costs)]

    # Links 0, 0, 0, 50, 50, 50 (lower median 0); costs median (1.1 + 1.5) / 2 = 1.3, and every 0-link
    # design costs more than that: the medians (0, 1.3) describe no design.
    (point,) = aggregate(setting((0, 0, 0, 50, 50, 50), (1.5, 1.6, 1.7, 1.0, 1.05, 1.1)))
    assert (point.x, point.cost[1], point.reached, point.reach) == (0, 1.3, False, 0)
    fig, axes = plot_cost_vs_links([point])
    (ax,) = axes.values()
    assert not [line for line in ax.lines if (line.get_gid() or "").startswith("method:") and len(line.get_xdata())]
    # One 0-link design at 1.1 reaches the medians (0, 1.15): 1 of 6 instances, not drawn (the old rule drew it).
    (point,) = aggregate(setting((0, 0, 0, 50, 50, 50), (1.1, 1.6, 1.7, 1.0, 1.05, 1.2)))
    assert (point.x, point.cost[1], point.reached) == (0, 1.15, False) and point.reach == pytest.approx(1 / 6)
    # Three 0-link designs below the median cost, but the method's front within 0 links is undefined (three of
    # six instances have none): the marker would stand below its own front, so it is not drawn.
    (point,) = aggregate(setting((0, 0, 0, 50, 50, 50), (1.1, 1.12, 1.15, 1.3, 1.4, 1.5)))
    assert (point.x, point.reached, point.reach) == (0, False, 0.5)
    # Four of six with a 0-link design: the front within 0 links is (1.15 + 1.3) / 2 = 1.225, the setting's
    # median cost too, so the marker sits on its front and is drawn.
    (point,) = aggregate(setting((0, 0, 0, 0, 50, 50), (1.1, 1.12, 1.15, 1.3, 1.4, 1.5)))
    assert (point.x, point.cost[1], point.reached, point.reach) == (0, pytest.approx(1.225), True, 0.5)
    # Another setting of the same method counts: the method reaches the point on that instance.
    more = setting((0, 0, 0, 50, 50, 50), (1.5, 1.6, 1.7, 1.0, 1.05, 1.1))
    more += [_rec(inst, "m", 0, 1.0, params={"beta": 10.0}) for inst in insts[3:]]
    point = next(p for p in aggregate(more) if p.params["beta"] == 1.0)
    assert (point.x, point.reach, point.reached) == (0, 0.5, True)
    (point,) = aggregate(setting((3, 4, 7, 8, 9, 10), (1.2,) * 6))
    assert point.x == 7  # the lower median, not 7.5


def test_topology_path_prefers_the_papers_a_norm_then_the_longest_path_and_draws_each_design():
    from codesign import paper_instance
    from compare.report.topologies import plot_topology_path, topology_path_records

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
    from compare.report.write import write_report

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
    assert "6 runs on 3 instances (1 panel, 3 instances per panel), 6 designs by 2 methods." in text
    assert ("Regenerate with `compare run x --out o` then `compare run y --out o` (runs already in the store "
            "are skipped), or rebuild this report from its folder alone") in text
    alone = write_report(records, tmp_path, title="T", commands=["compare report --out o"])["md"].read_text()
    assert "Rebuild this report from its folder alone with `compare report --out o`." in alone


def test_params_column_rounds_grid_values_and_keeps_the_rest():
    from compare.report.tables import _params_text

    text = _params_text({"gamma": 0.0021544346900318843, "reweight": 3, "rho": 100.0, "end": float("inf"),
                         "g": "plant"})
    assert text == "end=inf, g=plant, gamma=0.002154, reweight=3, rho=100"
    assert _params_text({}) == "—"


def test_sections_come_from_declarations_not_names(tmp_path):
    """Table 1 appears for any experiment that asks for it, whatever its name; not otherwise."""
    from compare import Store, parse_spec, run_experiment
    from compare.cli import _write_report

    for name, report, expected in (("renamed-table", '[report]\nsections = ["table1"]', True),
                                   ("table1-lookalike", "", False)):
        out = tmp_path / name
        spec = tiny_spec(name, methods=("lqr", "autonomous"), head=f"{report}\n")
        with Store(out / "results.sqlite") as store:
            run_experiment(parse_spec(spec), store, workers=1, progress=False)
            _write_report(store, out)
        assert ("## Table 1" in (out / "report.md").read_text()) is expected
        # LQR is the only design on the axis here (the autonomous loop is off it): the off-scale
        # triangle sits on the axis's top edge, not at LQR's rounding-level excess of -3e-12,
        # which a log axis put 300,000 px below and made a 1506 x 389,685 px figure.
        from PIL import Image

        for png in out.glob("*.png"):
            assert max(Image.open(png).size) < 4000, (png.name, Image.open(png).size)


def test_off_scale_values_get_one_label_per_value_and_neighbours_go_a_row_lower():
    """Costs above the axis: methods sharing a link count and value share a label; close labels do not overlap."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from compare.report.cost_links import _mark_off_scale

    fig, ax = plt.subplots(figsize=(4, 3))
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set_xlim(-0.2, 400)
    ax.set_ylim(0.9, 2.0)

    colours = {"a": "red", "b": "blue", "c": "green"}

    def point(label, links, cost):
        return (links, cost, colours[label])

    rows = _mark_off_scale(ax, [point("a", 0, 2.3), point("b", 0, 2.3), point("c", 0, 1e26), point("a", 300, 5.0),
                                point("b", 10, 3.0)], 2.0)
    texts = {t.get_text(): t for t in ax.texts}
    assert sorted(texts) == ["1e+26", "2.3", "3", "5"]
    assert texts["2.3"].get_color() == "0.25"  # shared by two methods
    assert texts["1e+26"].xyann[1] != texts["2.3"].xyann[1]  # same link count: stacked, not overlapping
    assert texts["5"].xyann[1] == 6  # far from the others: first row, above the frame where no line runs
    assert all(t.get_va() == "bottom" and t.xyann[1] > 0 for t in texts.values())
    assert rows == 2
    # At the axes' edges a label extends inwards instead of past the frame.
    assert texts["5"].get_ha() == "right" and texts["2.3"].get_ha() == "left" and texts["3"].get_ha() == "center"

    plt.close(fig)


def test_the_qi_boundary_is_named_in_the_legend_not_under_the_markers():
    import matplotlib.pyplot as plt

    from compare.report.figures import BOUNDARY_LABEL, boundary_handles, draw_boundary

    fig, (left, right) = plt.subplots(1, 2)
    assert boundary_handles([left, right]) == []  # no boundary drawn: no entry
    line = draw_boundary(right, 300)
    assert list(line.get_xdata()) == [300, 300] and line.get_zorder() < 1
    assert not right.texts  # a name on the panel was covered by the markers at that link count
    heading, entry = boundary_handles([left, right])
    assert heading.get_linestyle() == "None"  # a bold heading in finish_legend
    assert entry.get_label() == BOUNDARY_LABEL and entry.get_linestyle() == line.get_linestyle()
    plt.close(fig)


def test_report_says_how_many_simulated_costs_were_refined_on_importance_draws():
    from compare.run.records import Records
    from compare.report.tables import precision_text

    def row(stderr, estimator, importance):
        return {"cost": 2.0, "cost_stderr": stderr, "cost_kind": "simulated", "status": "optimal",
                "extras": {"cost_estimator": estimator, "plain_cost": 2.0, "plain_cost_stderr": 0.02,
                           "validation_size": 2000 + importance, "importance_draws": importance}}

    records = Records.from_rows([row(2e-4, "control variates: all 210 quadratic monomials", 0),
                                 row(1.6e-3, "importance sampling tilted along ...", 62000)])
    text = precision_text(records)
    assert text.startswith(" (control variates; 1 heavy-tailed cost re-estimated on up to 62,000")
    assert "largest 0.080%" in text and "median of 1.00%" in text
    plain = precision_text(Records.from_rows([row(2e-4, "control variates: ...", 0)]))
    assert "re-estimated" not in plain and plain.startswith(" (control variates; relative")


def test_report_warns_about_costs_that_stay_imprecise_after_refinement():
    from compare.run.records import Records
    from compare.report.tables import uncertain_text

    def row(label, stderr, a_norm):
        return {"label": label, "cost": 2.0, "cost_stderr": stderr, "cost_kind": "simulated", "status": "optimal",
                "instance": {"family": "paper", "n": 20, "a_norm": a_norm, "seed": 0},
                "extras": {"cost_estimator": "importance sampling ...", "importance_draws": 126000}}

    assert uncertain_text(Records.from_rows([row("GRNN", 1.9e-3, 1.2)])) == ""  # 0.1 %: imprecise, not unresolved
    text = uncertain_text(Records.from_rows([row("GRNN", 0.3, 1.2), row("GRNN", 0.1, 1.2), row("GCNN", 0.03, 1.05),
                                             row("GCNN", 1e-3, 1.2)]))
    assert text.startswith(" 3 simulated costs keep a relative standard error above 1%")
    assert "(1 of GCNN on N = 20, ‖A‖₂ = 1.05; 2 of GRNN on N = 20, ‖A‖₂ = 1.2)" in text
    assert "rare initial states" in text and "docs/evaluation.md" in text


def test_every_built_in_marker_is_visible_on_white():
    """A solid filled marker gets a white edge (it stands out from its line); a marker drawn by its
    edges alone ("x", "+") or hollow keeps its colour there: with a white edge the autonomous loop's
    "x" vanished from every figure."""
    from matplotlib.markers import MarkerStyle

    from compare.report.styles import METHOD_STYLES, Style

    assert Style("#555555", "x", "none").edge == "#555555"
    assert Style("#1f77b4", "o").edge == "white"
    for key, (colour, marker, info_model) in METHOD_STYLES.items():
        style = Style(colour, marker, info_model)
        visible = style.edge == style.colour or (MarkerStyle(marker).is_filled() and style.face == colour)
        assert visible, key
    assert Style(*METHOD_STYLES["autonomous"]).edge == METHOD_STYLES["autonomous"][0]


def test_both_cost_figures_draw_a_method_s_marker_edge_alike():
    """The cost-against-links figure and the budget fronts take a marker's edge colour and width from
    its one Style (they used to decide the width each on their own: 0.6 and 0.5 points)."""
    from matplotlib.lines import Line2D

    from compare.report.figures import plot_budget_fronts
    from compare.run.records import Records
    from compare.report.write import budget_fronts, label_styles
    from compare.report.styles import style_for

    records = []
    for method, links in (("sparse_admm", (20, 40)), ("autonomous", (0,)), ("lqr", (56,))):
        for inst in INST:
            records += [_rec(inst, method, k, 1.5 - k / 100, params={"gamma": k}) for k in links]
    records = Records.from_rows(records)
    styles = label_styles(records)
    drawn = {}
    for fig in (plot_cost_vs_links(aggregate(records), records=records, styles=styles)[0],
                plot_budget_fronts(budget_fronts(records), styles=styles)[0]):
        for ax in fig.axes:
            for line in ax.lines:
                gid = line.get_gid() or ""
                if isinstance(line, Line2D) and gid.startswith("method:") and line.get_marker() not in ("None", "", None):
                    drawn.setdefault(gid[7:], set()).add((line.get_markeredgecolor(), line.get_markeredgewidth()))
    assert set(drawn) == {"sparse_admm", "autonomous", "lqr"}
    for label, edges in drawn.items():
        style = style_for(label)
        assert edges == {(style.edge, style.edge_width)}, (label, edges)
    assert {style_for(label).edge_width for label in drawn} == {0.6, 1.2}  # solid and edge-only markers both drawn


def test_the_answer_comes_before_the_contents_on_the_page(tmp_path):
    from compare.report.html import render_html

    page = render_html("# Title\n\nThe answer, first.\n\n## Findings\n\ntext\n\n## More\n\nx\n", tmp_path, "Title")
    assert page.index("The answer, first.") < page.index('<nav class="toc">') < page.index('id="findings"')


def test_a_method_without_a_usable_design_on_any_panel_is_named_once_in_the_legend_not_in_every_title():
    import matplotlib.pyplot as plt

    from compare.report.figures import NOWHERE_SUFFIX, plot_budget_fronts
    from compare.report.statistics import budget_fronts
    from compare.run.records import Records

    rows = []
    for a_norm in (0.995, 1.05):
        for inst in INST:
            inst = dict(inst, a_norm=a_norm)
            rows += [_rec(inst, "m", 5, 1.2), _rec(inst, "lqr", 56, 1.0),
                     _rec(inst, "never", 10, float("nan"), status="infeasible"),
                     # no usable design on one panel only: named under that panel's title, as before
                     _rec(inst, "sometimes", 10, 1.3 if a_norm < 1 else float("nan"),
                          status="optimal" if a_norm < 1 else "infeasible")]
    fig, axes = plot_budget_fronts(budget_fronts(Records.from_rows(rows)))
    titles = {panel[2]: ax.get_title() for panel, ax in axes.items()}
    assert not any("never" in t for t in titles.values())
    assert "no usable design: sometimes" in titles[1.05] and "sometimes" not in titles[0.995]
    names = [t.get_text() for t in fig.legends[0].get_texts()]
    assert f"never{NOWHERE_SUFFIX}" in names and "sometimes" in names and "m" in names
    plt.close(fig)


def test_what_the_figures_cannot_show_names_a_method_without_any_usable_design_once():
    from compare.report.write import _missing_lines
    from compare.run.records import Records

    rows = [_rec(dict(inst, a_norm=a_norm), label, 10, cost, status=status)
            for a_norm in (0.995, 1.05) for inst in INST
            for label, cost, status in (("m", 1.2, "optimal"), ("never", float("nan"), "infeasible"))]
    rows += [_rec(dict(INST[0], a_norm=1.1), "once", 10, float("nan"), status="infeasible"),
             _rec(dict(INST[0], a_norm=1.1), "m", 10, 1.2)]
    records = Records.from_rows(rows)
    lines = [x for x in _missing_lines(records, aggregate(records), {}) if x.startswith("- ")]
    assert lines == ["- never has no usable design on any of its 2 panels (infeasible 6); it is absent from the "
                     "figures' panels.",
                     "- once has no usable design on N = 8, ‖A‖₂ = 1.1 (infeasible 1); it is absent there."]
