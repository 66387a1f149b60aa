// What the user does: start a run (the form), change the picked run live, stop it, enter the token.
import { api, setToken } from "./api.js";
import { setLiveOscillation } from "./inputs.js";
import { $, describeReference, fmt, LIVE, showMsg } from "./page.js";
import { parsePoints } from "./points.js";
import { refreshHistory, refreshRun, selectRun } from "./runs.js";
import { state } from "./state.js";

const pointLimits = () => state.furnace.limits.reference.points;
const camel = (s) => s.replace(/-([a-z])/g, (_, c) => c.toUpperCase());

function refMode(name) {
  const el = document.querySelector(`input[name="${name}"]:checked`);
  return el ? el.value : "transition";
}

function showRefMode(name) {
  const mode = refMode(name);
  for (const el of document.querySelectorAll(`[data-${name}]`)) el.hidden = el.dataset[camel(name)] !== mode;
}

function scenarioFromForm(form) {
  const v = (name) => form.elements[name].value;
  const num = (name) => Number(v(name));
  const speedText = v("speed").trim();
  const reference = refMode("refmode") === "points" ? { points: parsePoints(v("points"), pointLimits()) }
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

async function startRun(ev) {
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
}

async function changeReference() {
  let body;
  const area = $("new-points");
  area.classList.remove("invalid");
  try {
    body = refMode("live-refmode") === "points" ? { points: parsePoints(area.value, pointLimits()) }
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
  btn.disabled = !(state.run && LIVE.includes(state.run.status));
}

// On or off, the opposite of what the server says the run does now, with the live amplitude and period.
async function toggleOscillation() {
  const now = state.run && state.run.oscillation;
  const body = { enabled: !(now && now.enabled), amplitude: Number($("live-amplitude").value),
    period: Number($("live-period").value) };
  showMsg("switching oscillation…");
  try {
    const r = await api("PUT", `/api/runs/${state.runId}/oscillation`, body);
    showMsg(`oscillation ${r.body.enabled ? "on" : "off"}: ${r.status}${r.applied_t !== null && r.applied_t !== undefined ? ` at t = ${fmt(r.applied_t)} s` : ""}`);
    if (r.status === "applied" && state.run) { state.run.oscillation = r.body; setLiveOscillation(r.body); }
    refreshRun();
  } catch (e) { showMsg(e.message, true); }
}

async function stopRun() {
  const runId = state.runId;
  state.stopping = runId; // before the reply: the run's last frame may come first
  showMsg(`stopping run ${runId}…`);
  try {
    await api("POST", `/api/runs/${runId}/stop`); // the end of the run completes the message (noteStatus)
  } catch (e) { state.stopping = null; showMsg(e.message, true); }
  setTimeout(() => { refreshRun(); refreshHistory(); }, 800);
}

export function wireForms() {
  $("start-form").addEventListener("submit", startRun);
  $("ref-btn").addEventListener("click", changeReference);
  $("osc-btn").addEventListener("click", toggleOscillation);
  $("stop-btn").addEventListener("click", stopRun);
  $("token").addEventListener("input", (ev) => {
    setToken(ev.target.value.trim());
    ev.target.classList.remove("need");
  });
  for (const name of ["refmode", "live-refmode"]) {
    for (const el of document.querySelectorAll(`input[name="${name}"]`)) el.addEventListener("change", () => showRefMode(name));
    showRefMode(name);
  }
}
