// Reference points typed by the user: "time, temperature" per line (comma, semicolon, tab or spaces
// between; # starts a comment), checked against the furnace's limits (GET /api/furnace).

// Returns [[t, T], ...] or throws an Error that names every bad line.
// limits: {time: {min, max}, temperature: {min, max}} (limits.reference.points of the furnace).
export function parsePoints(text, limits) {
  const { time, temperature } = limits;
  const points = [], problems = [];
  let prevT = null;
  text.split(/\r?\n/).forEach((raw, k) => {
    const line = raw.replace(/#.*$/, "").trim();
    if (!line) return;
    const where = `line ${k + 1}`;
    const parts = line.split(/[\s,;]+/).filter(Boolean);
    const nums = parts.map(Number);
    if (parts.length !== 2 || nums.some((v) => !Number.isFinite(v))) {
      problems.push(`${where}: \u201c${line}\u201d is not \u201ctime, temperature\u201d (two numbers, e.g. \u201c60, 900\u201d)`);
      return;
    }
    const [t, T] = nums;
    if (t < time.min) problems.push(`${where}: time ${t} s is negative`);
    else if (t > time.max) problems.push(`${where}: time ${t} s is beyond ${time.max} s`);
    else if (prevT !== null && t <= prevT) problems.push(`${where}: time ${t} s is not after ${prevT} s (times must increase)`);
    if (T < temperature.min || T > temperature.max) {
      problems.push(`${where}: ${T} K is outside ${temperature.min}\u2026${temperature.max} K`);
    }
    prevT = t;
    points.push([t, T]);
  });
  if (!points.length && !problems.length) problems.push("enter at least one \u201ctime, temperature\u201d line");
  if (problems.length) {
    const shown = problems.slice(0, 3).join("; ");
    throw new Error(`reference points: ${shown}${problems.length > 3 ? ` (and ${problems.length - 3} more)` : ""}`);
  }
  return points;
}
