// The page's shared pieces: element lookup, number formats, HTML escaping, the message lines, the run badge,
// references and oscillations in words.

export const LIVE = ["queued", "starting", "running"]; // statuses of a run that is still going
// a run (from GET /api/runs) that is still going: also "degraded" (no TC reading reaches its estimate) until it
// ended; a run that ended blind keeps "degraded" with its end time
export function going(run) {
  return !!run && (LIVE.includes(run.status) || (run.status === "degraded" && !run.ended_at));
}

export const $ = (id) => document.getElementById(id);
const missing = (v) => v === null || v === undefined || Number.isNaN(v);
export const pct = (v, d = 2) => (missing(v) ? "–" : (100 * v).toFixed(d));
export const fmt = (v, d = 1) => (missing(v) ? "–" : Number(v).toFixed(d));

// Text from the server or the user, safe inside innerHTML.
export const esc = (s) => String(s ?? "").replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]);

// The message line answers what the user did (a start, a PUT, a stop); the event log holds what the run reports.
export function showMsg(text, kind = false, id = "ctl-msg") {
  const el = $(id);
  el.textContent = text;
  el.className = kind === true || kind === "err" ? "msg err" : kind === "warn" ? "msg warn" : "msg";
}

export function badge(status) {
  const b = $("run-badge");
  b.textContent = status || "no run";
  b.className = `badge ${status || "idle"}`;
}

export function describeReference(ref) {
  if (!ref) return "–";
  if (ref.points) {
    const pts = ref.points.map(([t, T]) => `${fmt(t, 0)} s \u2192 ${fmt(T, 0)} K`);
    return `points ${pts.slice(0, 4).join(", ")}${pts.length > 4 ? `, \u2026 (${pts.length})` : ""}`;
  }
  return `${ref.setpoint} K in ${ref.t_E} s`;
}

// Short form for tables: "1100 K / 120 s" or "3 pts → 1100 K".
export function shortReference(ref) {
  if (!ref) return "–";
  if (typeof ref.points === "number") return `${ref.points} pt${ref.points > 1 ? "s" : ""} \u2192 ${fmt(ref.setpoint, 0)} K`; // a list's summary
  if (ref.points) return `${ref.points.length} pt${ref.points.length > 1 ? "s" : ""} \u2192 ${fmt(ref.points[ref.points.length - 1][1], 0)} K`;
  return `${fmt(ref.setpoint, 0)} K / ${fmt(ref.t_E, 0)} s`;
}

export function describeOscillation(osc) {
  if (!osc) return "–";
  return osc.enabled ? `on (${fmt(1000 * osc.amplitude, 0)} mm, ${fmt(osc.period, 1)} s)` : "off";
}

// A run's name: the user's label, else the automatic one from what happened ("fixed", "osc 48 mm / 18 s");
// runName adds the short id (lists where two runs may share a label), runLabel does not (legends, columns).
export const runLabel = (r) => r.label || (r.story ? r.story.auto_label : "") || r.id;
export const runName = (r) => (runLabel(r) !== r.id ? `${runLabel(r)} (${r.id.slice(0, 6)})` : r.id);
// What happened: the reference and oscillation in force at the end (or now), live changes marked.
export const runStory = (r) => (r.story ? r.story.text : `${shortReference(r.scenario.reference)} · osc ${describeOscillation(r.scenario.oscillation)}`);
