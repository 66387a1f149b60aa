// The event log of the picked run: what the run reports (changes applied, re-plans, its end).
import { $, fmt, LIVE, showMsg } from "./page.js";
import { state } from "./state.js";

const MAX_EVENTS = 200; // entries kept (newest at top)

export function clearEvents() {
  $("event-log").innerHTML = '<li class="empty muted">events of the shown run appear here</li>';
  state.nEvents = 0;
  $("event-count").textContent = "";
}

export function addEvent(t, text, kind = "") {
  const log = $("event-log");
  const empty = log.querySelector("li.empty");
  if (empty) empty.remove();
  const li = document.createElement("li");
  if (kind) li.className = kind;
  const ts = document.createElement("span");
  ts.className = "t";
  ts.textContent = t === null || t === undefined ? "" : `t = ${fmt(t)} s`;
  li.append(ts, document.createTextNode(` ${text}`));
  log.prepend(li); // newest at top
  while (log.children.length > MAX_EVENTS) log.lastElementChild.remove();
  state.nEvents += 1;
  $("event-count").textContent = `· ${state.nEvents}`;
}

// A status change of the picked run goes to the event log once; the end of a run completes Stop's message.
export function noteStatus(status, t) {
  if (!status || status === state.lastStatus) return;
  const first = state.lastStatus === null;
  state.lastStatus = status;
  if (first && !LIVE.includes(status)) return;
  const run = state.run;
  const kind = status === "error" ? "err" : (status === "interrupted" ? "warn" : "");
  addEvent(t, `run ${status}${status === "error" && run && run.error ? `: ${run.error}` : ""}`, kind);
  if (state.stopping === state.runId && !LIVE.includes(status)) { // the Stop reply, completed
    showMsg(`run ${state.runId} ${status}${t !== null && t !== undefined ? ` at t = ${fmt(t)} s` : ""}; its data is kept`);
    state.stopping = null;
  }
  if (status === "error" && run && run.error) showMsg(`run ${run.id} failed: ${run.error}`, true);
}
