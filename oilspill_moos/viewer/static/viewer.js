// pMarineViewer page: draws what the server pushes (snapshot, then batches of updates) on a canvas
// in local x/y metres (+x east, +y north), and sends button presses / replay controls back.
"use strict";

const STALE_SECONDS = 10;          // MOOS seconds without a NODE_REPORT before a vehicle is greyed
const PALETTE = ["#ffd23f", "#ff6b6b", "#4ecdc4", "#c77dff", "#ff9f1c", "#9ef01a", "#48bfe3", "#f15bb5"];
// Forecast horizons, nearest first: colour and dash both differ, so they stay apart in grey too.
const FORECAST_STYLES = [
  { color: "#ff5fa2", dash: [] }, { color: "#b388ff", dash: [10, 5] }, { color: "#5ab4ff", dash: [4, 4] },
  { color: "#4de0c8", dash: [12, 4, 2, 4] }, { color: "#d4e157", dash: [2, 4] },
];

const state = {
  setup: null, time: 0, vehicles: new Map(), markers: new Map(), boundary: null, forecasts: [], starts: {}, loops: {},
  phase: "", commanded: {}, status: "", trailLength: 200, replay: null,
  observations: [], observedEdge: [], skill: "", ended: "", statusFields: [], skillFields: [],
};
const MAX_OBSERVATIONS = 1000;
const view = { cx: 0, cy: 0, scale: 0.5, userMoved: false };   // scale: pixels per metre
const stats = { messages: 0, updates: 0, frames: 0, frameMs: [], batchMs: [], connectedAt: 0 };
window.viewerStats = stats;
window.viewerState = state;
window.viewerView = view;

const canvas = document.getElementById("map");
const ctx = canvas.getContext("2d");
let socket = null;
let dirty = true;

// ---- connection ---------------------------------------------------------------------------------

function connect() {
  const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws";
  socket = new WebSocket(url);
  socket.onopen = () => { setLink(true); stats.connectedAt = performance.now(); };
  socket.onclose = () => {
    setLink(false);
    if (!state.ended) setTimeout(connect, 1000);   // a mission that ended has nothing more to say
  };
  socket.onmessage = (event) => {
    stats.messages += 1;
    const msg = JSON.parse(event.data);
    if (msg.type === "snapshot") loadSnapshot(msg);
    else if (msg.type === "batch") applyBatch(msg);
    dirty = true;
  };
}

function send(command) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(command));
}

function setLink(up) {
  const replaying = state.setup && state.setup.mode === "replay";
  document.getElementById("link-dot").className = state.ended ? "ended" : up ? "" : "down";
  document.getElementById("link-text").textContent = state.ended ? "mission ended"
    : up ? (replaying ? "replay" : "live") : "disconnected — retrying";
}

// The mission is over: say so over the map and keep the last picture (nothing is cleared).
function showEnded() {
  document.getElementById("ended").hidden = !state.ended;
  document.getElementById("ended-text").textContent = state.ended
    ? `(${state.ended}, ${clockText(state.time)} mission time)` : "";
  for (const b of document.querySelectorAll("#controls button")) b.disabled = Boolean(state.ended);
  setLink(socket !== null && socket.readyState === WebSocket.OPEN);
}

// An oil-spill mission shows its phase, status, forecast toggle and key; another (s1_alpha, ...)
// shows them only once spill data turns up (a replay of an unknown log).
function showSpill() {
  const spill = Boolean(state.setup && state.setup.spill) || Boolean(state.boundary) || state.forecasts.length > 0
    || Object.keys(state.loops).length > 0;
  document.getElementById("key").hidden = !spill;
  document.getElementById("forecast-toggle").hidden = !spill;
  document.getElementById("phase-section").hidden = !(spill || state.phase || state.status || state.skill);
}

// ---- the picture ----------------------------------------------------------------------------------

function loadSnapshot(msg) {
  const first = state.setup === null || state.setup.mode !== msg.mode;
  state.setup = { mode: msg.mode, community: msg.community, origin: msg.origin, buttons: msg.buttons, t0: msg.t0,
    actions: msg.actions, spill: msg.spill };
  state.vehicles.clear();
  state.markers.clear();
  state.trailLength = msg.trail_length;
  for (const v of msg.vehicles) state.vehicles.set(v.name.toLowerCase(), { ...v, trail: v.trail });
  for (const m of msg.markers) state.markers.set(m.kind + "/" + m.label, m);
  Object.assign(state, { boundary: msg.boundary, forecasts: msg.forecasts, starts: msg.starts, loops: msg.loops, phase: msg.phase,
    commanded: msg.commanded, status: msg.status, time: msg.time, observations: msg.observations,
    observedEdge: msg.observed_edge, skill: msg.skill, ended: msg.ended || "", statusFields: msg.status_fields,
    skillFields: msg.skill_fields });
  if (first) { buildControls(); setLink(true); }
  document.getElementById("log").replaceChildren();
  for (const note of msg.notes) addNote(note);
  setReplay(msg.replay || null);
  refreshForecasts();
  refreshPanel();
  showEnded();
  if (!view.userMoved) fit();
}

