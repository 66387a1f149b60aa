// The heat map of the shown run's estimated field: the fillet, the four TCs with their readings in K, a
// colour scale that follows the field (auto, in 10 K steps) or stays where the user fixed it.
import { $, fmt } from "./page.js";
import { state } from "./state.js";
import { lastSigma, sigmaTrace, unc } from "./uncertainty.js";

const TURBO = [[0, "#30123b"], [0.1, "#4145ab"], [0.2, "#4675ed"], [0.3, "#39a2fc"], [0.4, "#1bcfd4"],
  [0.5, "#24eca6"], [0.6, "#61fc6c"], [0.7, "#a4fc3b"], [0.8, "#d1e834"], [0.9, "#f3c63a"], [1, "#7a0403"]];
const KEY = "furnace-twin-heat-scale";
const LABEL = { bgcolor: "rgba(20, 26, 38, 0.78)", font: { color: "#fff", size: 10.5 }, borderpad: 2, showarrow: false };

// "fillet" (the default): the colours span the fillet's own temperatures, so its spread shows (the cold edges
// saturate at the low end; issue 27: an automatic 600-1100 K scale made the fillet one flat colour); "auto": the
// whole specimen; "fixed": lowest and highest K as entered
export const heat = { mode: "fillet", lo: null, hi: null };

function inFillet(z) {
  const fu = state.furnace, [x0, x1, y0, y1] = fu.fillet;
  const out = [];
  (z || []).forEach((row, i) => {
    if (fu.y[i] < y0 || fu.y[i] > y1) return;
    row.forEach((v, j) => { if (fu.x[j] >= x0 && fu.x[j] <= x1) out.push(v); });
  });
  return out;
}

export function scaleOf(z) {
  if (heat.mode === "fixed" && heat.lo !== null && heat.hi !== null && heat.hi > heat.lo) return [heat.lo, heat.hi];
  const values = heat.mode === "fillet" ? inFillet(z) : (z || []).flat();
  let lo = Infinity, hi = -Infinity;
  for (const v of values) if (v !== null) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
  if (!Number.isFinite(lo)) return [undefined, undefined];
  const step = heat.mode === "fillet" ? 1 : 10, least = heat.mode === "fillet" ? 4 : 20;
  lo = step * Math.floor(lo / step); hi = step * Math.ceil(hi / step);
  if (hi - lo < least) { const mid = (lo + hi) / 2; lo = mid - least / 2; hi = mid + least / 2; }
  return [lo, hi];
}

// TC1-TC3 where the furnace has them, TC4 where the shown run put it (m): [x], [y]
export function tcPositions() {
  const fu = state.furnace;
  const tcRel = fu.tc_relative.slice(0, 3).concat([state.run ? state.run.scenario.tc4 : fu.tc_relative[3]]);
  return [tcRel.map((p) => p[0] * fu.L_s), tcRel.map((p) => p[1] * fu.W_s)];
}

// The layout of a field over the specimen (true aspect ratio) with the fillet's frame drawn as `frame`
export function fieldLayout(xTitle, frame) {
  const fu = state.furnace;
  const [x0, x1, y0, y1] = fu.fillet;
  return {
    margin: { l: 50, r: 10, t: 6, b: 34 }, paper_bgcolor: "#fff", plot_bgcolor: "#e8ecf2", font: { size: 11, color: "#1d2330" },
    xaxis: { title: { text: xTitle, standoff: 2 }, range: [0, fu.L_s], constrain: "domain" },
    yaxis: { title: { text: "y (m)", standoff: 2 }, range: [0, fu.W_s], scaleanchor: "x", scaleratio: 1, constrain: "domain" },
    shapes: [{ type: "rect", x0, x1, y0, y1, line: { ...frame, dash: "dash" } }],
  };
}

// What a going run without a frame yet waits for (null once it has one, or for a run that ended)
function waitingFor(run) {
  if (!run || state.lastFrame) return null;
  if (run.status === "queued") return "queued: waiting for the radiation model …";
  if (run.status === "starting") return "planning the first trajectory …";
  if (run.status === "running") return "waiting for the first sample …";
  return null;
}

