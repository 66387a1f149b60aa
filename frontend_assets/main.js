// furnace-twin dashboard: the entry module.  Reads the server, its furnace and its words, builds the inputs
// from the furnace's limits, then shows the newest running run.  No build step, no CDN: ES modules from /assets/.
import { api, forgetOldToken, token } from "./api.js";
import { refreshCalibration, wireCalibration } from "./calibration.js";
import { render, startRendering } from "./charts.js";
import { refreshComparison, startComparing } from "./compare.js";
import { initEstimatorCharts } from "./estimators.js";
import { wireEventFilter } from "./events.js";
import { wireFaults } from "./faults.js";
import { wireForms } from "./forms.js";
import { wireHelp } from "./glossary.js";
import { wireHeatScale } from "./heatmap.js";
import { applyLimits } from "./inputs.js";
import { $, going } from "./page.js";
import { wirePanels } from "./panels.js";
import { refreshRun, selectRun } from "./run.js";
import { refreshRuns, wireRunList } from "./runlist.js";
import { emptySeries } from "./series.js";
import { state } from "./state.js";
import { initPlacement } from "./placement.js";
import { initStudies } from "./studies.js";
import { wireUncertainty } from "./uncertainty.js";

window.state = state; // the page's state, for the browser console and the browser tests

export function showView(name) {
  state.view = name;
  for (const el of document.querySelectorAll(".view")) el.hidden = el.dataset.view !== name;
  for (const el of document.querySelectorAll(".tab")) el.classList.toggle("active", el.dataset.view === name);
  if (name === "live") { state.dirty = true; render(); } else refreshComparison();
  window.dispatchEvent(new Event("resize")); // charts that were hidden take their size
}

// "server ok · 1 running", and while the radiation model warms up its progress (runs wait as queued); when it
// failed, why, with a Retry button
const seconds = (s) => (s >= 90 ? `${Math.round(s / 60)} min` : `${Math.round(s)} s`);

function serverState(h) {
  const queued = h.queued_runs || 0;
  let text = `server ok · ${h.active_runs - queued} running${queued ? ` · ${queued} queued` : ""}`;
  const p = h.radiation_progress;
  if (h.radiation === "computing") {
    const done = p && p.total ? ` ${p.done}/${p.total} positions` : "";
    const left = p && p.remaining_s != null ? `, about ${seconds(p.remaining_s)} left` : "";
    const since = p ? ` (${seconds(p.elapsed_s)} so far${left})` : "";
    text += ` · radiation model: ${p ? p.stage : "computing"}${done}${since}; new runs wait`;
  } else if (h.radiation === "failed") {
    text += ` · radiation model failed: ${p && p.error ? p.error : "see the server log"}`;
  }
  return text;
}

const serverLine = () => {
  const el = $("server-state");
  el.textContent = serverState(state.health);
  el.classList.toggle("error", state.health.radiation === "failed");
  $("radiation-retry").hidden = state.health.radiation !== "failed";
};

async function retryRadiation() {
  $("radiation-retry").disabled = true;
  try {
    await api("POST", "/api/radiation/retry");
    state.health = await api("GET", "/api/health");
    serverLine();
  } catch (e) {
    $("server-state").textContent = `retry refused: ${e.message}`;
  } finally {
    $("radiation-retry").disabled = false;
  }
}

async function init() {
  wirePanels();
  forgetOldToken();
  try {
    [state.health, state.furnace, state.glossary] = await Promise.all([api("GET", "/api/health"), api("GET", "/api/furnace"),
      api("GET", "/api/glossary")]);
    applyLimits(state.furnace);
    wireFaults();
    serverLine();
  } catch (e) {
    $("server-state").textContent = `server unreachable: ${e.message}`;
    return;
  }
  wireHelp();
  $("radiation-retry").addEventListener("click", retryRadiation);
  wireCalibration();
  wireEventFilter();
  initEstimatorCharts();
  wireForms();
  initStudies();
  initPlacement();
  wireHeatScale(() => { state.dirty = true; });
  wireUncertainty(() => { state.dirty = true; });
  wireRunList((id) => { selectRun(id); showView("live"); }, refreshComparison);
  for (const el of document.querySelectorAll(".tab")) el.addEventListener("click", () => showView(el.dataset.view));
  if (state.health.auth_required) { $("token-box").hidden = false; $("token").value = token(); }
  if (state.health.viser_url) { const a = $("viser-link"); a.href = state.health.viser_url; a.hidden = false; }
  if (state.health.rerun_url) { const a = $("rerun-link"); a.href = state.health.rerun_url; a.hidden = false; }
  state.series = emptySeries();
  render();
  startRendering();
  startComparing();
  await refreshRuns();
  const first = state.runs.find((r) => going(r)) || state.runs[0]; // the newest running, else newest
  if (first) await selectRun(first.id);
  setInterval(refreshRuns, 4000);
  setInterval(refreshCalibration, 15000); // a finished run may have taught the twin something
  setInterval(async () => {
    refreshRun();
    try { state.health = await api("GET", "/api/health"); serverLine(); } catch (e) { $("server-state").textContent = "server unreachable"; }
  }, state.health.radiation === "ready" ? 2000 : 1000); // progress from the first second of a cold start
}

init();
