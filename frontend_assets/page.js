// The page's shared pieces: element lookup, number formats, the message lines, the run badge.

export const LIVE = ["queued", "starting", "running"]; // statuses of a run that is still going

export const $ = (id) => document.getElementById(id);
export const pct = (v, d = 2) => (v === null || v === undefined || Number.isNaN(v) ? "–" : (100 * v).toFixed(d));
export const fmt = (v, d = 1) => (v === null || v === undefined || Number.isNaN(v) ? "–" : Number(v).toFixed(d));

// The message line answers what the user did (a start, a PUT, a stop); the event log holds what the run reports.
export function showMsg(text, isErr = false, id = "ctl-msg") {
  const el = $(id);
  el.textContent = text;
  el.className = isErr ? "msg err" : "msg";
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

export function describeOscillation(osc) {
  if (!osc) return "–";
  return osc.enabled ? `on (${fmt(1000 * osc.amplitude, 0)} mm, ${fmt(osc.period, 1)} s)` : "off";
}
