// The inputs of the page, built from the loaded furnace (GET /api/furnace): every min, max and
// default comes from its scenario limits, none is written in index.html; numbers are read with the
// same limits, and an empty or wrong field is named before anything is sent.
import { fillEstimatorChoices } from "./estimatorform.js";
import { $ } from "./page.js";
import { state } from "./state.js";

// input -> path of its range in furnace.limits; preset: a first value that is not the scenario's default
// (live changes), clamped into the range
const BOUND = [
  ["#start-form [name=setpoint]", "reference.setpoint"],
  ["#start-form [name=t_E]", "reference.t_E"],
  ["#start-form [name=duration]", "duration"],
  ["#start-form [name=amplitude]", "oscillation.amplitude"],
  ["#start-form [name=period]", "oscillation.period"],
  ["#start-form [name=tc4x]", "tc4.x"],
  ["#start-form [name=tc4y]", "tc4.y"],
  ["#start-form [name=tc_noise]", "tc_noise"],
  ["#start-form [name=seed]", "seed"],
  ["#start-form [name=m_eps]", "mismatch.emissivity"],
  ["#start-form [name=m_alpha]", "mismatch.alpha"],
  ["#start-form [name=m_lamp]", "mismatch.lamp_efficiency"],
  ["#new-setpoint", "reference.setpoint", { preset: 1050 }],
  ["#new-tE", "reference.t_E", { preset: 30 }],
  ["#live-amplitude", "oscillation.amplitude"],
  ["#live-period", "oscillation.period"],
];

const range = (limits, path) => path.split(".").reduce((node, key) => node[key], limits);
const num = (v) => String(Number(v.toPrecision(6)));

export function applyLimits(furnace) {
  const limits = furnace.limits;
  for (const [selector, path, opt = {}] of BOUND) {
    const el = document.querySelector(selector);
    const r = range(limits, path);
    el.min = String(r.min);
    el.max = String(r.max);
    el.dataset.open = r.exclusive_min ? "1" : "";
    el.dataset.unit = r.unit || "";
    const first = opt.preset !== undefined ? opt.preset : r.default;
    if (first !== undefined) el.value = num(Math.min(Math.max(first, r.min), r.max));
    el.title = `${r.exclusive_min ? "above " : ""}${r.min}\u2026${r.max}${r.unit ? ` ${r.unit}` : ""}`;
  }
  const truth = document.querySelector("#start-form [name=truth]");
  truth.replaceChildren(...limits.truth.choices.map((c) => new Option(c, c, false, c === limits.truth.default)));
  fillEstimatorChoices(furnace);
  const speed = document.querySelector("#start-form [name=speed]");
  speed.value = String(limits.speed.default);
  speed.title = `'max' or a real-time factor from ${limits.speed.min} to ${limits.speed.max}`;
  $("furnace-name").textContent = `furnace ${furnace.name} · η ≤ ${Number((1000 * furnace.eta_max).toPrecision(3))} mm`;
}

// A decimal number as people type it: "0.048", "0,048" (a decimal comma, issue 27: the browser's number field
// read "0,048" as 48), "-1.5e-3"; null for anything else, e.g. "1,234.5" or "1.234,5" (thousands separators are
// ambiguous: refused, never guessed).
export function parseDecimal(text) {
  const t = text.trim();
  const plain = /^[+-]?(\d+\.?\d*|\.\d+)(e[+-]?\d+)?$/i, comma = /^[+-]?(\d+,\d*|,\d+)(e[+-]?\d+)?$/i;
  if (plain.test(t)) return Number(t);
  if (comma.test(t)) return Number(t.replace(",", "."));
  return null;
}

// The number in an input, checked against its limits; throws an Error that names the field.
export function readNumber(el) {
  const what = el.dataset.what || el.name || el.id;
  const unit = el.dataset.unit ? ` ${el.dataset.unit}` : "";
  const text = el.value.trim();
  el.classList.remove("invalid");
  const fail = (msg) => { el.classList.add("invalid"); throw new Error(`${what}: ${msg}`); };
  if (!text) fail("enter a number");
  const v = parseDecimal(text);
  if (v === null) fail(`\u201c${text}\u201d is not a number (use digits with a decimal point or comma, e.g. 0.048)`);
  const lo = el.min === "" ? -Infinity : Number(el.min), hi = el.max === "" ? Infinity : Number(el.max);
  if (el.dataset.open && v <= lo) fail(`must be above ${lo}${unit}, got ${v}${unit}`);
  if (v < lo) fail(`must be at least ${lo}${unit}, got ${v}${unit}`);
  if (v > hi) fail(`must be at most ${hi}${unit}, got ${v}${unit}`);
  return v;
}

// The speed field: 'max' or a real-time factor within the limits.
export function readSpeed(el) {
  const text = el.value.trim().toLowerCase();
  if (text === "max") return "max";
  const r = state.furnace.limits.speed;
  el.classList.remove("invalid");
  const v = Number(text);
  if (!text || !Number.isFinite(v) || v < r.min || v > r.max) {
    el.classList.add("invalid");
    throw new Error(`Speed: \u2018max\u2019 or a real-time factor from ${r.min} to ${r.max}, got \u201c${el.value}\u201d`);
  }
  return v;
}

// The live oscillation controls show what the server says the run uses (null: no run picked).
// The inputs are refilled only when that changes, so a value being typed is not overwritten.
export function setLiveOscillation(osc) {
  const enabled = !!(osc && osc.enabled);
  $("osc-btn").textContent = enabled ? "Oscillation off" : "Oscillation on";
  $("osc-btn").classList.toggle("on", enabled);
  const shown = osc ? JSON.stringify(osc) : null;
  if (!osc || shown === state.oscShown) return;
  state.oscShown = shown;
  $("live-amplitude").value = String(osc.amplitude);
  $("live-period").value = String(osc.period);
}
