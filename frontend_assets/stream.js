// The picked run's websocket stream (WS /api/runs/{id}/stream): frames into the series, events into the log.
import { token } from "./api.js";
import { addEvent, noteStatus } from "./events.js";
import { $, badge, fmt, LIVE } from "./page.js";
import { pushFrame } from "./series.js";
import { state } from "./state.js";

export function closeStream() {
  if (state.ws) { state.ws.onclose = null; state.ws.close(); state.ws = null; }
}

// onEnd() is called when the server closes the stream (the run ended or the server went away).
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
    state.lastFrame = f;
    state.frames += 1;
    pushFrame(state.series, f);
    $("run-clock").textContent = `t = ${fmt(f.t)} s`;
    if (f.seq === undefined || f.seq > state.eventSeq) { // the last frame of a run may repeat its sample
      for (const e of f.events || []) addEvent(f.t, e, /fail|error|reject/i.test(e) ? "warn" : "");
      if (f.seq !== undefined) state.eventSeq = f.seq;
    }
    if (f.status && f.status !== (state.run && state.run.status)) badge(f.status);
    if (f.status && !LIVE.includes(f.status)) noteStatus(f.status, f.t);
    state.dirty = true;
  };
  ws.onclose = () => { if (state.ws === ws) { state.ws = null; onEnd(); } };
}
