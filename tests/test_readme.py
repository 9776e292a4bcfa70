"""The README says what the code does: its tables come from the registries, its example runs."""

from __future__ import annotations

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


def test_readme_states_the_two_commands_and_ci_runs_the_test_command() -> None:
    text = _text()
    assert "pip install -e . && pinobs demo" in text
    test_cmd = 'pip install -e ".[test]" && python -m pytest'
    assert test_cmd in text
    ci = (README.parent / ".ci" / "run").read_text()
    assert test_cmd in ci


def test_readme_benchmark_table_is_a_block_of_the_committed_results_file() -> None:
    m = re.search(
        r"<!-- bench: benchmarks/results.md, ur5 gauss -->\n(.*?)<!-- end bench -->", _text(), re.S
    )
    assert m is not None
    results = (README.parent / "benchmarks" / "results.md").read_text()
    shown = m.group(1)
    assert shown.startswith("**ur5** (nv = 6), gauss")
    assert shown in results, "paste the ur5 block of benchmarks/results.md into the README"


def test_readme_is_the_front_door_and_its_links_resolve() -> None:
    """Issue 37: the README says what pinobs is, the two commands, one usage block, the
    observer table, which observer when, one benchmark table, links; the rest is in docs/."""
    text = _text()
    assert len(text.splitlines()) <= 250
    for target in re.findall(r"\]\(((?:docs|benchmarks|models)/[^)#]+)", text):
        assert (README.parent / target).exists(), target


def test_python_that_starts_a_local_dask_cluster_guards_main() -> None:
    """Found by a sweep: the README's many-logs one-liner, pasted into a script, failed
    (Dask starts its local workers as new processes that import the script).  The
    example now lives in the docs' guides."""
    texts = [_text()] + [p.read_text() for p in (README.parent / "docs").rglob("*.md")]
    blocks = [b for t in texts for b in re.findall(r"```python\n(.*?)```", t, re.S)]
    local = [
        b
        for b in blocks
        if re.search(r"\b(estimate_logs|sweep)\(", b) and not re.search(r"scheduler=|workers=0", b)
    ]
    assert local, "the docs show estimate_logs on a local cluster"
    for block in local:
        assert 'if __name__ == "__main__":' in block, block
