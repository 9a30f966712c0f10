"""The interactive report page (compare.report.html, compare.report.interactive), checked in a real headless Chromium.

The page-building checks run everywhere; the browser checks skip, saying so, where
Playwright or a Chromium is missing.
"""

from __future__ import annotations

import os
import shutil

import pytest

pytest.importorskip("plotly", reason="plotly is not installed")

from compare.report.cost_links import aggregate  # noqa: E402
from compare.report.figures import BOUNDARY_LABEL, OFF_SCALE  # noqa: E402
from compare.report.html import PLOTLY_JS, render_html, write_plotly_js  # noqa: E402
from compare.report.interactive import KINDS, budget_fronts_figure, cost_links_figure, figure_div  # noqa: E402
from compare.run.records import Records, canonical_key  # noqa: E402
from compare.report.write import plant_links  # noqa: E402
from compare.report.statistics import budget_fronts  # noqa: E402
from compare.report.styles import label_styles  # noqa: E402

# A 1x1 PNG, enough for the static figure files the page links to.
_PNG = bytes.fromhex("89504e470d0a1a0a0000000d4948445200000001000000010806000000"
                     "1f15c4890000000d49444154789c63f8ffff3f0005fe02fea7d6a4c70000000049454e44ae426082")
_PANELS = ((20, 0.995), (30, 1.05))
_SEEDS = (0, 1, 2)
_LONG_ROWS = 20


def _row(spec, method, label, params, cost, links, info, idx, status="optimal"):
    stderr = None if cost is None else 0.01 * cost
    return {"run_key": f"{method}-{canonical_key(spec)}", "idx": idx, "experiment": "browser", "instance": spec,
            "method": method, "label": label, "params": params, "cost": cost, "cost_stderr": stderr,
            "cost_kind": "exact", "links": links, "self_loops": spec["n"], "info_model": info, "status": status,
            "message": None, "seconds": 0.1, "controller_kind": "static", "extras": {}, "fingerprint": "f"}


