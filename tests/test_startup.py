"""Start-up: ``import pinobs`` stays light (issue 18)."""

from __future__ import annotations

import subprocess
import sys


def test_import_pinobs_imports_no_numba_scipy_linalg_or_meshcat() -> None:
    code = (
        "import sys, pinobs; "
        "print(sorted(m for m in ('numba', 'scipy.linalg', 'meshcat', 'matplotlib') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_import_pinobs_cli_imports_no_plotting_playback_dataframes_or_dask() -> None:
    """Every command's parser is built at start-up; what a command needs beyond it is
    imported when it runs (``pinobs --help`` stays quick)."""
    heavy = ("numba", "scipy.linalg", "meshcat", "matplotlib", "pandas", "pyarrow", "dask", "rich")
    code = f"import sys, pinobs.cli; print(sorted(m for m in {heavy!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
