// The event log of the shown run: what the run reports (start, live changes, re-plans, saturated groups,
// feasibility warnings, its end), each event once, newest at top.  Events come numbered (n) from the
// run's history (GET .../series) and from the stream's frames (event_log), so every tab shows the same list.
import { $, fmt, LIVE, showMsg } from "./page.js";
import { state } from "./state.js";

const SHOWN = 300; // newest events listed

export function clearEvents() {
  state.events = new Map();
  render();
}

// events: [{n, t, text, level}]; unknown numbers are added, known ones ignored.
export function addEvents(events) {
  let added = false;
  for (const e of events || []) {
    if (e && e.n !== undefined && !state.events.has(e.n)) { state.events.set(e.n, e); added = true; }
  }
  if (added) render();
}

// The severity filter: every event, the start / end / changes / warnings (what the report lists), or warnings
const CHANGE = /^run (started|finished|stopped|interrupted|failed|lost|ended)|^fault injected|^faults cleared|reference changed at|oscillation (on|off) at|calibration at/;
const FILTERS = {
  all: () => true,
  changes: (e) => (e.level && e.level !== "info") || CHANGE.test(e.text),
  warn: (e) => e.level === "warn" || e.level === "error",
};

export function wireEventFilter() {
  const el = $("event-filter");
  try { el.value = localStorage.getItem("furnace-twin-event-filter") || "all"; } catch (e) { /* default */ }
  if (!FILTERS[el.value]) el.value = "all";
  el.addEventListener("change", () => {
    try { localStorage.setItem("furnace-twin-event-filter", el.value); } catch (e) { /* not kept */ }
    render();
  });
}

function render() {
  const log = $("event-log");
  const every = [...state.events.values()].sort((a, b) => b.n - a.n);
  const keep = FILTERS[$("event-filter").value] || FILTERS.all;
  const all = every.filter(keep);
  $("event-count").textContent = every.length ? (all.length === every.length ? `· ${every.length}` : `· ${all.length} of ${every.length}`) : "";
  if (!all.length) {
    log.innerHTML = every.length ? '<li class="empty muted">none of this kind (see the filter)</li>'
      : '<li class="empty muted">events of the shown run appear here</li>';
    return;
  }
  log.replaceChildren(...all.slice(0, SHOWN).map((e) => {
    const li = document.createElement("li");
    if (e.level && e.level !== "info") li.className = e.level;
    const ts = document.createElement("span");
    ts.className = "t";
    ts.textContent = `t = ${fmt(e.t)} s`;
    li.append(ts, document.createTextNode(` ${e.text}`));
    return li;
  }));
}

// A status change of the shown run completes Stop's message line once; an error goes there too.
export function noteStatus(status, t) {
  if (!status || status === state.lastStatus) return;
  state.lastStatus = status;
  const run = state.run;
  const failed = status === "error" || status === "plant_lost"; // plant_lost: the furnace's link was not restored
  if (state.stopping === state.runId && !LIVE.includes(status)) { // the Stop reply, completed
    showMsg(`run ${state.runId} ${status}${t !== null && t !== undefined ? ` at t = ${fmt(t)} s` : ""}; its data is kept`);
    state.stopping = null;
  }
  if (failed && run && run.error) showMsg(`run ${run.id} ${status === "plant_lost" ? "lost its furnace" : "failed"}: ${run.error}`, true);
}
