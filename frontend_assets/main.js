// furnace-twin dashboard: the entry module.  Reads the server and its furnace, builds the inputs from
// the furnace's limits, then follows the newest running run.  No build step, no CDN: ES modules from /assets/.
import { api, forgetOldToken, token } from "./api.js";
import { render, startRendering } from "./charts.js";
import { wireForms } from "./forms.js";
import { applyLimits } from "./inputs.js";
import { $, LIVE } from "./page.js";
import { refreshHistory, refreshRun, selectRun, wireHistory } from "./runs.js";
import { emptySeries } from "./series.js";
import { state } from "./state.js";

window.state = state; // the page's state, for the browser console and the browser tests

async function init() {
  forgetOldToken();
  wireForms();
  wireHistory();
  try {
    [state.health, state.furnace] = await Promise.all([api("GET", "/api/health"), api("GET", "/api/furnace")]);
    applyLimits(state.furnace);
    $("server-state").textContent = `server ok · ${state.health.active_runs} running`;
  } catch (e) {
    $("server-state").textContent = `server unreachable: ${e.message}`;
    return;
  }
  if (state.health.auth_required) { $("token-box").hidden = false; $("token").value = token(); }
  if (state.health.viser_url) { const a = $("viser-link"); a.href = state.health.viser_url; a.hidden = false; }
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
      $("server-state").textContent = `server ok · ${state.health.active_runs} running`;
    } catch (e) { $("server-state").textContent = "server unreachable"; }
  }, 2000);
}

init();
