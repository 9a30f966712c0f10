"""The interactive report page (compare.html, compare.interactive), checked in a real headless Chromium.

The page-building checks run everywhere; the browser checks skip, saying so, where
Playwright or a Chromium is missing.
"""

from __future__ import annotations

import os
import shutil

import pytest

pytest.importorskip("plotly", reason="plotly is not installed")

from compare.html import PLOTLY_JS, render_html, write_plotly_js  # noqa: E402
from compare.interactive import budget_fronts_figure, cost_links_figure, figure_div  # noqa: E402
from compare.records import Records, canonical_key  # noqa: E402
from compare.statistics import budget_fronts  # noqa: E402
from compare.styles import label_styles  # noqa: E402

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


def synthetic_records() -> Records:
    """Two panels, three seeds, four methods: LQR, a γ path, a β path (delayed), decentralized; one failure."""
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
    fronts = budget_fronts_figure(budget_fronts(records), styles)
    divs = {"cost_vs_links.png": figure_div(cost_links_figure(records, styles), "fig-cost-links"),
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
    fig = cost_links_figure(records, styles)
    labels = {"LQR", "sparse ADMM", "GRNN sparse", "decentralized"}
    legend = [t.name for t in fig.data if t.showlegend]
    assert sorted(legend) == sorted(labels)  # one legend entry per label, not per panel
    designs = [t for t in fig.data if t.meta == "designs"]
    assert sum(len(t.x) for t in designs) == sum(r.ok for r in records)  # the failed designs are not drawn
    assert min(min(t.x) for t in designs) == 1.0  # 0 links at x = 0 + 1, visible on the log axis
    medians = [t for t in fig.data if t.meta == "medians"]
    assert medians and all(t.legendgroup in labels and not t.showlegend for t in medians)
    hover = next(t for t in fig.data if t.name == "sparse ADMM").text[0]
    assert "gamma = " in hover and "rho" not in hover and "seed 0" in hover and "±" in hover
    for t in designs:
        assert t.marker.color == styles[t.name].colour
    fronts = budget_fronts_figure(budget_fronts(records), styles)
    drawn = [v for t in fronts.data for v in t.y if v is not None]
    assert drawn and all(v < float("inf") for v in drawn)
    delayed = next(t for t in fronts.data if t.name == "GRNN sparse")
    assert delayed.line.dash == "dash" and delayed.line.shape == "hv"


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
        tab.wait_for_function("document.querySelectorAll('.plotly-graph-div .main-svg').length >= 2")
        yield tab, problems
        browser.close()


def _points(tab, div: str) -> int:
    return tab.evaluate(f"document.querySelectorAll('#{div} .scatterlayer .trace .points path').length")


def test_page_loads_cleanly(page):
    tab, problems = page
    assert problems == []
    assert tab.evaluate("typeof Plotly") == "object"


def test_every_figure_drew(page):
    tab, _ = page
    ids = tab.evaluate("Array.from(document.querySelectorAll('.plotly-graph-div')).map(d => d.id)")
    assert sorted(ids) == ["fig-budget-fronts", "fig-cost-links"]
    for div in ids:
        assert tab.locator(f"#{div} .main-svg").count() > 0
        assert tab.evaluate(f"document.querySelectorAll('#{div} .scatterlayer .trace').length") > 0
    drawn = tab.evaluate("document.getElementById('fig-cost-links').data.reduce((n, t) => n + t.x.length, 0)")
    assert _points(tab, "fig-cost-links") == drawn > sum(r.ok for r in synthetic_records())  # designs + medians


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
    before = _points(tab, "fig-cost-links")
    tab.locator("#fig-cost-links .legend .traces").filter(has_text=label).locator(".legendtoggle").click()
    tab.wait_for_function(
        "l => document.getElementById('fig-cost-links').data.filter(t => t.legendgroup === l)"
        ".every(t => t.visible === 'legendonly')", arg=label)
    group = tab.evaluate("l => document.getElementById('fig-cost-links').data.filter(t => t.legendgroup === l)"
                         ".reduce((n, t) => n + t.x.length, 0)", label)
    hidden = tab.evaluate("l => document.getElementById('fig-cost-links').data.filter(t => t.name === l).length", label)
    assert hidden == len(_PANELS)  # its trace in every panel
    others = tab.evaluate("l => document.getElementById('fig-cost-links').data"
                          ".filter(t => t.legendgroup !== l && t.visible === 'legendonly').length", label)
    assert others == 0
    after = _points(tab, "fig-cost-links")
    assert after == before - group and group > 4 * len(_PANELS) * len(_SEEDS)  # its designs and its medians


def test_scale_buttons_switch_the_cost_axis(page):
    tab, _ = page
    for div in ("fig-cost-links", "fig-budget-fronts"):
        initial = tab.evaluate(f"document.getElementById('{div}').layout.yaxis.type")
        other = "log" if initial == "linear" else "linear"
        tab.locator(f"#{div} .updatemenu-button").filter(has_text=f"{other} cost").click()
        tab.wait_for_function(f"document.getElementById('{div}').layout.yaxis.type === '{other}'")
        assert tab.evaluate(f"document.getElementById('{div}').layout.yaxis2.type") == other
