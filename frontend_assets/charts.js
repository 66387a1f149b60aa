// The plotly.js charts (window.Plotly, served from /assets/plotly.min.js): heat map, mean vs
// reference, TC errors, group powers, inhomogeneity, eta.  Redrawn at most every RENDER_MS.
import { fmt } from "./page.js";
import { emptySeries } from "./series.js";
import { state } from "./state.js";

const GROUP_COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"];
const TC_COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728"];
const RENDER_MS = 250; // charts redraw at most 4 times per second; frames arrive up to 20/s
const CONFIG = { displaylogo: false, responsive: true, modeBarButtonsToRemove: ["lasso2d", "select2d"] };
const TURBO = [[0, "#30123b"], [0.1, "#4145ab"], [0.2, "#4675ed"], [0.3, "#39a2fc"], [0.4, "#1bcfd4"],
  [0.5, "#24eca6"], [0.6, "#61fc6c"], [0.7, "#a4fc3b"], [0.8, "#d1e834"], [0.9, "#f3c63a"], [1, "#7a0403"]];

let revision = 0; // plotly redraws arrays that grew in place only when datarevision changes
const baseLayout = (title, ytitle, extra = {}) => Object.assign({
  datarevision: revision,
  title: { text: title, font: { size: 13 }, x: 0.02, xanchor: "left", y: 0.97 },
  margin: { l: 56, r: 12, t: 28, b: 36 },
  xaxis: { title: { text: "t (s)", standoff: 4 }, zeroline: false },
  yaxis: { title: { text: ytitle, standoff: 4 }, zeroline: false },
  legend: { orientation: "h", x: 0, y: -0.22, font: { size: 10 } },
  paper_bgcolor: "#fff", plot_bgcolor: "#fafbfc", font: { size: 11, color: "#1d2330" },
}, extra);

function heatmapFigure() {
  const fu = state.furnace;
  const s = state.series;
  const [x0, x1, y0, y1] = fu.fillet;
  const tcRel = fu.tc_relative.slice(0, 3).concat([state.tc4]);
  const tcx = tcRel.map((p) => p[0] * fu.L_s), tcy = tcRel.map((p) => p[1] * fu.W_s);
  const z = s && s.field ? s.field : null;
  const f = state.lastFrame;
  const sub = f ? `t = ${fmt(f.t)} s · mean ${fmt(f.T_mean_hat)} K · ref ${fmt(f.T_ref)} K` : "";
  return {
    data: [
      { type: "heatmap", x: fu.x, y: fu.y, z: z || [[null]], colorscale: TURBO, zsmooth: "best",
        colorbar: { title: { text: "T (K)", side: "right" }, thickness: 12, len: 0.95 },
        hovertemplate: "x %{x:.3f} m<br>y %{y:.3f} m<br>%{z:.1f} K<extra></extra>" },
      { type: "scatter", mode: "markers+text", x: tcx, y: tcy, text: ["TC1", "TC2", "TC3", "TC4"],
        textposition: "top center", textfont: { color: "#fff", size: 11 }, hoverinfo: "text",
        marker: { symbol: ["circle", "circle", "circle", "diamond"], size: 9, color: ["#fff", "#fff", "#fff", "#ff4fc8"],
          line: { color: "#000", width: 1.5 } }, showlegend: false },
    ],
    layout: baseLayout(`Estimated field <span style="font-size:11px;color:#56627a">${sub}</span>`, "y (m)", {
      xaxis: { title: { text: "x (m), along the specimen length", standoff: 4 }, range: [0, fu.L_s], constrain: "domain" },
      yaxis: { title: { text: "y (m)", standoff: 4 }, range: [0, fu.W_s], scaleanchor: "x", scaleratio: 1, constrain: "domain" },
      margin: { l: 56, r: 12, t: 28, b: 38 },
      shapes: [{ type: "rect", x0, x1, y0, y1, line: { color: "#fff", width: 2, dash: "dash" } }],
      annotations: [{ x: x0, y: y0, xanchor: "left", yanchor: "bottom", xshift: 3, yshift: 2, text: "fillet",
        showarrow: false, font: { color: "#fff", size: 10 } }],
    }),
  };
}

