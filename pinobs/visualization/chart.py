"""The playback page's velocity chart: true against estimated velocity, under the 3-D view.

Two panels drawn on one ``<canvas>`` by plain JavaScript embedded in the page
(no library, nothing fetched): on the left one velocity coordinate (chosen
in a drop-down; the default is the one where the estimates are furthest
off), the truth as a thin black line on top of each estimate in its colour
(:mod:`pinobs.visualization.palette`); on the right ``|v̂(t) − v(t)|₂`` on a
log axis.  A cursor (a dark grey vertical line, with a dot on each curve) sits at the
animation's current time; dragging on the chart pauses the animation and
moves it there, and meshcat's own time slider moves the cursor.  A line
above the panels lists each estimate's error at the cursor, worst first.

The y-range of the velocity panel is the one of the PNG plots
(:func:`pinobs.visualization.axes.velocity_range`): the start transient of
the estimates is clipped, shaded, and said so in the panel's title.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from pinobs.evaluation import convergence_time
from pinobs.model import Robot
from pinobs.simulation import Result
from pinobs.visualization.axes import clip_start, velocity_labels, velocity_range, velocity_units
from pinobs.visualization.palette import TRUTH_LINE

__all__ = ["MAX_POINTS", "chart_data", "chart_html"]

#: At most this many samples per curve are embedded (evenly spaced in the run).
MAX_POINTS = 800


def _numbers(a: ArrayLike) -> list[float | None]:
    """4 significant digits; NaN and infinities become ``null``."""
    return [float(f"{x:.4g}") if math.isfinite(x) else None for x in np.asarray(a, float).ravel()]


def chart_data(
    result: Result, robot: Robot, observers: Sequence[str], colours: Sequence[str]
) -> dict[str, Any]:
    """What the chart draws, as plain JSON-able data.

    Args:
        result: the run.
        robot: the robot it was run on.
        observers: labels to chart.
        colours: their CSS colours (``#rrggbb``), as in the 3-D view's legend.

    Returns:
        ``t`` [s]; per velocity coordinate its label, unit, y-range and whether
        an estimate is clipped; ``start``, the time from which the estimates
        set the y-range [s]; the truth's velocities; per observer its label,
        colour, velocities and error norm ``|v̂ − v|₂``; ``err_range``, the log
        axis' range; ``joint``, the coordinate shown first.
    """
    n = result.t.size
    keep = np.unique(np.round(np.linspace(0, n - 1, min(n, MAX_POINTS))).astype(int))
    t = result.t
    # a diverged estimate may be inf or overflow (its error is then inf, drawn as no point)
    with np.errstate(invalid="ignore", over="ignore"):
        errors = {
            name: np.linalg.norm(result.trace(name).v - result.v, axis=1) for name in observers
        }
    start = clip_start(t, [convergence_time(t, errors[name]) for name in observers])
    after = t >= start
    # a diverged estimate does not set the range (it is clipped, and the legend says it diverged)
    sane = [o for o in observers if result.trace(o).diverged_at is None]
    ranges, clipped, worst = _joint_ranges(result, robot, observers, sane, start)
    err_range = _error_range(errors, after)
    units = velocity_units(robot)
    return {
        "t": _numbers(t[keep]),
        "joints": velocity_labels(robot),
        "units": units,
        "err_unit": units[0] if len(set(units)) == 1 else "rad/s and m/s mixed",
        "range": ranges,
        "clipped": clipped,
        "start": float(start),
        "joint": int(np.argmax(worst)) if worst else 0,
        "truth_colour": TRUTH_LINE,
        "truth": [_numbers(result.v[keep, i]) for i in range(robot.nv)],
        "obs": [
            {
                "name": name,
                "colour": colours[k],
                "v": [_numbers(result.trace(name).v[keep, i]) for i in range(robot.nv)],
                "err": _numbers(np.where(errors[name] > 0, errors[name], np.nan)[keep]),
            }
            for k, name in enumerate(observers)
        ],
        "err_range": err_range,
    }


def _joint_ranges(
    result: Result, robot: Robot, observers: Sequence[str], sane: list[str], start: float
) -> tuple[list[list[float]], list[bool], list[float]]:
    """Per velocity coordinate: its y-range (set by the truth and the ``sane`` estimates
    after ``start``), whether an estimate is clipped, and the worst ``sane`` estimate's
    RMS error after ``start``."""
    t = result.t
    after = t >= start
    ranges, clipped, worst = [], [], []
    for i in range(robot.nv):
        est = np.column_stack([result.trace(o).v[:, i] for o in observers] or [t * np.nan])
        lo, hi = velocity_range(t, result.v[:, i], [result.trace(o).v[:, i] for o in sane], start)
        ranges.append([lo, hi])
        # RMS error of each estimate from ``start`` on, over its finite samples (an estimate
        # NaN all along, e.g. diverged before ``start``, has none and does not count; it was
        # numpy's "Mean of empty slice")
        # the joint shown first is the worst of the estimates that did not diverge (a diverged
        # one overflowing to 1e200 made every joint's RMS inf: the first joint won)
        good = np.column_stack([result.trace(o).v[:, i] for o in sane] or [t * np.nan])
        with np.errstate(invalid="ignore", over="ignore"):
            clipped.append(bool(np.any((est < lo) | (est > hi))))
            e = good[after] - result.v[after, i][:, None]
            finite = np.isfinite(e)
            count = finite.sum(axis=0)
            square = (np.where(finite, e, 0.0) ** 2).sum(axis=0)
        has = count > 0
        worst.append(float(np.sqrt(square[has] / count[has]).max()) if has.any() else 0.0)
    return ranges, clipped, worst


def _error_range(errors: dict[str, Any], after: Any) -> list[float]:
    """The error panel's log axis: from half the smallest positive error after the start
    (or at all) to twice the largest, at most nine decades."""
    positive = np.concatenate([e[np.isfinite(e) & (e > 0)] for e in errors.values()] or [[]])
    late = np.concatenate(
        [e[after][np.isfinite(e[after]) & (e[after] > 0)] for e in errors.values()] or [[]]
    )
    if positive.size:
        hi = float(positive.max()) * 2.0
        lo = float(late.min() if late.size else positive.min()) / 2.0
        return [max(lo, hi * 1e-9), hi]
    return [1e-3, 1.0]


def chart_html(data: dict[str, Any]) -> str:
    """The chart's HTML (container, canvas, data, script); needs the page's ``viewer``."""
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    return (
        _CHART.replace("@DATA@", payload)
        .replace("@JS@", _JS)
        .replace("@TRUTH@", html.escape(data["truth_colour"]))
    )


_CHART = """<div id="pinobs-chart">
<div class="pinobs-chart-bar">
<label>velocity <select id="pinobs-joint"></select></label>
<span class="pinobs-key" id="pinobs-truth-key"><i style="background:@TRUTH@"></i>truth</span>
<span id="pinobs-readout"></span>
</div>
<canvas id="pinobs-chart-canvas"></canvas>
</div>
<script id="pinobs-chart-data" type="application/json">@DATA@</script>
<script>
@JS@
</script>
"""

_JS = r"""
(function () {
  "use strict";
  const D = JSON.parse(document.getElementById("pinobs-chart-data").textContent);
  const anim = viewer.animator;
  const canvas = document.getElementById("pinobs-chart-canvas");
  const select = document.getElementById("pinobs-joint");
  const readout = document.getElementById("pinobs-readout");
  const ctx = canvas.getContext("2d");
  const back = document.createElement("canvas");
  const CURSOR = "#444444";
  const T0 = D.t[0], T1 = D.t[D.t.length - 1], SPAN = (T1 - T0) || 1;
  let joint = D.joint, dirty = true, shown = NaN, size = "";
  D.joints.forEach(function (name, j) {
    const o = document.createElement("option");
    o.value = String(j);
    o.textContent = name + " [" + D.units[j] + "]";
    select.appendChild(o);
  });
  select.value = String(joint);
  if (!D.truth.some(function (v) { return v.some(function (x) { return x !== null; }); })) {
    document.getElementById("pinobs-truth-key").style.display = "none";  // a recorded log
  }
  select.addEventListener("change", function () {
    joint = parseInt(select.value, 10);
    dirty = true;
  });

  function layout() {
    const w = canvas.clientWidth, h = canvas.clientHeight, half = Math.floor(w / 2);
    const y0 = 18, y1 = h - 22;
    return {w: w, h: h, panels: [
      {x0: 58, x1: half - 12, y0: y0, y1: y1},
      {x0: half + 58, x1: w - 12, y0: y0, y1: y1}]};
  }
  function xOf(p, t) { return p.x0 + (t - T0) / SPAN * (p.x1 - p.x0); }
  function tOf(p, x) { return T0 + (x - p.x0) / (p.x1 - p.x0) * SPAN; }
  function yLin(p, v) {
    const r = D.range[joint];
    return p.y1 - (v - r[0]) / (r[1] - r[0]) * (p.y1 - p.y0);
  }
  const LO = Math.log10(D.err_range[0]), HI = Math.log10(D.err_range[1]);
  function yLog(p, v) { return p.y1 - (Math.log10(v) - LO) / (HI - LO) * (p.y1 - p.y0); }
  function fmt(v) {
    if (v === 0) return "0";
    const a = Math.abs(v);
    return (a >= 1e4 || a < 1e-3) ? v.toExponential(0) : String(+v.toPrecision(3));
  }
  function niceTicks(lo, hi, n) {
    const raw = (hi - lo) / n, mag = Math.pow(10, Math.floor(Math.log10(raw)));
    const step = [1, 2, 2.5, 5, 10].map(function (m) { return m * mag; })
      .find(function (s) { return s >= raw; });
    const out = [];
    for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) {
      out.push(Math.abs(v) < 1e-9 * step ? 0 : v);
    }
    return out;
  }
  function clamp(p, y) { return Math.max(p.y0, Math.min(p.y1, y)); }
  function curve(g, p, ys, yOf) {
    g.beginPath();
    let pen = false;
    for (let k = 0; k < D.t.length; k++) {
      const v = ys[k];
      if (v === null || (yOf === yLog && v <= 0)) { pen = false; continue; }
      const x = xOf(p, D.t[k]), y = clamp(p, yOf(p, v));
      if (pen) g.lineTo(x, y); else g.moveTo(x, y);
      pen = true;
    }
    g.stroke();
  }
  function axes(g, p, title, yt, yOf, label) {
    g.strokeStyle = "#e4e4e4";
    g.lineWidth = 1;
    g.fillStyle = "#333333";
    g.font = "11px system-ui, sans-serif";
    g.textAlign = "right";
    g.textBaseline = "middle";
    yt.forEach(function (v) {
      const y = Math.round(yOf(p, v)) + 0.5;
      g.beginPath(); g.moveTo(p.x0, y); g.lineTo(p.x1, y); g.stroke();
      g.fillText(label(v), p.x0 - 4, y);
    });
    g.textAlign = "center";
    g.textBaseline = "top";
    niceTicks(T0, T1, 6).forEach(function (t) {
      const x = Math.round(xOf(p, t)) + 0.5;
      g.beginPath(); g.moveTo(x, p.y0); g.lineTo(x, p.y1); g.stroke();
      if (x < p.x1 - 30) g.fillText(fmt(t), x, p.y1 + 3);  // room for the unit
    });
    g.textAlign = "right";
    g.fillText("t [s]", p.x1, p.y1 + 3);
    g.strokeStyle = "#999999";
    g.strokeRect(p.x0 + 0.5, p.y0 + 0.5, p.x1 - p.x0 - 1, p.y1 - p.y0 - 1);
    g.textAlign = "left";
    g.textBaseline = "bottom";
    g.fillText(title, p.x0, p.y0 - 3, p.x1 - p.x0);
  }
  function drawStatic(L, dpr) {
    back.width = canvas.width = Math.round(L.w * dpr);
    back.height = canvas.height = Math.round(L.h * dpr);
    const g = back.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.fillStyle = "#ffffff";
    g.fillRect(0, 0, L.w, L.h);
    const pv = L.panels[0], pe = L.panels[1];
    let title = D.joints[joint] + " [" + D.units[joint] + "]";
    if (D.clipped[joint]) {
      g.fillStyle = "#eeeeee";
      g.fillRect(pv.x0, pv.y0, xOf(pv, D.start) - pv.x0, pv.y1 - pv.y0);
      title += ", transient before " + fmt(D.start) + " s clipped (shaded)";
    }
    const r = D.range[joint];
    axes(g, pv, title, niceTicks(r[0], r[1], 4), yLin, fmt);
    const decades = [];
    const every = Math.max(1, Math.ceil((Math.floor(HI) - Math.ceil(LO) + 1) / 6));
    for (let e = Math.ceil(LO); e <= Math.floor(HI); e += every) decades.push(Math.pow(10, e));
    const known = D.obs.some(function (o) { return o.err.some(function (e) { return e !== null; }); });
    const errTitle = known ? "error |v\u0302 \u2212 v|\u2082 [" + D.err_unit + "], log scale"
      : "error: unknown (no true velocity, e.g. a recorded log)";
    axes(g, pe, errTitle, known ? decades : [], yLog,
      function (v) { return v.toExponential(0); });
    [pv, pe].forEach(function (p) {
      g.save();
      g.beginPath();
      g.rect(p.x0, p.y0, p.x1 - p.x0, p.y1 - p.y0);
      g.clip();
      g.lineJoin = "round";
      D.obs.forEach(function (o) {
        g.strokeStyle = o.colour;
        g.lineWidth = 2.2;
        if (p === pv) curve(g, p, o.v[joint], yLin); else curve(g, p, o.err, yLog);
      });
      if (p === pv) {  // the truth on top, thinner: a converged estimate shows as its rim
        g.strokeStyle = D.truth_colour;
        g.lineWidth = 1.2;
        curve(g, p, D.truth[joint], yLin);
      }
      g.restore();
    });
  }
  function nearest(t) {
    let lo = 0, hi = D.t.length - 1;
    while (hi - lo > 1) {
      const mid = (lo + hi) >> 1;
      if (D.t[mid] <= t) lo = mid; else hi = mid;
    }
    return (t - D.t[lo] <= D.t[hi] - t) ? lo : hi;
  }
  function dot(p, x, y, fill) {
    ctx.beginPath();
    ctx.arc(x, clamp(p, y), 4.5, 0, 2 * Math.PI);
    ctx.fillStyle = fill;
    ctx.fill();
    ctx.lineWidth = 1;
    ctx.strokeStyle = "#ffffff";
    ctx.stroke();
  }
  function drawCursor(L, dpr, t) {
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.drawImage(back, 0, 0);
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    const k = nearest(t), pv = L.panels[0], pe = L.panels[1];
    [pv, pe].forEach(function (p) {
      const x = Math.round(xOf(p, t));
      ctx.fillStyle = CURSOR;
      ctx.fillRect(x - 1, p.y0, 2, p.y1 - p.y0);
    });
    if (D.truth[joint][k] !== null) dot(pv, xOf(pv, t), yLin(pv, D.truth[joint][k]), D.truth_colour);
    const now = [];
    D.obs.forEach(function (o) {
      if (o.v[joint][k] !== null) dot(pv, xOf(pv, t), yLin(pv, o.v[joint][k]), o.colour);
      if (o.err[k] !== null) {
        dot(pe, xOf(pe, t), yLog(pe, o.err[k]), o.colour);
        now.push(o);
      }
    });
    now.sort(function (a, b) { return b.err[k] - a.err[k]; });
    readout.textContent = "";
    readout.appendChild(document.createTextNode(
      "at t = " + t.toFixed(2) + " s" + (now.length ? ", error (worst first): " : "")));
    now.forEach(function (o, i) {
      const s = document.createElement("span");
      s.className = "pinobs-key";
      const sw = document.createElement("i");
      sw.style.background = o.colour;
      s.appendChild(sw);
      s.appendChild(document.createTextNode(o.name + " " + fmt(o.err[k]) + (i + 1 < now.length ? " \u2265 " : "")));
      readout.appendChild(s);
    });
  }
  function now() { return T0 + (anim.actions.length ? anim.actions[0].time : 0); }
  function tick() {
    const L = layout(), dpr = window.devicePixelRatio || 1, key = L.w + "x" + L.h + "@" + dpr;
    if (key !== size) { size = key; dirty = true; }
    if (L.w > 0 && L.h > 0) {
      const t = now();
      if (dirty) { drawStatic(L, dpr); dirty = false; shown = NaN; }
      if (t !== shown) { drawCursor(L, dpr, t); shown = t; }
    }
    requestAnimationFrame(tick);
  }
  function scrub(ev) {
    const r = canvas.getBoundingClientRect(), x = ev.clientX - r.left, L = layout();
    const p = x < L.w / 2 ? L.panels[0] : L.panels[1];
    const t = Math.max(T0, Math.min(T1, tOf(p, x))) - T0;
    anim.pause();
    anim.seek(t);
    anim.display_progress(t);
  }
  canvas.addEventListener("pointerdown", function (ev) {
    canvas.setPointerCapture(ev.pointerId);
    scrub(ev);
  });
  canvas.addEventListener("pointermove", function (ev) { if (ev.buttons & 1) scrub(ev); });
  tick();
})();
"""