function applyBatch(msg) {
  const started = performance.now();
  if (!state.ended) state.time = msg.time;   // the clock stops with the mission
  if (msg.replay) setReplay(msg.replay);
  for (const u of msg.updates) apply(u);
  stats.updates += msg.updates.length;
  refreshPanel();
  if (!view.userMoved && msg.updates.length) fit();
  stats.batchMs.push(performance.now() - started);
  if (stats.batchMs.length > 600) stats.batchMs.shift();
}

function apply(u) {
  switch (u.t) {
    case "vehicle": {
      const key = u.name.toLowerCase();
      const old = state.vehicles.get(key);
      const trail = old ? old.trail : [];
      trail.push([u.x, u.y]);
      if (trail.length > state.trailLength) trail.splice(0, trail.length - state.trailLength);
      state.vehicles.set(key, { ...u, trail });
      break;
    }
    case "marker":
      if (u.active) state.markers.set(u.kind + "/" + u.label, u);
      else state.markers.delete(u.kind + "/" + u.label);
      break;
    case "boundary": state.boundary = u.points; break;
    case "forecasts": state.forecasts = u.forecasts; refreshForecasts(); break;
    case "phase": state.phase = u.phase; break;
    case "commanded": state.commanded[u.name] = u.phase; break;
    case "start": state.starts[u.name] = u.point; break;
    case "loop": state.loops[u.name] = u.points; break;
    case "status": state.status = u.text; state.statusFields = u.fields; break;
    case "obs":
      state.observations.push(u);
      if (state.observations.length > MAX_OBSERVATIONS) state.observations.shift();
      break;
    case "edge": state.observedEdge = u.points; break;
    case "skill": state.skill = u.text; state.skillFields = u.fields; break;
    case "note": addNote(u); break;
    case "ended": state.ended = u.text; showEnded(); break;
    case "resumed": state.ended = ""; showEnded(); break;
  }
}

// ---- panel ----------------------------------------------------------------------------------------

function buildControls() {
  const box = document.getElementById("buttons");
  box.replaceChildren();
  state.setup.buttons.forEach((label, index) => {
    const b = document.createElement("button");
    b.textContent = label;
    b.dataset.label = label;
    if (label === "RETURN_ALL") b.className = "return";
    if (label === "RE-PUSH BOUNDARY") {
      b.className = "repush";
      b.onclick = () => send({ cmd: "repush" });
    } else {
      b.onclick = () => send({ cmd: "button", index });
    }
    box.appendChild(b);
  });
  const actions = state.setup.actions || [];
  const menu = document.getElementById("actions");
  menu.replaceChildren(...actions.map((label, index) => new Option(label, String(index))));
  document.getElementById("action-row").hidden = actions.length === 0;
  document.getElementById("do-action").onclick = () => send({ cmd: "action", index: Number(menu.value) });
  document.getElementById("controls").hidden = state.setup.buttons.length === 0 && actions.length === 0;
  document.getElementById("community").textContent = state.setup.community
    ? "community " + state.setup.community : "";
}

// By name, so a vehicle keeps its row and colour whatever order its reports arrive in.
function sortedVehicles() {
  return [...state.vehicles.values()].sort((a, b) => a.name.localeCompare(b.name));
}

function vehicleColor(v, index) {
  return cssColor(v.color) || PALETTE[index % PALETTE.length];
}

