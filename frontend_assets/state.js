// What the page shows now: the furnace (GET /api/furnace), the words (GET /api/glossary), the shown run,
// its series and events, the runs list and the comparison.

export const state = {
  furnace: null, // name, geometry, TC positions, lamp groups, scenario limits and defaults
  glossary: null, // {metrics: {key: {name, meaning, unit}}, terms: {key: text}, groups: {name: text}}
  health: null,
  runId: null, run: null, // the shown run and its GET /api/runs/{id} (reference, oscillation, windows in force)
  ws: null, frames: 0, series: null, lastFrame: null, dirty: false,
  loading: false, // the shown run's history is being read; frames wait in `held`
  held: [],
  historyEnd: null, // run time of the last sample of the history (GET .../series)
  events: new Map(), // n -> {n, t, text, level}: the shown run's events, each once
  lastStatus: null, stopping: null,
  oscShown: null, // the in-force oscillation last copied into the live inputs (JSON)
  runs: [], // GET /api/runs, newest first
  compare: new Set(), // ids of the runs ticked for the comparison
  view: "live",
};