// The user's reference points of the shown run (start and applied live changes) in run time.
function referenceMarkers(run) {
  const x = [], y = [];
  if (!run) return { x, y };
  const add = (ref, t0) => { if (ref && ref.points) for (const [t, T] of ref.points) { x.push(t0 + t); y.push(T); } };
  add(run.scenario.reference, 0);
  for (const ch of run.changes || []) if (ch.kind === "reference" && ch.status === "applied") add(ch.body, ch.applied_t || 0);
  return { x, y };
}

function lineFigures() {
  const s = state.series || emptySeries();
  const groups = state.furnace.groups.map((g) => g.name);
  const pts = referenceMarkers(state.run);
  return {
    "mean-plot": {
      data: [
        { x: s.t, y: s.T_ref, name: "T_ref", line: { color: "#111", dash: "dash", width: 1.6 } },
        { x: s.t, y: s.T_mean_hat, name: "fillet mean (est.)", line: { color: "#d62728", width: 1.8 } },
        { x: pts.x, y: pts.y, name: "ref. points", mode: "markers", showlegend: pts.x.length > 0,
          marker: { symbol: "circle-open", size: 8, color: "#111", line: { width: 1.6 } },
          hovertemplate: "%{x:.1f} s, %{y:.0f} K<extra>reference point</extra>" },
      ],
      layout: baseLayout("Fillet mean vs reference", "T (K)"),
    },
    "tc-plot": {
      data: s.tcErr.map((e, i) => ({ x: s.t, y: e, name: i < 3 ? `TC${i + 1}` : "TC4 (validation)",
        line: { color: TC_COLORS[i], width: i < 3 ? 1.2 : 2 } })),
      layout: baseLayout("TC reading − estimate", "error (K)"),
    },
    "power-plot": {
      data: groups.flatMap((g, j) => [
        { x: s.t, y: s.u[j], name: `${g} u`, legendgroup: g, line: { color: GROUP_COLORS[j], width: 1.6 } },
        { x: s.t, y: s.u_ff[j], name: `${g} u_ff`, legendgroup: g, showlegend: false,
          line: { color: GROUP_COLORS[j], width: 1, dash: "dot" } },
      ]),
      layout: baseLayout("Group powers u (solid) and feedforward u_ff (dotted)", "u / u_max (–)",
        { yaxis: { title: { text: "u / u_max (–)", standoff: 4 }, range: [-0.02, 1.05] },
          legend: { orientation: "v", x: 1.01, y: 1, font: { size: 10 } }, margin: { l: 56, r: 90, t: 28, b: 36 } }),
    },
    "inh-plot": {
      data: [{ x: s.inh_t, y: s.inh, name: "T_sup", line: { color: "#805ad5", width: 1.6 } }],
      layout: baseLayout("Inhomogeneity max |T̂ − T_ref| on the fillet", "T_sup (K)", { showlegend: false }),
    },
    "eta-plot": {
      data: [{ x: s.t, y: s.eta.map((v) => v * 1000), name: "eta", line: { color: "#2c7a7b", width: 1.4 } }],
      layout: baseLayout("Specimen position η", "η (mm)", { showlegend: false }),
    },
  };
}

export function render() {
  if (!state.furnace) return;
  revision += 1;
  const hm = heatmapFigure();
  window.Plotly.react("heatmap", hm.data, hm.layout, CONFIG);
  const figs = lineFigures();
  for (const [id, fig] of Object.entries(figs)) window.Plotly.react(id, fig.data, fig.layout, CONFIG);
  state.dirty = false;
}

export function startRendering() { setInterval(() => { if (state.dirty) render(); }, RENDER_MS); }
