// furnace-twin dashboard: REST + websocket client, plotly.js charts (served locally).
"use strict";

const GROUP_COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"];
const TC_COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728"];
const RENDER_MS = 250; // charts redraw at most 4 times per second; frames arrive up to 20/s
const MAX_POINTS = 3000; // per trace, older samples are thinned
const MAX_EVENTS = 200; // entries kept in the event log (newest at top)
const TOKEN_KEY = "furnace-twin-token"; // sessionStorage: this tab only, never in the URL
const T_MIN = 250, T_MAX = 1300, T_END_MAX = 3600; // what the server accepts for reference points (twin/scenario.py)

const state = {
  furnace: null, health: null, runId: null, run: null, ws: null, frames: 0,
  series: null, lastFrame: null, dirty: false, oscEnabled: false, tc4: [0.5, 0.5],
  eventSeq: -1, lastStatus: null, nEvents: 0, stopping: null,
};

const $ = (id) => document.getElementById(id);
const pct = (v, d = 2) => (v === null || v === undefined || Number.isNaN(v) ? "–" : (100 * v).toFixed(d));
const fmt = (v, d = 1) => (v === null || v === undefined || Number.isNaN(v) ? "–" : Number(v).toFixed(d));

function token() { return sessionStorage.getItem(TOKEN_KEY) || ""; }

// One validation error of FastAPI / pydantic as a sentence: "reference › point 2 › temperature: ..."
function formatValidation(e) {
  const loc = e.loc || [];
  const parts = [];
  for (let k = 0; k < loc.length; k++) {
    const p = loc[k];
    if (k === 0 && p === "body") continue;
    if (p === "transition" || p === parts[parts.length - 1]) continue; // tags of the reference union
    if (typeof p === "number" && parts[parts.length - 1] === "points") {
      parts.push(`point ${p + 1}`);
      if (loc[k + 1] === 0 || loc[k + 1] === 1) { parts.push(loc[k + 1] === 0 ? "time" : "temperature"); k += 1; }
      continue;
    }
    parts.push(String(p));
  }
  const msg = String(e.msg || "invalid").replace(/^Value error, /, "");
  return parts.length ? `${parts.join(" › ")}: ${msg}` : msg;
}

function formatDetail(detail) {
  if (typeof detail === "string") return detail;
  if (Array.isArray(detail)) return detail.map(formatValidation).join("; ");
  return JSON.stringify(detail);
}

async function api(method, path, body) {
  const headers = { "Content-Type": "application/json" };
  if (method !== "GET" && token()) headers["X-API-Token"] = token();
  let r;
  try {
    r = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  } catch (e) { throw new Error(`the server did not answer (${e.message})`); }
  let data = null;
  try { data = await r.json(); } catch (e) { data = null; }
  if (!r.ok) {
    const detail = data && data.detail !== undefined ? formatDetail(data.detail) : r.statusText;
    let text = `${r.status}: ${detail}`;
    if (r.status === 401) {
      $("token-box").hidden = false;
      $("token").classList.add("need");
      text = token() ? "401: the API token is wrong: correct it in the \u201cAPI token\u201d field at the top right"
        : "401: this server needs its API token: enter it in the \u201cAPI token\u201d field at the top right";
    }
    const err = new Error(text);
    err.status = r.status;
    throw err;
  }
  return data;
}