function refreshPanel() {
  const replaying = state.setup && state.setup.mode === "replay";
  document.getElementById("clock").textContent = (replaying ? "log time " : "mission time ") + clockText(state.time);
  const phase = document.getElementById("phase");
  phase.textContent = state.phase || "—";
  phase.className = "phase-tag ph-" + (state.phase || "none");
  showFields(document.getElementById("status"), state.status, state.statusFields, "no status yet");
  const skill = document.getElementById("skill");
  skill.hidden = !state.skill;
  showFields(skill, state.skill, state.skillFields, "");
  showSpill();
  const body = document.querySelector("#vehicles tbody");
  const rows = [];
  sortedVehicles().forEach((v, i) => {
    const tr = document.createElement("tr");
    const age = Math.max(0, state.time - v.seen);
    tr.dataset.name = v.name.toLowerCase();
    tr.className = age > STALE_SECONDS ? "stale" : "";
    const commanded = state.commanded[v.name.toLowerCase()];
    tr.innerHTML = `<td><span class="swatch"></span><span class="name"></span></td>` +
      `<td class="phase"></td><td class="num">${v.spd.toFixed(1)}</td><td class="num">${v.hdg.toFixed(0)}</td>` +
      `<td class="num">${age.toFixed(0)}s</td>`;
    tr.querySelector(".swatch").style.background = vehicleColor(v, i);
    tr.querySelector(".name").textContent = v.name;
    const cell = tr.querySelector(".phase");
    cell.textContent = v.phase || "?";
    cell.className = "phase ph-" + v.phase;
    cell.title = "mode " + v.mode + (commanded ? "; shore asks " + commanded : "");
    rows.push(tr);
  });
  body.replaceChildren(...rows);
}

const FIELD_UNITS = { boundary_age: " s", horizon: " h" };
// A status line for people: one row per field (the server splits the `key=value` line), "boundary
// age  12.3 s", a vehicle list with spaces (so it wraps between names), -1 (pPathAssign's "none
// yet") as a dash; the raw line in the tooltip.
function showFields(dl, text, fields, empty) {
  const rows = [];
  for (const [key, raw] of fields) {
    const unit = FIELD_UNITS[key] || (key.endsWith("_m") ? " m" : "");
    const name = (unit === " m" ? key.slice(0, -2) : key).replace(/_/g, " ");
    const value = raw === "-1" ? "—" : key === "vehicles" ? raw.split(":").join(", ") : raw + (raw ? unit : "");
    const dt = document.createElement("dt"), dd = document.createElement("dd");
    dt.textContent = name || "·";
    dd.textContent = value || "—";
    dd.dataset.key = key;
    rows.push(dt, dd);
  }
  if (!rows.length && empty) {
    const dd = document.createElement("dd");
    dd.className = "empty";
    dd.textContent = empty;
    rows.push(dd);
  }
  dl.replaceChildren(...rows);
  dl.title = (dl.id === "status" ? "OILSPILL_STATUS" : "OIL_FUSION_SKILL") + (text ? ": " + text : "");
}

// The legend: one row per horizon of the forecast shown, in the style it is drawn with.
function refreshForecasts() {
  const rows = state.forecasts.map((f, i) => {
    const style = FORECAST_STYLES[i % FORECAST_STYLES.length];
    const li = document.createElement("li");
    li.dataset.horizon = String(f.horizon);
    const svg = `<svg width="26" height="12" aria-hidden="true"><rect x="0" y="1" width="26" height="10" ` +
      `fill="${style.color}" fill-opacity="${f.band.length ? 0.22 : 0}"/><line x1="0" y1="6" x2="26" y2="6" ` +
      `stroke="${style.color}" stroke-width="2" stroke-dasharray="${style.dash.join(" ")}"/></svg>`;
    li.innerHTML = svg + `<b class="horizon"></b><span class="band"></span><span class="valid"></span>`;
    li.querySelector(".horizon").textContent = horizonText(f.horizon);
    li.querySelector(".band").textContent = f.uncertainty > 0 ? "±" + distanceText(f.uncertainty) : "no band";
    li.querySelector(".valid").textContent = f.valid === null ? f.source : `${utcText(f.valid)} ${f.source}`;
    li.title = `cycle ${f.cycle}, ${f.source}` +
      (f.valid === null ? "" : `, valid ${new Date(f.valid * 1000).toISOString()}`);
    return li;
  });
  document.getElementById("forecast-legend").replaceChildren(...rows);
  document.getElementById("forecast-section").hidden = rows.length === 0;
  dirty = true;
}

function horizonText(h) { return `+${Number(h.toFixed(2))} h`; }
function distanceText(m) { return m >= 1000 ? `${Number((m / 1000).toFixed(1))} km` : `${Math.round(m)} m`; }
function utcText(t) { return new Date(t * 1000).toISOString().slice(5, 16).replace("T", " ") + "Z"; }

// Times are shown as mission time: seconds of (warped) MOOS time since the viewer started,
// or since the start of the log in a replay, as pMarineViewer's clock counts.
function clockText(t) {
  const s = Math.max(0, t - ((state.setup && state.setup.t0) || 0));
  const h = Math.floor(s / 3600), m = Math.floor(s / 60) % 60, sec = (s % 60).toFixed(1).padStart(4, "0");
  return (h ? `${h}:${String(m).padStart(2, "0")}` : `${m}`) + `:${sec}`;
}

