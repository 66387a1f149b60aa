// The list of runs (the "Runs & comparison" view) and the Show menu: label (editable), start time,
// reference, oscillation, status, steady-state errors, files, delete; a filter; ticks for the comparison.
import { api } from "./api.js";
import { $, describeOscillation, esc, going, pct, runLabel, runName, runStory, shortReference, showMsg } from "./page.js";
import { state } from "./state.js";

let tableHtml = null, pickHtml = null;
let onCompare = () => {};
let onShow = () => {};
const overOpcUa = (r) => !!(r.scenario.plant && r.scenario.plant.kind === "opcua");

const matches = (r, words) => {
  const text = `${runLabel(r)} ${r.id} ${r.status} ${runStory(r)} `
    + `${r.scenario.oscillation.enabled ? "oscillating osc" : "fixed"} ${overOpcUa(r) ? `opc ua ${r.scenario.plant.endpoint}` : "simulated"}`;
  return words.every((w) => text.toLowerCase().includes(w));
};

function row(r) {
  const m = r.metrics || {}, base = `/api/runs/${r.id}`, live = going(r);
  const when = new Date((r.started_at || r.created_at) * 1000);
  // what happened (the server's story); a run from an older server: as it started
  const story = r.story || { reference: shortReference(r.scenario.reference), oscillation: describeOscillation(r.scenario.oscillation) };
  // only the files the run has: an interrupted run may have none (its links answered a raw 404)
  const f = r.files || {}, series = f.timeseries || (live && r.latest);
  const files = (series ? `<a href="${base}/export.csv" download>csv</a><a href="${base}/report.pdf" download>pdf</a>` : "")
    + (f.timeseries ? `<a href="${base}/timeseries" download>npz</a>` : "")
    + (f.recording ? `<a href="${base}/recording.rrd" download>rrd</a>` : "")
    + (!series && !f.recording ? `<span class="muted" title="${live ? "files come with the run's first sample" : "the run ended before any sample was saved"}">no files</span>` : "")
    + (r.links && r.links.rerun ? `<a href="${esc(r.links.rerun)}" target="_blank" rel="noopener" title="open in the rerun web viewer">rerun</a>` : "");
  return `<tr data-id="${esc(r.id)}"><td><input type="checkbox" class="cmp" aria-label="compare ${esc(r.id)}"${state.compare.has(r.id) ? " checked" : ""}></td>
    <td class="label"><button class="name${r.label ? "" : " auto"}" title="${r.label ? "show this run" : "show this run (an automatic label, from what happened: ✎ names it)"}">${esc(runLabel(r))}</button>
      <button class="link edit" title="edit the label">✎</button><br><span class="id">${esc(r.id)}</span></td>
    <td title="${esc(when.toLocaleString())}">${esc(when.toLocaleDateString())} ${esc(when.toLocaleTimeString([], { hour: "2-digit", minute: "2-digit" }))}</td>
    <td class="story">${esc(story.reference)}${overOpcUa(r) ? `<br><span class="id" title="${esc(r.scenario.plant.endpoint)}">OPC UA</span>` : ""}</td>
    <td class="story">${esc(story.oscillation)}</td>
    <td><span class="badge ${esc(r.status)}">${esc(r.status)}</span></td>
    <td class="num">${pct(m.mean_error_steady_max)} %</td><td class="num">${pct(m.tc4_error_steady_max)} %</td>
    <td class="num">${pct(m.inhomogeneity_steady)} %</td><td>${files}</td>
    <td><button class="del" title="${live ? "a running run cannot be deleted: stop it first" : "delete this run and its files"}"${live ? " disabled" : ""}>✕</button></td></tr>`;
}