// ---------------------------------------------------------------- reference points
// "time, temperature" per line (comma, semicolon, tab or spaces between; # starts a comment).
// Returns [[t, T], ...] or throws an Error that names every bad line.
function parsePoints(text) {
  const points = [], problems = [];
  let prevT = null;
  text.split(/\r?\n/).forEach((raw, k) => {
    const line = raw.replace(/#.*$/, "").trim();
    if (!line) return;
    const where = `line ${k + 1}`;
    const parts = line.split(/[\s,;]+/).filter(Boolean);
    const nums = parts.map(Number);
    if (parts.length !== 2 || nums.some((v) => !Number.isFinite(v))) {
      problems.push(`${where}: \u201c${line}\u201d is not \u201ctime, temperature\u201d (two numbers, e.g. \u201c60, 900\u201d)`);
      return;
    }
    const [t, T] = nums;
    if (t < 0) problems.push(`${where}: time ${t} s is negative`);
    else if (t > T_END_MAX) problems.push(`${where}: time ${t} s is beyond ${T_END_MAX} s`);
    else if (prevT !== null && t <= prevT) problems.push(`${where}: time ${t} s is not after ${prevT} s (times must increase)`);
    if (T < T_MIN || T > T_MAX) problems.push(`${where}: ${T} K is outside ${T_MIN}\u2026${T_MAX} K`);
    prevT = t;
    points.push([t, T]);
  });
  if (!points.length && !problems.length) problems.push("enter at least one \u201ctime, temperature\u201d line");
  if (problems.length) {
    const shown = problems.slice(0, 3).join("; ");
    throw new Error(`reference points: ${shown}${problems.length > 3 ? ` (and ${problems.length - 3} more)` : ""}`);
  }
  return points;
}

function describeReference(ref) {
  if (!ref) return "–";
  if (ref.points) {
    const pts = ref.points.map(([t, T]) => `${fmt(t, 0)} s \u2192 ${fmt(T, 0)} K`);
    return `points ${pts.slice(0, 4).join(", ")}${pts.length > 4 ? `, \u2026 (${pts.length})` : ""}`;
  }
  return `${ref.setpoint} K in ${ref.t_E} s`;
}

function refMode(name) {
  const el = document.querySelector(`input[name="${name}"]:checked`);
  return el ? el.value : "transition";
}

function showRefMode(name) {
  const mode = refMode(name);
  for (const el of document.querySelectorAll(`[data-${name}]`)) el.hidden = el.dataset[camel(name)] !== mode;
}
const camel = (s) => s.replace(/-([a-z])/g, (_, c) => c.toUpperCase());

// The message line answers what the user did (a start, a PUT, a stop); the event log holds what the run reports.
function showMsg(text, isErr = false, id = "ctl-msg") {
  const el = $(id);
  el.textContent = text;
  el.className = isErr ? "msg err" : "msg";
}

function clearEvents() {
  $("event-log").innerHTML = '<li class="empty muted">events of the shown run appear here</li>';
  state.nEvents = 0;
  $("event-count").textContent = "";
}

function addEvent(t, text, kind = "") {
  const log = $("event-log");
  const empty = log.querySelector("li.empty");
  if (empty) empty.remove();
  const li = document.createElement("li");
  if (kind) li.className = kind;
  const ts = document.createElement("span");
  ts.className = "t";
  ts.textContent = t === null || t === undefined ? "" : `t = ${fmt(t)} s`;
  li.append(ts, document.createTextNode(` ${text}`));
  log.prepend(li); // newest at top
  while (log.children.length > MAX_EVENTS) log.lastElementChild.remove();
  state.nEvents += 1;
  $("event-count").textContent = `· ${state.nEvents}`;
}

function noteStatus(status, t) { // a status change of the shown run goes to the event log once
  if (!status || status === state.lastStatus) return;
  const first = state.lastStatus === null;
  state.lastStatus = status;
  if (first && !["queued", "starting", "running"].includes(status)) return;
  const run = state.run;
  const kind = status === "error" ? "err" : (status === "interrupted" ? "warn" : "");
  addEvent(t, `run ${status}${status === "error" && run && run.error ? `: ${run.error}` : ""}`, kind);
  if (state.stopping === state.runId && !["queued", "starting", "running"].includes(status)) { // the Stop reply, completed
    showMsg(`run ${state.runId} ${status}${t !== null && t !== undefined ? ` at t = ${fmt(t)} s` : ""}; its data is kept`);
    state.stopping = null;
  }
  if (status === "error" && run && run.error) showMsg(`run ${run.id} failed: ${run.error}`, true);
}

// ---------------------------------------------------------------- series buffer
function emptySeries() {
  return { t: [], T_ref: [], T_mean_hat: [], tcErr: [[], [], [], []], u: [[], [], [], [], [], []],
    u_ff: [[], [], [], [], [], []], inh_t: [], inh: [], eta: [], field: null };
}

function pushFrame(f) {
  const s = state.series;
  s.t.push(f.t); s.T_ref.push(f.T_ref); s.T_mean_hat.push(f.T_mean_hat); s.eta.push(f.eta);
  for (let i = 0; i < 4; i++) s.tcErr[i].push(f.tc[i] === null || f.tc_hat[i] === null ? null : f.tc[i] - f.tc_hat[i]);
  for (let j = 0; j < 6; j++) { s.u[j].push(f.u[j]); s.u_ff[j].push(f.u_ff[j]); }
  s.inh_t.push(f.t); s.inh.push(f.inhomogeneity);
  s.field = f.field;
  if (s.t.length > MAX_POINTS) thin(s);
}

function thin(s) { // keep every other sample: bounded memory for long runs
  const half = (a) => a.filter((_, k) => k % 2 === 0);
  for (const k of ["t", "T_ref", "T_mean_hat", "eta", "inh_t", "inh"]) s[k] = half(s[k]);
  s.tcErr = s.tcErr.map(half); s.u = s.u.map(half); s.u_ff = s.u_ff.map(half);
}

function seriesFromStored(d) {
  const s = emptySeries();
  s.t = d.t; s.T_ref = d.T_ref; s.T_mean_hat = d.T_mean_hat; s.eta = d.eta;
  for (let i = 0; i < 4; i++) s.tcErr[i] = d.tc.map((row, k) => (row[i] === null || d.tc_hat[k][i] === null ? null : row[i] - d.tc_hat[k][i]));
  for (let j = 0; j < 6; j++) { s.u[j] = d.u.map((r) => r[j]); s.u_ff[j] = d.u_ff.map((r) => r[j]); }
  s.inh_t = d.t_field || []; s.inh = d.inhomogeneity || [];
  s.field = d.field || null;
  return s;
}

// ---------------------------------------------------------------- charts
let revision = 0; // plotly redraws arrays that grew in place only when datarevision changes
const baseLayout = (title, ytitle, extra = {}) => Object.assign({
  datarevision: revision,
  title: { text: title, font: { size: 13 }, x: 0.02, xanchor: "left", y: 0.97 },
  margin: { l: 56, r: 12, t: 28, b: 36 },
  xaxis: { title: { text: "t (s)", standoff: 4 }, zeroline: false },
  yaxis: { title: { text: ytitle, standoff: 4 }, zeroline: false },
  legend: { orientation: "h", x: 0, y: -0.22, font: { size: 10 } },
  paper_bgcolor: "#fff", plot_bgcolor: "#fafbfc", font: { size: 11, color: "#1d2330" },
}, extra);
const CONFIG = { displaylogo: false, responsive: true, modeBarButtonsToRemove: ["lasso2d", "select2d"] };

const TURBO = [[0, "#30123b"], [0.1, "#4145ab"], [0.2, "#4675ed"], [0.3, "#39a2fc"], [0.4, "#1bcfd4"],
  [0.5, "#24eca6"], [0.6, "#61fc6c"], [0.7, "#a4fc3b"], [0.8, "#d1e834"], [0.9, "#f3c63a"], [1, "#7a0403"]];

function heatmapFigure() {
  const fu = state.furnace;
  const s = state.series;
  const [x0, x1, y0, y1] = fu.fillet;
  const tcRel = fu.tc_relative.slice(0, 3).concat([state.tc4]);
  const tcx = tcRel.map((p) => p[0] * fu.L_s), tcy = tcRel.map((p) => p[1] * fu.W_s);
  const z = s && s.field ? s.field : null;
  const f = state.lastFrame;
  const sub = f ? `t = ${fmt(f.t)} s · mean ${fmt(f.T_mean_hat)} K · ref ${fmt(f.T_ref)} K` : "";
  return {
    data: [
      { type: "heatmap", x: fu.x, y: fu.y, z: z || [[null]], colorscale: TURBO, zsmooth: "best",
        colorbar: { title: { text: "T (K)", side: "right" }, thickness: 12, len: 0.95 },
        hovertemplate: "x %{x:.3f} m<br>y %{y:.3f} m<br>%{z:.1f} K<extra></extra>" },
      { type: "scatter", mode: "markers+text", x: tcx, y: tcy, text: ["TC1", "TC2", "TC3", "TC4"],
        textposition: "top center", textfont: { color: "#fff", size: 11 }, hoverinfo: "text",
        marker: { symbol: ["circle", "circle", "circle", "diamond"], size: 9, color: ["#fff", "#fff", "#fff", "#ff4fc8"],
          line: { color: "#000", width: 1.5 } }, showlegend: false },
    ],
    layout: baseLayout(`Estimated field <span style="font-size:11px;color:#56627a">${sub}</span>`, "y (m)", {
      xaxis: { title: { text: "x (m), along the specimen length", standoff: 4 }, range: [0, fu.L_s], constrain: "domain" },
      yaxis: { title: { text: "y (m)", standoff: 4 }, range: [0, fu.W_s], scaleanchor: "x", scaleratio: 1, constrain: "domain" },
      margin: { l: 56, r: 12, t: 28, b: 38 },
      shapes: [{ type: "rect", x0, x1, y0, y1, line: { color: "#fff", width: 2, dash: "dash" } }],
      annotations: [{ x: x0, y: y0, xanchor: "left", yanchor: "bottom", xshift: 3, yshift: 2, text: "fillet",
        showarrow: false, font: { color: "#fff", size: 10 } }],
    }),
  };
}

// The user's reference points of the shown run (start and applied live changes) in run time.
function referenceMarkers(run) {
  const x = [], y = [];
  if (!run) return { x, y };
  const add = (ref, t0) => { if (ref && ref.points) for (const [t, T] of ref.points) { x.push(t0 + t); y.push(T); } };
  add(run.scenario.reference, 0);
  for (const ch of run.changes || []) if (ch.kind === "reference" && ch.status === "applied") add(ch.body, ch.applied_t || 0);
  return { x, y };
}

function lineFigures() {
  const s = state.series || emptySeries();
  const groups = state.furnace.groups;
  const pts = referenceMarkers(state.run);
  return {
    "mean-plot": {
      data: [
        { x: s.t, y: s.T_ref, name: "T_ref", line: { color: "#111", dash: "dash", width: 1.6 } },
        { x: s.t, y: s.T_mean_hat, name: "fillet mean (est.)", line: { color: "#d62728", width: 1.8 } },
        { x: pts.x, y: pts.y, name: "ref. points", mode: "markers", showlegend: pts.x.length > 0,
          marker: { symbol: "circle-open", size: 8, color: "#111", line: { width: 1.6 } },
          hovertemplate: "%{x:.1f} s, %{y:.0f} K<extra>reference point</extra>" },
      ],
      layout: baseLayout("Fillet mean vs reference", "T (K)"),
    },
    "tc-plot": {
      data: s.tcErr.map((e, i) => ({ x: s.t, y: e, name: i < 3 ? `TC${i + 1}` : "TC4 (validation)",
        line: { color: TC_COLORS[i], width: i < 3 ? 1.2 : 2 } })),
      layout: baseLayout("TC reading − estimate", "error (K)"),
    },
    "power-plot": {
      data: groups.flatMap((g, j) => [
        { x: s.t, y: s.u[j], name: `${g} u`, legendgroup: g, line: { color: GROUP_COLORS[j], width: 1.6 } },
        { x: s.t, y: s.u_ff[j], name: `${g} u_ff`, legendgroup: g, showlegend: false,
          line: { color: GROUP_COLORS[j], width: 1, dash: "dot" } },
      ]),
      layout: baseLayout("Group powers u (solid) and feedforward u_ff (dotted)", "u / u_max (–)",
        { yaxis: { title: { text: "u / u_max (–)", standoff: 4 }, range: [-0.02, 1.05] },
          legend: { orientation: "v", x: 1.01, y: 1, font: { size: 10 } }, margin: { l: 56, r: 90, t: 28, b: 36 } }),
    },
    "inh-plot": {
      data: [{ x: s.inh_t, y: s.inh, name: "T_sup", line: { color: "#805ad5", width: 1.6 } }],
      layout: baseLayout("Inhomogeneity max |T̂ − T_ref| on the fillet", "T_sup (K)", { showlegend: false }),
    },
    "eta-plot": {
      data: [{ x: s.t, y: s.eta.map((v) => v * 1000), name: "eta", line: { color: "#2c7a7b", width: 1.4 } }],
      layout: baseLayout("Specimen position η", "η (mm)", { showlegend: false }),
    },
  };
}

function render() {
  if (!state.furnace) return;
  revision += 1;
  const hm = heatmapFigure();
  Plotly.react("heatmap", hm.data, hm.layout, CONFIG);
  const figs = lineFigures();
  for (const [id, fig] of Object.entries(figs)) Plotly.react(id, fig.data, fig.layout, CONFIG);
  state.dirty = false;
}

setInterval(() => { if (state.dirty) render(); }, RENDER_MS);

// ---------------------------------------------------------------- runs
function badge(status) {
  const b = $("run-badge");
  b.textContent = status || "no run";
  b.className = `badge ${status || "idle"}`;
}

function setControls(run) {
  const live = run && ["queued", "starting", "running"].includes(run.status);
  for (const id of ["ref-btn", "osc-btn", "stop-btn"]) $(id).disabled = !live;
  $("ctl-run").textContent = run ? `· ${run.id}` : "";
  const osc = run ? currentOscillation(run) : null;
  state.oscEnabled = !!(osc && osc.enabled);
  $("osc-btn").textContent = state.oscEnabled ? "Oscillation off" : "Oscillation on";
  $("osc-btn").classList.toggle("on", state.oscEnabled);
}

function currentOscillation(run) {
  let osc = run.scenario.oscillation;
  for (const ch of run.changes || []) if (ch.kind === "oscillation" && ch.status === "applied") osc = ch.body;
  return osc;
}

function renderRunInfo(run) {
  if (!run) return;
  const m = run.metrics || {};
  const sc = run.scenario;
  const ref = describeReference(sc.reference);
  const rows = Object.entries(m).map(([k, v]) => `<tr><td>${k}</td><td class="num">${pct(v)} %</td></tr>`).join("");
  const files = run.files || {};
  const links = [
    files.recording ? `<a href="${run.links.recording}" download>recording.rrd</a>` : "",
    files.timeseries ? `<a href="${run.links.timeseries}" download>timeseries.npz</a>` : "",
    state.health && state.health.viser_url ? `<a href="${state.health.viser_url}" target="_blank" rel="noopener">3D view</a>` : "",
  ].filter(Boolean).join(" · ");
  $("run-details").innerHTML = `
    <div><b>${run.id}</b> · ${run.status}${run.error ? ` · <span style="color:#c53030">${run.error}</span>` : ""}</div>
    <div class="muted">reference ${ref} · ${sc.duration} s · speed ${sc.speed} · oscillation ${currentOscillation(run).enabled ? "on" : "off"} · TC4 (${sc.tc4.join(", ")})</div>
    <div>${links}</div>
    ${rows ? `<div class="muted">metrics, relative to the setpoint</div><table>${rows}</table>` : `<div class="muted">metrics when the run ends</div>`}`;
}

async function refreshRun(quiet = false) {
  if (!state.runId) return;
  try {
    const run = await api("GET", `/api/runs/${state.runId}`);
    if (run.id !== state.runId) return; // another run was picked meanwhile
    const before = state.run && state.run.id === run.id ? (state.run.changes || []).length : -1;
    state.run = run;
    badge(run.status);
    setControls(run);
    renderRunInfo(run);
    if (quiet) state.lastStatus = run.status; else noteStatus(run.status, run.latest ? run.latest.t : null);
    if ((run.changes || []).length !== before) state.dirty = true; // reference markers
  } catch (e) { /* transient */ }
}

function connectStream(runId) {
  if (state.ws) { state.ws.onclose = null; state.ws.close(); }
  const proto = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(`${proto}://${location.host}/api/runs/${runId}/stream`);
  state.ws = ws;
  ws.onmessage = (ev) => {
    const f = JSON.parse(ev.data);
    if (f.run_id !== state.runId) return;
    state.lastFrame = f;
    state.frames += 1;
    pushFrame(f);
    $("run-clock").textContent = `t = ${fmt(f.t)} s`;
    if (f.seq === undefined || f.seq > state.eventSeq) { // the last frame of a run may repeat its sample
      for (const ev of f.events || []) addEvent(f.t, ev, /fail|error|reject/i.test(ev) ? "warn" : "");
      if (f.seq !== undefined) state.eventSeq = f.seq;
    }
    if (f.status && f.status !== (state.run && state.run.status)) badge(f.status);
    if (f.status && !["queued", "starting", "running"].includes(f.status)) noteStatus(f.status, f.t);
    state.dirty = true;
  };
  ws.onclose = () => { if (state.ws === ws) { state.ws = null; refreshRun(); refreshHistory(); } };
}

async function selectRun(runId) {
  state.runId = runId;
  state.series = emptySeries();
  state.lastFrame = null;
  state.frames = 0;
  state.run = null;
  state.eventSeq = -1;
  state.lastStatus = null;
  clearEvents();
  await refreshRun(true);
  const run = state.run;
  if (!run || run.id !== runId) return;
  for (const ch of run.changes || []) { // what was changed before this page showed the run
    const what = ch.kind === "reference" ? `reference ${describeReference(ch.body)}` : `oscillation ${ch.body.enabled ? "on" : "off"}`;
    addEvent(ch.applied_t, `${what}: ${ch.status}${ch.message ? ` (${ch.message})` : ""}`, ch.status === "applied" ? "" : "warn");
  }
  addEvent(run.latest ? run.latest.t : null, `run ${run.status}${run.error ? `: ${run.error}` : ""}`,
    run.status === "error" ? "err" : (run.status === "interrupted" ? "warn" : ""));
  state.tc4 = run.scenario.tc4;
  if (["queued", "starting", "running"].includes(run.status)) {
    connectStream(runId);
  } else {
    if (state.ws) { state.ws.onclose = null; state.ws.close(); state.ws = null; }
    try {
      state.series = seriesFromStored(await api("GET", `/api/runs/${runId}/series`));
      const n = state.series.t.length;
      $("run-clock").textContent = n ? `t = ${fmt(state.series.t[n - 1])} s` : "";
    } catch (e) { showMsg(`no stored series: ${e.message}`, true); }
  }
  state.dirty = true;
  markSelected();
}

function markSelected() {
  for (const tr of document.querySelectorAll("#history tbody tr")) tr.classList.toggle("sel", tr.dataset.id === state.runId);
}

async function refreshHistory() {
  let runs = [];
  try { runs = await api("GET", "/api/runs?limit=50"); } catch (e) { return; }
  const tb = document.querySelector("#history tbody");
  tb.innerHTML = "";
  for (const r of runs) {
    const tr = document.createElement("tr");
    tr.dataset.id = r.id;
    const m = r.metrics || {};
    tr.innerHTML = `<td title="${new Date(r.created_at * 1000).toLocaleString()}">${r.id.slice(0, 6)}${r.scenario.oscillation.enabled ? " ↕" : ""}</td>
      <td><span class="badge ${r.status}" style="color:#fff">${r.status}</span></td>
      <td class="num">${pct(m.mean_error_steady_max)}</td><td class="num">${pct(m.inhomogeneity_steady)}</td>
      <td><a href="${r.links.recording}" title="rerun recording" download>rrd</a><a href="${r.links.timeseries}" title="raw time series" download>npz</a></td>`;
    tr.addEventListener("click", (ev) => { if (ev.target.tagName !== "A") selectRun(r.id); });
    tb.appendChild(tr);
  }
  markSelected();
}

// ---------------------------------------------------------------- forms
function scenarioFromForm(form) {
  const v = (name) => form.elements[name].value;
  const num = (name) => Number(v(name));
  const speedText = v("speed").trim();
  const reference = refMode("refmode") === "points" ? { points: parsePoints(v("points")) }
    : { setpoint: num("setpoint"), t_E: num("t_E") };
  return {
    reference,
    duration: num("duration"),
    oscillation: { enabled: form.elements.osc.checked, amplitude: num("amplitude"), period: num("period") },
    tc4: [num("tc4x"), num("tc4y")],
    speed: speedText === "max" ? "max" : Number(speedText),
    mismatch: { emissivity: num("m_eps"), alpha: num("m_alpha"), lamp_efficiency: num("m_lamp") },
    tc_noise: num("tc_noise"),
    seed: Math.trunc(num("seed")),
  };
}

$("start-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const btn = $("start-btn");
  const area = ev.target.elements.points;
  btn.disabled = true;
  area.classList.remove("invalid");
  let scenario = null;
  try {
    scenario = scenarioFromForm(ev.target);
    showMsg("starting…", false, "start-msg");
    const created = await api("POST", "/api/runs", scenario);
    showMsg(`run ${created.id} started: reference ${describeReference(scenario.reference)}`, false, "start-msg");
    await selectRun(created.id);
    refreshHistory();
  } catch (e) {
    if (!scenario || /reference/.test(e.message)) area.classList.toggle("invalid", refMode("refmode") === "points");
    showMsg(e.message, true, "start-msg");
  }
  btn.disabled = false;
});

