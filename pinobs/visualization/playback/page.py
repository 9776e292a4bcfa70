"""The standalone page: meshcat's viewer, the recorded scene commands and our overlay.

The page and legend templates are package data (``templates/*.html``,
``templates/*.js``) with ``@KEY@`` slots (:func:`fill_template`).
"""

from __future__ import annotations

import base64
import functools
import re
from importlib import resources
from pathlib import Path
from typing import Any

from pinobs.visualization._deps import require

__all__ = ["RecordingWindow", "fill_template", "viewer_js"]


class RecordingWindow:
    """Stand-in for meshcat's ``ViewerWindow``: records commands instead of sending them.

    ``meshcat.Visualizer(window=RecordingWindow(...))`` behaves like a
    visualizer connected to a server; :meth:`get_scene` (what
    ``Visualizer.static_html()`` calls) returns the standalone page with every
    recorded command replayed in order.
    """

    web_url: str | None = None

    def __init__(self, overlay: str = "") -> None:
        self.commands: list[bytes] = []
        self.overlay = overlay

    def send(self, command: Any) -> None:
        umsgpack = require("umsgpack", "meshcat playback")
        data = command.lower()
        self.commands.append(umsgpack.packb(data))

    def get_scene(self) -> str:
        script = viewer_js()
        cmds = ",\n".join(f'"{base64.b64encode(c).decode("ascii")}"' for c in self.commands)
        return fill_template("page.html", mainminjs=script, commands=cmds, overlay=self.overlay)

    def open(self) -> RecordingWindow:
        return self

    def close(self) -> None:
        return None


def viewer_js() -> str:
    """meshcat's viewer (three.js and its own code): the installed ``main.min.js``."""
    meshcat = require("meshcat", "meshcat playback")
    path = Path(str(meshcat.__file__)).parent / "viewer" / "dist" / "main.min.js"
    return path.read_text(encoding="utf-8")


_SLOT = re.compile(r"@([A-Z][A-Z0-9_]*)@")


@functools.cache
def _template(name: str) -> str:
    """The text of ``templates/<name>``, shipped as package data."""
    return (resources.files("pinobs.visualization.playback") / "templates" / name).read_text(
        encoding="utf-8"
    )


def fill_template(name: str, **values: str) -> str:
    """Template ``name`` with each slot ``@KEY@`` replaced by ``values["key"]``, in one pass
    (what a value holds is not read for slots).

    The templates: ``page.html``, the page meshcat's server builds for
    ``static_html()``, with the commands replayed synchronously (meshcat's own
    page fetches ``data:`` URLs, in no guaranteed order) and our overlay added
    (``"</script"`` cannot occur in base64 or in ``main.min.js``' string
    literals used there); ``legend.html`` and ``legend.js``, the legend overlay.
    """
    text = _template(name)
    slots = {m.lower() for m in _SLOT.findall(text)}
    if slots != set(values):
        raise KeyError(f"template {name} has slots {sorted(slots)}, given {sorted(values)}")
    return _SLOT.sub(lambda m: values[m.group(1).lower()], text)
