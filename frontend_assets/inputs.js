// The inputs of the page, built from the loaded furnace (GET /api/furnace): every min, max and
// default comes from its scenario limits, none is written in index.html.
import { $ } from "./page.js";
import { state } from "./state.js";

// input -> path of its range in furnace.limits; gap: how far above an open lower bound the input starts;
// preset: a first value that is not the scenario's default (live changes), clamped into the range
const BOUND = [
  ["#start-form [name=setpoint]", "reference.setpoint", { gap: 1 }],
  ["#start-form [name=t_E]", "reference.t_E", { gap: 0.1 }],
  ["#start-form [name=duration]", "duration", { gap: 1 }],
  ["#start-form [name=amplitude]", "oscillation.amplitude"],
  ["#start-form [name=period]", "oscillation.period"],
  ["#start-form [name=tc4x]", "tc4.x"],
  ["#start-form [name=tc4y]", "tc4.y"],
  ["#start-form [name=tc_noise]", "tc_noise"],
  ["#start-form [name=seed]", "seed"],
  ["#start-form [name=m_eps]", "mismatch.emissivity"],
  ["#start-form [name=m_alpha]", "mismatch.alpha"],
  ["#start-form [name=m_lamp]", "mismatch.lamp_efficiency"],
  ["#new-setpoint", "reference.setpoint", { gap: 1, preset: 1050 }],
  ["#new-tE", "reference.t_E", { gap: 0.1, preset: 30 }],
  ["#live-amplitude", "oscillation.amplitude"],
  ["#live-period", "oscillation.period"],
];

const range = (limits, path) => path.split(".").reduce((node, key) => node[key], limits);

export function applyLimits(furnace) {
  const limits = furnace.limits;
  for (const [selector, path, opt = {}] of BOUND) {
    const el = document.querySelector(selector);
    const r = range(limits, path);
    const lo = r.exclusive_min ? r.min + (opt.gap || 0) : r.min;
    el.min = String(lo);
    el.max = String(r.max);
    const first = opt.preset !== undefined ? opt.preset : r.default;
    if (first !== undefined) el.value = String(Math.min(Math.max(first, lo), r.max));
    el.title = `${lo}\u2026${r.max}${r.unit ? ` ${r.unit}` : ""}`;
  }
  const speed = document.querySelector("#start-form [name=speed]");
  speed.value = String(limits.speed.default);
  speed.title = `'max' or a real-time factor from ${limits.speed.min} to ${limits.speed.max}`;
  $("furnace-name").textContent = `furnace ${furnace.name} · η ≤ ${Number((1000 * furnace.eta_max).toPrecision(3))} mm`;
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