function addNote(note) {
  const log = document.getElementById("log");
  const li = document.createElement("li");
  li.className = note.level;
  li.textContent = `${clockText(note.time)}  ${note.text}`;
  log.prepend(li);
  while (log.children.length > 50) log.lastChild.remove();
}

// ---- replay controls --------------------------------------------------------------------------------

let sliderHeld = false;
function setReplay(replay) {
  state.replay = replay;
  const bar = document.getElementById("replay-bar");
  bar.hidden = !replay;
  if (!replay) return;
  const slider = document.getElementById("slider");
  slider.max = replay.end;
  if (!sliderHeld) slider.value = replay.t;
  document.getElementById("replay-time").textContent = `${replay.t.toFixed(1)} / ${replay.end.toFixed(1)} s`;
  document.getElementById("play").textContent = replay.playing ? "❚❚" : "▶";
}

document.getElementById("play").onclick = () => send({ cmd: state.replay && state.replay.playing ? "pause" : "play" });
document.getElementById("speed").onchange = (e) => send({ cmd: "speed", speed: Number(e.target.value) });
const sliderEl = document.getElementById("slider");
sliderEl.oninput = () => { sliderHeld = true; };
sliderEl.onchange = () => { sliderHeld = false; send({ cmd: "seek", t: Number(sliderEl.value) }); };

// ---- drawing --------------------------------------------------------------------------------------

const colorCache = new Map();
function cssColor(name) {
  if (!name) return null;
  if (colorCache.has(name)) return colorCache.get(name);
  const css = name.toLowerCase().replace(/_/g, "");
  ctx.fillStyle = "#010203";
  ctx.fillStyle = css;
  const ok = ctx.fillStyle !== "#010203" ? css : null;
  colorCache.set(name, ok);
  return ok;
}

function toScreen(x, y) {
  return [canvas.width / 2 + (x - view.cx) * view.scale, canvas.height / 2 - (y - view.cy) * view.scale];
}
function toWorld(px, py) {
  return [view.cx + (px - canvas.width / 2) / view.scale, view.cy - (py - canvas.height / 2) / view.scale];
}

function path(points, close) {
  ctx.beginPath();
  points.forEach(([x, y], i) => { const [sx, sy] = toScreen(x, y); if (i) ctx.lineTo(sx, sy); else ctx.moveTo(sx, sy); });
  if (close) ctx.closePath();
}

function niceStep(metres) {
  const p = Math.pow(10, Math.floor(Math.log10(metres)));
  for (const m of [1, 2, 5, 10]) if (m * p >= metres) return m * p;
  return 10 * p;
}

function drawGrid() {
  const step = niceStep(90 / view.scale);
  const [x0, y1] = toWorld(0, 0), [x1, y0] = toWorld(canvas.width, canvas.height);
  ctx.strokeStyle = state.setup && state.setup.origin && document.getElementById("show-latlon").checked
    ? "rgba(120, 160, 200, 0.06)" : "rgba(120, 160, 200, 0.12)";   // under a lat/long grid, fainter
  ctx.lineWidth = 1;
  ctx.beginPath();
  for (let x = Math.ceil(x0 / step) * step; x <= x1; x += step) {
    const [sx] = toScreen(x, 0); ctx.moveTo(sx, 0); ctx.lineTo(sx, canvas.height);
  }
  for (let y = Math.ceil(y0 / step) * step; y <= y1; y += step) {
    const [, sy] = toScreen(0, y); ctx.moveTo(0, sy); ctx.lineTo(canvas.width, sy);
  }
  ctx.stroke();
  const [ox, oy] = toScreen(0, 0);
  ctx.strokeStyle = "rgba(200, 220, 255, 0.35)";
  ctx.beginPath(); ctx.moveTo(ox - 8, oy); ctx.lineTo(ox + 8, oy); ctx.moveTo(ox, oy - 8); ctx.lineTo(ox, oy + 8); ctx.stroke();
}

function drawScaleBar() {
  const metres = niceStep(120 / view.scale);
  const px = metres * view.scale, x = 14, y = canvas.height - 18;
  ctx.fillStyle = "rgba(13, 27, 42, 0.8)";
  ctx.fillRect(x - 6, y - 20, px + 12, 28);
  ctx.strokeStyle = "#e0e6ee"; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(x, y - 5); ctx.lineTo(x, y); ctx.lineTo(x + px, y); ctx.lineTo(x + px, y - 5); ctx.stroke();
  ctx.fillStyle = "#e0e6ee"; ctx.font = "11px system-ui, sans-serif";
  ctx.fillText(metres >= 1000 ? `${metres / 1000} km` : `${metres} m`, x + 2, y - 8);
}

