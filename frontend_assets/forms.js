// What the user does: start a run (the form), change the shown run live, stop it, enter the token.
import { api, setToken } from "./api.js";
import { estimatorFromForm, showEstimatorSummary } from "./estimatorform.js";
import { checkSoon, showFeasibility } from "./feasibility.js";
import { followChange, followStart } from "./followup.js";
import { restoreForm, saveForm } from "./formstore.js";
import { readNumber, readSpeed, setLiveOscillation } from "./inputs.js";
import { $, describeReference, fmt, going, showMsg } from "./page.js";
import { parsePoints } from "./points.js";
import { refreshRun, selectRun } from "./run.js";
import { refreshRuns } from "./runlist.js";
import { state } from "./state.js";

const REPEAT_MS = 3000; // the same form sent again within this time after the last answer is the same start
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

export function scenarioFromForm(form = $("start-form")) {
  const el = (name) => form.elements[name];
  const n = (name) => readNumber(el(name));
  const reference = refMode("refmode") === "points" ? { points: parsePoints(el("points").value, pointLimits()) }
    : { setpoint: n("setpoint"), t_E: n("t_E") };
  const common = {
    reference,
    duration: n("duration"),
    oscillation: { enabled: el("osc").checked, amplitude: n("amplitude"), period: n("period") },
    tc4: [n("tc4x"), n("tc4y")],
  };
  if (refMode("plant") === "opcua") { // a real furnace: its own clock (speed 1), noise and deviations; no truth
    return { ...common, plant: { kind: "opcua", endpoint: el("endpoint").value.trim() } };
  }
  return {
    ...common,
    speed: readSpeed(el("speed")),
    mismatch: { emissivity: n("m_eps"), alpha: n("m_alpha"), lamp_efficiency: n("m_lamp") },
    tc_noise: n("tc_noise"),
    seed: Math.trunc(n("seed")),
    truth: el("truth").value,
    estimator: estimatorFromForm(form),
  };
}

// A start's request id: the same form sent again right after (a double click) keeps it, so the server
// answers with the run it already started (Idempotency-Key) instead of starting a second one.
let lastStart = null; // {id, body, at}
const newId = () => (crypto.randomUUID ? crypto.randomUUID() : `${Date.now()}-${Math.random().toString(16).slice(2)}`);

function requestId(body) {
  if (lastStart && lastStart.body === body && Date.now() - lastStart.at < REPEAT_MS) return lastStart.id;
  lastStart = { id: newId(), body, at: Date.now() };
  return lastStart.id;
}

async function startRun(ev) {
  ev.preventDefault();
  const btn = $("start-btn");
  if (btn.disabled) return; // one start at a time: the button stays disabled until the reply
  const area = ev.target.elements.points;
  btn.disabled = true;
  area.classList.remove("invalid");
  let scenario = null;
  try {
    scenario = scenarioFromForm(ev.target);
    const body = JSON.stringify(scenario);
    showMsg("sending the run…", false, "start-msg");
    const created = await api("POST", "/api/runs", scenario, { "Idempotency-Key": requestId(body) });
    if (lastStart) lastStart.at = Date.now();
    const again = created.replayed ? " (already sent: the same request came twice)" : "";
    const warn = created.warnings && created.warnings.length ? ` · warning: ${created.warnings[0]}` : "";
    // a run is queued until it starts (for long only while the radiation model loads): the message says so, and
    // says "starting" / "running" when the run does (followup.js), never "started" before it has
    const loading = state.health && state.health.radiation !== "ready" ? " (it starts when the radiation model is ready)" : "";
    const how = created.status === "queued" ? `queued${loading}` : created.status;
    const rest = `${again}: reference ${describeReference(scenario.reference)}${warn}`;
    showMsg(`run ${created.id} ${how}${rest}`, warn ? "warn" : false, "start-msg");
    followStart(created.id, rest, warn ? "warn" : false);
    btn.disabled = false; // the reply is in: a click from now on is a new request (or the same, if repeated)
    if (state.runId !== created.id) selectRun(created.id);
    refreshRuns();
  } catch (e) {
    if (!scenario && refMode("refmode") === "points" && /points/.test(e.message)) area.classList.add("invalid");
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
      : { setpoint: readNumber($("new-setpoint")), t_E: readNumber($("new-tE")) };
  } catch (e) { if (refMode("live-refmode") === "points") area.classList.add("invalid"); showMsg(e.message, true); return; }
  const what = body.points ? `reference ${describeReference(body)} (times from now)` : `reference ${body.setpoint} K over ${body.t_E} s`;
  const btn = $("ref-btn");
  btn.disabled = true;
  showMsg(`${what}: re-planning…`);
  try {
    const r = await api("PUT", `/api/runs/${state.runId}/reference`, body);
    const at = r.applied_t !== null && r.applied_t !== undefined ? ` at t = ${fmt(r.applied_t)} s` : "";
    const warn = r.warnings && r.warnings.length ? ` · warning: ${r.warnings[0]}` : "";
    showMsg(r.status === "pending" ? `${what}: still re-planning; it applies when ready${warn}` : `${what}: ${r.status}${at}${warn}`,
      warn ? "warn" : false);
    if (r.status === "pending") followChange(state.runId, "reference", what);
    refreshRun();
  } catch (e) {
    if (body.points && e.status === 422) area.classList.add("invalid");
    showMsg(`${what} refused: ${e.message}`, true);
  }
  btn.disabled = !going(state.run);
}

