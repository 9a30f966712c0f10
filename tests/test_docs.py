"""Everything the repository cites lies inside it: no path outside it, and every relative link resolves."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TEXT_SUFFIXES = {".py", ".md", ".toml", ".cff", ".html", ".txt", ".cfg", ".ini", ".yml", ".yaml", ".csv", ""}
#: Names of things a user of the repository does not have.
OUTSIDE = [re.compile(p) for p in (r"\.\./shared", r"DESIGN\.md", r"/work/", r"paper\.tex")]


def _tracked_files() -> list[Path]:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    files = [ROOT / name for name in out.decode().split("\0") if name]
    return [f for f in files if f.is_file() and f.suffix in TEXT_SUFFIXES]


def test_no_file_cites_a_path_outside_the_repository():
    this = Path(__file__).resolve()
    hits = []
    for path in _tracked_files():
        if path.resolve() == this:
            continue
        text = path.read_text(errors="replace")
        for number, line in enumerate(text.splitlines(), 1):
            if any(p.search(line) for p in OUTSIDE):
                hits.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:100]}")
    assert not hits, "references outside the repository:\n" + "\n".join(hits)


def _markdown_links(path: Path):
    text = path.read_text()
    text = re.sub(r"```.*?```", "", text, flags=re.S)  # links inside code blocks are examples
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if not re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            yield target


def test_relative_links_in_the_documentation_resolve():
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    assert len(pages) >= 8, "docs/ should hold the documentation pages"
    broken = []
    for page in pages:
        for target in _markdown_links(page):
            file_part, _, anchor = target.partition("#")
            resolved = (page.parent / file_part).resolve() if file_part else page
            if not resolved.exists():
                broken.append(f"{page.relative_to(ROOT)} -> {target}")
            elif anchor and resolved.suffix == ".md":
                headings = re.findall(r"^#+\s+(.*)$", resolved.read_text(), flags=re.M)
                slugs = {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-") for h in headings}
                if anchor not in slugs:
                    broken.append(f"{page.relative_to(ROOT)} -> {target} (no such heading)")
    assert not broken, "broken links:\n" + "\n".join(broken)


def test_source_files_cite_documentation_pages_that_exist():
    cited = set()
    for path in _tracked_files():
        if path.suffix == ".py":
            cited |= set(re.findall(r"docs/([\w\-]+\.md)", path.read_text()))
    missing = sorted(name for name in cited if not (ROOT / "docs" / name).is_file())
    assert not missing, f"cited but missing: {missing}"


def test_readme_gives_two_commands_and_ci_runs_the_second():
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Two commands for a fresh machine", 1)[1].split("\n## ", 1)[0]
    commands = [block.strip() for block in re.findall(r"```bash\n(.*?)```", section, flags=re.S)]
    assert len(commands) == 2, commands
    assert commands[0].endswith("compare run") and "pytest" in commands[1]
    ci = (ROOT / ".ci" / "run").read_text()
    assert commands[1] in ci.splitlines()