function drawBoundary() {
  if (!state.boundary || state.boundary.length < 3) return;
  path(state.boundary, true);
  ctx.fillStyle = "rgba(30, 22, 12, 0.72)";
  ctx.fill();
  ctx.strokeStyle = "#c98b2b"; ctx.lineWidth = 2; ctx.stroke();
  queueLabel("spill boundary", toScreen(...state.boundary[0]), 2, "#e8b25a", "11px system-ui, sans-serif", 3);
}

// Far horizons first so the near ones, the ones the fleet is likeliest to meet, lie on top: the
// band (every ring of it, filled even-odd so the inner buffer stays clear), then the outline.
function drawForecasts() {
  for (let i = state.forecasts.length - 1; i >= 0; i--) {
    const f = state.forecasts[i], style = FORECAST_STYLES[i % FORECAST_STYLES.length];
    if (f.band.length) {
      ctx.beginPath();
      for (const ring of f.band) {
        ring.forEach(([x, y], j) => { const [sx, sy] = toScreen(x, y); if (j) ctx.lineTo(sx, sy); else ctx.moveTo(sx, sy); });
        ctx.closePath();
      }
      ctx.fillStyle = style.color; ctx.globalAlpha = 0.16; ctx.fill("evenodd");
      ctx.strokeStyle = style.color; ctx.globalAlpha = 0.4; ctx.lineWidth = 0.8; ctx.stroke(); ctx.globalAlpha = 1;
    }
    path(f.points, true);
    ctx.strokeStyle = style.color; ctx.lineWidth = 1.8; ctx.setLineDash(style.dash); ctx.stroke(); ctx.setLineDash([]);
  }
  labelForecasts();
}

// Each outline's label at its northernmost vertex, nearest horizon first (the outlines of one
// forecast often share a top: the label placer moves the later ones aside).
function labelForecasts() {
  state.forecasts.forEach((f, i) => {
    queueLabel(horizonText(f.horizon), toScreen(...f.points.reduce((a, b) => (b[1] > a[1] ? b : a))), 3,
               FORECAST_STYLES[i % FORECAST_STYLES.length].color, "bold 11px system-ui, sans-serif", 2);
  });
}

// ---- labels: placed last, none over another or over a vehicle ------------------------------------

const LABEL_H = 13;
let queuedLabels = [], labelObstacles = [];
window.viewerLabels = [];   // what was placed in the last frame: {text, x, y, w, h} (tests read it)
window.viewerObstacles = [];   // the vehicles' hulls and the points' dots it kept clear of

// `rank`: lower is placed first and so gets its preferred spot (vehicle names 0, markers 1, ...).
function queueLabel(text, [x, y], clearance, color, font, rank) {
  if (text) queuedLabels.push({ text, x, y, clearance, color, font, rank, order: queuedLabels.length });
}

function overlaps(a, b) { return a.x < b.x + b.w && b.x < a.x + a.w && a.y < b.y + b.h && b.y < a.y + a.h; }

// Around the anchor: right, upper right, lower right, left, above, below; then the same rings
// further out, with a leader line back to the anchor. A label that fits nowhere takes its first spot.
function placeLabels() {
  const placed = [];
  queuedLabels.sort((a, b) => a.rank - b.rank || a.order - b.order);
  for (const label of queuedLabels) {
    ctx.font = label.font;
    const w = ctx.measureText(label.text).width + 2, h = LABEL_H;
    let chosen = null, ring = 0;
    for (; ring < 5 && !chosen; ring++) {
      const r = label.clearance + 3 + ring * (h + 2);
      for (const [dx, dy] of [[r, -h / 2 - 4], [r, -h - r * 0.6], [r, r * 0.6], [-w - r, -h / 2], [-w / 2, -h - r],
                              [-w / 2, r]]) {
        const box = { x: label.x + dx, y: label.y + dy, w, h };
        if (!placed.some((p) => overlaps(box, p)) && !labelObstacles.some((o) => overlaps(box, o))) {
          chosen = box;
          break;
        }
      }
    }
    if (!chosen) { ring = 1; chosen = { x: label.x + label.clearance + 3, y: label.y - h / 2 - 4, w, h }; }
    if (ring > 1) {   // moved away from its thing: a thin line shows whose it is
      ctx.strokeStyle = label.color; ctx.globalAlpha = 0.5; ctx.lineWidth = 1;
      ctx.beginPath(); ctx.moveTo(label.x, label.y);
      ctx.lineTo(Math.min(Math.max(label.x, chosen.x), chosen.x + w), Math.min(Math.max(label.y, chosen.y), chosen.y + h));
      ctx.stroke(); ctx.globalAlpha = 1;
    }
    ctx.fillStyle = label.color; ctx.textBaseline = "top";
    ctx.fillText(label.text, chosen.x + 1, chosen.y + 1);
    ctx.textBaseline = "alphabetic";
    placed.push({ text: label.text, ...chosen });
  }
  window.viewerLabels = placed;
  window.viewerObstacles = labelObstacles;
  queuedLabels = [];
  labelObstacles = [];
}