def synthetic_records(far: bool = False) -> Records:
    """Two panels, three seeds, four methods: LQR, a γ path, a β path (delayed), decentralized; one failure.

    ``far``: and an autonomous design costing 1e10 × LQR on the first instance.
    """
    rows, facts = [], {}
    for n, a_norm in _PANELS:
        for seed in _SEEDS:
            spec = {"family": "paper", "n": n, "a_norm": a_norm, "seed": seed}
            facts[canonical_key(spec)] = {"n": n, "plant_links": 5 * n, "comm_links": 5 * n}
            full = n * (n - 1)
            rows.append(_row(spec, "lqr", "LQR", {}, 1.0, full, "instantaneous", 0))
            for i, gamma in enumerate((0.01, 0.1, 1.0, 10.0)):
                rows.append(_row(spec, "sparse_admm", "sparse ADMM", {"gamma": gamma, "rho": 1.0},
                                 1.0 + 0.05 * i + 0.01 * seed, full // (3 ** i), "instantaneous", i))
            for i, beta in enumerate((0.1, 1.0, 3.0)):
                rows.append(_row(spec, "grnn_sparse", "GRNN sparse", {"beta": beta, "activation": "tanh"},
                                 1.02 + 0.08 * i, 4 * n // (i + 1), "delayed", i))
            rows.append(_row(spec, "decentralized", "decentralized", {}, 1.6 + 0.1 * seed, 0, "none", 0))
            rows.append(_row(spec, "grnn_sparse", "GRNN sparse", {"beta": 9.0, "activation": "tanh"},
                             None, None, "delayed", 9, status="error"))
            if far and not rows[0]["idx"] and len(facts) == 1:
                rows.append(_row(spec, "autonomous", "autonomous", {}, 1e10, 0, "none", 0))
    return Records.from_rows(rows, facts=facts)


def _markdown() -> str:
    rows = [f"| {i} | {1 + i / 100:.2f} |" for i in range(_LONG_ROWS)]
    long_table = "\n".join(["| run | cost |", "|---|---|", *rows])
    return "\n".join([
        "# Browser test report", "", "Synthetic designs.", "",
        "## Cost versus links", "", "![cost versus links](cost_vs_links.png)", "",
        "## Budget fronts", "", "![budget fronts](budget_fronts.png)", "",
        "## Tables", "", "### Short table", "", "| a | b |", "|---|---|", "| 1 | 2 |", "",
        "### Every run", "", long_table, "",
    ])


def build_report(folder) -> tuple:
    """Write the page, its static figure files and plotly.min.js into ``folder``; (page path, records, divs)."""
    records = synthetic_records()
    styles = label_styles(records)
    boundaries = plant_links(records)
    fronts = budget_fronts_figure(budget_fronts(records), styles, boundaries=boundaries)
    divs = {"cost_vs_links.png": figure_div(cost_links_figure(records, styles, boundaries=boundaries),
                                            "fig-cost-links"),
            "budget_fronts.png": figure_div(fronts, "fig-budget-fronts")}
    for stem in ("cost_vs_links", "budget_fronts"):
        (folder / f"{stem}.png").write_bytes(_PNG)
        (folder / f"{stem}.svg").write_text('<svg xmlns="http://www.w3.org/2000/svg"/>')
    write_plotly_js(folder)
    page = folder / "report.html"
    page.write_text(render_html(_markdown(), folder, "Browser test", divs))
    return page, records, divs


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    return build_report(tmp_path_factory.mktemp("report"))


# --- the page, without a browser -------------------------------------------------------------------------------


def test_page_structure(report):
    page, _, _ = report
    text = page.read_text()
    assert text.count(f'<script src="{PLOTLY_JS}"') == 1
    assert 'id="fig-cost-links"' in text and 'id="fig-budget-fronts"' in text
    assert "static figure:" in text and 'href="cost_vs_links.svg"' in text
    assert "<img" not in text  # both images were interactive
    assert f"table ({_LONG_ROWS} rows)" in text and text.count("<details>") == 1
    assert 'href="#cost-versus-links"' in text and 'href="#every-run"' in text


def test_no_script_without_interactive_figures(tmp_path):
    (tmp_path / "cost_vs_links.png").write_bytes(_PNG)
    text = render_html(_markdown(), tmp_path, "static")
    assert PLOTLY_JS not in text
    assert "data:image/png;base64," in text  # the PNG inlined, as before


def test_figure_named_like_a_heading_is_refused(tmp_path):
    records = synthetic_records()
    div = figure_div(cost_links_figure(records, label_styles(records)), "budget-fronts")
    with pytest.raises(ValueError, match="budget-fronts"):
        render_html(_markdown(), tmp_path, "clash", {"cost_vs_links.png": div})


def test_plotly_js_and_divs_are_deterministic(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    assert write_plotly_js(a).read_bytes() == write_plotly_js(b).read_bytes()
    records = synthetic_records()
    styles = label_styles(records)
    assert figure_div(cost_links_figure(records, styles), "x") == figure_div(cost_links_figure(records, styles), "x")


def test_figure_traces():
    records = synthetic_records()
    styles = label_styles(records)
    fig = cost_links_figure(records, styles, boundaries=plant_links(records))
    labels = {"LQR", "sparse ADMM", "GRNN sparse", "decentralized"}
    legend = [t.name for t in fig.data if t.showlegend]
    assert sorted(legend) == sorted(labels | {BOUNDARY_LABEL})  # one legend entry per label, not per panel
    assert all(t.meta["kind"] in KINDS for t in fig.data)
    designs = [t for t in fig.data if t.meta["kind"] == "designs"]
    assert sum(len(t.x) for t in designs) == sum(r.ok for r in records)  # the failed designs are not drawn
    assert fig.layout.meta["x_per_node"] and fig.layout.meta["x_offset"] == 0.1  # two N: links per node + 0.1
    assert min(min(t.x) for t in designs) == 0.1  # 0 links at x = 0 + 0.1, visible on the log axis
    settings = [t for t in fig.data if t.meta["kind"] == "setting"]
    assert settings and all(t.legendgroup in labels and not t.showlegend and t.mode == "markers" for t in settings)
    hover = next(t for t in fig.data if t.name == "sparse ADMM").text[0]
    assert "gamma = " in hover and "rho" not in hover and "seed 0" in hover and "±" in hover
    for t in designs:
        assert t.marker.color == styles[t.name].colour
    delayed = next(t for t in fig.data if t.meta["kind"] == "front" and t.name == "GRNN sparse")
    assert delayed.line.dash == "dash" and delayed.line.shape == "hv"
    fronts = budget_fronts_figure(budget_fronts(records), styles, boundaries=plant_links(records))
    drawn = [v for t in fronts.data for v in t.y if v is not None]
    assert drawn and all(v < float("inf") for v in drawn)
    delayed = next(t for t in fronts.data if t.name == "GRNN sparse" and t.meta["kind"] == "front")
    assert delayed.line.dash == "dash" and delayed.line.shape == "hv"
    assert {t.meta["kind"] for t in fronts.data} == {"front", "band", "boundary"}


def _links_costs(fig, kind):
    """(panel, label) -> sorted [(links, excess)] of the traces of ``kind``, read back from the plotly JSON alone."""
    data = fig.to_plotly_json()
    meta = data["layout"]["meta"]
    out = {}
    for t in data["data"]:
        if t["meta"]["kind"] != kind:
            continue
        panel = tuple(t["meta"]["panel"])
        scale = panel[1] if meta["x_per_node"] else 1
        out.setdefault((panel, t["meta"]["label"]), []).extend(
            (round((x - meta["x_offset"]) * scale, 6), y) for x, y in zip(t["x"], t["y"]))
    return {k: sorted(v, key=lambda p: (p[0], float("inf") if p[1] is None else p[1])) for k, v in out.items()}


def test_links_and_costs_come_back_from_the_plotly_json():
    """The contract of compare.report.interactive's docstring: x = links (per node) + offset, y = excess cost (floored)."""
    records = synthetic_records()
    styles = label_styles(records)
    fig = cost_links_figure(records, styles, boundaries=plant_links(records))
    floors = {tuple(p["panel"]): p["floor"] for p in fig.layout.meta["panels"]}
    designs = _links_costs(fig, "designs")
    for (panel, label), rs in records.filter(lambda r: r.ok).by_panel_label.items():
        want = sorted((float(r.links), max(r.cost - 1.0, floors[panel])) for r in rs)
        got = designs[(panel, label)]
        assert [x for x, _ in got] == [x for x, _ in want]
        assert all(abs(a[1] - b[1]) < 1e-12 for a, b in zip(got, want))
    settings = _links_costs(fig, "setting")
    for p in aggregate(records):
        if p.reached and p.cost[1] <= OFF_SCALE:
            assert (float(p.x), max(p.cost[1] - 1.0, floors[p.panel])) in settings[(p.panel, p.label)]
    fronts = _links_costs(fig, "front")
    for f in budget_fronts(records):
        got = dict(fronts[(f.panel, f.label)])
        for b, med in zip(f.budgets, f.cost[1]):
            assert got[float(b)] == (None if med == float("inf") else max(med - 1.0, floors[f.panel]))
    boundaries = plant_links(records)
    lines = _links_costs(fig, "boundary")
    assert {panel for panel, _ in lines} == set(boundaries)
    for (panel, label), xy in lines.items():
        assert label == BOUNDARY_LABEL and {x for x, _ in xy} == {boundaries[panel]}


def test_cost_axes_are_clipped_as_the_static_ones():
    """No axis runs to what lies far above LQR: the top is set by what is drawn at or below OFF_SCALE, and
    what lies above is an off-scale triangle on the top edge holding its value."""
    records = synthetic_records(far=True)
    styles = label_styles(records)
    for fig in (cost_links_figure(records, styles), budget_fronts_figure(budget_fronts(records), styles)):
        for p in fig.layout.meta["panels"]:
            axis = fig.layout[p["yaxis"]]
            assert axis.type == "log" and axis.autorange in (None, False)
            assert 10 ** axis.range[1] <= (OFF_SCALE - 1.0) * 1.3 * 1.0001 and p["top"] <= (OFF_SCALE - 1.0) * 1.3
        up = [t for t in fig.data if t.meta["kind"] == "off-scale" and t.meta["label"] == "autonomous"]
        assert len(up) == 1 and list(up[0].customdata) == pytest.approx([1e10 - 1.0] * len(up[0].x))
        panel = next(p for p in fig.layout.meta["panels"] if p["panel"] == up[0].meta["panel"])
        assert set(up[0].y) == {panel["top"]}
        # The value: written above the plot in the cost figure, in the panel's notes (as the static title has it)
        # in the budget fronts, whose triangle stands for a whole front.
        assert "J = 1e+10" in up[0].text or any("autonomous (1e+10)" in n for n in panel["notes"])
        # Nothing is drawn twice: no line of a front above OFF_SCALE on the axis, and no axis beyond the clip.
        for t in fig.data:
            if t.meta["kind"] == "front" and t.meta["label"] == "autonomous":
                assert all(y is None for y in t.y)


def test_the_page_holds_the_figures_json(report):
    """Where plotly's own HTML has it: ``Plotly.newPlot("<div id>", data, layout, ...)``, the figure's traces
    (their meta included) and its layout.meta, read back with nothing but a JSON decoder."""
    import json
    import re

    page, records, _ = report
    text = page.read_text()
    decoder = json.JSONDecoder()
    found = {}
    for match in re.finditer(r'Plotly\.newPlot\(\s*"([^"]+)",\s*', text):
        data, end = decoder.raw_decode(text, match.end())
        layout, _ = decoder.raw_decode(text[end:].lstrip()[1:].lstrip())
        found[match.group(1)] = (data, layout)
    assert set(found) == {"fig-cost-links", "fig-budget-fronts"}
    fig = cost_links_figure(records, label_styles(records), boundaries=plant_links(records))
    data, layout = found["fig-cost-links"]
    assert [t["meta"] for t in data] == [t.meta for t in fig.data]
    assert [t["x"] for t in data] == [list(t.x) for t in fig.data]
    assert layout["meta"] == json.loads(json.dumps(fig.layout.meta))
    assert "template" not in layout


def test_figure_html_does_not_depend_on_the_json_engine(monkeypatch):
    """The same bytes with plotly's json engine, with orjson (where installed), and with plotly's engine gone."""
    import plotly.io as pio

    records = synthetic_records()
    styles = label_styles(records)
    fig = cost_links_figure(records, styles, boundaries=plant_links(records))
    monkeypatch.setattr(pio.json.config, "_default_engine", "json")
    reference = figure_div(fig, "x")
    assert "\\u2264" not in reference and "≤" in reference  # the characters themselves, not escapes
    try:
        import orjson  # noqa: F401  (plotly's engine where it is installed)
    except ImportError:
        pass
    else:
        monkeypatch.setattr(pio.json.config, "_default_engine", "orjson")
        assert figure_div(fig, "x") == reference

    def refuse(*args, **kwargs):
        raise AssertionError("figure_div used plotly's JSON engine")

    monkeypatch.setattr("plotly.io._json.to_json_plotly", refuse)
    monkeypatch.setattr("plotly.io.json.to_json_plotly", refuse)
    assert figure_div(fig, "x") == reference
    script = reference.split("Plotly.newPlot(")[1]
    assert script.index("</script>") == len(script) - len("</script>\n</div>")  # no "</" inside the JSON


# --- the page in Chromium ---------------------------------------------------------------------------------------


def _browser_path() -> str | None:
    env = os.environ.get("CHROMIUM_PATH")
    if env and os.path.isfile(env):
        return env
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if found := shutil.which(name):
            return found
    return None


@pytest.fixture(scope="module")
def page(report):
    sync_api = pytest.importorskip("playwright.sync_api",
                                   reason="playwright is not installed: the browser test did not run")
    executable = _browser_path()
    if executable is None:
        pytest.skip("no Chromium found (chromium, chromium-browser, google-chrome or $CHROMIUM_PATH): "
                    "the browser test did not run")
    path, _, _ = report
    problems: list[str] = []
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=["--no-sandbox"])
        tab = browser.new_page(viewport={"width": 1300, "height": 900})
        tab.on("console", lambda m: problems.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
        tab.on("pageerror", lambda e: problems.append(f"page error: {e}"))
        tab.on("requestfailed", lambda r: problems.append(f"failed request: {r.url}"))
        tab.goto(path.as_uri())
        tab.wait_for_function("Array.from(document.querySelectorAll('.cl-plot'))"
                              ".every(d => d.querySelector('.main-svg'))")
        yield tab, problems
        browser.close()


_DATA = "Array.from(document.querySelectorAll('#{div} .cl-plot')).flatMap(d => d.data)"


def _points(tab, div: str) -> int:
    """Marker and line points drawn in every panel plot of figure ``div``."""
    return tab.evaluate(f"document.querySelectorAll('#{div} .cl-plot .scatterlayer .trace .points path').length")


def test_page_loads_cleanly(page):
    tab, problems = page
    assert problems == []
    assert tab.evaluate("typeof Plotly") == "object"


def test_every_figure_drew(page):
    tab, _ = page
    ids = tab.evaluate("Array.from(document.querySelectorAll('.cl-figure')).map(d => d.id)")
    assert sorted(ids) == ["fig-budget-fronts", "fig-cost-links"]
    for div in ids:
        plots = tab.evaluate(f"document.querySelectorAll('#{div} .cl-plot.js-plotly-plot').length")
        assert plots == len(_PANELS)  # one plotly plot per panel
        assert tab.evaluate(f"document.querySelectorAll('#{div} .scatterlayer .trace').length") > 0
        kinds = tab.evaluate(f"Array.from(new Set({_DATA.format(div=div)}.map(t => t.meta.kind)))")
        assert set(kinds) <= set(KINDS) and "front" in kinds
    drawn = tab.evaluate(f"{_DATA.format(div='fig-cost-links')}.filter(t => t.mode === 'markers')"
                         ".reduce((n, t) => n + t.x.length, 0)")
    assert _points(tab, "fig-cost-links") >= drawn > sum(r.ok for r in synthetic_records())  # designs + medians


def test_toc_and_collapsed_table(page):
    tab, _ = page
    hrefs = tab.evaluate("Array.from(document.querySelectorAll('nav.toc a')).map(a => a.getAttribute('href'))")
    assert {"#cost-versus-links", "#budget-fronts", "#every-run"} <= set(hrefs)
    for href in hrefs:
        assert tab.locator(f"[id='{href[1:]}']").count() == 1  # every entry has its heading
    assert tab.evaluate("document.querySelectorAll('details').length") == 1
    assert tab.evaluate("document.querySelector('details').open") is False
    assert not tab.locator("details table").is_visible()
    assert tab.locator("table").first.is_visible()  # the short table is open


def test_legend_click_hides_a_method_everywhere(page):
    tab, _ = page
    label = "sparse ADMM"
    data = _DATA.format(div="fig-cost-links")
    before = _points(tab, "fig-cost-links")
    key = tab.locator("#fig-cost-links .cl-key").filter(has_text=label)
    assert key.count() == 1
    key.click()
    tab.wait_for_function(f"l => {data}.filter(t => t.legendgroup === l).every(t => t.visible === 'legendonly')",
                          arg=label)
    assert key.get_attribute("aria-pressed") == "false"
    group = tab.evaluate(f"l => {data}.filter(t => t.legendgroup === l && t.mode !== 'lines')"
                         ".reduce((n, t) => n + t.x.length, 0)", label)
    panels = tab.evaluate(f"l => new Set({data}.filter(t => t.legendgroup === l).map(t => t.meta.panel.join())).size",
                          label)
    assert panels == len(_PANELS)  # hidden in every panel
    others = tab.evaluate(f"l => {data}.filter(t => t.legendgroup !== l && t.visible === 'legendonly').length", label)
    assert others == 0
    after = _points(tab, "fig-cost-links")
    assert before - after >= group > 4 * len(_PANELS) * len(_SEEDS)  # its designs and its medians
    key.click()  # and back
    tab.wait_for_function(f"l => {data}.filter(t => t.legendgroup === l).every(t => t.visible === true)", arg=label)
    assert _points(tab, "fig-cost-links") == before


def test_scale_buttons_switch_the_cost_axis_and_keep_the_clip(page):
    tab, _ = page
    for div in ("fig-cost-links", "fig-budget-fronts"):
        plots = f"Array.from(document.querySelectorAll('#{div} .cl-plot'))"
        tops = tab.evaluate(f"{plots}.map(d => d.layout.meta.top)")
        tab.locator(f"#{div} .cl-scale button[data-scale='linear']").click()
        tab.wait_for_function(f"{plots}.every(d => d.layout.yaxis.type === 'linear')")
        ranges = tab.evaluate(f"{plots}.map(d => d._fullLayout.yaxis.range)")
        assert [r[1] for r in ranges] == pytest.approx(tops)  # still clipped, not autorange
        tab.locator(f"#{div} .cl-scale button[data-scale='log']").click()
        tab.wait_for_function(f"{plots}.every(d => d.layout.yaxis.type === 'log')")
        ranges = tab.evaluate(f"{plots}.map(d => d._fullLayout.yaxis.range)")
        assert [10 ** r[1] for r in ranges] == pytest.approx(tops, rel=1e-4)
