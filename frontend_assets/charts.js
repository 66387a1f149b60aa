// The shown run's charts (plotly.js from /assets/plotly.min.js): a registry of figure functions, one per
// chart element, redrawn together at most every RENDER_MS.  A new chart: a card in #plots (panels.js) and
// registerFigure(id, () => ({data, layout})); a figure function that returns null is not drawn this time
// (e.g. its card is hidden because the shown run has no such data).
import { heatmapFigure } from "./heatmap.js";
import { GROUP_COLORS, LANE, LANE0, saturationShapes, windowShapes } from "./overlays.js";
import { emptySeries, saturationSpans } from "./series.js";
import { state } from "./state.js";
import { meanBand } from "./uncertainty.js";

const TC_COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728"];
const RENDER_MS = 250; // charts redraw at most 4 times per second; frames arrive up to 20/s
// no logo, no "Share chart" (plotly.js would upload the chart to its cloud), no lasso / box select
export const CONFIG = { displaylogo: false, responsive: true, showSendToCloud: false, showEditInChartStudio: false,
  showLink: false, modeBarButtonsToRemove: ["sendChartToCloud", "editInChartStudio", "lasso2d", "select2d"] };

let revision = 0; // plotly redraws arrays that grew in place only when datarevision changes
export const baseLayout = (ytitle, extra = {}) => Object.assign({
  datarevision: revision,
  margin: { l: 54, r: 10, t: 6, b: 34 },
  xaxis: { title: { text: "t (s)", standoff: 2 }, zeroline: false },
  yaxis: { title: { text: ytitle, standoff: 4 }, zeroline: false },
  legend: { orientation: "h", x: 0, y: -0.2, font: { size: 10 } },
  paper_bgcolor: "#fff", plot_bgcolor: "#fafbfc", font: { size: 11, color: "#1d2330" },
}, extra);

const FIGURES = new Map();
export function registerFigure(id, figure) { FIGURES.set(id, figure); }

const windows = () => (state.run && state.run.windows) || (state.series && state.series.windows) || null;
const tMax = (s) => (s.t.length ? s.t[s.t.length - 1] : 0);

// The user's reference points of the shown run (start and applied live changes) in run time.
function referenceMarkers(run) {
  const x = [], y = [];
  if (!run) return { x, y };
  const add = (ref, t0) => { if (ref && ref.points) for (const [t, T] of ref.points) { x.push(t0 + t); y.push(T); } };
  add(run.scenario.reference, 0);
  for (const ch of run.changes || []) if (ch.kind === "reference" && ch.status === "applied") add(ch.body, ch.applied_t || 0);
  return { x, y };
}

function meanFigure(s) {
  const pts = referenceMarkers(state.run);
  const w = windowShapes(windows(), tMax(s));
  return {
    data: [ // the band last: traces 0-2 keep their places (reference, estimate, points)
      { x: s.t, y: s.T_ref, name: "reference T_ref", line: { color: "#111", dash: "dash", width: 1.6 } },
      { x: s.t, y: s.T_mean_hat, name: "fillet mean (estimate)", line: { color: "#d62728", width: 1.8 } },
      { x: pts.x, y: pts.y, name: "reference points", mode: "markers", showlegend: pts.x.length > 0,
        marker: { symbol: "circle-open", size: 8, color: "#111", line: { width: 1.6 } },
        hovertemplate: "%{x:.1f} s, %{y:.0f} K<extra>reference point</extra>" },
      ...meanBand(s),
    ],
    layout: baseLayout("T (K)", { shapes: w.shapes, annotations: w.annotations }),
  };
}

function powerFigure(s) {
  const groups = state.furnace.groups.map((g) => g.name);
  const words = (state.glossary && state.glossary.groups) || {};
  const lanes = saturationShapes(saturationSpans(s));
  return {
    data: [
      ...groups.flatMap((g, j) => [
        { x: s.t, y: s.u[j], name: g, legendgroup: g, line: { color: GROUP_COLORS[j], width: 1.5 },
          hovertemplate: `%{y:.2f} at %{x:.1f} s<extra>${words[g] || g}</extra>` },
        { x: s.t, y: s.u_ff[j], name: `${g} u_ff`, legendgroup: g, showlegend: false,
          line: { color: GROUP_COLORS[j], width: 1, dash: "dot" }, hovertemplate: `u_ff %{y:.2f}<extra>${g}</extra>` },
      ]),
      { x: s.t, y: s.eta.map((v) => v * 1000), name: "η", yaxis: "y2", line: { color: "#2c7a7b", width: 1.2 },
        showlegend: false, hovertemplate: "η %{y:.1f} mm at %{x:.1f} s<extra></extra>" },
    ],
    layout: baseLayout("u / u_max", {
      yaxis: { title: { text: "u / u_max", standoff: 4 }, domain: [0.3, 1], range: [-0.03, LANE0 + 6 * LANE], zeroline: false,
        tickvals: [0, 0.25, 0.5, 0.75, 1] },
      yaxis2: { title: { text: "η (mm)", standoff: 4 }, domain: [0, 0.2], zeroline: false },
      xaxis: { title: { text: "t (s)", standoff: 2 }, zeroline: false, anchor: "y2" },
      legend: { orientation: "v", x: 1.01, y: 1, font: { size: 10 } }, margin: { l: 54, r: 58, t: 6, b: 34 },
      shapes: lanes, // the saturation lanes above u = 1 (their help mark: "saturation")
    }),
  };
}

