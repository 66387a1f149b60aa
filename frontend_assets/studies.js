// The Studies view: start a design study (the study file as JSON), the list with progress, and the picked
// study's progress, best case per metric, percentiles, failed cases, figures and downloads.
// Backed by POST /api/studies, GET /api/studies and GET /api/studies/{id}; stop and resume.
import { api, token } from "./api.js";
import { helpMark, metricName } from "./glossary.js";
import { $, esc, pct, showMsg } from "./page.js";

const ACTIVE = ["queued", "running"];
const view = { id: null, study: null, listHtml: "", detailKey: "", timer: null, edited: false };
window.studies = view; // for the browser console and the browser tests

const num = (v) => (typeof v === "number" ? (Number.isInteger(v) ? String(v) : v.toPrecision(4).replace(/\.?0+$/, "")) : JSON.stringify(v));
const params = (p) => Object.entries(p || {}).map(([k, v]) => `${esc(k)} = ${esc(num(v))}`).join(", ") || "(base)";

// Examples to start from, with the loaded furnace's default amplitude (GET /api/furnace's limits).
function examples() {
  const f = window.state && window.state.furnace;
  const amp = f ? f.limits.oscillation.amplitude.default : 0.048;
  const base = { duration: 240.0, reference: { setpoint: 1100.0, t_E: 120.0 } };
  return {
    grid: { name: "period x amplitude", base: { ...base, oscillation: { enabled: true } },
      grid: { "oscillation.period": [9.0, 18.0, 36.0], "oscillation.amplitude": [+(amp / 2).toFixed(4), amp], seed: [1, 2] } },
    mc: { name: "robustness to model error", base,
      monte_carlo: { n: 20, seed: 1, "mismatch.alpha": { dist: "uniform", low: -0.3, high: 0.3 },
        "mismatch.emissivity": { dist: "normal", mean: 0.0, std: 0.03, low: -0.1, high: 0.1 },
        tc_noise: { dist: "uniform", low: 0.5, high: 2.0 } } },
  };
}

// The study as a person reads it (under the examples; the JSON is the advanced box), and before Start what it
// would run: cases (design points x seeds) and an estimated time (POST /api/studies/plan), both on every edit.
function readable(doc) {
  const base = doc.base || {};
  const ref = base.reference || {};
  const head = `${esc(doc.name || "unnamed study")}: ${ref.setpoint ? `${num(ref.setpoint)} K` : "the default reference"}` +
    `${ref.t_E ? ` in ${num(ref.t_E)} s` : ""}, ${base.duration ? `${num(base.duration)} s` : "default duration"} per case`;
  return `<b>${head}</b>${varied({ ...doc, monte_carlo: doc.monte_carlo ? { seeds: "per_sample", ...doc.monte_carlo } : null })}`;
}

function duration(s) {
  if (s < 90) return `${Math.round(s)} s`;
  if (s < 5400) return `${Math.round(s / 60)} min`;
  return `${(s / 3600).toFixed(1)} h`;
}

let planSeq = 0;
async function refreshPlan() {
  const seq = ++planSeq;
  let doc;
  try { doc = JSON.parse($("study-text").value); } catch (e) {
    $("study-read").innerHTML = `<span class="err">the study is not valid JSON: ${esc(e.message)}</span>`;
    $("study-plan").textContent = "";
    return;
  }
  $("study-read").innerHTML = readable(doc);
  try {
    const p = await api("POST", "/api/studies/plan", doc);
    if (seq !== planSeq) return;
    const cases = `${p.cases} cases (${p.points} design point${p.points === 1 ? "" : "s"} x ${p.per_point} seed${p.per_point === 1 ? "" : "s"} or samples) on ${p.workers} workers`;
    const time = p.estimate_s === null ? "no time estimate yet" : `estimated ${duration(p.estimate_s)} (an estimate)`;
    $("study-plan").innerHTML = `<b>Start runs ${cases}; ${time}</b><span class="muted">${esc(p.basis || "")}</span>`;
  } catch (e) {
    if (seq === planSeq) $("study-plan").innerHTML = `<span class="err">${esc(e.message)}</span>`;
  }
}

function setText(doc) {
  $("study-text").value = JSON.stringify(doc, null, 2);
  refreshPlan();
}

function showView(which) {
  const studies = which === "studies";
  document.querySelector("main").hidden = studies;
  $("studies-view").hidden = !studies;
  $("view-runs").classList.toggle("on", !studies);
  $("view-studies").classList.toggle("on", studies);
  if (studies && !view.edited) setText(examples().grid); // the furnace is known now
  if (studies) { refreshStudies(); if (!view.timer) view.timer = setInterval(tick, 2000); }
  else if (view.timer) { clearInterval(view.timer); view.timer = null; }
}

async function tick() {
  await refreshStudies();
  if (view.id && (!view.study || ACTIVE.includes(view.study.status) || !view.study.cases)) await refreshStudy();
}

