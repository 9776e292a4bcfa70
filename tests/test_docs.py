"""The documentation site is whole: its pages exist, the benchmark pages include the
benchmarks' own files, the theory sections the code cites exist.

The site itself is built by CI (``mkdocs build --strict`` in ``.ci/run``), not here.
"""

from __future__ import annotations

import importlib
import importlib.util
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pinobs.cli import observer_table

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
SNIPPET = re.compile(r'^--8<-- "([^"]+)"$', re.M)
OLD_MATH = "shared/" + "MATH.md"  # where the theory note was, outside the repository


def _nav_pages() -> list[str]:
    text = (ROOT / "mkdocs.yml").read_text()
    nav = text[text.index("\nnav:") :]
    return re.findall(r"^\s+- (?:[^:\n]+: )?(\S+\.md)\s*$", nav, re.M)


def _included(page: Path) -> list[str]:
    return SNIPPET.findall(page.read_text())


def test_every_page_in_the_nav_exists_and_every_page_is_in_the_nav() -> None:
    nav = _nav_pages()
    assert len(nav) >= 10, nav
    assert len(set(nav)) == len(nav), "a page is listed twice in mkdocs.yml's nav"
    missing = [p for p in nav if not (DOCS / p).is_file()]
    assert not missing, f"in mkdocs.yml's nav but not under docs/: {missing}"
    pages = sorted(str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md"))
    assert sorted(nav) == pages, "every page under docs/ is in mkdocs.yml's nav"


def test_every_included_file_exists() -> None:
    for page in DOCS.rglob("*.md"):
        for target in _included(page):
            assert (ROOT / target).is_file(), f"{page.relative_to(ROOT)} includes {target}"


def test_benchmark_pages_include_every_benchmark_file() -> None:
    included = {t for page in (DOCS / "benchmarks").glob("*.md") for t in _included(page)}
    written = {f"benchmarks/{p.name}" for p in (ROOT / "benchmarks").glob("*.md")}
    assert written, "no benchmarks/*.md"
    assert written <= included, f"not on a benchmark page: {sorted(written - included)}"


def test_no_page_pastes_a_benchmark_file() -> None:
    """A results row or 'Made by' line of a benchmark file appears in no page's own text."""
    pages = {p: p.read_text() for p in DOCS.rglob("*.md")}
    for bench in (ROOT / "benchmarks").glob("*.md"):
        lines = [
            line
            for line in bench.read_text().splitlines()
            if line.startswith("Made by") or (line.startswith("|") and re.search(r"\d", line))
        ]
        assert lines, bench
        for page, text in pages.items():
            pasted = [line for line in lines if line in text]
            assert not pasted, f"{page.relative_to(ROOT)} pastes {bench.name}: {pasted[0]!r}"


def test_docs_observer_table_is_generated_from_the_registry() -> None:
    text = (DOCS / "guides" / "usage.md").read_text()
    m = re.search(r"<!-- observer-table.*?-->\n(.*?)\n<!-- end observer-table -->", text, re.S)
    assert m is not None
    assert m.group(1) == observer_table(), "regenerate with pinobs.cli.observer_table()"


def _math_sections() -> set[int]:
    text = (DOCS / "theory" / "math.md").read_text()
    return {int(n) for n in re.findall(r"^## (\d+)\. ", text, re.M)}


def test_theory_page_keeps_its_numbered_sections() -> None:
    assert _math_sections() == set(range(1, 10))


@pytest.mark.parametrize("folder", ["pinobs", "tests", "examples", "benchmarks"])
def test_math_sections_cited_in_the_code_exist(folder: str) -> None:
    sections = _math_sections()
    cite = re.compile(r"(?:MATH|docs/theory/math\.md`*) §(\d+)(?:[-–](\d+))?")
    for path in (ROOT / folder).rglob("*.py"):
        text = path.read_text()
        assert OLD_MATH not in text, f"{path}: cite docs/theory/math.md"
        for first, last in cite.findall(text):
            for n in range(int(first), int(last or first) + 1):
                assert n in sections, f"{path.relative_to(ROOT)} cites §{n}"


def test_readme_cites_the_theory_page_in_the_repository() -> None:
    text = (ROOT / "README.md").read_text()
    assert OLD_MATH not in text
    assert "docs/theory/math.md" in text


def test_no_rst_role_in_the_package_spans_a_line_or_names_a_title() -> None:
    """docs/rst_roles.py makes ``:attr:`target``` a link; a role whose target holds a line
    break or a Sphinx ``title <target>`` gave mkdocs-autorefs a reference without an
    identifier, and ``mkdocs build`` died on a ``KeyError`` (CI, session 22)."""
    role = re.compile(r":(?:py:)?(?:func|class|meth|attr|mod|data|exc|obj):`([^`]+)`")
    bad = [
        f"{path.relative_to(ROOT)}: {m.group(0)!r}"
        for path in sorted((ROOT / "pinobs").rglob("*.py"))
        for m in role.finditer(path.read_text())
        if re.search(r"\s", m.group(1))
    ]
    assert not bad, bad


def test_ci_builds_the_site_strictly() -> None:
    ci = (ROOT / ".ci" / "run").read_text()
    assert 'pip install -q -e ".[docs]" && mkdocs build --strict' in ci


def test_rst_roles_become_links_where_the_target_resolves_and_code_elsewhere(
    tmp_path: Path,
) -> None:
    griffe = pytest.importorskip("griffe", reason="the docs extra: pip install -e '.[docs]'")
    spec = importlib.util.spec_from_file_location("rst_roles", DOCS / "rst_roles.py")
    assert spec is not None and spec.loader is not None
    rst_roles = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rst_roles)
    pkg = tmp_path / "pkgx"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(
        '"""See :func:`helper`, :class:`~pkgx.Thing`, :meth:`Thing.go` and :func:`nowhere`."""\n'
        "class Thing:\n    def go(self): ...\n"
        "def helper(): ...\n"
    )
    mod = griffe.load(
        "pkgx", search_paths=[tmp_path], extensions=griffe.load_extensions(rst_roles.RstRoles())
    )
    text = mod.docstring.value
    assert '<autoref identifier="pkgx.helper" optional><code>helper</code></autoref>' in text
    assert '<autoref identifier="pkgx.Thing" optional><code>Thing</code></autoref>' in text
    assert '<autoref identifier="pkgx.Thing.go" optional><code>Thing.go</code></autoref>' in text
    assert "`nowhere`" in text
    assert ":func:" not in text and ":class:" not in text


