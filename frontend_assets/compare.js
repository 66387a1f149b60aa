// Run comparison: the ticked runs (live or finished) on one time axis (fillet mean with its reference,
// T_sup, TC4 error) with the metric windows shaded, their metrics side by side with the difference to the first,
// and a reading of the question a comparison asks ("did oscillation help?") from the true field and the estimate.
// Finished runs are read once, live ones every few seconds.
import { api } from "./api.js";
import { baseLayout, CONFIG } from "./charts.js";
import { compareTable, verdict } from "./metrics.js";
import { windowShapes } from "./overlays.js";
import { $, going, runLabel } from "./page.js";
import { state } from "./state.js";

const COLORS = ["#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf"];
const LIVE_EVERY_MS = 3000;
const cache = new Map(); // run id -> {detail, series, at}

async function load(id) {
  const known = cache.get(id);
  const live = known && going(known.detail);
  if (known && (!live || Date.now() - known.at < LIVE_EVERY_MS)) return known;
  const [detail, series] = await Promise.all([api("GET", `/api/runs/${id}`),
    api("GET", `/api/runs/${id}/series?max_points=1500`).catch(() => null)]);
  const entry = { detail, series, at: Date.now() };
  cache.set(id, entry);
  return entry;
}

function traces(entries, names) {
  const mean = [], sup = [], tc4 = [];
  entries.forEach(({ series: s }, i) => {
    if (!s || !s.t) return;
    const c = COLORS[i % COLORS.length], g = names[i];
    mean.push({ x: s.t, y: s.T_mean_hat, name: g, legendgroup: g, line: { color: c, width: 1.7 } },
      { x: s.t, y: s.T_ref, name: `${g} reference`, legendgroup: g, showlegend: false, line: { color: c, width: 1, dash: "dash" } });
    sup.push({ x: s.t_field || [], y: s.inhomogeneity || [], name: g, line: { color: c, width: 1.5 } });
    tc4.push({ x: s.t, y: s.tc.map((r, k) => (r[3] === null || s.tc_hat[k][3] === null ? null : r[3] - s.tc_hat[k][3])), name: g,
      line: { color: c, width: 1.4 } });
  });
  return { mean, sup, tc4 };
}

// The runs by their labels (automatic ones say what happened); the short id only where two labels are the same.
function uniqueNames(runs) {
  const labels = runs.map(runLabel);
  return labels.map((l, i) => (labels.indexOf(l) !== labels.lastIndexOf(l) ? `${l} (${runs[i].id.slice(0, 6)})` : l));
}

// The transient and steady windows, shaded when the runs share them (same reference, no live change moved
// them); else the first run's, and the note says so.
function sharedWindows(entries) {
  const ws = entries.map((e) => e.detail.windows).filter(Boolean);
  if (!ws.length) return { shapes: [], annotations: [], note: "" };
  const tEnd = Math.max(...entries.map((e) => (e.series && e.series.t && e.series.t.length ? e.series.t[e.series.t.length - 1] : 0)));
  const key = (w) => JSON.stringify([w.transient, w.steady]);
  const same = ws.every((w) => key(w) === key(ws[0]));
  return { ...windowShapes(ws[0], tEnd), note: same ? "shaded: the transient and steady windows the metrics are taken over"
    : "the runs' windows differ (their references do): shaded are the first run's" };
}

let busy = false;

export async function refreshComparison() {
  if (state.view !== "runs" || busy) return;
  const ids = [...state.compare];
  $("compare-hint").hidden = ids.length >= 2;
  $("compare-plots").hidden = ids.length < 1;
  if (!ids.length) return;
  busy = true;
  try {
    const entries = (await Promise.all(ids.map((id) => load(id).catch(() => null)))).filter(Boolean);
    // names from the runs list (a label edited since is shown at once), the rest from each run's detail
    const names = uniqueNames(entries.map((e) => state.runs.find((r) => r.id === e.detail.id) || e.detail));
    const tr = traces(entries, names);
    const w = sharedWindows(entries);
    const layout = (y) => baseLayout(y, { shapes: w.shapes, annotations: w.annotations });
    window.Plotly.react("cmp-mean", tr.mean, layout("T (K)"), CONFIG);
    window.Plotly.react("cmp-sup", tr.sup, layout("T_sup (K)"), CONFIG);
    window.Plotly.react("cmp-tc4", tr.tc4, layout("TC4 − estimate (K)"), CONFIG);
    $("cmp-windows").textContent = w.note;
    $("cmp-verdict").innerHTML = verdict(entries.map((e) => e.detail), names);
    $("cmp-table").innerHTML = compareTable(entries.map((e) => e.detail), names);
  } finally { busy = false; }
}

export function startComparing() { setInterval(refreshComparison, LIVE_EVERY_MS); }