function progressText(s) {
  const failed = s.failed ? ` · ${s.failed} failed` : "";
  const skipped = s.skipped ? ` · ${s.skipped} from before` : "";
  return `${s.finished} / ${s.total}${failed}${skipped}`;
}

export async function refreshStudies() {
  let list = [];
  try { list = await api("GET", "/api/studies"); } catch (e) { return; }
  const html = list.map((s) => `<tr data-id="${s.id}" class="${s.id === view.id ? "sel" : ""}">
      <td title="${esc(s.id)} · ${new Date(s.created_at * 1000).toLocaleString()}">${esc(s.name || s.id.slice(0, 6))}</td>
      <td><span class="badge ${s.status}" style="color:#fff">${s.status}</span></td>
      <td class="num"><progress max="${s.total}" value="${s.finished}"></progress> ${progressText(s)}</td></tr>`).join("");
  if (html !== view.listHtml) {
    document.querySelector("#study-list tbody").innerHTML = html || `<tr><td colspan="3" class="muted">no studies yet</td></tr>`;
    view.listHtml = html;
  }
}

export async function selectStudy(id) {
  view.id = id;
  view.study = null;
  view.detailKey = "";
  view.listHtml = "";
  await Promise.all([refreshStudy(), refreshStudies()]);
}

async function refreshStudy() {
  const id = view.id;
  try {
    const s = await api("GET", `/api/studies/${id}`);
    if (id !== view.id) return;
    view.study = s;
    renderStudy(s);
  } catch (e) { $("study-detail").innerHTML = `<div class="msg err">${esc(e.message)}</div>`; }
}

// Figures and downloads are plain GETs; a server beyond loopback wants the token on reads too, which an <img> or
// a link cannot send: then they are fetched with the header and shown / saved from a blob.
async function fetchBlob(url) {
  const r = await fetch(url, { headers: { "X-API-Token": token() } });
  if (!r.ok) throw new Error(`${r.status} ${r.statusText}`);
  return URL.createObjectURL(await r.blob());
}

function wireFiles(el) {
  if (!token()) return;
  for (const img of el.querySelectorAll(".figures img")) {
    fetchBlob(img.dataset.src).then((b) => { img.src = b; img.parentElement.href = b; }).catch(() => { img.alt = `${img.alt} (not loaded)`; });
  }
  for (const a of el.querySelectorAll(".downloads a")) {
    a.addEventListener("click", async (ev) => {
      if (a.dataset.blob) return;
      ev.preventDefault();
      try { a.href = await fetchBlob(a.dataset.url); a.dataset.blob = "1"; a.click(); }
      catch (e) { showMsg(`${a.textContent}: ${e.message}`, true, "study-ctl-msg"); }
    });
  }
}

function varied(doc) {
  const rows = Object.entries(doc.grid || {}).map(([p, v]) => `<li>grid <code>${esc(p)}</code>: ${v.map((x) => esc(num(x))).join(", ")}</li>`);
  const mc = doc.monte_carlo;
  if (mc) {
    rows.push(`<li>Monte Carlo: n = ${mc.n}, seed = ${mc.seed}, TC-noise seeds ${esc(mc.seeds)}</li>`);
    for (const [p, d] of Object.entries(mc)) {
      if (["n", "seed", "seeds"].includes(p)) continue;
      const args = Object.entries(d).filter(([k, v]) => k !== "dist" && v !== null).map(([k, v]) => `${k} ${esc(num(v))}`).join(", ");
      rows.push(`<li><code>${esc(p)}</code> ~ ${esc(d.dist)}(${args})</li>`);
    }
  }
  return `<ul class="varied">${rows.join("")}</ul>`;
}

