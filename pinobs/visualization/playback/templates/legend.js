(function () {
  const t0 = @T0@;
  const anim = viewer.animator;
  const label = document.getElementById("pinobs-time");
  // stretches without data: the entry's row says so while the time is in one
  const gaps = @GAPS@, tEnd = @T_END@;
  const rows = Array.from(document.querySelectorAll("#pinobs-legend .pinobs-entry"));
  function clipTime() {
    return anim.actions.length ? anim.actions[0].time : 0;
  }
  function applyHash() {
    const m = /[#&]t=([0-9.eE+-]+)/.exec(window.location.hash);
    if (m) {
      const t = Math.max(0, parseFloat(m[1]) - t0);
      anim.pause();
      anim.seek(t);
      anim.display_progress(t);
    } else if (/[#&]paused/.test(window.location.hash)) {
      anim.pause();
    }
  }
  function applyLegend() {
    const hide = /[#&]nolegend/.test(window.location.hash);
    document.getElementById("pinobs-legend").style.display = hide ? "none" : "block";
  }
  applyHash();
  applyLegend();
  window.addEventListener("hashchange", applyLegend);
  window.addEventListener("hashchange", applyHash);
  function tick() {
    const t = t0 + clipTime();
    label.textContent = "t = " + t.toFixed(2) + " s";
    gaps.forEach(function (g, i) {
      const now = g.some(function (ab) { return t >= ab[0] && (t < ab[1] || ab[1] >= tEnd); });
      rows[i].querySelector(".pinobs-gap").style.display = now ? "inline" : "none";
    });
    requestAnimationFrame(tick);
  }
  tick();
})();