def _cli_page_options() -> tuple[dict[str, set[str]], set[str]]:
    """The long options the command-line page's synopsis names: per command (its lines and
    their continuations), and those it says every robot-loading command takes."""
    text = (DOCS / "guides" / "cli.md").read_text()
    block = re.search(r"```text\n(.*?)```", text, re.S)
    assert block is not None
    per: dict[str, set[str]] = {}
    common: set[str] = set()
    command: str | None = None
    in_common = False
    for line in block.group(1).splitlines():
        started = re.match(r"pinobs (\w+)", line)
        if started:
            command = started.group(1)
        options = set(re.findall(r"--[a-z][a-z0-9-]*", line))
        if line.startswith("(every command") or in_common:
            common |= options
            in_common = not line.rstrip().endswith(")")
            continue
        if command is not None:
            per.setdefault(command, set()).update(options)
    return per, common


def test_command_line_page_names_every_option_of_every_command_and_no_other() -> None:
    """The page's synopsis is written by hand (it groups and explains): every option a
    parser takes is on it, under its command or in the common note, and it names none a
    parser does not take."""
    import argparse

    from pinobs.cli import _parser

    sub = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction))
    parsers = {
        name: {o for a in p._actions for o in a.option_strings if o.startswith("--")} - {"--help"}
        for name, p in sub.choices.items()
    }
    documented, common = _cli_page_options()
    assert set(documented) == set(parsers), "a command missing from docs/guides/cli.md"
    assert common <= set().union(*parsers.values()), common
    for name, options in parsers.items():
        assert options <= documented[name] | common, (name, sorted(options - documented[name]))
        assert documented[name] <= options, (name, sorted(documented[name] - options))


def test_the_worked_observer_of_the_usage_guide_converges_and_stays_on_the_truth() -> None:
    """The guide's minimal family (section **Writing an observer**) runs as printed: from
    zero velocity it converges to the constant true velocity, and started on the truth it
    stays there (noise-free samples)."""
    text = (DOCS / "guides" / "usage.md").read_text()
    section = text[text.index("### Writing an observer") :]
    block = re.search(r"^```python\n(.*?)^```", section, re.S | re.M)
    assert block is not None
    ns: dict[str, Any] = {}
    exec(compile(block.group(1), "usage.md", "exec"), ns)
    est, v_true, q0 = ns["est"], ns["v_true"], ns["q0"]
    assert np.max(np.abs(est.v - v_true)) < 1e-9
    obs = ns["AlphaBeta"](ns["robot"])
    obs.reset(0.0, q0, v_true)
    robot = ns["robot"]
    worst = 0.0
    for k in range(1, 101):
        e = obs.update(k * 1e-3, robot.integrate(q0, v_true * k * 1e-3))
        worst = max(worst, float(np.max(np.abs(e.v - v_true))))
    assert worst < 1e-10
