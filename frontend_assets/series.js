// The picked run's samples for the charts: from the live stream (frames) or its stored series.

const MAX_POINTS = 3000; // per trace, older samples are thinned

export function emptySeries() {
  return { t: [], T_ref: [], T_mean_hat: [], tcErr: [[], [], [], []], u: [[], [], [], [], [], []],
    u_ff: [[], [], [], [], [], []], inh_t: [], inh: [], eta: [], field: null };
}

export function pushFrame(s, f) {
  s.t.push(f.t); s.T_ref.push(f.T_ref); s.T_mean_hat.push(f.T_mean_hat); s.eta.push(f.eta);
  for (let i = 0; i < 4; i++) s.tcErr[i].push(f.tc[i] === null || f.tc_hat[i] === null ? null : f.tc[i] - f.tc_hat[i]);
  for (let j = 0; j < 6; j++) { s.u[j].push(f.u[j]); s.u_ff[j].push(f.u_ff[j]); }
  s.inh_t.push(f.t); s.inh.push(f.inhomogeneity);
  s.field = f.field;
  if (s.t.length > MAX_POINTS) thin(s);
}

function thin(s) { // keep every other sample: bounded memory for long runs
  const half = (a) => a.filter((_, k) => k % 2 === 0);
  for (const k of ["t", "T_ref", "T_mean_hat", "eta", "inh_t", "inh"]) s[k] = half(s[k]);
  s.tcErr = s.tcErr.map(half); s.u = s.u.map(half); s.u_ff = s.u_ff.map(half);
}

// GET /api/runs/{id}/series (a decimated timeseries.npz) as a series buffer.
export function seriesFromStored(d) {
  const s = emptySeries();
  s.t = d.t; s.T_ref = d.T_ref; s.T_mean_hat = d.T_mean_hat; s.eta = d.eta;
  for (let i = 0; i < 4; i++) s.tcErr[i] = d.tc.map((row, k) => (row[i] === null || d.tc_hat[k][i] === null ? null : row[i] - d.tc_hat[k][i]));
  for (let j = 0; j < 6; j++) { s.u[j] = d.u.map((r) => r[j]); s.u_ff[j] = d.u_ff.map((r) => r[j]); }
  s.inh_t = d.t_field || []; s.inh = d.inhomogeneity || [];
  s.field = d.field || null;
  return s;
}