$("ref-btn").addEventListener("click", async () => {
  let body;
  const area = $("new-points");
  area.classList.remove("invalid");
  try {
    body = refMode("live-refmode") === "points" ? { points: parsePoints(area.value) }
      : { setpoint: Number($("new-setpoint").value), t_E: Number($("new-tE").value) };
  } catch (e) { area.classList.add("invalid"); showMsg(e.message, true); return; }
  const what = body.points ? `reference ${describeReference(body)} (times from now)` : `reference ${body.setpoint} K over ${body.t_E} s`;
  const btn = $("ref-btn");
  btn.disabled = true;
  showMsg(`${what}: re-planning…`);
  try {
    const r = await api("PUT", `/api/runs/${state.runId}/reference`, body);
    const at = r.applied_t !== null && r.applied_t !== undefined ? ` at t = ${fmt(r.applied_t)} s` : "";
    showMsg(r.status === "pending" ? `${what}: still re-planning; it applies when ready` : `${what}: ${r.status}${at}`);
    refreshRun();
  } catch (e) {
    if (body.points && e.status === 422) area.classList.add("invalid");
    showMsg(`${what} refused: ${e.message}`, true);
  }
  btn.disabled = !(state.run && ["queued", "starting", "running"].includes(state.run.status));
});

$("osc-btn").addEventListener("click", async () => {
  const form = $("start-form");
  const body = { enabled: !state.oscEnabled, amplitude: Number(form.elements.amplitude.value), period: Number(form.elements.period.value) };
  showMsg("switching oscillation…");
  try {
    const r = await api("PUT", `/api/runs/${state.runId}/oscillation`, body);
    showMsg(`oscillation ${body.enabled ? "on" : "off"}: ${r.status}${r.applied_t !== null ? ` at t = ${fmt(r.applied_t)} s` : ""}`);
    state.oscEnabled = body.enabled;
    $("osc-btn").textContent = state.oscEnabled ? "Oscillation off" : "Oscillation on";
    $("osc-btn").classList.toggle("on", state.oscEnabled);
    refreshRun();
  } catch (e) { showMsg(e.message, true); }
});

