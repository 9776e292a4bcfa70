"""``pinobs list``: the robots and observers by name (``list_``: ``list`` is a builtin)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from pinobs.model import robot_entries
from pinobs.observers import observer_class, observer_names

if TYPE_CHECKING:
    from pinobs.cli.options import Subparsers

__all__ = ["add_parser", "handle", "observer_table"]


def add_parser(subparsers: Subparsers) -> argparse.ArgumentParser:
    """``pinobs list``."""
    p = subparsers.add_parser("list", help="list robots and observers")
    p.set_defaults(func=handle)
    return p


def handle(args: argparse.Namespace) -> int:
    """Print the robot and observer registries."""
    print("Robots (pinobs.load(name); root joint in brackets):")
    for e in robot_entries():
        print(f"  {e.name:28s} {e.description} [{e.root_joint}] ({e.origin})")
    print("\nObservers (pinobs.make_observer(name, robot, ...)):")
    for name in observer_names():
        print(f"  {name:10s} {observer_class(name).summary}")
    return 0


def observer_table() -> str:
    """The README's observer table, generated from the registry."""
    lines = ["| name | what it is |", "|---|---|"]
    lines += [f"| `{n}` | {observer_class(n).summary} |" for n in observer_names()]
    return "\n".join(lines)
