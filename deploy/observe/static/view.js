// swarmloc's page: one WebSocket, one canvas for the arena, one for the metrics over time.
// The world-to-pixel transform is exposed as window.swarmloc.toPixel(x, y) (the tests use it).
"use strict";
(function () {
  const arena = document.getElementById("arena");
  const ctx = arena.getContext("2d");
  const chart = document.getElementById("chart");
  const cctx = chart.getContext("2d");
  const $ = (id) => document.getElementById(id);
  const TRUE = "#d62728", DEAD = "#777777", EST = "rgba(31,119,180,0.55)";
  const BELIEF = "rgba(44,160,44,0.55)", LINK = "#ff9900", SAMPLE = "#17becf";
  const state = { scene: null, frame: null, mode: null, paused: false, history: [], frames: 0,
                  transform: null, socket: null, lastTick: -1 };
  window.swarmloc = state;

  function transform(scene) {
    const [x0, y0, x1, y1] = scene.bounds_m;
    const pad = 10;
    const s = Math.min((arena.width - 2 * pad) / (x1 - x0), (arena.height - 2 * pad) / (y1 - y0));
    const ox = pad + ((arena.width - 2 * pad) - s * (x1 - x0)) / 2;
    const oy = pad + ((arena.height - 2 * pad) - s * (y1 - y0)) / 2;
    // y up in the world, down on the canvas
    return { s, ox, oy, x0, y1,
             px: (x) => ox + (x - x0) * s, py: (y) => oy + (y1 - y) * s };
  }
  state.toPixel = (x, y) => {
    const t = state.transform;
    return t ? [t.px(x), t.py(y)] : null;
  };

  function disc(x, y, r, fill, stroke) {
    const t = state.transform;
    ctx.beginPath();
    ctx.arc(t.px(x), t.py(y), r, 0, 2 * Math.PI);
    if (fill) { ctx.fillStyle = fill; ctx.fill(); }
    if (stroke) { ctx.strokeStyle = stroke; ctx.stroke(); }
  }

  function drawScene() {
    const sc = state.scene, t = state.transform;
    ctx.fillStyle = "#ffffff";
    ctx.fillRect(0, 0, arena.width, arena.height);
    if (!sc) return;
    ctx.lineWidth = 2; ctx.strokeStyle = "#333";
    ctx.beginPath();
    for (const [x1, y1, x2, y2] of sc.walls) { ctx.moveTo(t.px(x1), t.py(y1)); ctx.lineTo(t.px(x2), t.py(y2)); }
    ctx.stroke();
    ctx.lineWidth = 1;
    for (const d of sc.discs) {
      disc(d.x, d.y, d.radius_m * t.s, d.colour || "#999", null);
      ctx.fillStyle = "#555"; ctx.font = "11px sans-serif";
      ctx.fillText(d.label, t.px(d.x) + d.radius_m * t.s + 3, t.py(d.y));
    }
    for (const lm of sc.landmarks) {
      const x = t.px(lm.x), y = t.py(lm.y);
      ctx.fillStyle = "#8a5cb8"; ctx.fillRect(x - 4, y - 4, 8, 8);
      ctx.fillStyle = "#555"; ctx.font = "10px sans-serif"; ctx.fillText(String(lm.id), x + 5, y - 5);
    }
  }

  function robotRadiusPx() {
    return Math.max(state.scene.robot_radius_m * state.transform.s, 5);
  }

  function drawFrame() {
    drawScene();
    const f = state.frame, t = state.transform;
    if (!f || !t) return;
    const r = robotRadiusPx();
    const truth = f.truth;
    // populations (particles, GA individuals) under everything else: a 3-pixel square each
    if (f.samples && $("samples").checked) {
      ctx.fillStyle = SAMPLE;
      for (const own of f.samples) {
        for (const p of own) ctx.fillRect(Math.round(t.px(p[0])) - 1, Math.round(t.py(p[1])) - 1, 3, 3);
      }
    }
    // links under the robots
    ctx.strokeStyle = LINK; ctx.lineWidth = 1.5;
    ctx.beginPath();
    for (const [a, b] of f.links) {
      const pa = truth[a], pb = truth[b];
      if (!pa || !pb) continue;
      ctx.moveTo(t.px(pa[0]), t.py(pa[1])); ctx.lineTo(t.px(pb[0]), t.py(pb[1]));
    }
    ctx.stroke();
    // beliefs: a cross, and the uncertainty circle where there is one
    ctx.lineWidth = 1;
    f.beliefs.forEach((marks, i) => {
      for (const m of marks) {
        const x = t.px(m.x), y = t.py(m.y);
        ctx.strokeStyle = BELIEF;
        ctx.beginPath(); ctx.moveTo(x - 4, y - 4); ctx.lineTo(x + 4, y + 4);
        ctx.moveTo(x - 4, y + 4); ctx.lineTo(x + 4, y - 4); ctx.stroke();
        if (m.radius_m > 0) { ctx.beginPath(); ctx.arc(x, y, m.radius_m * t.s, 0, 2 * Math.PI); ctx.stroke(); }
        const p = truth[i];
        if (p) { ctx.setLineDash([2, 3]); ctx.beginPath(); ctx.moveTo(t.px(p[0]), t.py(p[1])); ctx.lineTo(x, y); ctx.stroke(); ctx.setLineDash([]); }
      }
    });
    // own pose beliefs, joined to the truth
    f.estimates.forEach((e, i) => {
      if (!e) return;
      const p = truth[i];
      if (p) {
        ctx.strokeStyle = EST; ctx.beginPath(); ctx.moveTo(t.px(p[0]), t.py(p[1]));
        ctx.lineTo(t.px(e[0]), t.py(e[1])); ctx.stroke();
      }
      disc(e[0], e[1], r * 0.8, EST, null);
      heading(e, r * 0.8, "rgba(31,119,180,0.9)");
    });
    // true poses on top
    const alive = f.state.alive;
    truth.forEach((p, i) => {
      if (!p) return;
      disc(p[0], p[1], r, alive[i] ? TRUE : DEAD, "#000");
      heading(p, r, "#000");
      if (!alive[i]) {
        const x = t.px(p[0]), y = t.py(p[1]);
        ctx.strokeStyle = "#000"; ctx.lineWidth = 2; ctx.beginPath();
        ctx.moveTo(x - r, y - r); ctx.lineTo(x + r, y + r); ctx.moveTo(x - r, y + r); ctx.lineTo(x + r, y - r);
        ctx.stroke(); ctx.lineWidth = 1;
      }
      if (r >= 7) { ctx.fillStyle = "#000"; ctx.font = "10px sans-serif"; ctx.fillText(String(i), t.px(p[0]) + r + 1, t.py(p[1]) - r); }
    });
  }

  function heading(p, r, colour) {
    // from 0.45 r to 1.4 r along the heading: the disc's centre pixel keeps its fill colour
    const t = state.transform, c = Math.cos(p[2]), s = Math.sin(p[2]);
    ctx.strokeStyle = colour; ctx.lineWidth = 2; ctx.beginPath();
    ctx.moveTo(t.px(p[0] + c * 0.45 * r / t.s), t.py(p[1] + s * 0.45 * r / t.s));
    ctx.lineTo(t.px(p[0] + c * 1.4 * r / t.s), t.py(p[1] + s * 1.4 * r / t.s));
    ctx.stroke(); ctx.lineWidth = 1;
  }

  function drawChart() {
    const h = state.history, W = chart.width, H = chart.height;
    cctx.fillStyle = "#fff"; cctx.fillRect(0, 0, W, H);
    cctx.fillStyle = "#555"; cctx.font = "11px sans-serif";
    cctx.fillText("position error (m, blue) and round trips (purple) over ticks", 6, 12);
    if (h.length < 2) return;
    const t0 = h[0].tick, t1 = Math.max(h[h.length - 1].tick, t0 + 1);
    const maxErr = Math.max(1e-3, ...h.map((p) => p.err ?? 0));
    const maxTrips = Math.max(1, ...h.map((p) => p.trips ?? 0));
    const X = (tick) => 30 + (W - 40) * (tick - t0) / (t1 - t0);
    const line = (key, max, colour) => {
      cctx.strokeStyle = colour; cctx.beginPath(); let started = false;
      for (const p of h) {
        if (p[key] == null) continue;
        const y = H - 20 - (H - 40) * p[key] / max;
        if (started) cctx.lineTo(X(p.tick), y); else { cctx.moveTo(X(p.tick), y); started = true; }
      }
      cctx.stroke();
    };
    line("err", maxErr, "#1f77b4");
    line("trips", maxTrips, "#9467bd");
    cctx.fillStyle = "#555";
    cctx.fillText(`${maxErr.toFixed(3)} m`, 2, 30);
    cctx.fillText(`${maxTrips} trips`, W - 60, 30);
    cctx.fillText(String(t0), 30, H - 5); cctx.fillText(String(t1), W - 40, H - 5);
  }

  function onScene(scene) {
    state.scene = scene;
    state.transform = scene ? transform(scene) : null;
    drawFrame();
  }

  function onFrame(f) {
    state.frame = f;
    state.frames += 1;
    if (f.tick < state.lastTick) state.history = state.history.filter((p) => p.tick <= f.tick);
    state.lastTick = f.tick;
    state.history.push({ tick: f.tick, err: f.metrics.position_error_m, trips: f.metrics.round_trips });
    if (state.history.length > 2000) state.history = state.history.filter((_, i) => i % 2 === 0);
    $("tick").textContent = String(f.tick);
    $("time").textContent = Number(f.time_s).toFixed(1);
    const rate = f.metrics.ticks_per_s;
    $("rate").textContent = rate ? `${rate.toFixed(1)} ticks/s` : "";
    const dead = f.state.alive.filter((a) => !a).length;
    const m = Object.assign({}, f.metrics, { robots: f.truth.length, dead, links: f.links.length });
    $("metrics").textContent = Object.entries(m).map(([k, v]) =>
      `${k}: ${typeof v === "number" && !Number.isInteger(v) ? v.toFixed(4) : v}`).join("\n");
    if (state.mode === "recording" && !state.dragging) $("slider").value = String(f.tick);
    if (f.done) $("status").textContent = "run ended";
    if (f.samples) $("samples-toggle").hidden = false;
    drawFrame();
    drawChart();
  }

  function send(obj) {
    if (state.socket && state.socket.readyState === 1) state.socket.send(JSON.stringify(obj));
  }
  state.seek = (tick) => send({ cmd: "seek", tick: Math.round(tick) });
  state.send = send;

  $("pause").onclick = () => {
    state.paused = !state.paused;
    $("pause").textContent = state.paused ? "play" : "pause";
    send({ cmd: state.paused ? "pause" : "play" });
  };
  $("slider").oninput = () => { state.dragging = true; state.seek(Number($("slider").value)); };
  $("slider").onchange = () => { state.dragging = false; };
  $("samples").onchange = () => drawFrame();
  $("speed").onchange = () => send({ cmd: "speed", x: Number($("speed").value) });

  function connect() {
    const ws = new WebSocket(`ws://${location.host}/ws`);
    state.socket = ws;
    ws.onopen = () => { $("status").textContent = "connected"; };
    ws.onclose = () => { $("status").textContent = "disconnected"; setTimeout(connect, 1000); };
    ws.onmessage = (ev) => {
      const msg = JSON.parse(ev.data);
      if (msg.type === "hello") {
        state.mode = msg.mode;
        $("title").textContent = `swarmloc: ${msg.title}`;
        if (msg.mode === "recording") {
          $("playback").hidden = false;
          $("slider").min = String(msg.first_tick); $("slider").max = String(msg.last_tick);
          if (msg.truncated) $("status").textContent = "recording truncated";
        }
        onScene(msg.scene);
      } else if (msg.type === "scene") {
        onScene(msg.scene);
      } else if (msg.type === "frame") {
        onFrame(msg.frame);
      }
    };
  }
  drawScene();
  connect();
})();
