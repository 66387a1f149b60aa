// Messages that follow what they announced (issue 27 item 9): a start says "queued" while the run waits and
// "running" once it runs; a live change said "pending" says "applied at t = …", or that the run ended first.
// Both are settled from the shown run as GET /api/runs/{id} returns it (refreshRun).
import { fmt, going, showMsg } from "./page.js";

let start = null; // {id, rest, kind}: the start message of a run not yet running ("run <id> <status><rest>")
let change = null; // {runId, kind, what}: a live change the server answered "pending" to

export function followStart(id, rest, kind) { start = { id, rest, kind }; }

// kind: "reference" or "oscillation"; the change is the run's newest of that kind
export function followChange(runId, kind, what) { change = { runId, kind, what }; }

const at = (t) => (t !== null && t !== undefined ? ` at t = ${fmt(t)} s` : "");

export function settle(run) {
  if (start && start.id === run.id && run.status !== "queued") {
    showMsg(`run ${run.id} ${run.status}${start.rest}`, start.kind, "start-msg");
    if (run.status !== "starting") start = null;
  }
  if (!change || change.runId !== run.id) return;
  const mine = (run.changes || []).filter((c) => c.kind === change.kind);
  const last = mine[mine.length - 1];
  if (!last) return;
  if (last.status === "applied") showMsg(`${change.what}: applied${at(last.applied_t)}`);
  else if (last.status === "pending" && going(run)) return; // still re-planning
  else if (last.status === "pending" || last.status === "cancelled") {
    showMsg(`${change.what}: not applied: the run ${run.status} before it was ready`, "warn");
  } else showMsg(`${change.what}: ${last.status}${last.message ? `: ${last.message}` : ""}`, true);
  change = null;
}

