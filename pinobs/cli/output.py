"""What several commands write and print: output paths checked before the work, JSON,
the playback and plot (the visualization layer, imported only when asked), short
messages."""

from __future__ import annotations

import argparse
import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pinobs.cli.options import progress
from pinobs.errors import OutputExistsError, UnsupportedRobotError
from pinobs.model import Robot
from pinobs.simulation import Result

__all__ = [
    "check_output",
    "check_outputs",
    "consistency_warnings",
    "json_safe",
    "plural",
    "short_reason",
    "watch",
    "write_json",
]


def check_output(flag: str, path: str | Path, *, folder: bool = False) -> None:
    """Refuse an output path that cannot be written, before the work: a file where a
    folder is wanted or the reverse, a parent that is a file, a parent not writable."""
    path = Path(path)
    if path.is_dir() and not folder:
        raise OutputExistsError(f"{flag} {str(path)!r} is a directory; give a file name")
    if path.exists() and folder and not path.is_dir():
        raise OutputExistsError(f"{flag} {str(path)!r} is a file; give a folder")
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise OutputExistsError(
            f"{flag} {str(path)!r}: {str(parent)!r} is a file, not a folder; give another path"
        )
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputExistsError(f"{flag} {str(path)!r}: {str(parent)!r} is not writable")


def check_outputs(args: argparse.Namespace, flags: Sequence[str]) -> None:
    """The output files of ``flags`` (those given): writable, distinct, a plot's format known."""
    given = {f: getattr(args, f) for f in flags if getattr(args, f, None)}
    seen: dict[Path, str] = {}
    for flag, value in given.items():
        check_output(f"--{flag}", value)
        path = Path(value).resolve()
        if flag == "plot":
            from pinobs.visualization.plots import plot_path

            path = plot_path(path)  # .png added when no suffix; a format matplotlib lacks refused
        if path in seen:
            raise OutputExistsError(
                f"--{seen[path]} and --{flag} are the same file {value!r}; give each its own"
            )
        seen[path] = flag


def json_safe(x: Any) -> Any:
    """``x`` with non-finite floats as JSON can hold them (``None``, ``"inf"``, ``"-inf"``)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    return x


def write_json(path: str | Path, payload: Any) -> Path:
    """``payload`` as indented JSON in ``path`` (its folder made); the path written."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(json_safe(payload), indent=2, default=float) + "\n")
    return path


def watch(result: Result, robot: Robot, args: argparse.Namespace) -> None:
    """``--html`` / ``--plot`` / ``--meshcat``: the visualization layer, imported only when asked."""
    from pinobs.visualization import plot, serve, write_html

    if args.html:
        with progress(f"{robot.name}: playback", not args.no_progress) as step:
            path = write_html(result, robot, args.html, progress=step)
        print(
            f"wrote {path} (open it in a browser; Open Controls -> Animations: play, pause, time)"
        )
    if args.plot:
        print(f"wrote {plot(result, robot, args.plot)}")
    if args.meshcat:
        with serve(result, robot):
            try:
                input("meshcat is serving the playback; press Enter to stop\n")
            except (EOFError, KeyboardInterrupt):
                pass


def short_reason(exc: UnsupportedRobotError) -> str:
    """Why an observer refuses a robot, in one short clause (its message up to the first ';')."""
    reason = str(exc).split(";")[0]
    return reason if len(reason) <= 110 else reason[:107] + "..."


def consistency_warnings(reports: dict[str, Any]) -> list[str]:
    """One line per observer whose innovations say the model does not explain the data,
    and per observer that rejected outlier samples (``reports``: name -> Consistency)."""
    return [line for name, c in reports.items() if c is not None for line in c.messages(name)]


def plural(n: int, word: str) -> str:
    """``1 run``, ``2 runs``."""
    return f"{n} {word}{'' if n == 1 else 's'}"
