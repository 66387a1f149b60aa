// The estimators of the shown run (issue 11), three cards below the others, each shown only while the run
// has such data (history from GET .../series, then the stream's frames):
// - "Calibrated parameters": each learned parameter as a deviation from the model in %, with a ±1 sigma band;
// - "TC4 error: estimate vs shadow": TC4 reading − estimate for the run's estimator and for its shadow;
// - "Shadow − estimate": the last shadow field minus the estimated field (K), a diverging scale centred at 0.
import { baseLayout, registerFigure } from "./charts.js";
import { describeChoice } from "./estimatorform.js";
import { termText } from "./glossary.js";
import { fieldLayout, tcPositions } from "./heatmap.js";
import { windowShapes } from "./overlays.js";
import { $, esc, fmt } from "./page.js";
import { addChartCard } from "./panels.js";
import { emptySeries } from "./series.js";
import { state } from "./state.js";

const PARAM_WORDS = { lamp_efficiency: "lamp efficiency", emissivity: "emissivity", convection: "convection" };
const PARAM_COLORS = { lamp_efficiency: [214, 158, 46], emissivity: [128, 90, 213], convection: [44, 122, 123] };
const rgb = (c, a = 1) => `rgba(${c[0]}, ${c[1]}, ${c[2]}, ${a})`;
// blue: the shadow is colder than the estimate, red: hotter, white: the same (ColorBrewer RdBu)
const DIVERGING = [[0, "#2166ac"], [0.2, "#4393c3"], [0.4, "#d1e5f0"], [0.5, "#f7f7f7"], [0.6, "#fddbc7"],
  [0.8, "#d6604d"], [1, "#b2182b"]];
const ESTIMATE_COLOR = "#d62728", SHADOW_COLOR = "#1f77b4"; // the estimate's TC4 colour of the TC chart

const series = () => state.series || emptySeries();
const estimators = () => (state.run && state.run.scenario && state.run.scenario.estimator) || null;
const tMax = (s) => (s.t.length ? s.t[s.t.length - 1] : 0);
const windows = () => (state.run && state.run.windows) || (state.series && state.series.windows) || null;

// A card shows only with its data; its figure is not drawn while hidden (charts.js skips null).
function show(id, on) {
  const card = $(`card-${id}`);
  if (card && card.hidden === on) { card.hidden = !on; if (on) window.dispatchEvent(new Event("resize")); }
  return on;
}

// What the chart says, in words (issue 27 item 10): each line, the bound it sits at, and what that means.
const pctSigned = (v) => `${v >= 0 ? "+" : "−"}${Math.abs(100 * v).toFixed(1)} %`;
const AT_BOUND = 0.005; // within 0.5 % points of a bound: held there

export function parameterWords(name, v, sigma, bounds) {
  const word = PARAM_WORDS[name] || name;
  const now = `${word} ${pctSigned(v)}${sigma !== null && sigma !== undefined ? ` ± ${(100 * sigma).toFixed(1)} %` : ""}`;
  if (bounds) {
    const [lo, hi] = bounds;
    const side = v <= lo + AT_BOUND ? lo : v >= hi - AT_BOUND ? hi : null;
    if (side !== null) {
      return `${word} at its ${pctSigned(side)} bound: the twin's model cannot explain the TCs with ${word} alone ` +
        "(the furnace differs from the model in more than this parameter); it is held at the bound";
    }
  }
  if (sigma !== null && sigma !== undefined && Math.abs(v) < sigma) {
    return `${now}: not settled, within ±1σ of the model's own value (0 %)`;
  }
  return `${now}: the TCs say this furnace's ${word} is ${Math.abs(100 * v).toFixed(1)} % ${v >= 0 ? "above" : "below"} the model's`;
}

function paramWordsBox() {
  let box = $("param-words");
  if (!box) {
    box = document.createElement("div");
    Object.assign(box, { id: "param-words", className: "param-words" });
    $("card-param-plot").append(box);
  }
  return box;
}

function parameterFigure() {
  const s = series();
  const names = Object.keys(s.params).filter((n) => s.params[n].v.some((v) => v !== null));
  if (!show("param-plot", names.length > 0)) return null;
  const bounds = (state.furnace && state.furnace.calibration_bounds) || {};
  const last = (arr) => { for (let k = arr.length - 1; k >= 0; k--) if (arr[k] !== null) return arr[k]; return null; };
  const lines = names.map((n) => `<li>${esc(parameterWords(n, last(s.params[n].v), last(s.params[n].s), bounds[n]))}</li>`);
  const html = `<p>Each line: how far the twin's estimate of a furnace parameter has moved from the model's value (0 %), with a ±1σ band; dashed: the bounds it is held within.</p><ul>${lines.join("")}</ul>`;
  const box = paramWordsBox();
  if (box.dataset.html !== html) { box.innerHTML = html; box.dataset.html = html; }
  const data = [];
  for (const name of names) {
    const p = s.params[name], c = PARAM_COLORS[name] || [90, 90, 90], word = PARAM_WORDS[name] || name;
    const v = p.v.map((x) => (x === null ? null : 100 * x));
    const band = (sign) => p.v.map((x, k) => (x === null || p.s[k] === null ? null : 100 * (x + sign * p.s[k])));
    data.push(
      { x: s.t, y: band(-1), legendgroup: name, showlegend: false, hoverinfo: "skip", line: { width: 0, color: rgb(c) } },
      { x: s.t, y: band(+1), legendgroup: name, showlegend: false, hoverinfo: "skip", line: { width: 0, color: rgb(c) },
        fill: "tonexty", fillcolor: rgb(c, 0.2) },
      { x: s.t, y: v, name: `${word} ±1σ`, legendgroup: name, line: { color: rgb(c), width: 1.8 },
        customdata: p.s.map((x) => (x === null ? null : 100 * x)),
        hovertemplate: `${word} %{y:.2f} % ± %{customdata:.2f} % at %{x:.1f} s<extra></extra>` },
    );
  }
  const shapes = [], annotations = [];
  for (const name of names) {
    const c = PARAM_COLORS[name] || [90, 90, 90];
    for (const b of bounds[name] || []) {
      shapes.push({ type: "line", xref: "paper", x0: 0, x1: 1, y0: 100 * b, y1: 100 * b, line: { color: rgb(c, 0.8), width: 1, dash: "dash" } });
      annotations.push({ xref: "paper", x: 1, xanchor: "right", y: 100 * b, yanchor: b < 0 ? "bottom" : "top", showarrow: false,
        text: `${PARAM_WORDS[name] || name} bound ${pctSigned(b)}`, font: { size: 9, color: rgb(c) } });
    }
  }
  return { data, layout: baseLayout("deviation from the model (%)", { shapes, annotations,
    yaxis: { title: { text: "deviation from the model (%)", standoff: 4 }, zeroline: true, zerolinecolor: "#9aa5b8" } }) };
}

