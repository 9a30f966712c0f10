"""No shipped report holds a usable static design whose closed loop is unstable.

The rule (`codesign.status.STABILITY_TOL`, docs/methods.md): a static gain is usable only
if its closed loop's spectral radius is below 1 − STABILITY_TOL; otherwise it is recorded
``diverged``. Read from every shipped ``runs.csv``, whatever code made it. The autonomous
loop (u = 0) is the "no control" reference, reported with its finite-horizon cost on
unstable plants as the paper's Table 1 does, and is not a design.
"""

from pathlib import Path

import pytest

from codesign.status import STABILITY_TOL, USABLE
from compare.report.folder import read_folder

REPORTS = Path(__file__).resolve().parents[1] / "reports"
SHIPPED = sorted(p.name for p in REPORTS.iterdir() if (p / "runs.csv").exists())
STATIC = {"lqr", "decentralized", "sparse_admm", "sparse_newton", "sparse_sdp", "truncated_lqr", "sparse_budget",
          "best_pattern", "sparse_delayed"}


@pytest.mark.parametrize("name", SHIPPED)
def test_every_usable_static_design_of_a_shipped_report_is_stable(name):
    records = read_folder(REPORTS / name).records
    static = [r for r in records if r.method in STATIC and r.status in USABLE]
    unstable = [(r.instance.seed, r.label, r.status, r.extras.get("spectral_radius")) for r in static
                if not r.extras.get("spectral_radius", 0.0) < 1.0 - STABILITY_TOL]
    assert not unstable, f"{len(unstable)} usable static designs with an unstable loop: {unstable[:5]}"