// On or off, the opposite of what the server says the run does now, with the live amplitude and period.
async function toggleOscillation() {
  const now = state.run && state.run.oscillation;
  let body;
  try {
    body = { enabled: !(now && now.enabled), amplitude: readNumber($("live-amplitude")), period: readNumber($("live-period")) };
  } catch (e) { showMsg(e.message, true); return; }
  showMsg("switching oscillation…");
  try {
    const r = await api("PUT", `/api/runs/${state.runId}/oscillation`, body);
    const what = `oscillation ${r.body.enabled ? "on" : "off"}`;
    if (r.status === "pending") {
      showMsg(`${what}: still re-planning; it applies when ready`);
      followChange(state.runId, "oscillation", what);
    } else showMsg(`${what}: ${r.status}${r.applied_t !== null && r.applied_t !== undefined ? ` at t = ${fmt(r.applied_t)} s` : ""}`);
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
  setTimeout(() => { refreshRun(); refreshRuns(); }, 800);
}

// A refusal on a message line goes when its cause does: once the inputs read without error the line is
// cleared; while they do not, it names the problem they have now (not the one they had).
function recheck(id, read) {
  if (!$(id).classList.contains("err")) return;
  try { read(); showMsg("", false, id); } catch (e) { showMsg(e.message, true, id); }
}

export function wireForms() {
  const form = $("start-form");
  restoreForm(form);
  showEstimatorSummary(form);
  form.addEventListener("submit", startRun);
  const edited = () => {
    saveForm(form); showEstimatorSummary(form); checkSoon(() => scenarioFromForm(form));
    recheck("start-msg", () => scenarioFromForm(form));
  };
  form.addEventListener("input", edited);
  form.addEventListener("change", edited);
  const live = () => [$("new-setpoint"), $("new-tE"), $("live-amplitude"), $("live-period")].forEach(readNumber);
  for (const id of ["new-setpoint", "new-tE", "live-amplitude", "live-period"]) $(id).addEventListener("input", () => recheck("ctl-msg", live));
  $("ref-btn").addEventListener("click", changeReference);
  $("osc-btn").addEventListener("click", toggleOscillation);
  $("stop-btn").addEventListener("click", stopRun);
  $("token").addEventListener("input", (ev) => {
    setToken(ev.target.value.trim());
    ev.target.classList.remove("need");
  });
  for (const name of ["refmode", "live-refmode", "plant"]) {
    for (const el of document.querySelectorAll(`input[name="${name}"]`)) el.addEventListener("change", () => showRefMode(name));
    showRefMode(name);
  }
  showFeasibility(null);
  checkSoon(() => scenarioFromForm(form));
}