export function heatmapFigure() {
  const fu = state.furnace, s = state.series;
  const [x0, , , y1] = fu.fillet;
  const [tcx, tcy] = tcPositions();
  const z = s && s.field ? s.field : null;
  const [zmin, zmax] = scaleOf(z);
  const tc = s && s.tc ? s.tc : [null, null, null, null];
  const f = state.lastFrame;
  $("heat-sub").textContent = f ? `t = ${fmt(f.t)} s · mean ${fmt(f.T_mean_hat)} K · ref ${fmt(f.T_ref)} K`
    + (lastSigma(s) !== null ? ` ± ${fmt(2 * lastSigma(s))} K (2σ)` : "")
    + (unc.show ? (s && s.fieldSigma ? " · showing σ" : " · no σ for this run") : "") : "";
  const sigma = sigmaTrace(fu, s);
  // TC1-TC3 above their marks, TC4 (between TC1 and TC3) below: the labels do not cover each other
  const place = [{ yshift: 13 }, { yshift: 13 }, { yshift: 13 }, { yshift: -14 }];
  const annotations = tcx.map((x, i) => ({ ...LABEL, ...place[i], x, y: tcy[i],
    text: `TC${i + 1}${i === 3 ? " (val.)" : ""}${tc[i] === null || tc[i] === undefined ? "" : ` ${fmt(tc[i])} K`}` }));
  annotations.push({ ...LABEL, x: x0, y: y1, xanchor: "left", yanchor: "top", xshift: 3, yshift: -3, text: "fillet" });
  const waiting = waitingFor(state.run);
  if (!z && waiting) {
    $("heat-sub").textContent = waiting;
    annotations.push({ ...LABEL, x: fu.L_s / 2, y: fu.W_s / 2, font: { color: "#fff", size: 14 }, borderpad: 6, text: waiting });
  }
  return {
    data: [
      sigma || { type: "heatmap", x: fu.x, y: fu.y, z: z || [[null]], colorscale: TURBO, zsmooth: "best", zmin, zmax, zauto: zmin === undefined,
        colorbar: { title: { text: "T (K)", side: "right" }, thickness: 12, len: 0.95 },
        hovertemplate: "x %{x:.3f} m<br>y %{y:.3f} m<br>%{z:.1f} K<extra></extra>" },
      { type: "scatter", mode: "markers", x: tcx, y: tcy, hoverinfo: "skip", showlegend: false,
        marker: { symbol: ["circle", "circle", "circle", "diamond"], size: 9, color: ["#fff", "#fff", "#fff", "#ff4fc8"],
          line: { color: "#000", width: 1.5 } } },
    ],
    layout: { ...fieldLayout("x (m), along the specimen length", { color: "#fff", width: 2 }), annotations },
  };
}

// The colour-scale controls: auto / fixed with lowest and highest K, kept in this browser.
export function wireHeatScale(onChange) {
  try { Object.assign(heat, JSON.parse(localStorage.getItem(KEY) || "{}")); } catch (e) { /* defaults */ }
  const sp = state.furnace.limits.reference.setpoint;
  if (heat.lo === null) heat.lo = state.furnace.limits.reference.points.temperature.min;
  if (heat.hi === null) heat.hi = sp.max;
  $("heat-lo").value = heat.lo; $("heat-hi").value = heat.hi;
  for (const el of document.querySelectorAll("input[name=heat-mode]")) el.checked = el.value === heat.mode;
  const update = () => {
    heat.mode = document.querySelector("input[name=heat-mode]:checked").value;
    const lo = Number($("heat-lo").value), hi = Number($("heat-hi").value);
    if ($("heat-lo").value !== "" && $("heat-hi").value !== "" && hi > lo) { heat.lo = lo; heat.hi = hi; }
    for (const id of ["heat-lo", "heat-hi"]) $(id).classList.toggle("invalid", !(hi > lo));
    try { localStorage.setItem(KEY, JSON.stringify(heat)); } catch (e) { /* not kept */ }
    onChange();
  };
  for (const el of document.querySelectorAll("input[name=heat-mode], #heat-lo, #heat-hi")) el.addEventListener("input", update);
  for (const el of document.querySelectorAll("#heat-lo, #heat-hi")) el.addEventListener("focus", () => {
    if (heat.mode !== "fixed") { document.querySelector("input[name=heat-mode][value=fixed]").checked = true; update(); }
  });
}
