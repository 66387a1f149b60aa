// What the page shows now: the furnace (GET /api/furnace), the picked run and its series.

export const state = {
  furnace: null, // name, geometry, TC positions, lamp groups, scenario limits and defaults
  health: null,
  runId: null, run: null, // the picked run and its GET /api/runs/{id} (reference and oscillation in force)
  ws: null, frames: 0, series: null, lastFrame: null, dirty: false,
  tc4: [0.5, 0.5], eventSeq: -1, lastStatus: null, nEvents: 0, stopping: null,
  oscShown: null, // the in-force oscillation last copied into the live inputs (JSON)
};
