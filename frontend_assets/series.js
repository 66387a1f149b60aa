// The shown run's samples for the charts: its history (GET /api/runs/{id}/series) continued by the live
// stream's frames.  Per sample: t, T_ref, fillet mean, TC errors, group powers u and u_ff, the groups at a
// bound (+1 full power, -1 off), eta; per field sample: T_sup and the spread about the fillet mean.
// With a calibrating estimator (issue 11) `params`: {name: {v: [...], s: [...]}} (relative deviations and their
// sigmas, per sample); with a shadow estimator `shadowTc4Err` (TC4 reading - shadow estimate, K, per sample) and
// `shadowDelta` (the last shadow field - estimated field, K); both stay empty / null for other runs.
// The estimate's uncertainty (issue 25): `sigma_mean` (K, of the fillet mean, per sample) and `fieldSigma` (the
// last field's standard deviation, K); null where the run does not report them.

const MAX_POINTS = 4000; // per trace; older samples are thinned beyond it

export function emptySeries() {
  return { t: [], T_ref: [], T_mean_hat: [], tcErr: [[], [], [], []], tc: null, u: [[], [], [], [], [], []],
    u_ff: [[], [], [], [], [], []], sat: [], inh_t: [], inh: [], spread: [], eta: [], field: null,
    params: {}, shadowTc4Err: [], shadowDelta: null, sigma_mean: [], fieldSigma: null };
}

const lastT = (s) => (s.t.length ? s.t[s.t.length - 1] : -Infinity);

const diff = (a, b) => (a === null || a === undefined || b === null || b === undefined ? null : a - b);

// A frame's calibration and shadow into the series (the sample's t is already pushed).
function pushEstimators(s, f) {
  const n = s.t.length;
  for (const name of Object.keys(f.calibration || {})) {
    if (!s.params[name]) s.params[name] = { v: new Array(n - 1).fill(null), s: new Array(n - 1).fill(null) };
  }
  for (const [name, p] of Object.entries(s.params)) {
    const c = (f.calibration || {})[name];
    p.v.push(c ? c.value : null); p.s.push(c ? c.sigma : null);
  }
  if (f.shadow && s.shadowTc4Err.length < n - 1) s.shadowTc4Err = new Array(n - 1).fill(null).concat(s.shadowTc4Err);
  if (f.shadow || s.shadowTc4Err.length) s.shadowTc4Err.push(f.shadow ? diff(f.tc[3], f.shadow.tc_hat[3]) : null);
  if (f.shadow && f.shadow.field_delta) s.shadowDelta = f.shadow.field_delta;
}

export function pushFrame(s, f) {
  if (f.t <= lastT(s)) { // a repeated sample (a run's last frame)
    s.field = f.field; s.tc = f.tc; s.fieldSigma = f.field_sigma || s.fieldSigma;
    if (f.shadow && f.shadow.field_delta) s.shadowDelta = f.shadow.field_delta;
    return;
  }
  s.t.push(f.t); s.T_ref.push(f.T_ref); s.T_mean_hat.push(f.T_mean_hat); s.eta.push(f.eta);
  for (let i = 0; i < 4; i++) s.tcErr[i].push(f.tc[i] === null || f.tc_hat[i] === null ? null : f.tc[i] - f.tc_hat[i]);
  for (let j = 0; j < 6; j++) { s.u[j].push(f.u[j]); s.u_ff[j].push(f.u_ff[j]); }
  s.sat.push(f.saturated || [0, 0, 0, 0, 0, 0]);
  s.inh_t.push(f.t); s.inh.push(f.inhomogeneity); s.spread.push(f.spread ?? null);
  s.sigma_mean.push(f.sigma_mean ?? null);
  pushEstimators(s, f);
  s.field = f.field; s.fieldSigma = f.field_sigma || null;
  s.tc = f.tc;
  if (s.t.length > MAX_POINTS) thin(s);
}

function thin(s) { // keep every other sample: bounded memory for long runs
  const half = (a) => a.filter((_, k) => k % 2 === 0);
  for (const k of ["t", "T_ref", "T_mean_hat", "eta", "sat", "inh_t", "inh", "spread", "sigma_mean"]) s[k] = half(s[k]);
  s.tcErr = s.tcErr.map(half); s.u = s.u.map(half); s.u_ff = s.u_ff.map(half);
  s.shadowTc4Err = half(s.shadowTc4Err);
  for (const p of Object.values(s.params)) { p.v = half(p.v); p.s = half(p.s); }
}

// GET /api/runs/{id}/series as a series buffer.
export function seriesFromStored(d) {
  const s = emptySeries();
  if (!d.t) return s;
  s.t = d.t; s.T_ref = d.T_ref; s.T_mean_hat = d.T_mean_hat; s.eta = d.eta;
  for (let i = 0; i < 4; i++) s.tcErr[i] = d.tc.map((row, k) => (row[i] === null || d.tc_hat[k][i] === null ? null : row[i] - d.tc_hat[k][i]));
  for (let j = 0; j < 6; j++) { s.u[j] = d.u.map((r) => r[j]); s.u_ff[j] = d.u_ff.map((r) => r[j]); }
  s.sat = d.saturated || d.t.map(() => [0, 0, 0, 0, 0, 0]);
  s.inh_t = d.t_field || []; s.inh = d.inhomogeneity || []; s.spread = d.spread || [];
  s.field = d.field || null;
  s.sigma_mean = d.sigma_mean || d.t.map(() => null); s.fieldSigma = d.field_sigma || null;
  s.tc = d.tc.length ? d.tc[d.tc.length - 1] : null;
  for (const name of Object.keys(d.parameters || {})) {
    s.params[name] = { v: d.parameters[name], s: (d.parameter_sigma || {})[name] || d.t.map(() => null) };
  }
  if (d.shadow_tc_hat) s.shadowTc4Err = d.tc.map((row, k) => diff(row[3], d.shadow_tc_hat[k][3]));
  s.shadowDelta = d.shadow_field_delta || null;
  return s;
}

// Spans where group j stayed at a bound: [{j, bound (+1 / -1), t0, t1}] from the per-sample flags.
export function saturationSpans(s) {
  const spans = [];
  for (let j = 0; j < 6; j++) {
    let open = null;
    for (let k = 0; k < s.t.length; k++) {
      const b = (s.sat[k] || [])[j] || 0;
      if (open && b !== open.bound) { spans.push(open); open = null; }
      if (b && !open) open = { j, bound: b, t0: s.t[k], t1: s.t[k] };
      if (open) open.t1 = s.t[k];
    }
    if (open) spans.push(open);
  }
  return spans;
}