// ---- lat/long grid: lines of equal latitude and longitude from the page's linear readout -----------

const MINUTE_STEPS = [0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 15, 30, 60, 120, 300, 600];
window.viewerGrid = { lat: [], lon: [] };   // the labels drawn in the last frame (tests read them)

function latLon(o, x, y) { return [o.lat + o.dlat_dx * x + o.dlat_dy * y, o.lon + o.dlon_dx * x + o.dlon_dy * y]; }
function localOf(o, lat, lon) {
  const det = o.dlat_dx * o.dlon_dy - o.dlat_dy * o.dlon_dx, dl = lat - o.lat, dn = lon - o.lon;
  return [(o.dlon_dy * dl - o.dlat_dy * dn) / det, (o.dlat_dx * dn - o.dlon_dx * dl) / det];
}

// 28°44.25'N: degrees and decimal minutes, as many decimals as the grid step needs.
function minutesText(value, stepMin, pos, neg) {
  const decimals = stepMin >= 1 ? 0 : Math.ceil(-Math.log10(stepMin) - 1e-9);
  const a = Math.abs(value) + 1e-9;
  let deg = Math.floor(a), min = ((a - deg) * 60).toFixed(decimals);
  if (Number(min) >= 60) { deg += 1; min = (0).toFixed(decimals); }
  const hemi = value < 0 ? neg : pos;
  return stepMin >= 60 ? `${deg}°${hemi}` : `${deg}°${min.padStart(decimals ? decimals + 3 : 2, "0")}'${hemi}`;
}

function drawLatLonGrid() {
  const o = state.setup && state.setup.origin;
  window.viewerGrid = { lat: [], lon: [] };
  if (!o || !document.getElementById("show-latlon").checked) return;
  const corners = [[0, 0], [canvas.width, 0], [0, canvas.height], [canvas.width, canvas.height]]
    .map(([px, py]) => latLon(o, ...toWorld(px, py)));
  ctx.font = "10px ui-monospace, monospace";
  ctx.lineWidth = 1;
  for (const [index, dim, pos, neg] of [[0, canvas.height, "N", "S"], [1, canvas.width, "E", "W"]]) {
    const values = corners.map((c) => c[index]), lo = Math.min(...values), hi = Math.max(...values);
    const other = corners.map((c) => c[1 - index]), olo = Math.min(...other), ohi = Math.max(...other);
    const step = MINUTE_STEPS.find((m) => (hi - lo) * 60 / m <= Math.max(2, dim / 110)) || 600;
    for (let v = Math.ceil(lo * 60 / step) * step / 60; v <= hi; v += step / 60) {
      const ends = [olo, ohi].map((w) => toScreen(...(index === 0 ? localOf(o, v, w) : localOf(o, w, v))));
      ctx.strokeStyle = "rgba(150, 200, 170, 0.28)"; ctx.setLineDash([2, 4]);
      ctx.beginPath(); ctx.moveTo(...ends[0]); ctx.lineTo(...ends[1]); ctx.stroke(); ctx.setLineDash([]);
      const text = minutesText(v, step, pos, neg);
      // latitudes labelled at the left edge, longitudes along the top below the map tools
      const [[x0, y0], [x1, y1]] = ends;
      const at = index === 0 ? [4, y0 + (y1 - y0) * (4 - x0) / ((x1 - x0) || 1) - 3]
                             : [x0 + (x1 - x0) * (62 - y0) / ((y1 - y0) || 1) + 3, 62];
      if (at[1] < 76 && index === 0 || at[1] > canvas.height - 40 || at[0] > canvas.width - 70) continue;
      ctx.fillStyle = "rgba(170, 220, 190, 0.9)";
      ctx.fillText(text, ...at);
      window.viewerGrid[index === 0 ? "lat" : "lon"].push(text);
    }
  }
}

