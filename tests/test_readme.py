"""The README says what the code does: its tables come from the registries, its example runs."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

from pinobs.cli import observer_table

README = Path(__file__).resolve().parents[1] / "README.md"


def _text() -> str:
    return README.read_text()


def test_observer_table_is_generated_from_the_registry() -> None:
    m = re.search(r"<!-- observer-table.*?-->\n(.*?)\n<!-- end observer-table -->", _text(), re.S)
    assert m is not None
    assert m.group(1) == observer_table(), "regenerate with pinobs.cli.observer_table()"


def test_usage_example_runs_and_prints_what_the_readme_shows() -> None:
    m = re.search(
        r"## Usage\n\n```python\n(.*?)```\n\nprints[^\n]*\n\n```text\n(.*?)```", _text(), re.S
    )
    assert m is not None
    code, shown = m.groups()
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "README-usage", "exec"), {})
    assert out.getvalue() == shown


def test_readme_states_the_two_commands_and_ci_runs_the_test_command() -> None:
    text = _text()
    assert "pip install -e . && pinobs demo" in text
    test_cmd = 'pip install -e ".[test]" && python -m pytest'
    assert test_cmd in text
    ci = (README.parent / ".ci" / "run").read_text()
    assert test_cmd in ci


def test_readme_benchmark_section_is_the_committed_results_file() -> None:
    m = re.search(r"<!-- bench: benchmarks/results.md -->\n(.*?)<!-- end bench -->", _text(), re.S)
    assert m is not None
    results = (README.parent / "benchmarks" / "results.md").read_text()
    assert m.group(1) == results, "paste benchmarks/results.md into the README's benchmark section"


def test_readme_learning_section_is_the_committed_results_file() -> None:
    m = re.search(
        r"<!-- learning: benchmarks/learning.md -->\n(.*?)<!-- end learning -->", _text(), re.S
    )
    assert m is not None
    results = (README.parent / "benchmarks" / "learning.md").read_text()
    assert m.group(1) == results, "paste benchmarks/learning.md into the README's learning section"


def test_readme_python_that_starts_a_local_dask_cluster_guards_main() -> None:
    """Found by a sweep: the README's many-logs one-liner, pasted into a script, failed
    (Dask starts its local workers as new processes that import the script)."""
    blocks = re.findall(r"```python\n(.*?)```", _text(), re.S)
    local = [
        b
        for b in blocks
        if re.search(r"\b(estimate_logs|sweep)\(", b) and not re.search(r"scheduler=|workers=0", b)
    ]
    assert local, "the README shows estimate_logs on a local cluster"
    for block in local:
        assert 'if __name__ == "__main__":' in block, block