function tcFigure(s) {
  const w = windowShapes(windows(), tMax(s));
  return {
    data: s.tcErr.map((e, i) => ({ x: s.t, y: e, name: i < 3 ? `TC${i + 1}` : "TC4 (validation)",
      line: { color: TC_COLORS[i], width: i < 3 ? 1.1 : 2 } })),
    layout: baseLayout("reading − estimate (K)", { shapes: w.shapes, annotations: w.annotations }),
  };
}

function inhFigure(s) {
  const w = windowShapes(windows(), tMax(s));
  return {
    data: [
      { x: s.inh_t, y: s.inh, name: "T_sup = max |T̂ − T_ref| (paper, metrics)", line: { color: "#805ad5", width: 1.6 } },
      { x: s.inh_t, y: s.spread, name: "spread = max |T̂ − fillet mean|", line: { color: "#2c7a7b", width: 1.3 } },
    ],
    layout: baseLayout("K", { shapes: w.shapes, annotations: w.annotations }),
  };
}

registerFigure("heatmap", heatmapFigure);
registerFigure("mean-plot", () => meanFigure(state.series || emptySeries()));
registerFigure("power-plot", () => powerFigure(state.series || emptySeries()));
registerFigure("tc-plot", () => tcFigure(state.series || emptySeries()));
registerFigure("inh-plot", () => inhFigure(state.series || emptySeries()));

function draw(id) {
  const el = document.getElementById(id);
  if (!el) return;
  const fig = FIGURES.get(id)();
  if (!fig) return;
  fig.layout.datarevision = revision;
  window.Plotly.react(el, fig.data, fig.layout, CONFIG);
}

// All charts at once (a run shown, a view opened): the page must not keep the previous run's charts.
export function render() {
  if (!state.furnace || state.view !== "live") return;
  revision += 1;
  for (const id of FIGURES.keys()) draw(id);
  state.dirty = false;
}

// While a run streams, the charts are redrawn one per task, so that a click or a key between two charts is
// answered at once, and a whole pass is followed by a pause of at least (1 / BUSY_SHARE - 1) times what it cost:
// on a slow machine (or a software-rendered browser) the charts take at most about BUSY_SHARE of the page's
// main thread.  Redrawing all of them every RENDER_MS had kept it 90 % busy on a loaded 2-core machine (small
// furnace, speed 2): typing a new setpoint took 3 s.
export const BUSY_SHARE = 0.25;
let timer = null, drawing = false;

function schedule(ms) { clearTimeout(timer); timer = setTimeout(pass, ms); }

function pass() {
  timer = null;
  if (!state.dirty || !state.furnace || state.view !== "live") { schedule(RENDER_MS); return; }
  // "drawing" until the pass is done (still truthy: the charts are not yet all drawn); a frame arriving during
  // the pass sets it true again, and the next pass draws it
  state.dirty = "drawing";
  drawing = true;
  revision += 1;
  const ids = [...FIGURES.keys()];
  let spent = 0;
  const next = (i) => {
    if (i < ids.length && state.view === "live") {
      const t0 = performance.now();
      draw(ids[i]);
      spent += performance.now() - t0;
      setTimeout(() => next(i + 1), 0);
      return;
    }
    drawing = false;
    if (state.dirty === "drawing") state.dirty = false;
    // the pause only while frames stream in: a run's last frame is drawn at once (renderSoon)
    schedule(state.ws ? Math.max(RENDER_MS, spent * (1 / BUSY_SHARE - 1)) : RENDER_MS);
  };
  next(0);
}

// The stream ended (or the run did): draw what is there now, not after the pause.
export function renderSoon() { if (!drawing) schedule(0); }

export function startRendering() { schedule(RENDER_MS); }
