// The metrics (product.md) in words, in K and in % of the setpoint, for one run or side by side.
// Relative values come from the server; K = relative x the setpoint of the run's metric windows.
import { helpMark, metricName } from "./glossary.js";
import { esc, fmt } from "./page.js";
import { state } from "./state.js";

// the order of GET /api/glossary's metrics (twin.runs.metrics.METRIC_WORDS)
const keys = () => (state.glossary ? Object.keys(state.glossary.metrics) : []);

// The setpoint the relative errors of a run are divided by: its windows' (the last reference).
export function scaleOf(run) {
  if (run.windows && run.windows.setpoint) return run.windows.setpoint;
  const ref = run.scenario.reference || {};
  return ref.points ? ref.points[ref.points.length - 1][1] : ref.setpoint;
}

const kelvin = (v, scale) => (v === null || v === undefined ? "–" : `${fmt(v * scale, 1)} K`);
const percent = (v) => (v === null || v === undefined ? "–" : `${fmt(100 * v, 2)} %`);

function windowNote(run) {
  const w = run.windows;
  if (!w) return "";
  const from = w.t0 > 0 ? `from the reference change at t = ${fmt(w.t0)} s: ` : "";
  return `${from}transient ${fmt(w.transient[0], 0)}–${fmt(w.transient[1], 0)} s, steady ${fmt(w.steady[0], 0)}–${fmt(w.steady[1], 0)} s; `
    + `% of ${fmt(w.setpoint, 0)} K`;
}

const PARAM_WORDS = { lamp_efficiency: "lamp efficiency", emissivity: "emissivity", convection: "convection" };

// A calibrating run's learned parameters at its end, in % of the model's: "lamp efficiency −9.8 % ± 0.4 %".
function calibrationNote(cal) {
  if (!cal || !Object.keys(cal).length) return "";
  const one = ([name, c]) => `${esc(PARAM_WORDS[name] || name)} ${c.value === null ? "–" : `${fmt(100 * c.value, 1)} %`}`
    + `${c.sigma === null || c.sigma === undefined ? "" : ` ± ${fmt(100 * c.sigma, 1)} %`}`;
  return `<div class="note">calibrated at the end (vs the model): ${Object.entries(cal).map(one).join(" · ")}</div>`;
}

// One run: metric | K | % (| shadow % with a shadow estimator), with a help mark per metric and the windows
// they were taken over; a calibrating run's learned parameters below.
export function metricsTable(run) {
  const m = run.metrics;
  if (!m) return `<div class="note">metrics when the run ends · ${esc(windowNote(run))}</div>`;
  const scale = scaleOf(run), shadow = m.shadow && typeof m.shadow === "object" ? m.shadow : null;
  // a furnace over OPC UA has no truth: no rows for the true_* and field-estimation metrics (always null)
  const noTruth = run.scenario.plant && run.scenario.plant.kind === "opcua";
  const shown = (k) => k in m && !(noTruth && (k.startsWith("true_") || k.startsWith("field_estimation")));
  const rows = keys().filter(shown).map((k) => `<tr><td>${esc(metricName(k))} ${helpMark(k)}</td>`
    + `<td class="num">${kelvin(m[k], scale)}</td><td class="num">${percent(m[k])}</td>`
    + `${shadow ? `<td class="num">${percent(shadow[k])}</td>` : ""}</tr>`).join("");
  const shadowHead = shadow ? '<th class="num" title="the same metric of the shadow estimator">shadow %</th>' : "";
  return `<div class="note">${esc(windowNote(run))}</div><table><thead><tr><th>metric</th><th class="num">K</th>`
    + `<th class="num">% of setpoint</th>${shadowHead}</tr></thead><tbody>${rows}</tbody></table>${calibrationNote(m.calibration)}`
    + uncertaintyNote(m);
}

// The reported uncertainty against the truth (issue 25): shares and normalised squares, not errors in K.
function uncertaintyNote(m) {
  const share = (v) => (v === null || v === undefined ? "–" : `${fmt(100 * v, 1)} %`);
  if (!("coverage_2sigma_steady" in m) && !("nis_mean" in m)) return "";
  return `<div class="note" id="uncertainty-note">truth within ±2σ of the estimate (fillet cells): transient `
    + `${share(m.coverage_2sigma_transient)}, steady ${share(m.coverage_2sigma_steady)} (95 % if σ is right) · `
    + `NEES/cell ${m.nees_mean === null || m.nees_mean === undefined ? "–" : fmt(m.nees_mean, 2)} · `
    + `NIS/reading ${m.nis_mean === null || m.nis_mean === undefined ? "–" : fmt(m.nis_mean, 2)} (1 if consistent)</div>`;
}

// Several runs side by side: one column per run ("K · %"), one row per metric.
export function compareTable(runs, names) {
  const head = runs.map((r, i) => `<th class="num">${esc(names[i])}</th>`).join("");
  const rows = keys().map((k) => {
    const cells = runs.map((r) => {
      const v = r.metrics ? r.metrics[k] : undefined;
      return `<td class="num">${v === undefined || v === null ? "–" : `${kelvin(v, scaleOf(r))} · ${percent(v)}`}</td>`;
    }).join("");
    return `<tr><td>${esc(metricName(k))} ${helpMark(k)}</td>${cells}</tr>`;
  }).join("");
  const notes = runs.map((r, i) => `${esc(names[i])}: ${r.metrics ? esc(windowNote(r)) : "metrics when it ends"}`).join("<br>");
  return `<table><thead><tr><th>metric</th>${head}</tr></thead><tbody>${rows}</tbody></table><div class="note">${notes}</div>`;
}
