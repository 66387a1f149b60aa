// furnace-twin dashboard: the entry module.  Reads the server and its furnace, builds the inputs from
// the furnace's limits, then follows the newest running run.  No build step, no CDN: ES modules from /assets/.
import { api, forgetOldToken, token } from "./api.js";
import { render, startRendering } from "./charts.js";
import { wireFaults } from "./faults.js";
import { wireForms } from "./forms.js";
import { applyLimits } from "./inputs.js";
import { $, LIVE } from "./page.js";
import { refreshHistory, refreshRun, selectRun, wireHistory } from "./runs.js";
import { emptySeries } from "./series.js";
import { state } from "./state.js";

window.state = state; // the page's state, for the browser console and the browser tests

// "server ok · 1 running", and while the radiation model warms up its progress (runs wait as queued)
function serverState(h) {
  let text = `server ok · ${h.active_runs} running`;
  const p = h.radiation_progress;
  if (h.radiation === "computing") {
    const done = p && p.total ? ` ${p.done}/${p.total} positions (${Math.round(100 * p.fraction)} %)` : "";
    text += ` · radiation model: ${p ? p.stage : "computing"}${done}; new runs wait`;
  } else if (h.radiation === "failed") {
    text += ` · radiation model failed: ${p && p.error ? p.error : "see the server log"}`;
  }
  return text;
}

async function init() {
  forgetOldToken();
  wireForms();
  wireHistory();
  try {
    [state.health, state.furnace] = await Promise.all([api("GET", "/api/health"), api("GET", "/api/furnace")]);
    applyLimits(state.furnace);
    wireFaults();
    $("server-state").textContent = serverState(state.health);
  } catch (e) {
    $("server-state").textContent = `server unreachable: ${e.message}`;
    return;
  }
  if (state.health.auth_required) { $("token-box").hidden = false; $("token").value = token(); }
  if (state.health.viser_url) { const a = $("viser-link"); a.href = state.health.viser_url; a.hidden = false; }
  if (state.health.rerun_url) { const a = $("rerun-link"); a.href = state.health.rerun_url; a.hidden = false; }
  state.series = emptySeries();
  render();
  startRendering();
  await refreshHistory();
  const runs = await api("GET", "/api/runs?limit=20");
  const live = runs.find((r) => LIVE.includes(r.status));
  if (live) selectRun(live.id);
  setInterval(refreshHistory, 4000);
  setInterval(async () => {
    refreshRun();
    try {
      state.health = await api("GET", "/api/health");
      $("server-state").textContent = serverState(state.health);
    } catch (e) { $("server-state").textContent = "server unreachable"; }
  }, 2000);
}

init();