function renderStudy(s) {
  const key = JSON.stringify([s.status, s.finished, s.failed, s.figures.length, !!s.cases]);
  if (key === view.detailKey) return; // nothing new: keep the page (and the images) as they are
  view.detailKey = key;
  const active = ACTIVE.includes(s.status);
  const resumable = ["interrupted", "stopped", "error"].includes(s.status);
  const downloads = Object.entries(s.downloads).map(([n, u]) => `<a href="${u}" data-url="${u}" download="${esc(s.id)}-${esc(n)}">${esc(n)}</a>`).join(" · ");
  // metrics by their names in the glossary (the dashboard's words), the code key on hover (issue 27 item 8)
  const metric = (k) => `<span title="${esc(k)}">${esc(metricName(k))}</span> ${helpMark(k)}`;
  // a best case only beyond the seed-to-seed spread; the range is the one colour scale of the metric's maps
  const best = (s.best || []).map((b) => `<tr><td>${metric(b.metric)}</td>
      <td class="num">${pct(b.min)} – ${pct(b.max)} %</td><td class="num">${b.spread === null ? "unknown" : `${pct(b.spread)} %`}</td>
      <td class="reading ${b.decided ? "decided" : ""}">${esc(b.reading)}</td></tr>`).join("");
  const pcts = Object.entries(s.percentiles || {}).map(([m, p]) => `<tr><td>${metric(m)}</td>${["p5", "p50", "p95", "max"]
    .map((q) => `<td class="num">${pct(p[q])}</td>`).join("")}</tr>`).join("");
  const failed = (s.cases || []).filter((c) => c.status === "failed");
  const figures = s.figures.map((u) => `<a href="${u}" target="_blank" rel="noopener" title="${esc(u.split("/").pop())}"><img ${token() ? "" : `src="${u}"`} data-src="${u}" loading="lazy" alt="${esc(u.split("/").pop())}"></a>`).join("");
  $("study-detail").innerHTML = `
    <div class="study-head">
      <b>${esc(s.name || s.id)}</b> <span class="badge ${s.status}">${s.status}</span>
      <span class="muted">furnace ${esc(s.furnace)} · ${s.workers ? `${s.workers} workers · ` : ""}id ${esc(s.id)}</span>
      <span class="spacer"></span>
      <button id="study-stop" class="danger" ${active ? "" : "disabled"}>Stop</button>
      <button id="study-resume" ${resumable ? "" : "disabled"}>Resume</button>
    </div>
    <div class="study-progress"><progress max="${s.total}" value="${s.finished}"></progress> ${progressText(s)} cases
      ${s.error ? `<span class="msg err">${esc(s.error)}</span>` : ""}</div>
    <div id="study-ctl-msg" class="msg" role="status" aria-live="polite"></div>
    ${varied(s.study)}
    ${downloads ? `<div class="downloads">Downloads: ${downloads}</div>` : ""}
    <div class="study-tables">
      ${best ? `<div><h3>Best case per metric</h3><p class="muted">Design points ranked by their median over the seeds; a best case is named only where it beats the next by more than the seed-to-seed spread (median over the points of max − min over their seeds). The maps of a metric share one colour scale over its range.</p><table class="study-table"><thead><tr><th>metric</th><th>range of the points</th><th>seed spread</th><th>reading</th></tr></thead><tbody>${best}</tbody></table></div>` : ""}
      ${pcts ? `<div><h3>Percentiles over the samples (%)</h3><table class="study-table"><thead><tr><th>metric</th><th>p5</th><th>p50</th><th>p95</th><th>max</th></tr></thead><tbody>${pcts}</tbody></table></div>` : ""}
    </div>
    ${failed.length ? `<h3>Failed cases</h3><ul class="failed">${failed.map((c) => `<li>${params(c.params)}: <span class="err">${esc(c.error)}</span></li>`).join("")}</ul>` : ""}
    ${figures ? `<h3>Figures</h3><div class="figures">${figures}</div>` : active ? `<div class="muted">figures and tables when the study ends</div>` : ""}`;
  wireFiles($("study-detail"));
  $("study-stop").addEventListener("click", () => control("stop"));
  $("study-resume").addEventListener("click", () => control("resume"));
}

async function control(action) {
  try {
    await api("POST", `/api/studies/${view.id}/${action}`);
    view.detailKey = "";
    await refreshStudy();
    showMsg(action === "stop" ? "stopping after the cases that are running" : "resumed: only missing cases run", false, "study-ctl-msg");
  } catch (e) { showMsg(e.message, true, "study-ctl-msg"); }
}

async function submitStudy(ev) {
  ev.preventDefault();
  const text = $("study-text");
  let body;
  try { body = JSON.parse(text.value); } catch (e) {
    text.classList.add("invalid");
    showMsg(`the study is not valid JSON: ${e.message}`, true, "study-msg");
    return;
  }
  text.classList.remove("invalid");
  try {
    const s = await api("POST", "/api/studies", body);
    showMsg(`study ${s.id} queued: ${s.total} cases`, false, "study-msg");
    await selectStudy(s.id);
  } catch (e) { showMsg(e.message, true, "study-msg"); }
}

export function initStudies() {
  $("view-runs").addEventListener("click", () => showView("runs"));
  $("view-studies").addEventListener("click", () => showView("studies"));
  $("study-form").addEventListener("submit", submitStudy);
  const example = (which) => () => { setText(examples()[which]); view.edited = false; };
  $("study-example-grid").addEventListener("click", example("grid"));
  $("study-example-mc").addEventListener("click", example("mc"));
  let timer = null;
  $("study-text").addEventListener("input", () => {
    view.edited = true;
    clearTimeout(timer);
    timer = setTimeout(refreshPlan, 300);
  });
  document.querySelector("#study-list tbody").addEventListener("click", (ev) => {
    const tr = ev.target.closest("tr");
    if (tr && tr.dataset.id) selectStudy(tr.dataset.id);
  });
  if (location.hash === "#studies") showView("studies");
}
