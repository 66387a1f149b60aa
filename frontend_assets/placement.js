// Where to put the thermocouples (issue 25, the paper's Remark 3), in the Studies view: POST /api/placement ranks
// TC positions for the loaded furnace by the information they give about the fillet along the twin's nominal
// run (furnace-twin place-tcs), GET /api/placement reads the ranking; shown in the detail pane as a map of each
// candidate's score alone with the recommended and the paper's TCs, and the ranking with its scores.
import { api } from "./api.js";
import { $, esc, showMsg } from "./page.js";

const COUNT = 3;

async function rank() {
  const oscillate = $("place-osc").checked;
  const mode = oscillate ? "oscillating" : "fixed";
  try {
    let r = await api("POST", `/api/placement?count=${COUNT}`, { oscillate });
    if (r.state === "computing") showMsg(`ranking positions for the ${mode} specimen (the twin's plan and its Gramians: 5-30 s)`, false, "place-msg");
    while (r.state === "computing") {
      await new Promise((res) => setTimeout(res, 1000));
      r = await api("GET", `/api/placement?oscillate=${oscillate}&count=${COUNT}`);
    }
    if (r.state === "failed") { showMsg(`the ranking failed: ${r.error}`, true, "place-msg"); return; }
    showMsg(`ranked in ${r.seconds.toFixed(1)} s`, false, "place-msg");
    render(r);
  } catch (e) {
    showMsg(e.message, true, "place-msg");
  }
}

function render(r) {
  const f = (window.state && window.state.furnace) || { L_s: 1, W_s: 1 };
  const mode = r.oscillate ? "oscillating" : "fixed";
  const best = r.positions.length ? r.positions[r.positions.length - 1].score : null;
  const rows = r.positions.map((p) => `<tr><td>#${p.rank}</td><td class="num">${p.x.toFixed(4)}</td><td class="num">${p.y.toFixed(4)}</td>
      <td class="num">${p.x_rel.toFixed(3)}</td><td class="num">${p.y_rel.toFixed(3)}</td><td class="num">${p.score.toFixed(1)}</td></tr>`).join("");
  const paper = r.paper.positions.map(([x, y]) => `${x.toFixed(2)}, ${y.toFixed(2)}`).join("; ");
  const ratio = best !== null && r.paper.score > 0 ? best / r.paper.score : null;
  $("study-detail").innerHTML = `
    <div class="study-head"><b>Where to put TC1-${r.positions.length}</b><span class="muted">furnace ${esc(r.furnace)} · ${mode} specimen</span></div>
    <p class="muted">${esc(r.criterion)}. Greedy choice; each score is that of the positions up to its rank.</p>
    <div id="place-map" class="place-map"></div>
    <div class="study-tables"><div>
      <table id="place-table" class="study-table"><thead><tr><th>rank</th><th>x (m)</th><th>y (m)</th><th>x / L_s</th><th>y / W_s</th><th>score (nats)</th></tr></thead><tbody>${rows}</tbody></table>
      <p id="place-paper">The paper's TC1-3 (x / L_s, y / W_s: ${paper}): <b>${r.paper.score.toFixed(1)} nats</b>${ratio === null ? "" : `; the recommended ${r.positions.length}: ${best.toFixed(1)} nats (${ratio.toFixed(2)} ×)`}.</p>
      <p class="muted">A statement about the linearised model's information, not about the error against a real furnace: in the
        closed loop against the honest truth the recommended positions did not estimate the field better than the paper's
        (docs/uncertainty.md, "Does it pay?"), which stay the default.</p>
    </div></div>`;
  const x = r.map.x_rel.map((v) => v * f.L_s);
  const y = r.map.y_rel.map((v) => v * f.W_s);
  const data = [
    { type: "heatmap", x, y, z: r.map.score, colorscale: "Viridis", zsmooth: false, colorbar: { title: { text: "nats (one TC)", side: "right" }, thickness: 12 },
      hovertemplate: "x %{x:.3f} m<br>y %{y:.3f} m<br>%{z:.1f} nats alone<extra></extra>" },
    { type: "scatter", mode: "markers+text", name: "recommended", x: r.positions.map((p) => p.x), y: r.positions.map((p) => p.y),
      text: r.positions.map((p) => `#${p.rank}`), textposition: "top right", textfont: { color: "#ff4fc8", size: 13 },
      marker: { symbol: "circle-open", size: 16, color: "#ff4fc8", line: { width: 3 } } },
    { type: "scatter", mode: "markers", name: "paper TC1-3", x: r.paper.positions.map((p) => p[0] * f.L_s), y: r.paper.positions.map((p) => p[1] * f.W_s),
      marker: { symbol: "square-open", size: 12, color: "#f6ad55", line: { width: 2.5 } } },
  ];
  const fil = f.fillet;
  const shapes = fil ? [{ type: "rect", x0: fil[0], x1: fil[1], y0: fil[2], y1: fil[3], line: { color: "#fff", dash: "dash", width: 1.5 } }] : [];
  const layout = { margin: { l: 50, r: 10, t: 10, b: 40 }, height: 320, shapes, legend: { orientation: "h", y: -0.2 },
    xaxis: { title: { text: "x (m), along the specimen" }, range: [0, f.L_s], constrain: "domain" },
    yaxis: { title: { text: "y (m)" }, range: [0, f.W_s], scaleanchor: "x" } };
  window.Plotly.react("place-map", data, layout, { displaylogo: false, responsive: true });
}

export function initPlacement() {
  $("place-rank").addEventListener("click", rank);
}
