// furnace-twin dashboard: REST + websocket client, plotly.js charts (served locally).
"use strict";

const GROUP_COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"];
const TC_COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728"];
const RENDER_MS = 250; // charts redraw at most 4 times per second; frames arrive up to 20/s
const MAX_POINTS = 3000; // per trace, older samples are thinned

const state = {
  furnace: null, health: null, runId: null, run: null, ws: null, frames: 0,
  series: null, lastFrame: null, dirty: false, oscEnabled: false, tc4: [0.5, 0.5],
};

const $ = (id) => document.getElementById(id);
const pct = (v, d = 2) => (v === null || v === undefined || Number.isNaN(v) ? "–" : (100 * v).toFixed(d));
const fmt = (v, d = 1) => (v === null || v === undefined || Number.isNaN(v) ? "–" : Number(v).toFixed(d));

function token() { return localStorage.getItem("furnace-twin-token") || ""; }

async function api(method, path, body) {
  const headers = { "Content-Type": "application/json" };
  if (token()) headers["X-API-Token"] = token();
  const r = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  let data = null;
  try { data = await r.json(); } catch (e) { data = null; }
  if (!r.ok) {
    let msg = data && data.detail !== undefined ? data.detail : r.statusText;
    if (Array.isArray(msg)) msg = msg.map((e) => `${(e.loc || []).slice(1).join(".")}: ${e.msg}`).join("; ");
    throw new Error(`${r.status}: ${msg}`);
  }
  return data;
}

function showMsg(text, isErr = false) {
  const el = $("ctl-msg");
  el.textContent = text;
  el.className = isErr ? "msg err" : "msg";
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

function lineFigures() {
  const s = state.series || emptySeries();
  const groups = state.furnace.groups;
  return {
    "mean-plot": {
      data: [
        { x: s.t, y: s.T_ref, name: "T_ref", line: { color: "#111", dash: "dash", width: 1.6 } },
        { x: s.t, y: s.T_mean_hat, name: "fillet mean (est.)", line: { color: "#d62728", width: 1.8 } },
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
  const ref = sc.reference.points ? `${sc.reference.points.length} points` : `${sc.reference.setpoint} K in ${sc.reference.t_E} s`;
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

async function refreshRun() {
  if (!state.runId) return;
  try {
    const run = await api("GET", `/api/runs/${state.runId}`);
    state.run = run;
    badge(run.status);
    setControls(run);
    renderRunInfo(run);
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
    if (f.events && f.events.length) showMsg(`t = ${fmt(f.t)} s: ${f.events.join("; ")}`);
    if (f.status && f.status !== (state.run && state.run.status)) badge(f.status);
    state.dirty = true;
  };
  ws.onclose = () => { if (state.ws === ws) { state.ws = null; refreshRun(); refreshHistory(); } };
}

async function selectRun(runId) {
  state.runId = runId;
  state.series = emptySeries();
  state.lastFrame = null;
  state.frames = 0;
  await refreshRun();
  const run = state.run;
  if (!run) return;
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
  return {
    reference: { setpoint: num("setpoint"), t_E: num("t_E") },
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
  btn.disabled = true;
  try {
    const created = await api("POST", "/api/runs", scenarioFromForm(ev.target));
    showMsg(`run ${created.id} started`);
    await selectRun(created.id);
    refreshHistory();
  } catch (e) { showMsg(e.message, true); }
  btn.disabled = false;
});

$("ref-btn").addEventListener("click", async () => {
  const body = { setpoint: Number($("new-setpoint").value), t_E: Number($("new-tE").value) };
  showMsg("re-planning…");
  try {
    const r = await api("PUT", `/api/runs/${state.runId}/reference`, body);
    showMsg(`reference ${body.setpoint} K over ${body.t_E} s: ${r.status}${r.applied_t !== null ? ` at t = ${fmt(r.applied_t)} s` : ""}`);
    refreshRun();
  } catch (e) { showMsg(e.message, true); }
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
  try { await api("POST", `/api/runs/${state.runId}/stop`); showMsg("stopping…"); } catch (e) { showMsg(e.message, true); }
  setTimeout(() => { refreshRun(); refreshHistory(); }, 800);
});

$("token").addEventListener("change", (ev) => localStorage.setItem("furnace-twin-token", ev.target.value));

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
