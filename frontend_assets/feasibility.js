// Can the furnace follow the reference of the start form?  Asked of the server (POST /api/feasibility,
// the model's heating and cooling limits) while the form is edited; the answer shows above Start.
import { api } from "./api.js";
import { $, esc } from "./page.js";

const WAIT_MS = 500; // after the last keystroke
let timer = null;
let asked = 0;

export function showFeasibility(report) {
  const box = $("feasibility");
  if (!report || report.verdict === "ok" || !report.messages.length) { box.hidden = true; box.innerHTML = ""; return; }
  box.hidden = false;
  box.className = `feas ${report.verdict}`;
  const head = report.verdict === "refuse" ? "The server will refuse this run:"
    : report.verdict === "pending" ? "Not checked yet:" : "Warning: the furnace cannot quite follow this reference:";
  box.innerHTML = `<b>${head}</b><ul>${report.messages.map((m) => `<li>${esc(m)}</li>`).join("")}</ul>`;
}

// scenario(): the form's scenario, or throws (a field the form names itself: no question to the server).
export function checkSoon(scenario) {
  clearTimeout(timer);
  timer = setTimeout(async () => {
    let body;
    try { body = scenario(); } catch (e) { showFeasibility(null); return; }
    const mine = ++asked;
    try {
      const report = await api("POST", "/api/feasibility", body);
      if (mine === asked) showFeasibility(report);
    } catch (e) { if (mine === asked) showFeasibility(null); }
  }, WAIT_MS);
}