// Seglists (the helm's waypoint lists) first and faint, so the polygons and points drawn over
// them stay readable where the fleet shares one loop.
const MARKER_ORDER = { seglist: 0, polygon: 1, point: 2 };
function drawMarkers() {
  const markers = [...state.markers.values()].sort((a, b) => MARKER_ORDER[a.kind] - MARKER_ORDER[b.kind]);
  for (const m of markers) {
    const style = m.style || {};
    if (m.kind === "point") {
      const [sx, sy] = toScreen(...m.points[0]);
      const r = Math.max(2, Number(style.vertex_size) || 4);
      ctx.fillStyle = cssColor(style.vertex_color) || "#ffe066";
      ctx.beginPath(); ctx.arc(sx, sy, r, 0, 2 * Math.PI); ctx.fill();
      queueLabel(m.label, [sx, sy], r, "//cfd8e3", "10px system-ui, sans-serif", 1);
      labelObstacles.push({ x: sx - r, y: sy - r, w: 2 * r, h: 2 * r });   // no other label over the point
      continue;
    }
    if (m.points.length < 2) continue;
    path(m.points, m.kind === "polygon");
    const polygon = m.kind === "polygon";
    ctx.strokeStyle = cssColor(style.edge_color) || (polygon ? "#ffa94d" : "#b0c4de");
    ctx.lineWidth = polygon ? Math.max(1, Number(style.edge_size) || 1.5) : 1;
    ctx.globalAlpha = polygon ? 1 : 0.45;
    ctx.setLineDash(polygon ? [6, 4] : []);
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.globalAlpha = 1;
  }
}

// The vessels' oil samples (filled: oil within range; hollow: clear water) and the edge
// uFldOilFusion places half-way between samples whose reading flips.
function drawObservations() {
  for (const o of state.observations) {
    const [sx, sy] = toScreen(o.x, o.y);
    ctx.beginPath(); ctx.arc(sx, sy, 3, 0, 2 * Math.PI);
    if (o.oil) { ctx.fillStyle = "#d2691e"; ctx.fill(); }
    else { ctx.strokeStyle = "#7fdbff"; ctx.lineWidth = 1; ctx.stroke(); }
  }
  ctx.fillStyle = "#ffffff";
  for (const [x, y] of state.observedEdge) {
    const [sx, sy] = toScreen(x, y);
    ctx.fillRect(sx - 2, sy - 2, 4, 4);
  }
}

function drawPlans(colors) {
  for (const [name, points] of Object.entries(state.loops)) {
    if (points.length < 2) continue;
    path(points, true);
    ctx.strokeStyle = colors.get(name) || "#9fb3c8"; ctx.globalAlpha = 0.55; ctx.lineWidth = 1.5;
    ctx.setLineDash([3, 3]); ctx.stroke(); ctx.setLineDash([]); ctx.globalAlpha = 1;
  }
  for (const [name, point] of Object.entries(state.starts)) {
    const [sx, sy] = toScreen(...point);
    ctx.fillStyle = colors.get(name) || "#fff";
    star(sx, sy, 7);
    ctx.strokeStyle = "#0d1b2a"; ctx.lineWidth = 1; ctx.stroke();
  }
}

function star(x, y, r) {
  ctx.beginPath();
  for (let i = 0; i < 10; i++) {
    const a = Math.PI / 5 * i - Math.PI / 2, rr = i % 2 ? r * 0.45 : r;
    ctx.lineTo(x + rr * Math.cos(a), y + rr * Math.sin(a));
  }
  ctx.closePath(); ctx.fill();
}

function drawVehicles(colors) {
  const showTrails = document.getElementById("show-trails").checked;
  for (const v of state.vehicles.values()) {
    const color = colors.get(v.name.toLowerCase());
    const stale = state.time - v.seen > STALE_SECONDS;
    if (showTrails && v.trail.length > 1) {
      path(v.trail, false);
      ctx.strokeStyle = color; ctx.globalAlpha = 0.5; ctx.lineWidth = 1.2; ctx.stroke(); ctx.globalAlpha = 1;
    }
    const [sx, sy] = toScreen(v.x, v.y);
    const size = Math.max(9, (v.len || 4) * view.scale);
    labelObstacles.push({ x: sx - size, y: sy - size, w: 2 * size, h: 2 * size });
    ctx.save();
    ctx.translate(sx, sy);
    ctx.rotate(v.hdg * Math.PI / 180);
    ctx.beginPath();
    ctx.moveTo(0, -size); ctx.lineTo(size * 0.5, size * 0.6); ctx.lineTo(0, size * 0.3); ctx.lineTo(-size * 0.5, size * 0.6);
    ctx.closePath();
    if (stale) { ctx.strokeStyle = "#6b7f94"; ctx.lineWidth = 1.5; ctx.stroke(); }
    else { ctx.fillStyle = color; ctx.fill(); ctx.strokeStyle = "#0d1b2a"; ctx.lineWidth = 1; ctx.stroke(); }
    ctx.restore();
    queueLabel(v.name, [sx, sy], size, stale ? "#6b7f94" : "#e0e6ee", "bold 11px system-ui, sans-serif", 0);
  }
}

