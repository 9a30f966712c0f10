"""Where and with what the runs of an experiment were computed: date, commit, CPU, threads."""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
from pathlib import Path

__all__ = ["environment", "cpu_model", "git_commit"]


def cpu_model() -> str:
    """The CPU's model name (Linux /proc/cpuinfo, else the platform's processor string)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


#: What the numbers depend on in a checkout: ``+dirty`` means one of these differs from the commit
#: (regenerated reports or notebooks beside them do not).
SOURCE_PATHS = ("codesign", "baselines", "compare", "pyproject.toml")
#: The checkout's root, where SOURCE_PATHS lie, when the toolkit runs from one (compare/run/ is two below it).
CHECKOUT = Path(__file__).resolve().parents[2]


def git_commit(root: Path | None = None) -> str | None:
    """Commit of the checkout the toolkit runs from (``+dirty`` with local changes to its source), or None."""
    root = CHECKOUT if root is None else Path(root)
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                                text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no", "--",
                                *SOURCE_PATHS], capture_output=True, text=True, timeout=5, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return commit + ("+dirty" if dirty else "") if commit else None


def environment(workers: int, executor: str = "process") -> dict:
    """What a report says about the machine that computed an experiment's runs."""
    return {
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": git_commit(),
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "workers": int(workers),
        "executor": executor,
        "python": platform.python_version(),
    }
