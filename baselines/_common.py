"""Small helpers shared by the baselines."""

from __future__ import annotations

from codesign.design import Timer

__all__ = ["Timer"]