function tc4Figure() {
  const s = series();
  if (!show("shadow-tc4-plot", s.shadowTc4Err.some((v) => v !== null))) return null;
  const est = estimators(), w = windowShapes(windows(), tMax(s));
  const name = (who, c) => `${who}${c ? `: ${describeChoice(c)}` : ""}`;
  return {
    data: [
      { x: s.t, y: s.tcErr[3], name: name("estimate", est), line: { color: ESTIMATE_COLOR, width: 1.6 },
        hovertemplate: "estimate: %{y:.2f} K at %{x:.1f} s<extra></extra>" },
      { x: s.t, y: s.shadowTc4Err, name: name("shadow", est && est.shadow), line: { color: SHADOW_COLOR, width: 1.6 },
        hovertemplate: "shadow: %{y:.2f} K at %{x:.1f} s<extra></extra>" },
    ],
    layout: baseLayout("TC4 reading − estimate (K)", { shapes: w.shapes, annotations: w.annotations,
      yaxis: { title: { text: "TC4 reading − estimate (K)", standoff: 4 }, zeroline: true, zerolinecolor: "#9aa5b8" } }),
  };
}

const largest = (z) => { let m = 0; for (const row of z) for (const v of row) if (v !== null) m = Math.max(m, Math.abs(v)); return m; };

// The scale: ±(largest |difference|), at least 0.1 K, rounded up to 2 significant digits.
function symmetricRange(big) {
  const m = Math.max(big, 0.1);
  const step = 10 ** (Math.floor(Math.log10(m)) - 1);
  return Math.ceil(m / step - 1e-9) * step;
}

function deltaFigure() {
  const s = series();
  if (!show("shadow-delta-plot", !!s.shadowDelta)) return null;
  const fu = state.furnace, z = s.shadowDelta, big = largest(z), m = symmetricRange(big);
  const [tcx, tcy] = tcPositions();
  const f = state.lastFrame;
  $("shadow-delta-sub").textContent = `${f ? `t = ${fmt(f.t)} s · ` : ""}max |Δ| ${fmt(big, big < 1 ? 2 : 1)} K`;
  return {
    data: [
      { type: "heatmap", x: fu.x, y: fu.y, z, colorscale: DIVERGING, zmid: 0, zmin: -m, zmax: m, zsmooth: "best",
        colorbar: { title: { text: "K", side: "right" }, thickness: 12, len: 0.95 },
        hovertemplate: "x %{x:.3f} m<br>y %{y:.3f} m<br>shadow − estimate %{z:.2f} K<extra></extra>" },
      { type: "scatter", mode: "markers+text", x: tcx, y: tcy,
        text: ["TC1", "TC2", "TC3", "TC4"], textposition: ["top center", "top center", "top center", "bottom center"],
        textfont: { size: 10, color: "#1d2330" }, hoverinfo: "skip", showlegend: false,
        marker: { symbol: ["circle", "circle", "circle", "diamond"], size: 8, color: ["#fff", "#fff", "#fff", "#ff4fc8"],
          line: { color: "#000", width: 1.2 } } },
    ],
    layout: fieldLayout("x (m)", { color: "#56627a", width: 1.5 }),
  };
}

// The cards (after the glossary is loaded: their help marks carry its words) and their figures.
export function initEstimatorCharts() {
  const term = (key, fallback) => (termText(key) ? key : fallback);
  addChartCard("param-plot", "Calibrated parameters (±1σ)", term("calibration", "estimate"));
  addChartCard("shadow-tc4-plot", "TC4 error: estimate vs shadow", term("shadow", "tc4"));
  addChartCard("shadow-delta-plot", "Shadow − estimate", term("shadow", "estimate"));
  const sub = document.createElement("span");
  Object.assign(sub, { id: "shadow-delta-sub", className: "muted" });
  $("card-shadow-delta-plot").querySelector(".card-title").append(sub);
  for (const id of ["param-plot", "shadow-tc4-plot", "shadow-delta-plot"]) $(`card-${id}`).hidden = true;
  registerFigure("param-plot", parameterFigure);
  registerFigure("shadow-tc4-plot", tc4Figure);
  registerFigure("shadow-delta-plot", deltaFigure);
}
