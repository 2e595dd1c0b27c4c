// sdrpeer dashboard: one page per agent, fed by the agent's server-sent events (/v1/stream).
//
// How it works: the stream first sends `hello` (which robot, the history window), `history`
// (every robot's metric series and the fleet moments of the window), `events` (this agent's event
// log) and a `sample`; then a `sample` every second and an `event` whenever the agent logs one.
// Messages only update the state `S`; drawing happens once per animation frame for the parts
// marked dirty, and every render's duration is kept in `S.perf` (the benchmark and the browser
// test read `window.__sdrpeer`). Nothing is fetched from outside the agent: uPlot is vendored.
//
// The topology draws connections without text (labels of ten connections overlap): hovering an
// edge, or its row in the connections table under it, shows that one connection's traffic. Dead
// robots stay, greyed, with "dead since" (the agent keeps them after gossip reaps them). The
// component timelines are drawn from the `component` moments (the state of whichever instance is
// the component's active), so a failover is a change of colour, never a gap. `?snapshot=1` reads
// the stream once (`/v1/stream?once=1`), draws everything, marks `<html data-snapshot="ready">`
// and keeps nothing open, so `chromium --headless --screenshot --virtual-time-budget=...` ends.
"use strict";
(() => {
  const METRICS = [
    ["mem_free", "free memory (MB)", (v) => v / 1e6],
    ["cpu_pct", "CPU (%)", (v) => v],
    ["battery_pct", "battery (%)", (v) => v],
    ["rssi_dbm", "RSSI (dBm)", (v) => v],
    ["rtt_ms", "link RTT, typical (ms)", (v) => v],
    ["jitter_ms", "link jitter, typical (ms)", (v) => v],
    ["loss", "link loss, typical (%)", (v) => v * 100],
  ];
  const STATE_COLORS = {
    active: "#1a9850", inactive: "#4575b4", error: "#d73027", failed: "#d73027",
    pending: "#fdae61", starting: "#fdae61", updating: "#fdae61", cold: "#e5e7eb",
    "robot down": "#7f7f7f", lost: "#7f7f7f", gone: "#ffffff", stopped: "#bdbdbd",
  };
  const MARKERS = { allocation: "#f28e2b", move: "#8a3ffc", election: "#9ca3af" };
  const MAX_EVENTS = 5000, MAX_ROWS = 200, MAX_PERF = 4000, MAX_POINTS = 300;
  const SNAPSHOT = new URLSearchParams(location.search).has("snapshot");
  const GONE_STATES = new Set(["dead", "left"]);

  const S = {
    robot: null, windowS: 900, connected: false,
    t: [], series: {}, robots: [], members: [], status: null,
    events: [], moments: [], momentsVersion: 0, fleet: [], charts: {}, chartRobots: null,
    warnings: [], snapshot: SNAPSHOT,
    dirty: new Set(), scheduled: false,
    perf: { renders: [], frames: [], samples: 0, events: 0, lastSampleAt: 0 },
  };
  window.__sdrpeer = S;

  const $ = (id) => document.getElementById(id);
  const esc = (x) => String(x ?? "").replace(/[&<>"']/g, (c) => ({
    "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c]));
  const color = (i) => `hsl(${(i * 137.508) % 360}, 62%, 45%)`;
  const num = (v, digits = 1) => (v === null || v === undefined || Number.isNaN(v)) ? "-"
    : Number(v).toFixed(digits);
  const bytes = (v) => v === null || v === undefined ? "-"
    : v >= 1e6 ? `${(v / 1e6).toFixed(1)} MB/s` : v >= 1e3 ? `${(v / 1e3).toFixed(1)} kB/s`
    : `${Math.round(v)} B/s`;
  // a connection's label: its port and traffic, and the frames/s lost to full buffers if any
  const edgeText = (c) => `${c.from.split(".")[1]}: ${bytes(c.bytes_per_s)}` +
    (c.lost_per_s ? ` · ${c.lost_per_s} lost/s` : "");
  const clock = (ts) => new Date(ts * 1000).toLocaleTimeString([], { hour12: false });
  const isFleet = (m) => m.kind !== "state" && m.kind !== "component";
  // an instance's label: a promoted standby keeps its name, so its role says what it was
  const roleText = (role, wasStandby) => wasStandby ? `${role} (was standby)` : role;
  const instText = (i) => `${i.name} · ${i.state}${i.was_standby ? " (was standby)" : ""}`;
  const connName = (c) => `${c.from} → ${c.to}`;

  // ------------------------------------------------------------------ state updates
  function setHistory(h) {
    S.t = h.t.slice();
    S.series = {};
    for (const [name, lists] of Object.entries(h.robots)) {
      S.series[name] = {};
      for (const [m] of METRICS) S.series[name][m] = lists[m].slice();
    }
    S.moments = (h.moments || []).slice();
    S.held = 0;
    S.momentsVersion += 1;
    S.fleet = S.moments.filter(isFleet).map(fleetEvent);
    mark("charts", "states", "events");
  }

  function memberValues(m) {
    const x = m.metrics || {}, l = m.link || {};
    return { mem_free: x.mem_free, cpu_pct: x.cpu_pct, battery_pct: x.battery_pct,
      rssi_dbm: x.rssi_dbm, rtt_ms: l.rtt_ms, jitter_ms: l.jitter_ms, loss: l.loss };
  }

  function addSample(s) {
    S.perf.samples += 1;
    S.perf.lastSampleAt = performance.now();
    S.members = s.members;
    S.status = s.status;
    S.warnings = s.warnings || [];
    const k = S.t.length;
    S.t.push(s.ts);
    const seen = new Set();
    for (const m of s.members) {
      if (m.state !== "alive" && m.state !== "suspect") continue;
      seen.add(m.name);
      let lists = S.series[m.name];
      if (!lists) {
        lists = S.series[m.name] = {};
        for (const [metric] of METRICS) lists[metric] = new Array(k).fill(null);
      }
      const v = memberValues(m);
      for (const [metric] of METRICS) lists[metric].push(v[metric] ?? null);
    }
    for (const [name, lists] of Object.entries(S.series)) {
      if (!seen.has(name)) for (const [metric] of METRICS) lists[metric].push(null);
    }
    trim(s.ts);
    for (const mo of s.moments || []) {
      S.moments.push(mo);
      if (isFleet(mo)) S.fleet.push(fleetEvent(mo));
    }
    if ((s.moments || []).length) S.momentsVersion += 1;
    mark("summary", "warnings", "fleet", "topology", "compliance", "charts", "states");
    if ((s.moments || []).some(isFleet)) mark("events");
  }

  function trim(now) {
    let cut = 0;
    while (cut < S.t.length && S.t[cut] < now - S.windowS) cut++;
    if (cut > 0) {
      S.t.splice(0, cut);
      for (const lists of Object.values(S.series)) for (const a of Object.values(lists)) a.splice(0, cut);
    }
    // the first `S.held` moments are components' states older than the window that still hold
    let m = S.held || 0;
    while (m < S.moments.length && S.moments[m].ts < now - S.windowS) m++;
    if (m > (S.held || 0)) {
      const held = {};
      for (const mo of S.moments.slice(0, m)) if (mo.kind === "component") held[mo.component] = mo;
      const later = new Set(S.moments.slice(m).filter((mo) => mo.kind === "component").map((mo) => mo.component));
      const keep = Object.values(held).filter((mo) => !later.has(mo.component) && mo.state !== "gone");
      S.moments.splice(0, m, ...keep);
      S.held = keep.length;
      S.momentsVersion += 1;
      S.fleet = S.fleet.filter((e) => e.ts >= now - S.windowS);
    }
    for (const [name, lists] of Object.entries(S.series)) {
      if (lists.mem_free.every((v) => v === null)) delete S.series[name];
    }
  }

  function addEvents(list) {
    for (const e of list) S.events.push(e);
    S.perf.events += list.length;
    if (S.events.length > MAX_EVENTS) S.events.splice(0, S.events.length - MAX_EVENTS);
    mark("events");
  }

  // ------------------------------------------------------------------ rendering
  function mark(...parts) {
    for (const p of parts) S.dirty.add(p);
    if (!S.scheduled) {
      S.scheduled = true;
      requestAnimationFrame(render);
    }
  }

  function render() {
    S.scheduled = false;
    const t0 = performance.now();
    const parts = [...S.dirty];
    S.dirty.clear();
    const each = {};
    for (const p of parts) {
      const t1 = performance.now();
      RENDER[p]();
      each[p] = performance.now() - t1;
    }
    const took = performance.now() - t0;
    S.perf.renders.push([parts.join(","), took, each]);
    if (S.perf.renders.length > MAX_PERF) S.perf.renders.splice(0, S.perf.renders.length - MAX_PERF);
  }

  function renderSummary() {
    const st = S.status || {};
    const a = st.allocator || {};
    $("allocator").textContent = a.name || "none";
    $("epoch").textContent = a.epoch ?? "-";
    const p = st.plan;
    $("plan").textContent = p ? `${p.system ?? "undeployed"} ${p.epoch}.${p.version}` : "none";
  }

  function renderFleet() {
    const leader = (S.status && S.status.allocator || {}).name;
    const rows = S.members.map((m) => {
      const x = m.metrics || {}, l = m.link || {};
      const role = m.name === leader ? '<span class="badge alloc">allocator</span>' : "";
      const insts = (m.instances || []).map((i) =>
        `<span class="badge s-${esc(String(i.state).replace(" ", "-"))}" data-instance="${esc(i.name)}" ` +
        `data-role="${esc(roleText(i.role, i.was_standby))}" ` +
        `title="${esc(i.component)} ${esc(roleText(i.role, i.was_standby))}">${esc(i.name)}${i.was_standby ? " ↑" : ""}</span>`).join(" ");
      const gone = GONE_STATES.has(m.state);
      const since = m.dead_since ? `<span class="dead-since">${esc(m.state)} since ${clock(m.dead_since)}` +
        `${m.reaped ? " · forgotten by gossip" : ""}</span>` : "";
      return `<tr id="robot-${esc(m.name)}" class="${gone ? "gone" : ""}" data-state="${esc(m.state)}"` +
        `${m.reaped ? ' data-reaped="1"' : ""}><td>${esc(m.name)}</td>` +
        `<td><span class="badge s-${esc(m.state)}">${esc(m.state)}</span> ${since}</td><td>${role}</td>` +
        `<td class="num">${num(x.cpu_pct)} %</td><td class="num">${num(x.mem_free / 1e6, 0)} MB</td>` +
        `<td class="num">${num(x.battery_pct, 0)} %</td><td class="num">${num(x.rssi_dbm)} dBm</td>` +
        `<td class="num">${num(l.rtt_ms, 2)} ms</td><td class="num">${num(l.jitter_ms, 2)} ms</td>` +
        `<td class="num">${l.loss == null ? "-" : num(l.loss * 100, 0) + " %"}</td><td>${insts}</td></tr>`;
    });
    $("fleet").tBodies[0].innerHTML = rows.join("");
  }

  function renderWarnings() {
    const list = S.warnings;
    $("warnings-section").hidden = !list.length;
    const html = list.map((w) =>
      `<li data-kind="${esc(w.kind)}" data-subject="${esc(w.subject)}">${esc(w.text)}</li>`).join("");
    if (html !== S.warningsHtml) {
      $("warnings").innerHTML = html;
      S.warningsHtml = html;
    }
  }

  function topologyKey(width, robots, leader, st) {
    const parts = [width, leader];
    for (const m of robots) {
      parts.push(m.name, m.state, m.dead_since, m.reaped);
      for (const i of m.instances || []) parts.push(i.name, i.role, i.was_standby);
    }
    for (const c of st.components || []) parts.push(c.component, c.instance, c.robot);
    for (const c of st.connections || []) parts.push(c.from, c.to);
    return parts.join("\u0001");
  }

  const BOX_W = 230, ROW_H = 15, CHARS = Math.floor((BOX_W - 24) / 5.8);
  const clip = (text) => text.length <= CHARS ? text : `${text.slice(0, CHARS - 1)}…`;

  function renderConnections(conns) {  // the table under the topology: every edge's label
    const rows = conns.map((c, k) =>
      `<tr data-edge="${k}" class="${c.lost_per_s ? "lossy" : ""}"><td>${esc(c.from)}</td><td>${esc(c.to)}</td>` +
      `<td class="num">${bytes(c.bytes_per_s)}</td><td class="num">${bytes(c.expected_bytes_per_s)}</td>` +
      `<td class="num">${c.lost_per_s == null ? "-" : esc(c.lost_per_s)}</td></tr>`).join("");
    if (rows !== S.connectionsHtml) {
      $("connections").tBodies[0].innerHTML = rows;
      S.connectionsHtml = rows;
    }
    $("connections").hidden = !conns.length;
  }

  function showEdge(k) {  // a bundle's labels at its middle, one line per connection (hover only)
    const tip = $("edge-tip");
    S.hoverEdge = k;
    for (const el of $("topology").querySelectorAll("path.edge.hover")) el.classList.remove("hover");
    const g = k === null || !S.topo ? undefined : S.topo.groupOf[k];
    const conns = (S.status || {}).connections || [];
    if (g === undefined) { tip.hidden = true; return; }
    const bundle = S.topo.groups[g];
    const el = $("topology").querySelector(`path.edge[data-group="${g}"]`);
    if (el) el.classList.add("hover");
    const svg = $("topology"), [x, y] = bundle.mid;
    const scale = svg.clientWidth / S.topo.width || 1;
    const box = svg.getBoundingClientRect(), section = $("topology-section").getBoundingClientRect();
    tip.innerHTML = bundle.ks.filter((j) => conns[j]).map((j) =>
      `<div data-edge="${j}"${j === k ? ' class="this"' : ""}>${esc(connName(conns[j]))} · ${esc(edgeText(conns[j]))}</div>`).join("");
    tip.dataset.group = g;
    tip.style.left = `${box.left - section.left + x * scale + 6}px`;
    tip.style.top = `${box.top - section.top + y * scale + 6}px`;
    tip.hidden = false;
  }

  function renderTopology() {
    const svg = $("topology");
    S.topoWidth ||= Math.max(600, svg.clientWidth || 900);  // measured again only on resize
    const width = S.topoWidth;
    const robots = S.members.filter((m) => m.state !== "left" || m.dead_since);
    const leader = (S.status && S.status.allocator || {}).name;
    const st = S.status || {};
    const conns = st.connections || [];
    renderConnections(conns);
    const key = topologyKey(width, robots, leader, st);
    if (S.topo && S.topo.key === key) {  // same shapes: only states and traffic change
      for (const m of robots) {
        for (const inst of m.instances || []) {
          const t = S.topo.inst[`${m.name}/${inst.name}`];
          if (!t || t.state === inst.state) continue;
          t.state = inst.state;
          t.g.dataset.state = inst.state;
          t.g.querySelector("rect").setAttribute("fill", STATE_COLORS[inst.state] || "#cbd5e1");
          t.g.querySelector("text").textContent = clip(instText(inst));
        }
      }
      for (const [el, ks] of S.topo.edges) el.classList.toggle("lossy", ks.some((k) => conns[k] && conns[k].lost_per_s));
      if (S.hoverEdge !== null && S.hoverEdge !== undefined) showEdge(S.hoverEdge);
      return;
    }
    const boxW = BOX_W, rowH = ROW_H, pad = 10, gap = 26;
    const cols = Math.max(1, Math.floor((width + gap) / (boxW + gap)));
    const pos = {};
    let html = '<defs><marker id="arrow" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="7" ' +
      'markerHeight="7" markerUnits="userSpaceOnUse" orient="auto-start-reverse"><path d="M 0 0 L 10 5 L 0 10 z" fill="#64748b"/></marker></defs>';
    let y = 0, rowMax = 0, boxes = "";
    robots.forEach((m, i) => {
      const col = i % cols;
      if (col === 0 && i > 0) { y += rowMax + gap; rowMax = 0; }
      const insts = (m.instances || []).slice().sort((a, b) =>
        (a.role === b.role ? a.name.localeCompare(b.name) : a.role === "active" ? -1 : 1));
      const head = m.dead_since ? 36 : 24;
      const h = head + insts.length * rowH + pad;
      rowMax = Math.max(rowMax, h);
      const x = col * (boxW + gap);
      const cls = `robot ${m.state}${m.name === leader ? " allocator" : ""}${m.reaped ? " reaped" : ""}`;
      boxes += `<g class="${esc(cls)}" data-robot="${esc(m.name)}"><rect x="${x}" y="${y}" width="${boxW}" height="${h}" rx="6"/>` +
        `<text class="name" x="${x + 8}" y="${y + 16}">${esc(m.name)}${m.name === leader ? " ★ allocator" : ""}</text>`;
      if (m.dead_since) {
        boxes += `<text class="since" x="${x + 8}" y="${y + 30}">${esc(m.state)} since ${clock(m.dead_since)}</text>`;
      }
      insts.forEach((inst, k) => {
        const iy = y + head - 2 + k * rowH;
        const fill = STATE_COLORS[inst.state] || "#cbd5e1";
        const full = `${inst.component} ${roleText(inst.role, inst.was_standby)}: ${instText(inst)}`;
        boxes += `<g class="inst ${esc(inst.role)}${inst.was_standby ? " promoted" : ""}" data-instance="${esc(inst.name)}" ` +
          `data-robot="${esc(m.name)}" data-state="${esc(inst.state)}" data-role="${esc(roleText(inst.role, inst.was_standby))}">` +
          `<title>${esc(full)}</title>` +
          `<rect x="${x + 8}" y="${iy}" width="${boxW - 16}" height="${rowH - 3}" rx="3" fill="${fill}"/>` +
          `<text x="${x + 12}" y="${iy + 9}">${esc(clip(instText(inst)))}</text></g>`;
        pos[`${m.name}/${inst.name}`] = [x + 8, iy + (rowH - 3) / 2, x + boxW - 8];
      });
      boxes += "</g>";
    });
    const total = y + rowMax + 4;
    // connections between the same two instances are one bundle: one path, its width growing
    // with their number, their labels together on hover
    const where = {}, groups = [], groupOf = {}, byEnds = {};
    for (const c of st.components || []) if (c.instance) where[c.component] = `${c.robot}/${c.instance}`;
    conns.forEach((c, k) => {
      const ka = where[c.from.split(".")[0]], kb = where[c.to.split(".")[0]];
      if (!pos[ka] || !pos[kb]) return;
      const ends = `${ka}\u0001${kb}`;
      if (byEnds[ends] === undefined) {
        byEnds[ends] = groups.length;
        groups.push({ a: pos[ka], b: pos[kb], ks: [] });
      }
      groupOf[k] = byEnds[ends];
      groups[byEnds[ends]].ks.push(k);
    });
    let edges = "";
    groups.forEach((bundle, g) => {
      const { a, b } = bundle;
      let d;
      if (a[0] === b[0]) {  // same robot: a loop on the box's right side
        const x = a[2], bulge = x + 14 + (g % 6) * 4 + Math.min(30, Math.abs(b[1] - a[1]) / 3);
        d = `M ${x} ${a[1]} C ${bulge} ${a[1]}, ${bulge} ${b[1]}, ${x} ${b[1]}`;
        bundle.mid = [x + (bulge - x) * 0.75, (a[1] + b[1]) / 2];
      } else {
        const x1 = a[2], y1 = a[1], x2 = b[0], y2 = b[1];
        const dx = Math.max(40, Math.abs(x2 - x1) / 2);
        d = `M ${x1} ${y1} C ${x1 + dx} ${y1}, ${x2 - dx} ${y2}, ${x2} ${y2}`;
        bundle.mid = [(x1 + x2) / 2, (y1 + y2) / 2];
      }
      const lossy = bundle.ks.some((k) => conns[k].lost_per_s);
      const names = bundle.ks.map((k) => connName(conns[k])).join("\n");
      edges += `<path class="${lossy ? "edge lossy" : "edge"}" data-group="${g}" data-count="${bundle.ks.length}" ` +
        `style="stroke-width:${Math.min(6, 1.2 + 0.5 * (bundle.ks.length - 1))}" d="${d}"/>` +
        `<path class="edge-hit" data-group="${g}" data-edge="${bundle.ks[0]}" d="${d}"><title>${esc(names)}</title></path>`;
    });
    svg.setAttribute("viewBox", `-2 -2 ${width + 4} ${total + 4}`);
    svg.style.height = `${total + 4}px`;
    svg.innerHTML = html + boxes + edges;
    const inst = {};
    for (const g of svg.querySelectorAll("g.inst")) {
      inst[`${g.dataset.robot}/${g.dataset.instance}`] = { g, state: g.dataset.state };
    }
    const paths = [...svg.querySelectorAll("path.edge")].map((el) => [el, groups[Number(el.dataset.group)].ks]);
    S.topo = { key, inst, edges: paths, groups, groupOf, width: width + 4 };
    if (S.hoverEdge !== null && S.hoverEdge !== undefined) showEdge(S.hoverEdge);
  }

  function markerHook(u) {
    const ctx = u.ctx, [lo, hi] = [u.scales.x.min, u.scales.x.max];
    ctx.save();
    ctx.lineWidth = 1.5 * devicePixelRatio;
    for (const mo of S.moments) {
      const c = MARKERS[mo.kind];
      if (!c || mo.ts < lo || mo.ts > hi) continue;
      const x = u.valToPos(mo.ts, "x", true);
      ctx.strokeStyle = c;
      ctx.setLineDash(mo.kind === "allocation" ? [6, 4] : mo.kind === "move" ? [8, 3, 2, 3] : [2, 3]);
      ctx.beginPath();
      ctx.moveTo(x, u.bbox.top);
      ctx.lineTo(x, u.bbox.top + u.bbox.height);
      ctx.stroke();
    }
    ctx.restore();
  }

  function renderCharts() {
    const robots = Object.keys(S.series).sort();
    const key = robots.join("|");
    const box = $("charts");
    if (key !== S.chartRobots) {
      for (const c of Object.values(S.charts)) c.destroy();
      S.charts = {};
      box.innerHTML = "";
      S.chartRobots = key;
      for (const [metric, title] of METRICS) {
        const div = document.createElement("div");
        div.className = "chart";
        div.innerHTML = `<h3>${esc(title)}</h3>`;
        box.appendChild(div);
        const width = Math.max(300, (div.clientWidth || 440) - 4);
        const opts = {
          width, height: 170, legend: { show: robots.length <= 12 },
          scales: { x: { time: true } },
          series: [{}, ...robots.map((r, i) => ({ label: r, stroke: color(i), width: 1, spanGaps: false }))],
          hooks: { draw: [markerHook] },
        };
        S.charts[metric] = new uPlot(opts, dataFor(metric, robots), div);
      }
      return;
    }
    const picks = decimate();
    for (const [metric] of METRICS) S.charts[metric].setData(dataFor(metric, robots, picks));
  }

  function decimate() {
    // More points than a chart has pixels only costs drawing time: past MAX_POINTS keep the
    // last sample of each time bucket (buckets aligned to the clock, so only the newest one
    // changes as samples arrive and the lines do not shimmer).
    const t = S.t;
    if (t.length <= MAX_POINTS) return null;
    const step = (t[t.length - 1] - t[0]) / MAX_POINTS;
    const picks = [];
    for (let i = 0; i < t.length; i++) {
      if (i === t.length - 1 || Math.floor(t[i] / step) !== Math.floor(t[i + 1] / step)) picks.push(i);
    }
    return picks;
  }

  function dataFor(metric, robots, picks = decimate()) {
    const scale = METRICS.find((m) => m[0] === metric)[2];
    const pick = (a) => (picks ? picks.map((i) => a[i]) : a);
    return [pick(S.t), ...robots.map((r) => pick(S.series[r][metric]).map((v) => v === null ? null : scale(v)))];
  }

  function renderStates() {
    const canvas = $("states");
    const comps = ((S.status && S.status.components) || []).map((c) => c.component);
    for (const comp of Object.keys(segments())) if (!comps.includes(comp)) comps.push(comp);
    const rowH = 14, left = 190, top = 4;
    S.statesWidth ||= Math.max(600, canvas.clientWidth || 900);  // no layout read per frame
    const width = S.statesWidth;
    const height = top + Math.max(1, comps.length) * rowH + 18;
    const dpr = devicePixelRatio || 1;
    if (canvas.width !== width * dpr || canvas.height !== height * dpr) {
      canvas.width = width * dpr; canvas.height = height * dpr; canvas.style.height = `${height}px`;
    }
    const ctx = canvas.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, width, height);
    const now = S.t.length ? S.t[S.t.length - 1] : Date.now() / 1000;
    const first = Math.min(S.t.length ? S.t[0] : now, S.moments.length ? S.moments[0].ts : now);
    const t0 = Math.max(now - S.windowS, first), span = Math.max(1, now - t0);
    const xOf = (ts) => left + (width - left - 60) * Math.max(0, Math.min(1, (ts - t0) / span));
    const segs = segments();
    const labelsKey = `${comps.join("|")}@${dpr}`;
    if (S.labelsKey !== labelsKey) {  // component names drawn once, then copied
      const lc = document.createElement("canvas");
      lc.width = left * dpr; lc.height = height * dpr;
      const lx = lc.getContext("2d");
      lx.setTransform(dpr, 0, 0, dpr, 0, 0);
      lx.font = "11px system-ui, sans-serif";
      lx.fillStyle = "#1d2125";
      comps.forEach((comp, i) => lx.fillText(comp, 4, top + i * rowH + 10));
      S.labels = lc;
      S.labelsKey = labelsKey;
    }
    ctx.drawImage(S.labels, 0, 0, left, height);
    ctx.font = "11px system-ui, sans-serif";
    comps.forEach((comp, i) => {
      const y = top + i * rowH;
      const list = segs[comp] || [];
      for (let k = 0; k < list.length; k++) {
        const [ts, state] = list[k];
        const end = k + 1 < list.length ? list[k + 1][0] : now;
        if (state === "gone") continue;
        ctx.fillStyle = STATE_COLORS[state] || "#cbd5e1";
        ctx.fillRect(xOf(ts), y + 2, Math.max(1, xOf(end) - xOf(ts)), rowH - 4);
      }
    });
    for (const mo of S.moments) {
      const c = MARKERS[mo.kind];
      if (!c || mo.ts < t0) continue;
      ctx.strokeStyle = c;
      ctx.beginPath();
      ctx.moveTo(xOf(mo.ts), top);
      ctx.lineTo(xOf(mo.ts), height - 16);
      ctx.stroke();
    }
    ctx.fillStyle = "#6b7280";
    ctx.fillText(clock(t0), left, height - 4);
    ctx.fillText(clock(now), width - 60, height - 4);
  }

  // Each component's timeline: [ts, state, instance, robot, was_standby] from its `component`
  // moments (whichever instance is its active), rebuilt only when the moments change.
  function segments() {
    if (S.segsAt !== S.momentsVersion) {
      S.segs = {};
      for (const mo of S.moments) {
        if (mo.kind !== "component") continue;
        (S.segs[mo.component] ||= []).push([mo.ts, mo.state, mo.instance, mo.robot, mo.was_standby]);
      }
      S.segsAt = S.momentsVersion;
    }
    return S.segs;
  }

  // What the timeline draws for a component: [from, to, state, instance, was_standby] spans
  // (the browser test reads it: a failover must be a change of state, never a gap).
  S.timeline = (comp) => {
    const list = segments()[comp] || [];
    const now = S.t.length ? S.t[S.t.length - 1] : Date.now() / 1000;
    return list.map(([ts, state, inst, , promoted], k) =>
      [ts, k + 1 < list.length ? list[k + 1][0] : Math.max(ts, now), state, inst, !!promoted]);
  };

  function fleetEvent(m) {
    return {
      id: null, ts: m.ts, kind: `fleet.${m.kind}`, robot: m.to || m.leader || "",
      detail: Object.fromEntries(Object.entries(m).filter(([k]) => k !== "ts" && k !== "kind")),
    };
  }

  function row(e) {  // each event's row and search text are made once
    if (e._row === undefined) {
      const detail = JSON.stringify(e.detail);
      e._text = `${e.kind} ${e.robot} ${detail}`.toLowerCase();
      e._row = `<tr data-kind="${esc(e.kind)}"><td>${clock(e.ts)}</td><td>${esc(e.kind)}</td>` +
        `<td>${esc(e.robot)}</td><td class="detail">${esc(detail)}</td></tr>`;
    }
    return e._row;
  }

  function renderEvents() {
    const kind = $("event-kind").value, text = $("event-text").value.toLowerCase();
    const all = S.events.concat(S.fleet).sort((a, b) => b.ts - a.ts);
    const match = (e) => (!kind || e.kind.startsWith(kind) || (kind === "allocation" && e.kind.startsWith("plan"))) &&
      (!text || (row(e), e._text.includes(text)));
    const rows = [];
    let shown = 0;
    for (const e of all) {
      if (!match(e)) continue;
      if (shown++ < MAX_ROWS) rows.push(row(e));
    }
    const html = rows.join("");
    if (html !== S.eventsHtml) {
      $("events").tBodies[0].innerHTML = html;
      S.eventsHtml = html;
    }
    $("event-count").textContent = `${Math.min(shown, MAX_ROWS)} of ${shown} shown (${all.length} kept)`;
  }

  function renderLegend() {
    $("state-legend").innerHTML = ["active", "inactive", "error", "pending", "robot down", "lost"].map((s) =>
      `<span style="--c:${STATE_COLORS[s]}">${s}</span>`).join("") +
      Object.entries(MARKERS).map(([k, c]) => `<span style="--c:${c}">${k}</span>`).join("");
  }

  // ------------------------------------------------------------------ compliance
  // The status's `compliance` rows (sdrpeer.recovery.compliance.rows): one per constraint of a
  // running placement, grouped by component; a violated row is red, one past its bound for less
  // than the sustain ("holding") amber, an unmeasured one grey.
  const TABLE_I = new Set(["cpu", "memory", "battery"]);
  function quantity(constraint, v) {
    if (v === null || v === undefined) return "-";
    switch (constraint) {
      case "loss": return `${num(v * 100, 1)} %`;
      case "cpu": case "battery": return `${num(v, 1)} %`;
      case "memory": return `${num(v / 1e6, 0)} MB`;
      case "rssi": return `${num(v, 1)} dBm`;
      case "delay": case "jitter": return `${num(v, 2)} ms`;
      case "distance": return `${num(v, 1)} m`;
      default: return num(v, 2);
    }
  }
  function renderCompliance() {
    const rows = (S.status && S.status.compliance) || [];
    const html = rows.map((r, i) => {
      const first = i === 0 || rows[i - 1].component !== r.component;
      const of = TABLE_I.has(r.constraint) ? r.subject : `${r.subject} (${(r.robots || []).join(" / ")})`;
      return `<tr class="c-${esc(r.state)}" data-component="${esc(r.component)}" ` +
        `data-constraint="${esc(r.constraint)}" data-state="${esc(r.state)}">` +
        `<td>${first ? esc(r.component) : ""}</td><td>${TABLE_I.has(r.constraint) ? "I" : "II"}</td>` +
        `<td>${esc(r.constraint)}</td><td>${esc(of)}</td>` +
        `<td class="num">${quantity(r.constraint, r.value)}</td>` +
        `<td class="num">${esc(r.must_be)} ${quantity(r.constraint, r.bound)}</td>` +
        `<td><span class="badge comp-${esc(r.state)}">${esc(r.state)}</span></td>` +
        `<td>${r.since == null ? "-" : clock(r.since)}</td></tr>`;
    });
    $("compliance").tBodies[0].innerHTML = html.length ? html.join("")
      : '<tr><td colspan="8" class="muted">no constraint applies to a running placement</td></tr>';
  }

  const RENDER = {
    compliance: renderCompliance,
    summary: renderSummary, warnings: renderWarnings, fleet: renderFleet, topology: renderTopology,
    charts: renderCharts, states: renderStates, events: renderEvents,
  };

  // ------------------------------------------------------------------ the stream
  function connect() {
    const es = new EventSource(SNAPSHOT ? "/v1/stream?once=1" : "/v1/stream");
    const on = (kind, fn) => es.addEventListener(kind, (msg) => fn(JSON.parse(msg.data)));
    on("hello", (h) => {
      S.robot = h.robot;
      S.windowS = h.window_s;
      $("robot").textContent = h.robot;
      document.title = `sdrpeer · ${h.robot}`;
    });
    on("history", setHistory);
    on("events", (list) => { S.events = []; addEvents(list); });
    on("event", (e) => addEvents([e]));
    on("sample", addSample);
    on("end", () => {  // snapshot mode: everything is here; draw it now and keep nothing open
      es.close();
      S.connected = false;
      $("conn").className = "conn snap";
      $("conn").textContent = `snapshot ${S.t.length ? clock(S.t[S.t.length - 1]) : ""}`;
      mark("summary", "warnings", "fleet", "topology", "compliance", "charts", "states", "events");
      render();
      document.documentElement.dataset.snapshot = "ready";
    });
    es.onopen = () => {
      if (SNAPSHOT) return;
      S.connected = true; $("conn").className = "conn on"; $("conn").textContent = "live";
    };
    es.onerror = () => {
      if (SNAPSHOT) return;
      S.connected = false; $("conn").className = "conn off"; $("conn").textContent = "reconnecting";
    };
  }

  function frames(last) {  // frame intervals, for the benchmark's smoothness figure
    requestAnimationFrame((now) => {
      if (last !== undefined) {
        S.perf.frames.push(now - last);
        if (S.perf.frames.length > MAX_PERF) S.perf.frames.splice(0, S.perf.frames.length - MAX_PERF);
      }
      frames(now);
    });
  }

  let resized = null;
  window.addEventListener("resize", () => {
    clearTimeout(resized);
    resized = setTimeout(() => {
      S.chartRobots = null;
      S.topoWidth = 0;
      S.statesWidth = 0;
      mark("charts", "topology", "states");
    }, 200);
  });
  $("event-kind").addEventListener("change", () => mark("events"));
  $("event-text").addEventListener("input", () => mark("events"));
  const edgeOf = (e) => { const el = e.target.closest("[data-edge]"); return el ? Number(el.dataset.edge) : null; };
  for (const id of ["topology", "connections"]) {
    $(id).addEventListener("mouseover", (e) => showEdge(edgeOf(e)));
    $(id).addEventListener("mouseleave", () => showEdge(null));
  }
  renderLegend();
  if (!SNAPSHOT) frames();
  connect();
})();
