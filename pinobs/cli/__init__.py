"""The ``pinobs`` command: a thin shell over the library.

One module per command, each with its ``add_parser(subparsers)`` and the handler it
sets as ``func`` (:data:`COMMANDS`, in the order ``pinobs --help`` lists them); the
options several commands share are :mod:`pinobs.cli.options`, what they write and print
:mod:`pinobs.cli.output`.  ``pinobs --help`` ends with a synopsis of every command
generated from these parsers (:func:`synopsis`); ``pinobs COMMAND --help`` gives all of
a command's options.
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

__all__ = ["COMMANDS", "DEMO_GHOSTS", "Command", "main", "observer_table", "synopsis"]


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
    """``pinobs``'s parser, assembled from :data:`COMMANDS`; its epilog the synopsis."""
    parser = argparse.ArgumentParser(
        prog="pinobs",
        description="Velocity observers for any URDF robot.",
        formatter_class=argparse.RawDescriptionHelpFormatter,  # the synopsis as it is laid out
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.add_parser(sub)
    parser.epilog = synopsis(sub)
    return parser


def synopsis(subparsers: Subparsers) -> str:
    """One line per command, generated from its parser: its positional arguments and
    required options, ``[options]`` when it has others."""
    lines = ["synopsis (pinobs COMMAND --help: all of a command's options):"]
    for name, p in subparsers.choices.items():
        lines.append("  " + " ".join(["pinobs", name, *_required(p)]))
    return "\n".join(lines)


def _required(p: argparse.ArgumentParser) -> list[str]:
    """What a command line of ``p`` must hold, in the parser's order; ``[options]`` last
    when ``p`` takes others."""
    grouped = {id(a): g for g in p._mutually_exclusive_groups for a in g._group_actions}
    words: list[str] = []
    optional = False
    for action in p._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        group = grouped.get(id(action))
        if group is not None and group.required:
            if action is group._group_actions[0]:
                words.append("(" + " | ".join(_word(a) for a in group._group_actions) + ")")
        elif not action.option_strings or action.required:
            words.append(_word(action))
        else:
            optional = True
    return [*words, "[options]"] if optional else words


def _word(action: argparse.Action) -> str:
    """``--flag METAVAR`` (or a positional's metavar) as the usage writes it."""
    if action.metavar is not None:
        metavar = str(action.metavar)
    elif action.choices is not None:
        metavar = "{" + ",".join(map(str, action.choices)) + "}"
    else:
        metavar = action.dest.upper() if action.option_strings else action.dest
    if not action.option_strings:
        return metavar
    return action.option_strings[0] + ("" if action.nargs == 0 else " " + metavar)


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