function render() {
  if (document.querySelector("#history input.label-edit")) return; // not while a label is being typed
  const words = $("run-filter").value.trim().toLowerCase().split(/\s+/).filter(Boolean);
  const shown = state.runs.filter((r) => matches(r, words));
  $("runs-count").textContent = `${shown.length} of ${state.runs.length} runs`;
  const html = shown.map(row).join("");
  if (html !== tableHtml) { document.querySelector("#history tbody").innerHTML = html; tableHtml = html; }
  const opts = [`<option value="">–</option>`, ...state.runs.slice(0, 60).map((r) =>
    `<option value="${esc(r.id)}">${esc(runName(r))} · ${esc(r.status)} · ${esc(runStory(r))}</option>`)].join("");
  if (opts !== pickHtml) { $("run-pick").innerHTML = opts; pickHtml = opts; }
  markShown();
  $("compare-count").textContent = state.compare.size ? `· ${state.compare.size} ticked` : "";
  $("compare-clear").disabled = !state.compare.size;
}

export function markShown() {
  for (const tr of document.querySelectorAll("#history tbody tr")) tr.classList.toggle("sel", tr.dataset.id === state.runId);
  if (state.runId && $("run-pick").value !== state.runId) $("run-pick").value = state.runId;
}

export async function refreshRuns() {
  try { state.runs = await api("GET", "/api/runs?limit=200"); } catch (e) { return; }
  for (const id of [...state.compare]) if (!state.runs.some((r) => r.id === id)) state.compare.delete(id);
  render();
  onCompare();
}

function editLabel(tr) {
  const run = state.runs.find((r) => r.id === tr.dataset.id);
  const cell = tr.querySelector("td.label");
  cell.innerHTML = `<input class="label-edit" maxlength="80" value="${esc(run ? runLabel(run) : "")}" aria-label="label of run ${esc(tr.dataset.id)}">`;
  const input = cell.querySelector("input");
  input.focus();
  let done = false;
  const finish = async (save) => {
    if (done) return;
    done = true;
    // an automatic label left as it was stays automatic (it follows what happens next)
    const same = run && !run.label && input.value.trim() === runLabel(run);
    if (save && !same) {
      try { await api("PATCH", `/api/runs/${tr.dataset.id}`, { label: input.value }); } catch (e) { showMsg(e.message, true, "start-msg"); }
    }
    input.remove();
    tableHtml = null;
    await refreshRuns();
  };
  input.addEventListener("keydown", (ev) => { if (ev.key === "Enter") finish(true); if (ev.key === "Escape") finish(false); });
  input.addEventListener("blur", () => finish(true));
}

async function deleteRun(id) {
  const run = state.runs.find((r) => r.id === id);
  if (!window.confirm(`Delete run ${run ? runName(run) : id} with its recording, time series and metrics? This cannot be undone.`)) return;
  try {
    await api("DELETE", `/api/runs/${id}`);
    state.compare.delete(id);
    showMsg(`run ${id} deleted`, false, "start-msg");
  } catch (e) { showMsg(e.message, true, "start-msg"); }
  tableHtml = null;
  await refreshRuns();
}

// show(id): show a run; compareChanged(): the ticked runs changed.
export function wireRunList(show, compareChanged) {
  onShow = show; onCompare = compareChanged;
  const tbody = document.querySelector("#history tbody");
  tbody.addEventListener("click", (ev) => {
    const tr = ev.target.closest("tr");
    if (!tr) return;
    if (ev.target.closest("button.name")) onShow(tr.dataset.id);
    else if (ev.target.closest("button.edit")) editLabel(tr);
    else if (ev.target.closest("button.del")) deleteRun(tr.dataset.id);
  });
  tbody.addEventListener("change", (ev) => {
    if (!ev.target.classList.contains("cmp")) return;
    const id = ev.target.closest("tr").dataset.id;
    if (ev.target.checked) state.compare.add(id); else state.compare.delete(id);
    tableHtml = null;
    render();
    onCompare();
  });
  $("run-filter").addEventListener("input", render);
  $("compare-clear").addEventListener("click", () => { state.compare.clear(); tableHtml = null; render(); onCompare(); });
  $("run-pick").addEventListener("change", (ev) => { if (ev.target.value) onShow(ev.target.value, false); });
}
