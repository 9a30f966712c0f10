"""Checks shared by the tests of bad input and faults: a file's hash, and the one-line error of a refused command."""

import hashlib
from pathlib import Path


def file_sha(path: Path) -> str:
    """SHA-256 of a file's bytes: a store the command must leave untouched hashes the same after it."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def error_line(result) -> str:
    """The one ``Error:`` line of a refused command (exit 2, nothing else on stdout or stderr, no traceback)."""
    assert result.exit_code == 2, (result.exit_code, result.output)
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:"), result.output
    assert "Traceback" not in result.output
    return lines[0]
