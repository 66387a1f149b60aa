// The metrics (product.md) in words, in K and in % of the setpoint, for one run or side by side.
// Relative values come from the server; K = relative x the setpoint of the run's metric windows.
import { helpMark, metricName } from "./glossary.js";
import { esc, fmt } from "./page.js";
import { state } from "./state.js";

// the errors relative to the setpoint (shown in K and %), in the order of GET /api/glossary's metrics
// (twin.runs.metrics.metric_glossary; its other metrics are shares, normalised squares or counts: not in K)
const RELATIVE = "fraction of the setpoint"; // twin.runs.metrics.RELATIVE
const keys = () => (state.glossary
  ? Object.entries(state.glossary.metrics).filter(([, v]) => v.unit === RELATIVE).map(([k]) => k) : []);

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

// Several runs side by side: one column per run ("K · %"), one row per metric, and for each run after the
// first its difference to the first (K and % points: negative = smaller than the first's).
export function compareTable(runs, names) {
  const diffHead = runs.slice(1).map((r, i) => `<th class="num diff" title="this run's value minus the first's">`
    + `${esc(names[i + 1])} − ${esc(names[0])}</th>`).join("");
  const head = runs.map((r, i) => `<th class="num">${esc(names[i])}</th>`).join("") + diffHead;
  const val = (r, k) => (r.metrics && r.metrics[k] !== null && r.metrics[k] !== undefined ? r.metrics[k] : null);
  const rows = keys().map((k) => {
    const cells = runs.map((r) => {
      const v = val(r, k);
      return `<td class="num">${v === null ? "–" : `${kelvin(v, scaleOf(r))} · ${percent(v)}`}</td>`;
    }).join("");
    const a = val(runs[0], k);
    const diffs = runs.slice(1).map((r) => {
      const b = val(r, k);
      if (a === null || b === null) return '<td class="num diff">–</td>';
      const dK = b * scaleOf(r) - a * scaleOf(runs[0]);
      return `<td class="num diff">${signed(dK, 1)} K · ${signed(100 * (b - a), 2)} pts</td>`;
    }).join("");
    return `<tr><td>${esc(metricName(k))} ${helpMark(k)}</td>${cells}${diffs}</tr>`;
  }).join("");
  const notes = runs.map((r, i) => `${esc(names[i])}: ${r.metrics ? esc(windowNote(r)) : "metrics when it ends"}`).join("<br>");
  return `<table><thead><tr><th>metric</th>${head}</tr></thead><tbody>${rows}</tbody></table><div class="note">${notes}</div>`;
}

const signed = (v, d) => `${v > 0 ? "+" : v < 0 ? "\u2212" : "\u00b1"}${Math.abs(v).toFixed(d)}`;

// The answer to "did it help?" for each run against the first, in one line each: the steady inhomogeneity
// (T_sup) by the true field, which judges (it is the furnace itself, here simulated), and by the estimate, which
// is what the twin of a real furnace would show; the estimate's own error on the fillet says how far a difference
// in it can be trusted.
export function verdict(runs, names) {
  const v = (r, k) => (r.metrics && r.metrics[k] !== null && r.metrics[k] !== undefined ? r.metrics[k] : null);
  const p = (x) => `${fmt(100 * x, 2)} %`;
  const a = runs[0];
  if (runs.length < 2 || !a.metrics) return "";
  const lines = runs.slice(1).map((b, i) => {
    const head = `<b>${esc(names[i + 1])}</b> against <b>${esc(names[0])}</b>`;
    if (!b.metrics) return `<div>${head}: when it ends.</div>`;
    const [ta, tb] = [v(a, "true_inhomogeneity_steady"), v(b, "true_inhomogeneity_steady")];
    const [ea, eb] = [v(a, "inhomogeneity_steady"), v(b, "inhomogeneity_steady")];
    const err = Math.max(v(a, "field_estimation_error_steady_max") || 0, v(b, "field_estimation_error_steady_max") || 0);
    const est = ea === null || eb === null ? "" : `the estimate (what a real furnace would show) says ${p(eb)} against ${p(ea)}`
      + ` (${signed(100 * (eb - ea), 2)} pts)`;
    if (ta === null || tb === null) {
      const real = [a, b].some((r) => r.scenario.plant && r.scenario.plant.kind === "opcua");
      const why = real ? "a furnace over OPC UA has no true field" : "their metrics have no true T<sub>sup</sub>";
      return `<div>${head}: steady T<sub>sup</sub> — ${why}; ${est ? `${est}, and its TC4 error is the only check of it`
        : "nor an estimated one"}.</div>`;
    }
    const d = tb - ta;
    const word = Math.abs(d) < 1e-4 ? "the same as" : d < 0 ? "lower (better) than" : "higher (worse) than";
    const trust = err ? `; the estimate is off the true field by up to ${p(err)} on the fillet, so it cannot settle a difference smaller than that` : "";
    return `<div class="verdict-line">${head}: steady T<sub>sup</sub> by the <b>true field</b> ${p(tb)}, ${word} ${p(ta)}`
      + ` (${signed(100 * d, 2)} pts) — the true field judges. ${est ? `${est[0].toUpperCase()}${est.slice(1)}${trust}.` : ""}`
      + ` One seed each: a difference of a few hundredths of a % needs more seeds (Studies).</div>`;
  });
  return lines.join("");
}
