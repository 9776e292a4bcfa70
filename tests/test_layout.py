"""Layout: no pinobs module reaches into another one's private names (issue 37).

What two modules share is public in one of them (``pinobs.observers.linalg`` for
the filters' linear algebra).  Checked on the source with :mod:`ast`:

* ``from pinobs.x import _y`` (and ``from . import _y``, ``from .x import _y``,
  ``from pinobs.x import _y as z``) from a module other than ``pinobs.x``;
* ``x._y`` where ``x`` is bound to another pinobs module
  (``from pinobs import x``, ``import pinobs.x as x``, ``pinobs.x._y``);
* ``import``/``from`` of a private module (``pinobs.visualization._deps``) from
  outside its package: a private module is private to the package that holds it.

A module's own private names are its business, and so is ``y as _z`` of a public
``y``.  ``pinobs._models`` is package data, not code.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pinobs

PACKAGE_DIR = Path(pinobs.__file__).parent
ALLOWED_PRIVATE_MODULES = ("pinobs._models",)


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def pinobs_modules(root: Path = PACKAGE_DIR) -> dict[str, Path]:
    """Every module and package of pinobs by dotted name."""
    return {_module_name(p, root): p for p in sorted(root.rglob("*.py"))}


def _outside_package(target: str, importer: str) -> bool:
    """Whether ``target`` has a private component whose package ``importer`` is not in."""
    if target.startswith(ALLOWED_PRIVATE_MODULES):
        return False
    parts = target.split(".")
    for i, part in enumerate(parts):
        if _private(part):
            package = ".".join(parts[:i])
            if importer != package and not importer.startswith(package + "."):
                return True
    return False


def private_imports(
    module: str, source: str, modules: set[str], *, is_package: bool = False
) -> list[tuple[int, str]]:
    """``(line, what)`` for each private name of another pinobs module that ``module`` uses."""
    tree = ast.parse(source)
    found: list[tuple[int, str]] = []
    bound: dict[str, str] = {}  # local name -> the pinobs module it stands for

    def check_module(target: str, line: int) -> None:
        if _outside_package(target, module):
            found.append((line, f"imports private module {target}"))

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] != "pinobs":
                    continue
                check_module(alias.name, node.lineno)
                if alias.asname:
                    bound[alias.asname] = alias.name
                else:
                    bound["pinobs"] = "pinobs"
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                here = module.split(".") if is_package else module.split(".")[:-1]
                base = here[: len(here) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "pinobs":
                continue
            check_module(target, node.lineno)
            for alias in node.names:
                full = f"{target}.{alias.name}"
                if full in modules:  # a submodule: private only as a module is
                    check_module(full, node.lineno)
                    bound[alias.asname or alias.name] = full
                elif _private(alias.name) and target != module:
                    found.append((node.lineno, f"imports {alias.name} from {target}"))
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Attribute) and _private(node.attr)):
            continue
        chain, value = [], node.value
        while isinstance(value, ast.Attribute):
            chain.append(value.attr)
            value = value.value
        if not isinstance(value, ast.Name) or value.id not in bound:
            continue
        owner = ".".join([bound[value.id], *reversed(chain)])
        if owner in modules and owner != module:
            found.append((node.lineno, f"uses {owner}.{node.attr}"))
    return sorted(set(found))


def test_no_module_imports_a_private_name_of_another() -> None:
    modules = pinobs_modules()
    bad = [
        f"{path.relative_to(PACKAGE_DIR.parent)}:{line}: {what}"
        for name, path in modules.items()
        for line, what in private_imports(
            name, path.read_text(encoding="utf-8"), set(modules), is_package=path.stem == "__init__"
        )
    ]
    assert not bad, "private names used across modules (make them public):\n" + "\n".join(bad)


_MODULES = {
    "pinobs",
    "pinobs.observers",
    "pinobs.observers.ekf",
    "pinobs.observers.kf",
    "pinobs.visualization",
    "pinobs.visualization._deps",
    "pinobs.visualization.plots",
    "pinobs.cli",
}


def test_the_check_finds_every_form_of_private_import() -> None:
    source = (
        "from pinobs.observers.ekf import _posv, joseph_update\n"
        "from pinobs.observers.ekf import _State as EKFState\n"
        "from .ekf import _LazyKernel\n"
        "from . import _helper\n"
        "from pinobs.observers import ekf\n"
        "import pinobs.observers.ekf as e\n"
        "import pinobs.observers.ekf\n"
        "ekf._joseph_kernel.compiled\n"
        "e._transition_kernel\n"
        "pinobs.observers.ekf._eye(3)\n"
    )
    found = private_imports("pinobs.observers.kf", source, _MODULES)
    assert found == [
        (1, "imports _posv from pinobs.observers.ekf"),
        (2, "imports _State from pinobs.observers.ekf"),
        (3, "imports _LazyKernel from pinobs.observers.ekf"),
        (4, "imports _helper from pinobs.observers"),
        (8, "uses pinobs.observers.ekf._joseph_kernel"),
        (9, "uses pinobs.observers.ekf._transition_kernel"),
        (10, "uses pinobs.observers.ekf._eye"),
    ]


def test_the_check_allows_own_names_public_aliases_and_package_private_modules() -> None:
    source = (
        "from pinobs.observers.base import median_period as _median_period\n"
        "from pinobs.visualization._deps import require\n"
        "from pinobs.visualization import _deps\n"
        "from pinobs.visualization.plots import _own\n"
        "import numpy as np\n"
        "np._private\n"
        "_deps.require\n"
    )
    assert private_imports("pinobs.visualization.plots", source, _MODULES) == []
    from_outside = "from pinobs.visualization._deps import require\n"
    assert private_imports("pinobs.cli", from_outside, _MODULES) == [
        (1, "imports private module pinobs.visualization._deps")
    ]


def test_relative_imports_of_a_package_resolve_from_the_package_itself() -> None:
    source = "from .ekf import _posv\n"
    assert private_imports("pinobs.observers", source, _MODULES, is_package=True) == [
        (1, "imports _posv from pinobs.observers.ekf")
    ]


# ------------------------------------------------------------ size (issue 37)
#: A function's length (``def`` to its last line, docstring included) and a module's.
MAX_FUNCTION_LINES, MAX_MODULE_LINES = 80, 800
#: Functions over the limit today, each with its length: they may shrink (lower the entry,
#: remove it once under the limit), never grow, and no other may join them.
LONG_FUNCTIONS: dict[tuple[str, str], int] = {
    ("pinobs/calibration.py", "identify"): 102,
    ("pinobs/model/identification/offline.py", "identify"): 134,
    ("pinobs/simulation/legged.py", "_record"): 107,
    ("pinobs/smoothing/api.py", "smooth"): 141,
}
#: Modules over the limit today, likewise.
LARGE_MODULES: dict[str, int] = {}


def _sizes() -> tuple[dict[tuple[str, str], int], dict[str, int]]:
    functions: dict[tuple[str, str], int] = {}
    modules: dict[str, int] = {}
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        rel = path.relative_to(PACKAGE_DIR.parent).as_posix()
        source = path.read_text(encoding="utf-8")
        modules[rel] = len(source.splitlines())
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                length = (node.end_lineno or node.lineno) - node.lineno + 1
                key = (rel, node.name)
                functions[key] = max(functions.get(key, 0), length)
    return functions, modules


def test_no_function_or_module_grows_past_the_limits() -> None:
    functions, modules = _sizes()
    long = {k: n for k, n in functions.items() if n > MAX_FUNCTION_LINES}
    large = {k: n for k, n in modules.items() if n > MAX_MODULE_LINES}
    grown = [
        f"{f}:{name} {n} lines (allowed {LONG_FUNCTIONS.get((f, name), MAX_FUNCTION_LINES)})"
        for (f, name), n in long.items()
        if n > LONG_FUNCTIONS.get((f, name), MAX_FUNCTION_LINES)
    ] + [
        f"{f} {n} lines (allowed {LARGE_MODULES.get(f, MAX_MODULE_LINES)})"
        for f, n in large.items()
        if n > LARGE_MODULES.get(f, MAX_MODULE_LINES)
    ]
    assert not grown, "split these along their seams:\n" + "\n".join(grown)
    stale = [
        f"{f}:{n}" for (f, n) in LONG_FUNCTIONS if functions.get((f, n), 0) <= MAX_FUNCTION_LINES
    ]
    stale += [f for f in LARGE_MODULES if modules.get(f, 0) <= MAX_MODULE_LINES]
    assert not stale, "under the limit now: remove from the allow-lists:\n" + "\n".join(stale)
