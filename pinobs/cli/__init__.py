"""The ``pinobs`` command: a thin shell over the library.

One module per command, each with its ``add_parser(subparsers)`` and the handler it
sets as ``func`` (:data:`COMMANDS`, in the order ``pinobs --help`` lists them); the
options several commands share are :mod:`pinobs.cli.options`, what they write and print
:mod:`pinobs.cli.output`.  ``pinobs COMMAND --help`` gives all of a command's options.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Protocol

from pinobs.cli import (
    bench,
    check,
    demo,
    estimate,
    excite,
    identify,
    list_,
    play,
    run,
    sweep,
)
from pinobs.cli.demo import DEMO_GHOSTS
from pinobs.cli.list_ import observer_table
from pinobs.errors import PinobsError, PinobsWarning

if TYPE_CHECKING:
    from pinobs.cli.options import Subparsers

__all__ = ["COMMANDS", "DEMO_GHOSTS", "Command", "main", "observer_table"]


class Command(Protocol):
    """A command module: adds its subparser, with ``func`` set to its handler."""

    def add_parser(self, subparsers: Subparsers) -> argparse.ArgumentParser: ...


#: The commands, in the order ``pinobs --help`` lists them.
COMMANDS: tuple[Command, ...] = (
    list_,
    run,
    play,
    estimate,
    check,
    identify,
    excite,
    bench,
    sweep,
    demo,
)


def _parser() -> argparse.ArgumentParser:
    """``pinobs``'s parser, assembled from :data:`COMMANDS`."""
    parser = argparse.ArgumentParser(
        prog="pinobs", description="Velocity observers for any URDF robot."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pinobs`` command; returns the exit code."""
    args = _parser().parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            return func(args)
    except PinobsError as exc:
        print(f"pinobs: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # an output the system refused (a full disk, permissions, ...)
        print(f"pinobs: error: {exc}", file=sys.stderr)
        return 1


def _show_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: Any = None,
    line: str | None = None,
) -> None:
    """A pinobs warning as ``warning: …`` (as a run's own warnings; not Python's file and
    line); others as usual."""
    if issubclass(category, PinobsWarning):
        print(f"warning: {message}", file=sys.stderr)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))
