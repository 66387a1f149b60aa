// The picked run (its panel, live controls and stream) and the list of runs.
import { api } from "./api.js";
import { addEvent, clearEvents, noteStatus } from "./events.js";
import { setLiveOscillation } from "./inputs.js";
import { $, badge, describeOscillation, describeReference, fmt, LIVE, pct, showMsg } from "./page.js";
import { emptySeries, seriesFromStored } from "./series.js";
import { state } from "./state.js";
import { closeStream, connectStream } from "./stream.js";

// The live controls follow what the server says the run uses now (GET /api/runs/{id}: reference, oscillation).
function setControls(run) {
  const live = run && LIVE.includes(run.status);
  for (const id of ["ref-btn", "osc-btn", "stop-btn"]) $(id).disabled = !live;
  $("ctl-run").textContent = run ? `· ${run.id}` : "";
  setLiveOscillation(run ? run.oscillation : null);
}

function renderRunInfo(run) {
  if (!run) return;
  const m = run.metrics || {};
  const sc = run.scenario;
  const rows = Object.entries(m).map(([k, v]) => `<tr><td>${k}</td><td class="num">${pct(v)} %</td></tr>`).join("");
  const files = run.files || {};
  const links = [
    files.recording ? `<a href="${run.links.recording}" download>recording.rrd</a>` : "",
    files.timeseries ? `<a href="${run.links.timeseries}" download>timeseries.npz</a>` : "",
    state.health && state.health.viser_url ? `<a href="${state.health.viser_url}" target="_blank" rel="noopener">3D view</a>` : "",
  ].filter(Boolean).join(" · ");
  const now = LIVE.includes(run.status) ? "now" : "at the end";
  $("run-details").innerHTML = `
    <div><b>${run.id}</b> · ${run.status}${run.error ? ` · <span style="color:#c53030">${run.error}</span>` : ""}</div>
    <div class="muted">reference ${describeReference(run.reference)} · oscillation ${describeOscillation(run.oscillation)} (${now})
      · ${sc.duration} s · speed ${sc.speed} · TC4 (${sc.tc4.join(", ")})</div>
    <div>${links}</div>
    ${rows ? `<div class="muted">metrics, relative to the setpoint</div><table>${rows}</table>` : `<div class="muted">metrics when the run ends</div>`}`;
}

export async function refreshRun(quiet = false) {
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

export async function selectRun(runId) {
  Object.assign(state, { runId, series: emptySeries(), lastFrame: null, frames: 0, run: null, eventSeq: -1,
    lastStatus: null, oscShown: null });
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
  if (LIVE.includes(run.status)) {
    connectStream(runId, () => { refreshRun(); refreshHistory(); });
  } else {
    closeStream();
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

// The rows are rebuilt only when a run's row changed, so a click never races a refresh.
let historyHtml = null;

export async function refreshHistory() {
  let runs = [];
  try { runs = await api("GET", "/api/runs?limit=50"); } catch (e) { return; }
  const html = runs.map((r) => {
    const m = r.metrics || {};
    return `<tr data-id="${r.id}"><td title="${new Date(r.created_at * 1000).toLocaleString()}">${r.id.slice(0, 6)}${r.scenario.oscillation.enabled ? " ↕" : ""}</td>
      <td><span class="badge ${r.status}" style="color:#fff">${r.status}</span></td>
      <td class="num">${pct(m.mean_error_steady_max)}</td><td class="num">${pct(m.inhomogeneity_steady)}</td>
      <td><a href="${r.links.recording}" title="rerun recording" download>rrd</a><a href="${r.links.timeseries}" title="raw time series" download>npz</a></td></tr>`;
  }).join("");
  if (html !== historyHtml) {
    document.querySelector("#history tbody").innerHTML = html;
    historyHtml = html;
  }
  markSelected();
}

export function wireHistory() {
  document.querySelector("#history tbody").addEventListener("click", (ev) => {
    const tr = ev.target.closest("tr");
    if (tr && ev.target.tagName !== "A") selectRun(tr.dataset.id);
  });
}
