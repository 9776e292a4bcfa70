"""Griffe extension for the API pages: the docstrings' reST roles as links.

The docstrings are Google style but cite other objects the Sphinx way,
``:func:`read_log``` or ``:class:`~pinobs.errors.NoiseWarning```, which Markdown
shows as ``:func:`` followed by code.  Before mkdocstrings renders a docstring,
each role becomes a mkdocs-autorefs reference to the object it names, resolved
in the docstring's scope as Python would (its class, its module, the module's
imports).  The reference is optional: a target without a page of its own (a
private helper, a submodule the reference does not render) is shown as plain
code, without a link and without a warning.  ``~`` shows the last component,
as in Sphinx.  Loaded by mkdocs.yml (``extensions:``); not part of the package.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:func|class|meth|attr|mod|data|exc|obj):`(~?)([^`]+)`")


class RstRoles(griffe.Extension):
    """Rewrite the roles of every docstring of a package once it is loaded."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        for obj in _objects(pkg):
            if obj.docstring is not None:
                obj.docstring.value = ROLE.sub(
                    lambda m, o=obj: _reference(o, m), obj.docstring.value
                )


def _objects(obj: griffe.Object) -> Iterator[griffe.Object]:
    yield obj
    for member in obj.members.values():
        if not member.is_alias:
            yield from _objects(member)  # type: ignore[arg-type]


def _reference(obj: griffe.Object, m: re.Match[str]) -> str:
    tilde, target = m.group(1), m.group(2).strip()
    shown = target.rsplit(".", 1)[-1] if tilde else target
    path = _resolve(obj, target)
    if path is None:
        return f"`{shown}`"
    return f'<autoref identifier="{path}" optional><code>{shown}</code></autoref>'


def _resolve(obj: griffe.Object, target: str) -> str | None:
    head, _, rest = target.partition(".")
    scope = obj if (obj.is_module or obj.is_class) else obj.parent
    for where in (scope, scope.parent if scope else None, obj.module):
        if where is None:
            continue
        try:
            return where.resolve(head) + (f".{rest}" if rest else "")
        except Exception:  # griffe's NameResolutionError, or an alias it cannot follow
            continue
    return target if head == obj.package.name else None  # a full path: pinobs.x.y
