"""`compare --help` and `compare methods` stay instant: no heavy package loads until a command needs it.

Checked by what a fresh interpreter has loaded (sys.modules, which a module bound by
``lazy_import`` but never used does not enter), not by timing.
"""

import json
import subprocess
import sys

import pytest

HEAVY = ("torch", "cvxpy", "matplotlib", "scipy", "networkx", "pandas")


def _imported_after(code: str) -> list[str]:
    probe = (f"import json, sys\n{code}\n"
             f"loaded = [m for m in {HEAVY!r} if m in sys.modules]\n"
             f"print(json.dumps(sorted(loaded)))")
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.strip().splitlines()[-1])


def test_importing_the_cli_imports_no_heavy_package():
    assert _imported_after("import compare.cli") == []


@pytest.mark.parametrize("args", [["--help"], ["run", "--help"], ["report", "--help"], ["export", "--help"],
                                  ["methods", "--help"], ["presets", "--help"], ["--version"]])
def test_help_imports_no_heavy_package(args):
    code = ("from compare.cli import main\n"
            "try:\n"
            f"    main({args!r}, prog_name='compare')\n"
            "except SystemExit as exc:\n"
            "    assert exc.code in (0, None), exc.code\n")
    assert _imported_after(code) == []


def test_listing_methods_loads_no_heavy_package():
    code = ("from compare.cli import main\n"
            "try:\n"
            "    main(['methods'], prog_name='compare')\n"
            "except SystemExit as exc:\n"
            "    assert exc.code in (0, None), exc.code\n")
    assert _imported_after(code) == []


def test_a_lazily_bound_torch_loads_on_first_use():
    code = ("import codesign.learned.trainer as t\n"
            "assert 'torch' not in sys.modules\n"
            "assert t.torch_dtype('float32') is t.torch.float32\n"
            "assert 'torch' in sys.modules and t.torch.float64 is sys.modules['torch'].float64\n")
    assert _imported_after(code) == ["torch"]


def test_scipy_stats_beside_a_lazily_bound_torch_does_not_load_it():
    """Libraries that ask sys.modules whether torch is loaded (scipy's array-API checks) must not be told yes."""
    code = "import codesign.learned.trainer\nimport scipy.stats\nimport compare.report.write\n"
    assert "torch" not in _imported_after(code)


def test_run_help_lists_the_presets_with_their_run_times():
    from click.testing import CliRunner

    from compare.cli import PRESET_TIMES, _preset_names, main

    result = CliRunner().invoke(main, ["run", "--help"])
    assert result.exit_code == 0
    assert "2 cores" in result.output
    for name in _preset_names():
        assert name in result.output
    assert {"quick", "table1", "tradeoff"} <= set(PRESET_TIMES)
