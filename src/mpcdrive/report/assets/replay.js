"use strict";
(function () {
  const RUNS = JSON.parse(document.getElementById("replay-data").textContent);
  if (!RUNS.length) return;
  RUNS.forEach((r) => {  // horizons: integer steps of 10^-decimals m, from the vehicle position
    const u = Math.pow(10, -r.decimals), F = r.frames;
    r.horizon = r.horizon.map((d, i) => {
      const pts = []; if (!d.length || F.x[i] === null) return pts;
      let qx = Math.round(F.x[i] / u), qy = Math.round(F.y[i] / u);
      for (let j = 0; j + 1 < d.length; j += 2) { qx += d[j]; qy += d[j + 1]; pts.push([qx * u, qy * u]); }
      return pts;
    });
  });
  const $ = (id) => document.getElementById(id);
  const view = $("view"), series = $("series"), slider = $("time-slider"), label = $("frame-label");
  const playBtn = $("play"), speedSel = $("speed"), follow = $("follow"), showHz = $("show-horizon");
  const hud = $("hud"), picker = $("experiment");
  let run = null, frame = 0, playing = false, simT = 0, lastTs = null;
  let cam = {cx: 0, cy: 0, scale: 1}, fit = null, drag = null;

  function dims(c) {
    const r = c.getBoundingClientRect(), d = window.devicePixelRatio || 1;
    const w = Math.max(50, Math.round(r.width)), h = Math.max(50, Math.round(r.height));
    if (c.width !== Math.round(w * d) || c.height !== Math.round(h * d)) { c.width = Math.round(w * d); c.height = Math.round(h * d); }
    const g = c.getContext("2d"); g.setTransform(d, 0, 0, d, 0, 0); return {g: g, w: w, h: h};
  }
  function bounds() {
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    const add = (x, y) => { if (x === null || y === null) return; if (x < x0) x0 = x; if (x > x1) x1 = x; if (y < y0) y0 = y; if (y > y1) y1 = y; };
    run.path.forEach((p) => add(p[0], p[1]));
    [run.left, run.right].forEach((b) => { if (b) b.forEach((p) => add(p[0], p[1])); });
    const F = run.frames;
    for (let i = 0; i < F.x.length; i++) add(F.x[i], F.y[i]);
    for (const o of run.obstacles) {
      if (o.type === "circle") (Array.isArray(o.c[0]) ? o.c : [o.c]).forEach((c) => { add(c[0] - o.r, c[1] - o.r); add(c[0] + o.r, c[1] + o.r); });
      else (Array.isArray(o.p[0][0]) ? o.p : [o.p]).forEach((ps) => ps.forEach((p) => add(p[0], p[1])));
    }
    const L = Math.max(run.footprint.length, run.footprint.width);
    if (!isFinite(x0)) { x0 = -1; x1 = 1; y0 = -1; y1 = 1; }
    return {x0: x0 - L, x1: x1 + L, y0: y0 - L, y1: y1 + L};
  }
  function fitView() {
    const {w, h} = dims(view), b = bounds();
    const sx = (w - 20) / Math.max(b.x1 - b.x0, 1e-9), sy = (h - 20) / Math.max(b.y1 - b.y0, 1e-9);
    fit = {cx: (b.x0 + b.x1) / 2, cy: (b.y0 + b.y1) / 2, scale: Math.min(sx, sy)};
    cam = Object.assign({}, fit);
  }
  function tx(g, w, h) { return [(x) => w / 2 + (x - cam.cx) * cam.scale, (y) => h / 2 - (y - cam.cy) * cam.scale]; }
  function poly(g, pts, X, Y, close) { g.beginPath(); trace(g, pts, X, Y); if (close) g.closePath(); }
  function trace(g, pts, X, Y, joined) {  // add a polyline to the current path
    let pen = !!joined;
    for (const p of pts) { if (p[0] === null || p[1] === null) { pen = false; continue; }
      if (pen) g.lineTo(X(p[0]), Y(p[1])); else { g.moveTo(X(p[0]), Y(p[1])); pen = true; } }
  }
  function obstacleAt(o, i) {
    if (o.type === "circle") return {c: Array.isArray(o.c[0]) ? o.c[i] : o.c, r: o.r};
    return {p: Array.isArray(o.p[0][0]) ? o.p[i] : o.p};
  }
  function niceStep(x) { const e = Math.pow(10, Math.floor(Math.log10(x))), m = x / e; return (m < 2 ? 1 : m < 5 ? 2 : 5) * e; }

  function drawView() {
    const {g, w, h} = dims(view), F = run.frames, i = frame;
    if (follow.checked && F.x[i] !== null) { cam.cx = F.x[i]; cam.cy = F.y[i]; }
    const [X, Y] = tx(g, w, h);
    g.clearRect(0, 0, w, h); g.fillStyle = "#fff"; g.fillRect(0, 0, w, h);
    g.lineJoin = "round"; g.lineCap = "round";
    g.fillStyle = "#f6f6f6"; g.strokeStyle = "#c8c8c8"; g.lineWidth = 1;  // the road's lanelets
    for (const p of run.lanelets || []) { poly(g, p, X, Y, true); g.fill(); g.stroke(); }
    if (run.left && run.right) {  // the lane as a grey band (a ring on a closed path)
      g.fillStyle = "#ececec"; g.beginPath();
      if (run.closed) { trace(g, run.left, X, Y); g.closePath(); trace(g, run.right, X, Y); g.closePath(); g.fill("evenodd"); }
      else { trace(g, run.left, X, Y); trace(g, run.right.slice().reverse(), X, Y, true); g.closePath(); g.fill(); }
      g.strokeStyle = "#555"; g.lineWidth = 1.2; g.setLineDash([6, 4]);
      poly(g, run.left, X, Y, false); g.stroke(); poly(g, run.right, X, Y, false); g.stroke(); g.setLineDash([]);
    }
    g.strokeStyle = "#1f77b4"; g.lineWidth = 1.5; poly(g, run.path, X, Y, false); g.stroke();
    // obstacles at this frame
    for (const o of run.obstacles) {
      const s = obstacleAt(o, i); g.fillStyle = "rgba(148,103,189,0.35)"; g.strokeStyle = "#9467bd"; g.lineWidth = 1.5;
      g.beginPath();
      if (s.c) g.arc(X(s.c[0]), Y(s.c[1]), Math.max(1, s.r * cam.scale), 0, 2 * Math.PI); else poly(g, s.p, X, Y, true);
      g.fill(); g.stroke();
    }
    // driven so far, the rest faint
    g.lineWidth = 1; g.strokeStyle = "rgba(214,39,40,0.18)"; g.beginPath();
    for (let j = 0; j < F.x.length; j++) { if (F.x[j] === null) continue; j ? g.lineTo(X(F.x[j]), Y(F.y[j])) : g.moveTo(X(F.x[j]), Y(F.y[j])); }
    g.stroke();
    g.lineWidth = 2; g.strokeStyle = "#d62728"; g.beginPath();
    for (let j = 0; j <= i; j++) { if (F.x[j] === null) continue; j ? g.lineTo(X(F.x[j]), Y(F.y[j])) : g.moveTo(X(F.x[j]), Y(F.y[j])); }
    g.stroke();
    // vehicle footprint
    if (F.x[i] !== null && F.yaw[i] !== null) {
      const fp = run.footprint, c = Math.cos(F.yaw[i]), s = Math.sin(F.yaw[i]);
      const hl = fp.length / 2, hw = fp.width / 2, o = fp.offset;
      const body = [[o + hl, hw], [o + hl, -hw], [o - hl, -hw], [o - hl, hw]].map((q) => [F.x[i] + c * q[0] - s * q[1], F.y[i] + s * q[0] + c * q[1]]);
      g.fillStyle = "rgba(255,127,14,0.55)"; g.strokeStyle = "#b35900"; g.lineWidth = 1.5;
      poly(g, body, X, Y, true); g.fill(); g.stroke();
      const nose = [F.x[i] + c * (o + hl), F.y[i] + s * (o + hl)];
      g.beginPath(); g.moveTo(X(F.x[i]), Y(F.y[i])); g.lineTo(X(nose[0]), Y(nose[1])); g.stroke();
      g.fillStyle = "#000"; g.beginPath(); g.arc(X(F.x[i]), Y(F.y[i]), 2.5, 0, 2 * Math.PI); g.fill();
    }
    // predicted horizon
    const hz = run.horizon[i];
    if (showHz.checked && hz && hz.length) {
      g.strokeStyle = "#2ca02c"; g.lineWidth = 1.5; poly(g, hz, X, Y, false); g.stroke();
      g.fillStyle = "#2ca02c";
      for (const p of hz) { if (p[0] === null) continue; g.beginPath(); g.arc(X(p[0]), Y(p[1]), 2, 0, 2 * Math.PI); g.fill(); }
    }
    // scale bar
    const len = niceStep(100 / cam.scale), px = len * cam.scale;
    g.strokeStyle = "#333"; g.lineWidth = 2; g.beginPath(); g.moveTo(12, h - 14); g.lineTo(12 + px, h - 14); g.stroke();
    g.fillStyle = "#333"; g.font = "12px sans-serif"; g.fillText(String(+len.toPrecision(2)) + " m", 16 + px, h - 10);
  }

  function drawSeries() {
    const {g, w, h} = dims(series), F = run.frames, n = F.t.length;
    g.clearRect(0, 0, w, h); g.fillStyle = "#fff"; g.fillRect(0, 0, w, h);
    const t0 = F.t[0], t1 = Math.max(F.t[n - 1], t0 + 1e-9), L = 56, R = 10;
    const XT = (t) => L + (t - t0) / (t1 - t0) * (w - L - R);
    const rows = [["lateral error e_y [m]", F.ey, 1, "#d62728"], ["steering [deg]", F.steer, 180 / Math.PI, "#1f77b4"]];
    const ph = (h - 16) / rows.length;
    rows.forEach((r, k) => {
      const top = 4 + k * ph, bot = top + ph - 14;
      let lo = Infinity, hi = -Infinity;
      r[1].forEach((v) => { if (v === null) return; v *= r[2]; if (v < lo) lo = v; if (v > hi) hi = v; });
      if (!isFinite(lo)) { lo = -1; hi = 1; }
      if (hi - lo < 1e-12) { lo -= 1e-3; hi += 1e-3; }
      const YV = (v) => bot - (v - lo) / (hi - lo) * (bot - top);
      g.strokeStyle = "#ddd"; g.lineWidth = 1; g.strokeRect(L, top, w - L - R, bot - top);
      if (lo < 0 && hi > 0) { g.beginPath(); g.moveTo(L, YV(0)); g.lineTo(w - R, YV(0)); g.stroke(); }
      g.fillStyle = "#333"; g.font = "11px sans-serif";
      g.fillText(r[0], L + 4, top + 11); g.fillText(hi.toPrecision(3), 2, top + 9); g.fillText(lo.toPrecision(3), 2, bot);
      g.strokeStyle = r[3]; g.lineWidth = 1.3; g.beginPath(); let pen = false;
      for (let j = 0; j < n; j++) { const v = r[1][j]; if (v === null) { pen = false; continue; }
        const X = XT(F.t[j]), Y = YV(v * r[2]); if (pen) g.lineTo(X, Y); else { g.moveTo(X, Y); pen = true; } }
      g.stroke();
    });
    g.fillStyle = "#333"; g.fillText("t [s]  " + t0.toFixed(2) + " … " + t1.toFixed(2), L, h - 2);
    const xc = XT(F.t[frame]); g.strokeStyle = "#000"; g.lineWidth = 1; g.beginPath(); g.moveTo(xc, 2); g.lineTo(xc, h - 14); g.stroke();
  }

  function fmt(v, d) { return v === null || v === undefined ? "—" : Number(v).toFixed(d); }
  function setFrame(i, fromTimer) {
    const F = run.frames; frame = Math.max(0, Math.min(F.t.length - 1, i));
    if (!fromTimer) simT = F.t[frame];
    slider.value = String(frame);
    label.textContent = "frame " + (frame + 1) + "/" + F.t.length + "  step " + F.k[frame] + "  t = " + F.t[frame].toFixed(3) + " s";
    const st = run.statuses[F.st[frame]];
    hud.textContent = "v " + fmt(F.v[frame], 3) + " m/s   steer " + fmt(F.steer[frame] === null ? null : F.steer[frame] * 180 / Math.PI, 2) +
      "°   accel " + fmt(F.accel[frame], 2) + " m/s²   e_y " + fmt(F.ey[frame], 4) + " m   e_psi " +
      fmt(F.epsi[frame] === null ? null : F.epsi[frame] * 180 / Math.PI, 2) + "°   solver " + st;
    drawView(); drawSeries();
  }
  function frameAt(t) {
    const T = run.frames.t; let lo = 0, hi = T.length - 1;
    if (t >= T[hi]) return hi;
    while (hi - lo > 1) { const m = (lo + hi) >> 1; if (T[m] <= t) lo = m; else hi = m; }
    return lo;
  }
  function tick(ts) {
    if (!playing) return;
    if (lastTs === null) lastTs = ts;
    simT += (ts - lastTs) / 1000 * parseFloat(speedSel.value); lastTs = ts;
    const last = run.frames.t.length - 1, f = frameAt(simT);
    setFrame(f, true);
    if (f >= last) { setPlaying(false); return; }
    requestAnimationFrame(tick);
  }
  function setPlaying(on) {
    playing = on; playBtn.textContent = on ? "Pause" : "Play"; lastTs = null;
    if (on) { if (frame >= run.frames.t.length - 1) setFrame(0); requestAnimationFrame(tick); }
  }
  function select(id) {
    run = RUNS.find((r) => r.id === id) || RUNS[0];
    if (picker) picker.value = run.id;
    setPlaying(false);
    slider.max = String(run.frames.t.length - 1);
    $("skipped").textContent = run.skipped_obstacles.length ? "obstacle shapes not drawn (unknown type): " + run.skipped_obstacles.join(", ") : "";
    document.querySelectorAll("section.run").forEach((s) => { s.style.display = (RUNS.length < 2 || s.dataset.run === run.id) ? "" : "none"; });
    fitView(); setFrame(0);
  }

  playBtn.addEventListener("click", () => setPlaying(!playing));
  slider.addEventListener("input", () => { setFrame(parseInt(slider.value, 10)); });
  speedSel.addEventListener("change", () => { lastTs = null; });
  follow.addEventListener("change", () => { if (!follow.checked) { cam.cx = fit.cx; cam.cy = fit.cy; } drawView(); });
  showHz.addEventListener("change", drawView);
  $("reset-view").addEventListener("click", () => { follow.checked = false; fitView(); drawView(); });
  if (picker) picker.addEventListener("change", () => select(picker.value));
  document.querySelectorAll("a.pick").forEach((a) => a.addEventListener("click", (ev) => {
    ev.preventDefault(); if (RUNS.some((r) => r.id === a.dataset.run)) { select(a.dataset.run); $("replay").scrollIntoView(); }
  }));
  view.addEventListener("wheel", (ev) => {
    ev.preventDefault(); const r = view.getBoundingClientRect(), k = Math.exp(-ev.deltaY * 0.0015);
    const mx = ev.clientX - r.left - r.width / 2, my = ev.clientY - r.top - r.height / 2;
    if (!follow.checked) { cam.cx += mx / cam.scale * (1 - 1 / k); cam.cy -= my / cam.scale * (1 - 1 / k); }
    cam.scale *= k; drawView();
  }, {passive: false});
  view.addEventListener("mousedown", (ev) => { drag = [ev.clientX, ev.clientY]; });
  window.addEventListener("mouseup", () => { drag = null; });
  window.addEventListener("mousemove", (ev) => {
    if (!drag || follow.checked) return;
    cam.cx -= (ev.clientX - drag[0]) / cam.scale; cam.cy += (ev.clientY - drag[1]) / cam.scale; drag = [ev.clientX, ev.clientY]; drawView();
  });
  series.addEventListener("click", (ev) => {
    const r = series.getBoundingClientRect(), F = run.frames, t0 = F.t[0], t1 = F.t[F.t.length - 1];
    const u = (ev.clientX - r.left - 56) / Math.max(1, r.width - 66); setFrame(frameAt(t0 + Math.max(0, Math.min(1, u)) * (t1 - t0)));
  });
  document.addEventListener("keydown", (ev) => {
    if (ev.target && (ev.target.tagName === "INPUT" && ev.target.type !== "range" || ev.target.tagName === "SELECT")) return;
    if (ev.key === " ") { ev.preventDefault(); setPlaying(!playing); }
    else if (ev.key === "ArrowRight") { ev.preventDefault(); setFrame(frame + 1); }
    else if (ev.key === "ArrowLeft") { ev.preventDefault(); setFrame(frame - 1); }
  });
  window.addEventListener("resize", () => { const keep = cam.scale / fit.scale; fitView(); cam.scale = fit.scale * keep; drawView(); drawSeries(); });
  select(RUNS[0].id);
})();
