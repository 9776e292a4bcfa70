"""The legend of a playback: what each colour is, and when a copy has no data."""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from dataclasses import dataclass

from pinobs.visualization.playback.page import fill_template

__all__ = ["LegendEntry", "legend_html", "legend_json"]


@dataclass(frozen=True)
class LegendEntry:
    """One line of the legend.

    Attributes:
        label: observer label (or ``"truth"``).
        colour: CSS colour (``#rrggbb``) of its swatch, or ``None`` for the truth's own colours.
        colour_name: human name of the colour (``"model colours"`` for the truth).
        node: meshcat path of its scene node under ``/meshcat``.
        diverged_at: time of divergence [s], or ``None``.
        model_colours: for the truth, the CSS colours its body renders in (the
            visual model's ``meshColor``, most used first); empty for a ghost.
        gaps: stretches ``(start, end)`` [s] without a finite configuration (NaN
            rows: dropped samples, a divergence), from the first such row to the
            next finite one: the truth holds its last pose, a ghost is hidden.
    """

    label: str
    colour: str | None
    colour_name: str
    node: str
    diverged_at: float | None = None
    model_colours: tuple[str, ...] = ()
    gaps: tuple[tuple[float, float], ...] = ()

    @property
    def gap_note(self) -> str:
        """The gaps in words (empty without gaps), e.g. ``"no data 0.3–0.5 s: pose held"``."""
        if not self.gaps:
            return ""
        what = "no data" if self.colour is None else "no estimate"
        shown = "pose held" if self.colour is None else "hidden"
        a, b = self.gaps[0][0], self.gaps[-1][1]
        if self.diverged_at is not None and len(self.gaps) == 1 and a >= self.diverged_at:
            return f"hidden from {a:.3g} s"
        if len(self.gaps) == 1:
            return f"{what} {a:.3g}–{b:.3g} s: {shown}"
        lost = sum(e - s for s, e in self.gaps)
        return (
            f"{what} in {len(self.gaps)} stretches between {a:.3g} and {b:.3g} s "
            f"({lost:.3g} s in all): {shown}"
        )


def legend_html(
    title: str,
    entries: Sequence[LegendEntry],
    t0: float,
    t_end: float,
    notes: Sequence[str] = (),
) -> str:
    """The legend overlay of a page (top left; needs the page's ``viewer``): ``title``, a
    row per entry with its swatch and gaps, the ``notes``, and the animation time, from
    ``t0`` to ``t_end`` [s] (``#t=…``, ``#paused`` and ``&nolegend`` read from the URL)."""
    rows = []
    for e in entries:
        if e.colour is None:
            cs = e.model_colours or ("#cccccc",)
            stops = ",".join(
                f"{c} {100 * k / len(cs):.0f}% {100 * (k + 1) / len(cs):.0f}%"
                for k, c in enumerate(cs)
            )
            swatch = (
                '<span style="display:inline-block;width:12px;height:12px;margin-right:6px;'
                f'border:1px solid #555;background:linear-gradient(135deg,{stops})"></span>'
            )
        else:
            swatch = (
                '<span style="display:inline-block;width:12px;height:12px;margin-right:6px;'
                f'border:1px solid #555;background:{e.colour};opacity:0.8"></span>'
            )
        said = [f"diverged at {e.diverged_at:.3g} s"] if e.diverged_at is not None else []
        said += [e.gap_note] if e.gaps else []
        note = f" ({'; '.join(said)})" if said else ""
        what = "estimate"
        if e.colour is None:
            what = "true motion" if e.label == "truth" else "recorded motion"
        now = "no data now: pose held" if e.colour is None else "no estimate now: hidden"
        rows.append(
            f'<div class="pinobs-entry" data-label="{html.escape(e.label)}">{swatch}'
            f"<b>{html.escape(e.label)}</b> · {what}{html.escape(note)}"
            f'<span class="pinobs-gap" style="display:none;color:#b00"> · {now}</span></div>'
        )
    gaps = json.dumps([[[round(a, 6), round(b, 6)] for a, b in e.gaps] for e in entries])
    script = fill_template("legend.js", t0=repr(float(t0)), t_end=repr(float(t_end)), gaps=gaps)
    return fill_template(
        "legend.html",
        title=html.escape(title),
        rows="\n".join(rows),
        time=f"{float(t0):.2f}",
        notes="".join(
            f'<div class="pinobs-note" style="color:#666;font-size:11px">{html.escape(n)}</div>\n'
            for n in notes
        ),
        script=script,
    )


def legend_json(entries: Sequence[LegendEntry]) -> str:
    """The legend as JSON (label, colour, colour name, diverged_at), for scripts."""
    return json.dumps(
        [
            {
                "label": e.label,
                "colour": e.colour,
                "colour_name": e.colour_name,
                "diverged_at": e.diverged_at,
            }
            for e in entries
        ]
    )
