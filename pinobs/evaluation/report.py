"""Plain-text tables of :class:`~pinobs.evaluation.Metrics` (what the CLI prints)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from pinobs.evaluation.metrics import Metrics

__all__ = ["format_table"]

_HEADER = (
    "observer",
    "rms v err [rad/s]",
    "max v err [rad/s]",
    "rms q err [rad]",
    "t_conv [s]",
    "update [us]",
    "x aba",
)


def _num(x: float, fmt: str) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if math.isinf(x):
        return "inf"
    return format(x, fmt)


def format_table(
    metrics: Sequence[Metrics], *, aba_seconds: float | None = None, title: str = ""
) -> str:
    """A fixed-width table, one row per observer; ``x aba`` is ``time_per_update / aba_seconds``.

    A footnote says what the time is: the mean inside the run's loop, where
    the observers interleave (each evicts the others from the caches), not
    the observer's own cost, which ``pinobs bench`` measures.
    """
    rows = []
    for m in metrics:
        name = (
            m.observer
            if m.diverged_at is None
            else f"{m.observer} (diverged {m.diverged_at:.3g} s)"
        )
        ratio = m.time_per_update / aba_seconds if aba_seconds else math.nan
        rows.append(
            (
                name,
                _num(m.rms_v_error, ".3e"),
                _num(m.max_v_error, ".3e"),
                _num(m.rms_q_error, ".3e"),
                _num(m.convergence_time, ".3f"),
                _num(m.time_per_update * 1e6, ".1f"),
                _num(ratio, ".1f"),
            )
        )
    widths = [max([len(h), *(len(r[i]) for r in rows)]) for i, h in enumerate(_HEADER)]
    lines = []
    if title:
        lines.append(title)
    lines.append(
        "  ".join(
            h.ljust(w) if i == 0 else h.rjust(w)
            for i, (h, w) in enumerate(zip(_HEADER, widths, strict=True))
        )
    )
    lines.append("  ".join("-" * w for w in widths))
    for r in rows:
        lines.append(
            "  ".join(
                c.ljust(w) if i == 0 else c.rjust(w)
                for i, (c, w) in enumerate(zip(r, widths, strict=True))
            )
        )
    if len(rows) > 1:
        lines.append(
            f"(update: mean time inside this run's loop, {len(rows)} observers interleaved; "
            "each observer's own cost is in `pinobs bench`)"
        )
    return "\n".join(lines)
