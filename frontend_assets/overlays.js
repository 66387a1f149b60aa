// What is drawn over the charts: the metric windows (from the last reference change, as the server counts
// them: GET /api/runs/{id} "windows") and the lamp groups that sat at a bound (lanes above the power chart).

export const GROUP_COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"];
const WINDOW_STYLE = { transient: "rgba(66, 153, 225, 0.10)", steady: "rgba(72, 187, 120, 0.13)" };
export const LANE0 = 1.05; // first saturation lane (in u / u_max) and the lanes' pitch
export const LANE = 0.05;

// Shaded transient and steady windows with their names; tMax clips them to the data shown.
export function windowShapes(w, tMax, xref = "x") {
  if (!w) return { shapes: [], annotations: [] };
  const shapes = [], annotations = [];
  for (const [name, [a, b]] of [["transient", w.transient], ["steady", w.steady]]) {
    if (!(a < tMax)) continue;
    shapes.push({ type: "rect", xref, yref: "paper", x0: a, x1: Math.min(b, tMax), y0: 0, y1: 1, layer: "below",
      fillcolor: WINDOW_STYLE[name], line: { width: 0 } });
    const top = name === "transient"; // transient named at the top, steady at the bottom: narrow bands never collide
    annotations.push({ xref, yref: "paper", x: a, y: top ? 1 : 0, xanchor: "left", yanchor: top ? "top" : "bottom",
      showarrow: false, text: top ? "transient" : "steady (1.5–2 t<sub>E</sub>)", font: { size: 9, color: "#56627a" } });
  }
  return { shapes, annotations };
}

// One lane per group above u = 1: solid where the group was at full power, pale where it was off.
export function saturationShapes(spans) {
  return spans.map((s) => {
    const y0 = LANE0 + LANE * s.j;
    return { type: "rect", xref: "x", yref: "y", x0: s.t0, x1: Math.max(s.t1, s.t0 + 0.05), y0, y1: y0 + LANE * 0.8,
      fillcolor: GROUP_COLORS[s.j], opacity: s.bound > 0 ? 0.9 : 0.25, line: { width: 0 } };
  });
}