function draw() {
  const started = performance.now();
  ctx.fillStyle = "#0b2239";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  drawGrid();
  drawLatLonGrid();
  drawBoundary();
  if (document.getElementById("show-forecasts").checked) drawForecasts();
  const colors = new Map();
  sortedVehicles().forEach((v, i) => colors.set(v.name.toLowerCase(), vehicleColor(v, i)));
  if (document.getElementById("show-markers").checked) drawMarkers();
  drawObservations();
  drawPlans(colors);
  drawVehicles(colors);
  placeLabels();
  drawScaleBar();
  stats.frames += 1;
  stats.frameMs.push(performance.now() - started);
  if (stats.frameMs.length > 600) stats.frameMs.shift();
}

function frame() {
  if (dirty) { dirty = false; draw(); }
  requestAnimationFrame(frame);
}

// ---- view: fit, pan, zoom, readout --------------------------------------------------------------------

function extent() {
  const pts = [];
  for (const v of state.vehicles.values()) pts.push([v.x, v.y]);
  if (state.boundary) pts.push(...state.boundary);
  for (const f of state.forecasts) pts.push(...f.points);
  for (const p of Object.values(state.starts)) pts.push(p);
  for (const l of Object.values(state.loops)) pts.push(...l);
  for (const m of state.markers.values()) pts.push(...m.points);   // the helm's survey lines and points
  return pts;
}

function fit() {
  const pts = extent();
  if (!pts.length) return;
  const xs = pts.map((p) => p[0]), ys = pts.map((p) => p[1]);
  const [x0, x1, y0, y1] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  view.cx = (x0 + x1) / 2; view.cy = (y0 + y1) / 2;
  view.scale = Math.min(canvas.width / Math.max(x1 - x0 + 80, 80), canvas.height / Math.max(y1 - y0 + 80, 80)) * 0.85;
  dirty = true;
}

function resize() {
  const rect = canvas.getBoundingClientRect();
  canvas.width = Math.max(100, Math.floor(rect.width));
  canvas.height = Math.max(100, Math.floor(rect.height));
  dirty = true;
}

let drag = null;
canvas.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; canvas.classList.add("dragging"); });
window.addEventListener("mouseup", () => { drag = null; canvas.classList.remove("dragging"); });
canvas.addEventListener("mousemove", (e) => {
  const rect = canvas.getBoundingClientRect();
  const [x, y] = toWorld(e.clientX - rect.left, e.clientY - rect.top);
  document.getElementById("cursor-xy").textContent = `x ${x.toFixed(1)} m, y ${y.toFixed(1)} m`;
  const o = state.setup && state.setup.origin;
  document.getElementById("cursor-ll").textContent = o
    ? `lat ${(o.lat + o.dlat_dx * x + o.dlat_dy * y).toFixed(6)}, lon ${(o.lon + o.dlon_dx * x + o.dlon_dy * y).toFixed(6)}` : "";
  if (drag) {
    view.cx -= (e.clientX - drag[0]) / view.scale;
    view.cy += (e.clientY - drag[1]) / view.scale;
    drag = [e.clientX, e.clientY];
    view.userMoved = true; dirty = true;
  }
});
canvas.addEventListener("wheel", (e) => {
  e.preventDefault();
  const rect = canvas.getBoundingClientRect();
  const [wx, wy] = toWorld(e.clientX - rect.left, e.clientY - rect.top);
  view.scale *= Math.exp(-e.deltaY * 0.0015);
  const [nx, ny] = toWorld(e.clientX - rect.left, e.clientY - rect.top);
  view.cx += wx - nx; view.cy += wy - ny;     // keep the point under the cursor still
  view.userMoved = true; dirty = true;
}, { passive: false });
document.getElementById("fit").onclick = () => { view.userMoved = false; fit(); };
document.getElementById("show-trails").onchange = () => { dirty = true; };
document.getElementById("show-markers").onchange = () => { dirty = true; };
document.getElementById("show-forecasts").onchange = () => { dirty = true; };
document.getElementById("show-latlon").onchange = () => { dirty = true; };
window.addEventListener("resize", resize);

resize();
connect();
requestAnimationFrame(frame);
