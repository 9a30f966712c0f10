"""The report header's commit: ``+dirty`` only for changes to the source, not to generated files."""

import shutil
import subprocess
from pathlib import Path

import pytest

from compare.run.environment import CHECKOUT, SOURCE_PATHS, git_commit


@pytest.mark.skipif(shutil.which("git") is None, reason="needs git")
def test_dirty_means_changed_source_not_regenerated_reports(tmp_path):
    def git(*args):
        subprocess.run(["git", "-C", str(tmp_path), *args], check=True, capture_output=True)

    git("init", "-q")
    (tmp_path / "codesign").mkdir()
    (tmp_path / "reports").mkdir()
    (tmp_path / "codesign" / "x.py").write_text("a = 1\n")
    (tmp_path / "reports" / "report.md").write_text("old\n")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "init")
    clean = git_commit(tmp_path)
    assert clean and not clean.endswith("+dirty")
    (tmp_path / "reports" / "report.md").write_text("regenerated\n")
    assert git_commit(tmp_path) == clean
    (tmp_path / "codesign" / "x.py").write_text("a = 2\n")
    assert git_commit(tmp_path) == clean + "+dirty"
    assert git_commit(tmp_path / "nowhere") is None


def test_the_default_root_is_the_checkout():
    assert CHECKOUT == Path(__file__).resolve().parents[1]
    assert all((CHECKOUT / name).exists() for name in SOURCE_PATHS)
