// "Learnt furnace": what the twin has learnt about this furnace from earlier runs (GET /api/furnace/calibration),
// per plant it ran on; the next run's plan and feasibility check start from it.  Reset forgets it (DELETE).
import { api } from "./api.js";
import { $, esc, showMsg } from "./page.js";

const NAMES = { lamp_efficiency: "lamp efficiency", emissivity: "emissivity", convection: "convection" };
const signed = (v) => `${v >= 0 ? "+" : "−"}${Math.abs(100 * v).toFixed(1)} %`;

export function showCalibration(data) {
  const box = $("learnt-list");
  const plants = (data && data.plants) || [];
  const learnt = plants.filter((p) => Object.keys(p.parameters || {}).length);
  $("learnt-reset").disabled = !learnt.length;
  if (!learnt.length) {
    box.innerHTML = '<p class="muted">nothing learnt yet: runs plan with the nominal model</p>';
    return;
  }
  box.innerHTML = learnt.map((p) => {
    const rows = Object.entries(p.parameters).map(([name, v]) => {
      const runs = (v.runs || []).length;
      return `<tr><td>${esc(NAMES[name] || name)}</td><td class="num">${signed(v.value)}</td>`
        + `<td class="num">± ${(100 * v.sigma).toFixed(1)} %</td>`
        + `<td class="muted" title="${esc((v.runs || []).join(", "))}">${esc(String(v.when || "").replace("T", " ").slice(0, 16))}`
        + ` · ${runs} run${runs === 1 ? "" : "s"}</td></tr>`;
    }).join("");
    return `<div class="learnt"><div class="muted">${esc(p.plant)}</div><table class="metrics">${rows}</table></div>`;
  }).join("");
}

export async function refreshCalibration() {
  try { showCalibration(await api("GET", "/api/furnace/calibration")); } catch (e) { /* the next refresh tries again */ }
}

export function wireCalibration() {
  $("learnt-reset").addEventListener("click", async () => {
    try {
      showCalibration(await api("DELETE", "/api/furnace/calibration"));
      showMsg("forgot what the twin had learnt: the next run plans with the nominal model", false, "learnt-msg");
    } catch (e) { showMsg(e.message, true, "learnt-msg"); }
  });
  refreshCalibration();
}
