// The shown run's websocket stream (WS /api/runs/{id}/stream): frames into the series, events into the log.
// While the run's history is being read (state.loading) frames are held, then replayed after it.
import { token } from "./api.js";
import { addEvents, noteStatus } from "./events.js";
import { $, badge, fmt, LIVE } from "./page.js";
import { renderSoon } from "./charts.js";
import { pushFrame } from "./series.js";
import { state } from "./state.js";

export function closeStream() {
  if (state.ws) { state.ws.onclose = null; state.ws.close(); state.ws = null; }
}

export function applyFrame(f) {
  state.lastFrame = f;
  state.frames += 1;
  pushFrame(state.series, f);
  $("run-clock").textContent = `t = ${fmt(f.t)} s${f.late_samples ? ` · ${f.late_samples} late` : ""}`;
  addEvents(f.event_log);
  if (f.status && f.status !== (state.run && state.run.status)) badge(f.status);
  const ended = f.status && !LIVE.includes(f.status) && f.status !== "degraded"; // degraded: blind, going
  if (ended) noteStatus(f.status, f.t);
  state.dirty = true;
  if (ended) renderSoon(); // the run's last frame: drawn at once, not after the charts' pause
}

// onEnd() is called when the server closes the stream (the run ended or the server went away).  Returns a
// promise that settles once the server sends frames to this page (or gave up): read the history after it,
// so that no sample falls between the history and the first frame.
export function connectStream(runId, onEnd) {
  closeStream();
  const proto = location.protocol === "https:" ? "wss" : "ws";
  // a browser cannot set headers on a websocket: the token rides as a subprotocol (never in the URL)
  const protocols = token() ? ["furnace-twin", `token.${token()}`] : [];
  const ws = new WebSocket(`${proto}://${location.host}/api/runs/${runId}/stream`, protocols);
  state.ws = ws;
  ws.onmessage = (ev) => {
    const f = JSON.parse(ev.data);
    if (f.run_id !== state.runId) return;
    if (state.loading) state.held.push(f); else applyFrame(f);
  };
  const opened = new Promise((resolve) => {
    ws.onopen = resolve;
    ws.onerror = resolve;
    setTimeout(resolve, 5000);
  });
  ws.onclose = () => { if (state.ws === ws) { state.ws = null; renderSoon(); onEnd(); } };
  return opened;
}