$("stop-btn").addEventListener("click", async () => {
  const runId = state.runId;
  state.stopping = runId; // before the reply: the run's last frame may come first
  showMsg(`stopping run ${runId}…`);
  try {
    await api("POST", `/api/runs/${runId}/stop`); // the end of the run completes the message (noteStatus)
  } catch (e) { state.stopping = null; showMsg(e.message, true); }
  setTimeout(() => { refreshRun(); refreshHistory(); }, 800);
});

$("token").addEventListener("input", (ev) => {
  const v = ev.target.value.trim();
  if (v) sessionStorage.setItem(TOKEN_KEY, v); else sessionStorage.removeItem(TOKEN_KEY);
  ev.target.classList.remove("need");
});
for (const name of ["refmode", "live-refmode"]) {
  for (const el of document.querySelectorAll(`input[name="${name}"]`)) el.addEventListener("change", () => showRefMode(name));
  showRefMode(name);
}
localStorage.removeItem(TOKEN_KEY); // an older dashboard kept the token there; it now lives only in this tab

// ---------------------------------------------------------------- start-up
async function init() {
  try {
    [state.health, state.furnace] = await Promise.all([api("GET", "/api/health"), api("GET", "/api/furnace")]);
    $("server-state").textContent = `server ok · ${state.health.active_runs} running`;
  } catch (e) {
    $("server-state").textContent = `server unreachable: ${e.message}`;
    return;
  }
  if (state.health.auth_required) { $("token-box").hidden = false; $("token").value = token(); }
  if (state.health.viser_url) { const a = $("viser-link"); a.href = state.health.viser_url; a.hidden = false; }
  state.series = emptySeries();
  render();
  await refreshHistory();
  const runs = await api("GET", "/api/runs?limit=20");
  const live = runs.find((r) => ["queued", "starting", "running"].includes(r.status));
  if (live) selectRun(live.id);
  setInterval(refreshHistory, 4000);
  setInterval(async () => {
    refreshRun();
    try {
      state.health = await api("GET", "/api/health");
      $("server-state").textContent = `server ok · ${state.health.active_runs} running`;
    } catch (e) { $("server-state").textContent = "server unreachable"; }
  }, 2000);
}

init();
