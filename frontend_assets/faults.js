// Faults of the picked run's simulated furnace: build a list, inject it (PUT /api/runs/{id}/faults replaces
// the faults in force, times from now), clear it; and what the twin detected (GET /api/runs/{id}: fault_events).
import { api } from "./api.js";
import { parseDecimal, readNumber } from "./inputs.js";
import { $, fmt, going, showMsg } from "./page.js";
import { state } from "./state.js";

const UNIT = { drift: "K/s", offset: "K", derate: "fraction kept" };
let pending = []; // the list the user builds; sent whole by "Inject"

const esc = (s) => String(s).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" }[c]));

export function describeFault(f) {
  const v = f.value === null || f.value === undefined ? "" : ` ${f.value} ${UNIT[f.kind] || ""}`;
  return `${f.target} ${f.kind}${v}`;
}

function limits() { return state.furnace.limits.faults; }

function kindsFor(target) {
  const l = limits();
  return l.targets.tc.includes(target) ? l.kinds.tc : l.kinds.group;
}

function showKinds() {
  const kinds = kindsFor($("fault-target").value);
  const sel = $("fault-kind");
  const before = sel.value;
  sel.innerHTML = kinds.map((k) => `<option>${k}</option>`).join("");
  if (kinds.includes(before)) sel.value = before;
  showValue();
}

function showValue() {
  const kind = $("fault-kind").value;
  const input = $("fault-value");
  const r = limits()[kind];
  input.disabled = !r;
  $("fault-unit").textContent = r ? UNIT[kind] : "–";
  if (r) {
    input.min = String(r.min); input.max = String(r.max);
    input.title = `${r.min}\u2026${r.max} ${UNIT[kind]}`;
    const v = parseDecimal(input.value);
    if (v === null || v < r.min || v > r.max) {
      input.value = String({ drift: 0.5, offset: 10, derate: 0.5 }[kind]);
    }
  }
}

function renderPending() {
  $("fault-pending").innerHTML = pending.length
    ? pending.map((f, i) => `<li>${esc(describeFault(f))} in ${fmt(f.at)} s <button data-i="${i}" title="remove">×</button></li>`).join("")
    : '<li class="muted">no fault in the list</li>';
  updateButtons();
}

function updateButtons() {
  const live = !!state.run && state.run.id === state.runId && going(state.run);
  $("fault-inject").disabled = !live || !pending.length;
  $("fault-clear").disabled = !live;
}

// the numbers as the other forms read them: a decimal comma taken, anything unclear refused in words
function addFault() {
  const kind = $("fault-kind").value;
  let f;
  try {
    f = { at: readNumber($("fault-at")), target: $("fault-target").value, kind };
    if (limits()[kind]) f.value = readNumber($("fault-value"));
  } catch (e) { showMsg(e.message, true, "fault-msg"); return; }
  if ($("fault-msg").classList.contains("err")) showMsg("", false, "fault-msg");
  pending.push(f);
  renderPending();
}

async function send(list, what) {
  const msg = $("fault-msg");
  msg.className = "msg";
  msg.textContent = `${what}…`;
  try {
    const r = await api("PUT", `/api/runs/${state.runId}/faults`, list);
    msg.textContent = `${what}: ${r.status}${r.applied_t !== null && r.applied_t !== undefined ? ` at t = ${fmt(r.applied_t)} s` : ""}`;
    if (list.length) pending = [];
    renderPending();
  } catch (e) {
    msg.className = "msg err";
    msg.textContent = `${what} refused: ${e.message}`;
  }
}

// Called with the picked run (GET /api/runs/{id}) whenever it is refreshed.
export function renderFaults(run) {
  updateButtons();
  const inForce = (run && run.faults) || [];
  $("fault-force").innerHTML = inForce.length
    ? inForce.map((f) => `<li>${esc(describeFault(f))} from t = ${fmt(f.at)} s</li>`).join("")
    : '<li class="muted">none</li>';
  const found = ((run && run.fault_events) || []).filter((e) => e.text.startsWith("fault detected"));
  $("fault-found").innerHTML = found.length
    ? found.slice(-8).reverse().map((e) => `<li><span class="t">t = ${fmt(e.t)} s</span> ${esc(e.text.replace(/^fault detected: /, ""))}</li>`).join("")
    : '<li class="muted">nothing so far</li>';
  $("fault-count").textContent = found.length ? `· ${found.length} detected` : "";
}

export function wireFaults() {
  const l = limits();
  $("fault-target").innerHTML = [...l.targets.tc, ...l.targets.group].map((t) => `<option>${t}</option>`).join("");
  $("fault-at").max = String(l.at.max);
  $("fault-target").addEventListener("change", showKinds);
  $("fault-kind").addEventListener("change", showValue);
  $("fault-add").addEventListener("click", addFault);
  $("fault-pending").addEventListener("click", (ev) => {
    if (ev.target.tagName !== "BUTTON") return;
    pending.splice(Number(ev.target.dataset.i), 1);
    renderPending();
  });
  $("fault-inject").addEventListener("click", () => send(pending.slice(), `inject ${pending.map(describeFault).join(", ")}`));
  $("fault-clear").addEventListener("click", () => send([], "clear the faults"));
  showKinds();
  renderPending();
  renderFaults(null);
}
