// The shown run: its card (what it is, files, metrics), the live controls, and its history: a page that
// connects to a running run reads everything so far (GET .../series), then continues with the stream.
import { api } from "./api.js";
import { render } from "./charts.js";
import { describeChoice, setEstimatorForm } from "./estimatorform.js";
import { addEvents, clearEvents, noteStatus } from "./events.js";
import { settle } from "./followup.js";
import { setLiveOscillation } from "./inputs.js";
import { metricsTable } from "./metrics.js";
import { $, badge, describeOscillation, describeReference, esc, fmt, going, runLabel, runStory, showMsg } from "./page.js";
import { markShown, refreshRuns } from "./runlist.js";
import { emptySeries, seriesFromStored } from "./series.js";
import { state } from "./state.js";
import { applyFrame, closeStream, connectStream } from "./stream.js";
import { renderFaults } from "./faults.js";

// The live controls act on the shown run: Stop while it is going, changes only once it runs (the server answers
// 409 while it is queued or starting: there is no estimate to check a change from yet).
export function changeable(run) {
  return !!run && ["running", "degraded"].includes(run.status) && !run.ended_at && !!run.latest;
}

function setControls(run) {
  $("stop-btn").disabled = !going(run);
  for (const id of ["ref-btn", "osc-btn"]) {
    $(id).disabled = !changeable(run);
    $(id).title = changeable(run) ? "" : (going(run) ? "live changes are taken once the run runs (its first sample)" : "");
  }
  $("ctl-run").textContent = run ? `· ${run.label || run.id}` : "";
  setLiveOscillation(run ? run.oscillation : null);
}

function fileLinks(run) {
  const f = run.files || {}, base = `/api/runs/${run.id}`;
  const links = [];
  if (f.timeseries || going(run)) {
    links.push(`<a href="${base}/export.csv" download>CSV</a>`, `<a href="${base}/report.pdf" download>report PDF</a>`,
      `<a href="${base}/report.png" download>report PNG</a>`);
  }
  if (f.timeseries) links.push(`<a href="${base}/timeseries" download>npz</a>`);
  if (f.recording) links.push(`<a href="${base}/recording.rrd" download title="rerun recording: rerun FILE">rrd</a>`);
  if (state.health && state.health.viser_url) links.push(`<a href="${state.health.viser_url}" target="_blank" rel="noopener">3D view</a>`);
  if (run.links && run.links.rerun) {
    const what = going(run) ? "the live stream in the rerun web viewer" : "the recording in the rerun web viewer";
    links.push(`<a href="${esc(run.links.rerun)}" target="_blank" rel="noopener" title="${what}">Open in rerun</a>`);
  }
  return links.join(" ");
}

// The furnace of a run over OPC UA, with the samples that came late (live from the stream, else the metrics);
// a simulated one: its speed, noise, seed and truth.
function describeFurnace(run) {
  const sc = run.scenario, plant = sc.plant || { kind: "simulated" };
  if (plant.kind !== "opcua") return `speed ${esc(sc.speed)} · noise ${sc.tc_noise} K · seed ${sc.seed}${sc.truth ? ` · truth ${esc(sc.truth)}` : ""}`;
  const frame = state.lastFrame && state.lastFrame.late_samples !== undefined ? state.lastFrame : null;
  const late = frame ? frame.late_samples : (run.metrics || {}).late_samples;
  return `furnace over OPC UA <span class="id">${esc(plant.endpoint)}</span> (real time, no truth)`
    + `${late !== undefined && late !== null ? ` · ${late} late samples` : ""}`;
}

function renderRunInfo(run) {
  const sc = run.scenario;
  const now = going(run) ? "now" : "at the end";
  $("run-title").textContent = `· ${runLabel(run) !== run.id ? `${runLabel(run)} · ` : ""}${run.id}`;
  $("run-details").innerHTML = `
    <div><span class="badge ${esc(run.status)}">${esc(run.status)}</span>${run.error ? ` <span class="msg err">${esc(run.error)}</span>`
      : (run.status_reason ? ` <span class="msg${run.status === "degraded" ? " err" : ""}">${esc(run.status_reason)}</span>` : "")}
      · started ${new Date((run.started_at || run.created_at) * 1000).toLocaleString()}</div>
    <div id="run-story">${run.story ? `${esc(runStory(run))} (${now}) · reference ${esc(describeReference(run.reference))}`
      : `reference ${esc(describeReference(run.reference))} · oscillation ${esc(describeOscillation(run.oscillation))} (${now})`}</div>
    ${sc.estimator ? `<div class="muted">estimator ${esc(describeChoice(sc.estimator))}${sc.estimator.shadow
    ? ` · shadow ${esc(describeChoice(sc.estimator.shadow))}` : ""}</div>` : ""}
    <div class="muted">${sc.duration} s · TC4 at (${sc.tc4.join(", ")}) · ${describeFurnace(run)}
      · <button class="link" id="reuse-btn" title="copy this run's scenario into the New run form">use as new run</button></div>`;
  $("run-files").innerHTML = fileLinks(run);
  $("run-metrics").innerHTML = metricsTable(run);
  $("reuse-btn").addEventListener("click", () => reuseScenario(run.scenario));
}

