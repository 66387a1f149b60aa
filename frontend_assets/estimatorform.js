// The start form's estimator choice (issue 11): the run's estimator and an optional shadow estimator on the
// same TC data, sent as the scenario's `estimator` ({motion, calibrate, shadow}).  The preselected choice is
// the server's default scenario (GET /api/furnace `defaults.estimator`); the paper's is one setting away.
import { $ } from "./page.js";
import { termText } from "./glossary.js";

// option value <-> {motion, calibrate}
const keyOf = (c) => `${c.motion}${c.calibrate ? "+calibrate" : ""}`;
const choiceOf = (key) => ({ motion: key.split("+")[0], calibrate: key.endsWith("+calibrate") });

const PRIMARY = [
  ["position_aware+calibrate", "position-aware, calibrating"],
  ["position_aware", "position-aware"],
  ["averaged", "paper: averaged, no calibration"],
];
const SHADOW = [
  ["none", "none"],
  ["averaged", "paper: averaged, no calibration"],
  ["position_aware", "position-aware"],
  ["position_aware+calibrate", "position-aware, calibrating"],
];
const SHORT = { "position_aware+calibrate": "position-aware, calibrating", position_aware: "position-aware", averaged: "paper" };

// An estimator in words, e.g. "position-aware, calibrating" or "averaged, no calibration" (twin.estimation.choice.describe).
export function describeChoice(c) {
  if (!c) return "none";
  const motion = c.motion === "position_aware" ? "position-aware" : "averaged";
  return `${motion}, ${c.calibrate ? "calibrating" : "no calibration"}`;
}

function options(select, list, selected) {
  const known = list.some(([v]) => v === selected);
  const all = known ? list : [...list, [selected, describeChoice(choiceOf(selected))]]; // a server default not listed
  select.replaceChildren(...all.map(([v, text]) => new Option(text, v, false, v === selected)));
}

// The choice in words on the collapsed box's summary line.
export function showEstimatorSummary(form = $("start-form")) {
  const p = form.elements.estimator.value, s = form.elements.shadow.value;
  const short = (v) => SHORT[v] || describeChoice(choiceOf(v));
  $("estimator-sum").textContent = p ? `· ${short(p)}${s && s !== "none" ? ` · shadow: ${short(s)}` : ""}` : "";
}

// The form shows an estimator spec (the furnace's default scenario's, or a run's for "use as new run").
export function setEstimatorForm(est, form = $("start-form")) {
  const d = est || { motion: "position_aware", calibrate: true, shadow: null }; // twin.scenario.EstimatorSpec
  options(form.elements.estimator, PRIMARY, keyOf(d));
  options(form.elements.shadow, SHADOW, d.shadow ? keyOf(d.shadow) : "none");
  showEstimatorSummary(form);
}

// The choices with the furnace's default scenario preselected (before the form is restored from this browser).
export function fillEstimatorChoices(furnace, form = $("start-form")) {
  setEstimatorForm(furnace.defaults && furnace.defaults.estimator, form);
  for (const el of form.querySelectorAll("#estimator-box .help[data-term]")) if (!termText(el.dataset.term)) el.hidden = true; // no words yet
}

export function estimatorFromForm(form = $("start-form")) {
  const p = form.elements.estimator.value, s = form.elements.shadow.value;
  if (!p) throw new Error("Estimator: pick one");
  return { ...choiceOf(p), shadow: !s || s === "none" ? null : choiceOf(s) };
}
