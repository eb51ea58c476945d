// The live page of shear-twin: server-sent events in, canvas plots out. No library, no build
// step: the file is served from the binary as it is. Arrays are bounded; drawing happens once
// per animation frame, whatever the rate events come at.
"use strict";
(() => {
  const query = new URLSearchParams(location.search);
  const view = query.get("view") || "";
  const MAX_POINTS = 8000;          // points kept (all channels share a point)
  const MAX_ALERTS = 500;           // alert list items kept
  const MAX_LATENCIES = 20000;      // latency samples kept for the benchmark
  const MAX_MODES = 400;            // identifications kept for the frequency plot
  const $ = (id) => document.getElementById(id);

  let meta = null;
  let lastSeq = 0;
  let live = false;
  let points = [];
  let received = 0;                 // points received since the page (re)started
  let fresh = [];                   // live points not drawn yet (their latency is due)
  let dirty = true;
  let channels = [];
  let modes = [];
  const latencies = [];
  const drawMs = [];                // how long each drawn frame took, ms (bounded)
  const arrivals = [];              // sample read → its event handled here, ms (bounded)
  const acknowledged = new Set();

  window.twinPage = {
    latencies,
    drawMs,
    arrivals,
    received: () => received,
    kept: () => points.length,
    live: () => live,
  };

  const fmt = (v, digits = 3) => (v === null || v === undefined || !isFinite(v)) ? "-" : Number(v).toFixed(digits);
  const el = (tag, attrs = {}, text) => {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    return e;
  };

  function reset() {
    points = []; received = 0; fresh = []; lastSeq = 0; channels = []; modes = [];
    acknowledged.clear();
    $("channels").replaceChildren();
    $("alerts").replaceChildren();
    $("alert-count").textContent = "0"; $("alert-count").dataset.count = "0";
    $("diagnosis").dataset.action = ""; $("diagnosis-body").textContent = "none yet";
    $("accept").hidden = true;
  }

  function setup(m) {
    if (!meta || meta.run !== m.run) reset();
    meta = m;
    document.title = m.title || "shear-twin";
    $("title").textContent = m.title || "shear-twin";
    $("token-box").hidden = !m.token;
    document.body.dataset.mode = m.mode || "";
    if (m.mode === "fleet") document.querySelector("main").style.gridTemplateColumns = "1fr";
    if (channels.length) return;
    channels = (m.channels || []).map((name, c) => {
      const box = el("div", { class: "channel", "data-channel": name });
      const head = el("h3");
      head.append(el("span", {}, name),
        el("span", { class: "legend" }, "measured (blue) · twin (orange) ± 3σ"),
        el("span", { class: "nmse-value", "data-channel": name, "data-nmse": "" }, "NMSE -"));
      const plot = el("canvas", { class: "plot", "data-channel": name, "data-points": "0", "data-drawn": "0" });
      const strip = el("canvas", { class: "strip", "data-channel": name });
      box.append(head, plot, strip);
      $("channels").append(box);
      return { name, c, plot, strip, nmse: head.querySelector(".nmse-value") };
    });
    dirty = true;
  }

  function addPoint(e) {
    points.push(e);
    received += 1;
    if (live) {
      fresh.push(e);
      if (e.wall) arrivals.push(performance.timeOrigin + performance.now() - e.wall);
      if (arrivals.length > MAX_LATENCIES) arrivals.splice(0, arrivals.length - MAX_LATENCIES);
    }
    if (points.length > MAX_POINTS * 1.25) points.splice(0, points.length - MAX_POINTS);
    if (fresh.length > MAX_POINTS) fresh.splice(0, fresh.length - MAX_POINTS);
    dirty = true;
  }

  function describeAlert(a) {
    const parts = [];
    if (a.time !== null && a.time !== undefined) parts.push(`t = ${fmt(a.time, 2)} s`);
    if (a.channels && a.channels.length) parts.push(a.channels.join(", "));
    switch (a.kind) {
      case "failing": case "recovered":
        if (a.nmse) parts.push(`NMSE ${a.nmse.map((v) => fmt(v, 2)).join(" / ")} %`);
        if (a.change) parts.push(`changed at ${fmt(a.change.time, 2)} s (${fmt(a.change.low, 2)}–${fmt(a.change.high, 2)})`);
        break;
      case "diagnosis":
        parts.push(a.action || (a.error ? `failed: ${a.error}` : ""));
        parts.push(`samples ${fmt(a.from, 1)}–${fmt(a.to, 1)} s`);
        if (a.change_time !== undefined) parts.push(`${fmt(a.post_change_seconds, 1)} s after the change, look ${a.round}${a.firm ? ", firm" : ""}`);
        break;
      case "end":
        parts.push(`${a.samples} samples`);
        if (a.still_failing && a.still_failing.length) parts.push(`still failing since ${a.still_failing.map((w) => fmt(w.start, 2)).join(", ")} s`);
        break;
      case "gap": parts.push(`${a.missing} missing`); break;
      case "bad_sample": parts.push(`line ${a.line}: ${a.reason}`); break;
      case "frequency": parts.push(`mode ${a.mode}: ${fmt(a.frequency, 3)} Hz (twin ${fmt(a.twin_frequency, 3)})`); break;
      case "acknowledged": parts.push(`alert ${a.ack}${a.note ? ": " + a.note : ""}`); break;
      case "connection": parts.push(a.state); break;
      default: break;
    }
    return parts.filter(Boolean).join(" · ");
  }

  function addAlert(a) {
    const li = el("li", { "data-kind": a.kind || "", "data-seq": a.seq ?? "", "data-time": a.time ?? "" });
    li.append(el("span", { class: "kind" }, a.kind), document.createTextNode(" " + describeAlert(a)));
    if (meta && meta.token && a.seq && a.kind !== "acknowledged") {
      const b = el("button", { "data-ack": a.seq }, "acknowledge");
      b.addEventListener("click", () => post("/api/ack", { seq: a.seq }, b));
      li.append(b);
    }
    if (a.kind === "acknowledged") {
      acknowledged.add(a.ack);
      const item = $("alerts").querySelector(`li[data-seq="${a.ack}"]`);
      if (item) item.classList.add("acknowledged");
    } else if (a.seq && acknowledged.has(a.seq)) {
      li.classList.add("acknowledged");
    }
    const list = $("alerts");
    list.prepend(li);
    while (list.children.length > MAX_ALERTS) list.lastChild.remove();
    const n = Number($("alert-count").dataset.count) + 1;
    $("alert-count").dataset.count = String(n); $("alert-count").textContent = String(n);
    if (a.kind === "diagnosis") showDiagnosis(a);
    if (a.kind === "modes") addModes(a);
  }

  function showDiagnosis(d) {
    const panel = $("diagnosis");
    panel.dataset.action = d.action || (d.error ? "error" : "");
    panel.dataset.windowStart = d.window_start ?? "";
    const body = $("diagnosis-body");
    body.replaceChildren();
    if (d.error) { body.append(el("p", { class: "error" }, `failed: ${d.error}`)); return; }
    body.append(el("p", { "data-field": "action" }, `action: ${d.action}`));
    if (d.reason) body.append(el("p", { "data-field": "reason" }, d.reason));
    const effects = el("ul", { "data-field": "effects" });
    for (const e of d.effects || []) {
      const name = e.label || e.name || e.kind || JSON.stringify(e);
      const params = e.parameters ? Object.entries(e.parameters).map(([k, v]) => `${k} = ${Number(v).toPrecision(4)}`).join(", ") : "";
      effects.append(el("li", {}, params ? `${name}: ${params}` : name));
    }
    if (effects.children.length) body.append(effects);
    const nb = d.nmse_before || [], na = d.nmse_after || [];
    const rows = (d.channels || []).map((c, i) => `${c} ${fmt(nb[i], 3)} → ${fmt(na[i], 3)} %`);
    if (rows.length) body.append(el("p", { "data-field": "nmse" }, `NMSE ${rows.join("; ")}`));
    body.append(el("p", { class: "muted" }, `samples ${fmt(d.from, 1)}–${fmt(d.to, 1)} s, ${fmt(d.seconds, 1)} s of work`));
    if (d.change_time !== undefined) body.append(el("p", { "data-field": "change" }, `after the change at ${fmt(d.change_time, 2)} s: ${fmt(d.post_change_seconds, 1)} s of it, look ${d.round}${d.firm ? " (firm: the same verdict as the look before)" : ""}`));
    if (d.report) body.append(el("p", { "data-field": "report" }, `report: ${d.report}`));
    if (d.plot) body.append(el("p", { "data-field": "plot" }, `plot: ${d.plot}`));
    $("accept").hidden = !(meta && meta.token && d.action === "add_physics");
  }

  function addModes(a) {
    if (!a.modes) return;
    $("modes-panel").hidden = false;
    modes.push({ t: a.time, modes: a.modes });
    if (modes.length > MAX_MODES) modes.splice(0, modes.length - MAX_MODES);
    const body = $("modes-table").tBodies[0];
    body.replaceChildren();
    for (const m of a.modes) {
      const tr = el("tr", { "data-mode": m.mode, "data-outside": m.outside ? "1" : "0" });
      tr.append(el("td", {}, `mode ${m.mode}`), el("td", { class: "num" + (m.outside ? " outside" : "") }, `${fmt(m.frequency, 3)} Hz`),
        el("td", { class: "num" }, `twin ${fmt(m.twin_frequency, 3)} ± ${fmt(m.band, 3)}`));
      body.append(tr);
    }
    dirty = true;
  }

  function showState(s) {
    const set = (field, text) => { const d = document.querySelector(`#state [data-field="${field}"]`); if (d) d.textContent = text; };
    set("samples", s.samples ?? "-");
    set("time", s.time === undefined ? "-" : `${fmt(s.time, 2)} s`);
    set("speed", s.samples_per_second ? `${fmt(s.samples_per_second, 0)} samples/s (${fmt(s.real_time_factor, 1)}× real time)` : "-");
    set("gaps", s.gaps === undefined ? "-" : `${s.gaps} (${s.missing_samples ?? 0} samples missing)`);
    set("bad_lines", s.bad_lines ?? "-");
    set("mqtt", s.mqtt ? `${s.mqtt.messages} messages, ${s.mqtt.connections} connections, ${s.mqtt.disconnections} lost` : "-");
    set("checkpoint_age", s.checkpoint_age !== undefined && s.checkpoint_age !== null ? `${fmt(s.checkpoint_age, 1)} s` : (s.checkpoint ? `${s.checkpoint.path}` : "-"));
    set("diagnosing", s.diagnosing ? "yes" : "no");
    set("page", s.hub ? `${s.hub.clients} browsers, ${s.hub.published} events, ${s.hub.dropped_clients} slow browsers dropped` : (s.finished ? "finished" : "-"));
    document.getElementById("state").dataset.finished = s.finished ? "1" : "0";
    if (s.nmse && !points.length) {
      channels.forEach((ch) => showNmse(ch, s.nmse[ch.c], false));
    }
  }

  function showFleet(rows) {
    $("fleet").hidden = false;
    const body = $("fleet-table").tBodies[0];
    body.replaceChildren();
    for (const r of rows) {
      const tr = el("tr", { "data-structure": r.name, "data-status": r.status || "" });
      const link = el("td");
      if (r.view) link.append(el("a", { href: `?view=${encodeURIComponent(r.name)}` }, "open"));
      tr.append(el("td", {}, r.name), el("td", {}, r.status ?? "-"), el("td", { "data-field": "action" }, r.action ?? "-"),
        el("td", { class: "num" }, Array.isArray(r.nmse) ? r.nmse.map((v) => fmt(v, 3)).join(" / ") : fmt(r.nmse, 3)),
        el("td", { class: "num" }, fmt(r.frequency_shift, 2)), link);
      body.append(tr);
    }
  }

  function handle(e) {
    if (e.type === "meta") { setup(e); lastSeq = Math.max(lastSeq, e.seq || 0); return; }
    if (e.type === "live") { live = true; return; }
    if (e.seq && e.seq <= lastSeq) return;   // seen before a reconnect
    if (e.seq) lastSeq = e.seq;
    switch (e.type) {
      case "point": addPoint(e); break;
      case "alert": addAlert(e.alert); break;
      case "state": showState(e); break;
      case "fleet": showFleet(e.rows || []); break;
      case "accept":
        $("accept-status").dataset.status = e.status;
        $("accept-status").textContent = e.status === "failed" ? `accept failed: ${e.error}` : `accept ${e.status}: ${e.out || ""}`;
        break;
      case "stopped":
        $("connection").textContent = `watch stopped: ${e.error}`; break;
      default: break;
    }
  }

  async function post(path, body, button) {
    const headers = { "Content-Type": "application/json" };
    const token = $("token").value;
    if (token) headers.Authorization = `Bearer ${token}`;
    try {
      const r = await fetch(path, { method: "POST", headers, body: JSON.stringify(body) });
      const answer = await r.json();
      if (!r.ok && button) button.textContent = answer.error || `error ${r.status}`;
      return answer;
    } catch (err) {
      if (button) button.textContent = String(err);
      return null;
    }
  }
  $("accept").addEventListener("click", () => post("/api/accept", {}, $("accept")));

  function connect() {
    const es = new EventSource("/events" + (view ? `?view=${encodeURIComponent(view)}` : ""));
    es.onopen = () => { $("connection").dataset.state = "live"; $("connection").textContent = "connected"; };
    es.onerror = () => { live = false; $("connection").dataset.state = "lost"; $("connection").textContent = "reconnecting"; };
    es.onmessage = (m) => { try { handle(JSON.parse(m.data)); } catch (err) { console.error(err); } };
  }

  // Drawing.
  function fit(canvas) {
    const ratio = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(canvas.clientWidth * ratio)), h = Math.max(1, Math.round(canvas.clientHeight * ratio));
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    const g = canvas.getContext("2d");
    g.setTransform(1, 0, 0, 1, 0, 0);
    g.clearRect(0, 0, w, h);
    return { g, w, h, ratio };
  }

  function firstAtOrAfter(t) {
    let lo = 0, hi = points.length;
    while (lo < hi) { const mid = (lo + hi) >> 1; if (points[mid].t < t) lo = mid + 1; else hi = mid; }
    return lo;
  }

  function shadeFailing(g, from, x, h) {
    g.fillStyle = "rgba(200, 30, 40, 0.14)";
    let start = null;
    for (let i = from; i < points.length; i++) {
      const p = points[i];
      if (p.open && start === null) start = x(p.t);
      if (!p.open && start !== null) { g.fillRect(start, 0, x(p.t) - start, h); start = null; }
    }
    if (start !== null) g.fillRect(start, 0, x(points[points.length - 1].t) - start + 1, h);
  }

  function drawChannel(ch, from, t0, t1) {
    const { g, w, h, ratio } = fit(ch.plot);
    const c = ch.c;
    const x = (t) => ((t - t0) / Math.max(t1 - t0, 1e-9)) * w;
    let lo = Infinity, hi = -Infinity;
    for (let i = from; i < points.length; i++) {
      const p = points[i], b = p.band ? p.band[c] : null;
      for (const v of [p.y[c], p.p[c], b !== null && p.p[c] !== null ? p.p[c] + b : null, b !== null && p.p[c] !== null ? p.p[c] - b : null]) {
        if (v !== null && isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
      }
    }
    if (!(hi > lo)) { lo = -1; hi = 1; }
    const pad = 0.05 * (hi - lo);
    const y = (v) => h - ((v - lo + pad) / (hi - lo + 2 * pad)) * h;
    shadeFailing(g, from, x, h);
    // The ±3σ band around the twin.
    g.fillStyle = "rgba(208, 96, 28, 0.18)";
    g.beginPath();
    let open = false;
    const upper = [], lower = [];
    for (let i = from; i < points.length; i++) {
      const p = points[i];
      if (p.band && p.band[c] !== null && p.p[c] !== null) { upper.push([x(p.t), y(p.p[c] + p.band[c])]); lower.push([x(p.t), y(p.p[c] - p.band[c])]); }
    }
    if (upper.length > 1) {
      g.moveTo(upper[0][0], upper[0][1]);
      for (const [a, b] of upper) g.lineTo(a, b);
      for (let i = lower.length - 1; i >= 0; i--) g.lineTo(lower[i][0], lower[i][1]);
      g.closePath(); g.fill(); open = true;
    }
    const line = (key, colour) => {
      g.strokeStyle = colour; g.lineWidth = 1.2 * ratio; g.beginPath();
      let started = false;
      for (let i = from; i < points.length; i++) {
        const v = points[i][key][c];
        if (v === null) { started = false; continue; }
        if (started) g.lineTo(x(points[i].t), y(v)); else { g.moveTo(x(points[i].t), y(v)); started = true; }
      }
      g.stroke();
    };
    line("y", "#1f5fa8");
    line("p", "#d0601c");
    // The corrector's latent sd, as dotted ±3√V(f) around the twin.
    if (points.length && points[points.length - 1].latent_sd) {
      g.setLineDash([2 * ratio, 3 * ratio]); g.strokeStyle = "#6a3aa8"; g.lineWidth = ratio;
      for (const sign of [1, -1]) {
        g.beginPath(); let started = false;
        for (let i = from; i < points.length; i++) {
          const p = points[i];
          if (!p.latent_sd || p.latent_sd[c] === null || p.p[c] === null) { started = false; continue; }
          const v = y(p.p[c] + sign * 3 * p.latent_sd[c]);
          if (started) g.lineTo(x(p.t), v); else { g.moveTo(x(p.t), v); started = true; }
        }
        g.stroke();
      }
      g.setLineDash([]);
    }
    g.fillStyle = "#777"; g.font = `${11 * ratio}px system-ui`;
    g.fillText(`${fmt(hi, 4)}`, 4 * ratio, 12 * ratio);
    g.fillText(`${fmt(lo, 4)}`, 4 * ratio, h - 4 * ratio);
    const span = `${fmt(Math.max(t0, points[from] ? points[from].t : t0), 1)} – ${fmt(t1, 1)} s`;
    g.fillText(span, w - g.measureText(span).width - 4 * ratio, h - 4 * ratio);
    ch.plot.dataset.points = String(received);
    ch.plot.dataset.drawn = String(points.length - from);
    ch.plot.dataset.band = open ? "1" : "0";
  }

  function showNmse(ch, v, failing) {
    ch.nmse.textContent = `NMSE ${fmt(v, 3)} %`;
    ch.nmse.dataset.nmse = v === null || v === undefined ? "" : String(v);
    ch.nmse.classList.toggle("failing", !!failing);
  }

  function drawStrip(ch, from, t0, t1) {
    const { g, w, h, ratio } = fit(ch.strip);
    const c = ch.c;
    const x = (t) => ((t - t0) / Math.max(t1 - t0, 1e-9)) * w;
    const tol = meta && meta.tolerance ? meta.tolerance : null;
    let top = tol ? 3 * tol : 1;
    for (let i = from; i < points.length; i++) { const v = points[i].nmse[c]; if (v !== null && v > top) top = v; }
    top *= 1.1;
    const y = (v) => h - (v / top) * h;
    shadeFailing(g, from, x, h);
    if (tol) {
      g.strokeStyle = "#b22"; g.setLineDash([4 * ratio, 3 * ratio]); g.lineWidth = ratio;
      g.beginPath(); g.moveTo(0, y(tol)); g.lineTo(w, y(tol)); g.stroke(); g.setLineDash([]);
    }
    g.strokeStyle = "#333"; g.lineWidth = 1.2 * ratio; g.beginPath();
    let started = false, last = null;
    for (let i = from; i < points.length; i++) {
      const v = points[i].nmse[c];
      if (v === null) { started = false; continue; }
      last = v;
      if (started) g.lineTo(x(points[i].t), y(v)); else { g.moveTo(x(points[i].t), y(v)); started = true; }
    }
    g.stroke();
    g.fillStyle = "#777"; g.font = `${10 * ratio}px system-ui`;
    g.fillText(`rolling NMSE %, tolerance ${fmt(tol, 3)} (max ${fmt(top, 2)})`, 4 * ratio, 11 * ratio);
    if (points.length) showNmse(ch, last, points[points.length - 1].open && last !== null && tol !== null && last > tol);
  }

  function drawModes() {
    if (!modes.length) return;
    const canvas = $("modes");
    const { g, w, h, ratio } = fit(canvas);
    const t0 = modes[0].t, t1 = modes[modes.length - 1].t;
    let lo = Infinity, hi = -Infinity;
    for (const m of modes) for (const d of m.modes) {
      for (const v of [d.frequency, d.twin_frequency - d.band, d.twin_frequency + d.band]) if (v !== null && isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    }
    if (!(hi > lo)) return;
    const x = (t) => (t1 > t0 ? (t - t0) / (t1 - t0) : 0.5) * (w - 8 * ratio) + 4 * ratio;
    const y = (v) => h - ((v - lo) / (hi - lo)) * (h - 8 * ratio) - 4 * ratio;
    const last = modes[modes.length - 1].modes;
    g.fillStyle = "rgba(208, 96, 28, 0.18)";
    for (const d of last) g.fillRect(0, y(d.twin_frequency + d.band), w, y(d.twin_frequency - d.band) - y(d.twin_frequency + d.band));
    let drawn = 0;
    for (const m of modes) for (const d of m.modes) {
      if (d.frequency === null) continue;
      g.fillStyle = d.outside ? "#b22" : "#1f5fa8";
      g.fillRect(x(m.t) - 1.5 * ratio, y(d.frequency) - 1.5 * ratio, 3 * ratio, 3 * ratio);
      drawn += 1;
    }
    canvas.dataset.points = String(drawn);
  }

  function draw() {
    const span = Number($("span").value) || 30;
    if (points.length) {
      const t1 = points[points.length - 1].t, t0 = t1 - span;
      const from = firstAtOrAfter(t0);
      for (const ch of channels) { drawChannel(ch, from, t0, t1); drawStrip(ch, from, t0, t1); }
    }
    drawModes();
    // Sample in → drawn: the watch stamped when it read the sample; now it is on the screen.
    if (fresh.length) {
      const now = performance.timeOrigin + performance.now();
      for (const p of fresh) if (p.wall) latencies.push(now - p.wall);
      if (latencies.length > MAX_LATENCIES) latencies.splice(0, latencies.length - MAX_LATENCIES);
      fresh = [];
      document.body.dataset.latencies = String(latencies.length);
    }
  }

  function frame() {
    if (dirty) {
      dirty = false;
      const began = performance.now();
      draw();
      drawMs.push(performance.now() - began);
      if (drawMs.length > MAX_LATENCIES) drawMs.splice(0, drawMs.length - MAX_LATENCIES);
    }
    requestAnimationFrame(frame);
  }
  $("span").addEventListener("change", () => { dirty = true; });
  window.addEventListener("resize", () => { dirty = true; });
  connect();
  requestAnimationFrame(frame);
})();
