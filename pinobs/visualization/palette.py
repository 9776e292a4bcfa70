"""One palette for every picture of a run: the playback's ghosts and chart, and the PNG plots.

Observer ``i`` of a run (in run order) gets ``PALETTE[i]`` everywhere.  The
first seven colours are Okabe and Ito's colour-blind-safe set (Okabe & Ito,
*Color Universal Design*, 2008; their eighth colour, black, is kept for the
truth's curves); the last three are from matplotlib's ``tab10`` (purple,
brown, olive).  Any two of the ten are at least 60 apart in RGB (0–255 per
channel, Euclidean distance); after ten the colours repeat.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["PALETTE", "TRUTH_LINE", "colour", "hex_colour"]

#: Observer colours in run order: (name, RGB in [0, 1]).
PALETTE: tuple[tuple[str, tuple[float, float, float]], ...] = tuple(
    (name, (r / 255.0, g / 255.0, b / 255.0))
    for name, (r, g, b) in (
        ("vermillion", (213, 94, 0)),  # Okabe–Ito
        ("blue", (0, 114, 178)),
        ("bluish green", (0, 158, 115)),
        ("orange", (230, 159, 0)),
        ("reddish purple", (204, 121, 167)),
        ("sky blue", (86, 180, 233)),
        ("yellow", (240, 228, 66)),
        ("purple", (148, 103, 189)),  # tab10
        ("brown", (140, 86, 75)),
        ("olive", (188, 189, 34)),
    )
)

#: Colour of the truth's curves in the plots and the playback chart (its 3-D
#: body keeps the model's own colours).
TRUTH_LINE = "#000000"


def colour(i: int) -> tuple[str, tuple[float, float, float]]:
    """Name and RGB in [0, 1] of observer ``i`` (run order; repeats after ten)."""
    return PALETTE[i % len(PALETTE)]


def hex_colour(rgb: Sequence[float]) -> str:
    """CSS ``#rrggbb`` of an RGB triple in [0, 1]."""
    return "#" + "".join(f"{round(255 * float(c)):02x}" for c in rgb[:3])