// The New run form takes a run's scenario (its reference as it started).
function reuseScenario(sc) {
  const form = $("start-form"), set = (name, v) => { form.elements[name].value = String(v); };
  const points = !!sc.reference.points;
  for (const el of form.elements.refmode) { el.checked = el.value === (points ? "points" : "transition"); el.dispatchEvent(new Event("change")); }
  if (points) form.elements.points.value = sc.reference.points.map(([t, T]) => `${t}, ${T}`).join("\n");
  else { set("setpoint", sc.reference.setpoint); set("t_E", sc.reference.t_E); }
  const plant = sc.plant || { kind: "simulated" };
  for (const el of form.elements.plant) { el.checked = el.value === plant.kind; el.dispatchEvent(new Event("change")); }
  if (plant.kind === "opcua") set("endpoint", plant.endpoint);
  else { set("speed", sc.speed); if (sc.truth) set("truth", sc.truth); }
  set("duration", sc.duration); form.elements.osc.checked = sc.oscillation.enabled;
  set("amplitude", sc.oscillation.amplitude); set("period", sc.oscillation.period); set("tc4x", sc.tc4[0]); set("tc4y", sc.tc4[1]);
  set("tc_noise", sc.tc_noise); set("seed", sc.seed); set("m_eps", sc.mismatch.emissivity); set("m_alpha", sc.mismatch.alpha);
  set("m_lamp", sc.mismatch.lamp_efficiency);
  if (sc.truth) set("truth", sc.truth);
  setEstimatorForm(sc.estimator || state.furnace.defaults.estimator); // a run from before the choice: the default
  form.dispatchEvent(new Event("input"));
  showMsg(`the form holds the scenario of run ${state.runId}`, false, "start-msg");
}

export async function refreshRun(quiet = false) {
  if (!state.runId) return;
  try {
    const run = await api("GET", `/api/runs/${state.runId}`);
    if (run.id !== state.runId) return; // another run was picked meanwhile
    const before = state.run && state.run.id === run.id ? JSON.stringify([run.changes, run.windows]) : null;
    const changed = !state.run || JSON.stringify([state.run.changes, state.run.windows]) !== before;
    state.run = run;
    badge(run.status);
    setControls(run);
    renderRunInfo(run);
    renderFaults(run);
    if (quiet) state.lastStatus = run.status; else noteStatus(run.status, run.latest ? run.latest.t : null);
    settle(run);
    if (changed) state.dirty = true; // reference markers, windows
  } catch (e) { /* transient */ }
}

// A run that ended: its last events (the end itself) may be stored after its stream closed and after the history
// was read; its events are read again (every 2 s, at most 5 times) until the end is listed.
const END = /^run (finished|stopped|interrupted|failed|lost|ended)/;
function readEndEvents(runId, tries = 5) {
  if (state.runId !== runId || state.loading || tries <= 0) return;
  if ([...state.events.values()].some((e) => e.kind === "run_ended" || END.test(e.text || ""))) return;
  setTimeout(async () => {
    if (state.runId !== runId || state.loading) return;
    try { addEvents((await api("GET", `/api/runs/${runId}/series`)).events); } catch (e) { /* the next try */ }
    readEndEvents(runId, tries - 1);
  }, 2000);
}

// Everything so far: the stored (or live) series with its events, then the frames that came meanwhile.
async function loadHistory(runId, keep = false) {
  try {
    const d = await api("GET", `/api/runs/${runId}/series`);
    if (state.runId !== runId) return;
    if (keep) clearEvents(); // the history brings every event again
    state.series = seriesFromStored(d);
    state.series.windows = d.windows;
    state.historyEnd = d.t_last; // the last sample the history brought; the stream continues after it
    addEvents(d.events);
    const n = d.t ? d.t.length : 0;
    if (n) state.lastFrame = { t: d.t[n - 1], T_mean_hat: d.T_mean_hat[n - 1], T_ref: d.T_ref[n - 1] };
    $("run-clock").textContent = n ? `t = ${fmt(d.t[n - 1])} s` : "";
  } catch (e) {
    if (e.status !== 404) showMsg(`the run's history could not be read: ${e.message}`, true);
  }
}

// Show a run.  Another run's view is emptied at once (a new run reads "planning ..." until its first frame, never
// the previous run's heat map and clock); the same run again (its stream ended) keeps its charts until the stored
// history replaces them, so they do not blank when a run ends.
export async function selectRun(runId) {
  closeStream();
  const keep = state.runId === runId && !!state.run;
  Object.assign(state, { runId, lastStatus: null, oscShown: null, loading: true, held: [] });
  if (!keep) {
    Object.assign(state, { series: emptySeries(), lastFrame: null, frames: 0, run: null });
    clearEvents();
    $("run-clock").textContent = "";
    render(); // at once: the previous run's heat map and charts must not stay up under the new run's name
  }
  markShown();
  await refreshRun(true);
  const run = state.run;
  if (!run || run.id !== runId) return;
  if (going(run)) await connectStream(runId, () => { selectRun(runId); refreshRuns(); }); // frames wait
  await loadHistory(runId, keep);
  if (state.runId !== runId) return;
  state.loading = false;
  for (const f of state.held.splice(0)) applyFrame(f); // only those after the history's last sample count
  state.dirty = true;
  if (!going(run)) readEndEvents(runId);
}
