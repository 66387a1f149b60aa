// The estimate's uncertainty on the dashboard (issue 25): a toggle that shows the field's standard deviation
// (field_sigma, K) in place of the field on the heat map, and the +-2 sigma band around the fillet mean
// (sigma_mean, K).  The toggle is kept in this browser.
import { $ } from "./page.js";

const KEY = "furnace-twin-show-sigma";
export const unc = { show: false };

// Blues to dark: a scale that cannot be mistaken for the temperature's Turbo
export const SIGMA_SCALE = [[0, "#f7fbff"], [0.25, "#c6dbef"], [0.5, "#6baed6"], [0.75, "#2171b5"], [1, "#08306b"]];

// The heat map's trace for the sigma map (undefined when hidden or the run has none)
export function sigmaTrace(fu, s) {
  if (!unc.show || !s || !s.fieldSigma) return undefined;
  return { type: "heatmap", x: fu.x, y: fu.y, z: s.fieldSigma, colorscale: SIGMA_SCALE, zsmooth: "best", zmin: 0,
    colorbar: { title: { text: "σ (K)", side: "right" }, thickness: 12, len: 0.95 },
    hovertemplate: "x %{x:.3f} m<br>y %{y:.3f} m<br>σ %{z:.2f} K<extra></extra>" };
}

// The fillet mean's latest sigma (K) in the shown series, or null
export function lastSigma(s) {
  const v = s && s.sigma_mean && s.sigma_mean.length ? s.sigma_mean[s.sigma_mean.length - 1] : null;
  return v === undefined ? null : v;
}

// The +-2 sigma band around the fillet mean: two traces (the lower edge, then the upper filled to it)
export function meanBand(s) {
  if (!s || !s.sigma_mean || !s.sigma_mean.some((v) => v !== null)) return [];
  const edge = (k) => s.T_mean_hat.map((m, i) => (m === null || s.sigma_mean[i] === null ? null : m + 2 * k * s.sigma_mean[i]));
  return [
    { x: s.t, y: edge(-1), line: { width: 0 }, showlegend: false, hoverinfo: "skip", legendgroup: "band" },
    { x: s.t, y: edge(1), name: "fillet mean ± 2σ", fill: "tonexty", fillcolor: "rgba(214, 39, 40, 0.18)",
      line: { width: 0 }, legendgroup: "band", hoverinfo: "skip" },
  ];
}

export function wireUncertainty(onChange) {
  const box = $("show-sigma");
  if (!box) return;
  try { unc.show = localStorage.getItem(KEY) === "1"; } catch (e) { /* default */ }
  box.checked = unc.show;
  box.addEventListener("input", () => {
    unc.show = box.checked;
    try { localStorage.setItem(KEY, unc.show ? "1" : "0"); } catch (e) { /* not kept */ }
    onChange();
  });
}
