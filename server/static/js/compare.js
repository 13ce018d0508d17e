// The compare page (#/compare?ids=1,2,...): two or more experiments side by side — how their runs ended
// (outcomes, success rate with the server's Wilson interval), each metric's mean with its 95% interval and
// over how many runs, and the differences of every pair: the success rate's risk difference with Fisher's
// exact p, and each metric's difference of means with a studentized bootstrap 95% interval (paired by
// repetition when both ran the same problem with the same seed). A study's tests with Holm's correction
// are in `twb study` (summary.md, comparisons.csv) and StudyData.compare(); docs/study.md explains both.

import { $, VOCABULARY, badge, h, num, pose, report } from "./dom.js";
import { plannerName } from "./experiments.js";
import { METRICS, allEqual, clipNote, intervalText, showIfClipped } from "./metrics.js";

/** The compared metrics: [key, name, unit]. */
export const COMPARE_METRICS = ["length_m", "execution_time_s", "average_speed_m_s", "deviation_mean_m", "smoothness_rad", "clearance_min_m"]
  .map((key) => [key, ...METRICS[key].slice(0, 2)]);
const NOT_COUNTED = VOCABULARY.notCounted;
const MIN_BOOTSTRAP = 5; // as planners.stats: fewer values a side get no interval
const IDENTICAL = "identical repetitions (deterministic simulation)";

/** Seeded uniform [0, 1) (mulberry32), so the intervals shown are the same on every load. */
function random(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

const mean = (xs) => xs.reduce((s, x) => s + x, 0) / xs.length;
function variance(xs) {
  const m = mean(xs);
  return xs.reduce((s, x) => s + (x - m) ** 2, 0) / (xs.length - 1);
}
function constant(xs) {
  if (!xs.length) return false;
  const hi = Math.max(...xs.map(Math.abs));
  return Math.max(...xs) - Math.min(...xs) <= 1e-9 * Math.max(1, hi);
}

/**
 * Studentized bootstrap interval of mean(a) - mean(b) (paired: of the mean difference), as planners.stats:
 * t* = (estimate* - estimate) / se*, interval estimate - q * se at the t* quantiles. Returns [low, high] or null.
 */
export function bootstrapDifference(a, b, { paired = false, level = 0.95, resamples = 4000, seed = 1 } = {}) {
  const rnd = random(seed);
  const pick = (xs) => xs[Math.floor(rnd() * xs.length)];
  const ts = new Float64Array(resamples);
  let est;
  let se;
  if (paired) {
    const d = a.map((x, i) => x - b[i]);
    if (d.length < MIN_BOOTSTRAP) return null;
    est = mean(d);
    se = Math.sqrt(variance(d) / d.length);
    for (let k = 0; k < resamples; k++) {
      const r = d.map(() => pick(d));
      ts[k] = (mean(r) - est) / Math.sqrt(variance(r) / r.length);
    }
  } else {
    if (Math.min(a.length, b.length) < MIN_BOOTSTRAP) return null;
    est = mean(a) - mean(b);
    se = Math.sqrt(variance(a) / a.length + variance(b) / b.length);
    for (let k = 0; k < resamples; k++) {
      const ra = a.map(() => pick(a));
      const rb = b.map(() => pick(b));
      ts[k] = (mean(ra) - mean(rb) - est) / Math.sqrt(variance(ra) / ra.length + variance(rb) / rb.length);
    }
  }
  for (let k = 0; k < resamples; k++) if (Number.isNaN(ts[k])) ts[k] = 0; // 0/0: no spread, mean = estimate
  ts.sort();
  const q = (p) => ts[Math.min(resamples - 1, Math.max(0, Math.ceil(p * resamples) - 1))];
  return [est - q((1 + level) / 2) * se, est - q((1 - level) / 2) * se];
}

function logFactorial(n) {
  let s = 0;
  for (let i = 2; i <= n; i++) s += Math.log(i);
  return s;
}

/** Fisher's exact test, two-sided, of k1/n1 against k2/n2 (as scipy.stats.fisher_exact). */
export function fisherExact(k1, n1, k2, n2) {
  const K = k1 + k2;
  const N = n1 + n2;
  const lp = (x) => logFactorial(K) + logFactorial(N - K) + logFactorial(n1) + logFactorial(n2)
    - logFactorial(x) - logFactorial(K - x) - logFactorial(n1 - x) - logFactorial(n2 - K + x) - logFactorial(N);
  const observed = lp(k1);
  let p = 0;
  for (let x = Math.max(0, K - n2); x <= Math.min(K, n1); x++) {
    const v = lp(x);
    if (v <= observed + 1e-7) p += Math.exp(v);
  }
  return Math.min(1, p);
}

/** Wilson score interval of k/n (as scipy.stats.binomtest(...).proportion_ci(method="wilson")). */
export function wilson(k, n, z = 1.959963984540054) {
  if (!n) return null;
  const p = k / n;
  const den = 1 + (z * z) / n;
  const centre = (p + (z * z) / (2 * n)) / den;
  const half = (z / den) * Math.sqrt((p * (1 - p)) / n + (z * z) / (4 * n * n));
  return [Math.max(0, centre - half), Math.min(1, centre + half)];
}

/** Newcombe's hybrid score interval of k1/n1 - k2/n2 from the two Wilson intervals (as planners.stats). */
export function newcombe(k1, n1, k2, n2) {
  const a = wilson(k1, n1);
  const b = wilson(k2, n2);
  if (!a || !b) return null;
  const p1 = k1 / n1;
  const p2 = k2 / n2;
  const d = p1 - p2;
  return [Math.max(-1, d - Math.hypot(p1 - a[0], b[1] - p2)), Math.min(1, d + Math.hypot(a[1] - p1, p2 - b[0]))];
}

function pct(v) {
  return v == null ? "–" : `${Math.round(100 * v)} %`;
}

function fmtP(p) {
  if (!Number.isFinite(p)) return "–";
  return p < 0.001 ? "< 0.001" : p.toPrecision(2);
}

/** One experiment's runs in one mode, with the values the comparisons use. */
function modeRuns(d, m, mode) {
  const outcome = new Map((m.runs || []).map((r) => [r.run_id, r.outcome]));
  return d.runs.filter((r) => r.mode === mode).map((r) => ({
    ...r,
    outcome: outcome.get(r.id) ?? "pending", // the server's outcome rule (contract/vocabulary.py run_outcome)
  }));
}

/** The counted runs, identical repetitions kept once (the deterministic simulation repeats itself). */
function distinct(runs) {
  const counted = runs.filter((r) => !NOT_COUNTED.has(r.outcome));
  if (counted.length < 2) return { runs: counted, merged: false };
  const keys = ["length_m", "execution_time_s", "deviation_mean_m", "smoothness_rad", "clearance_min_m"];
  const same = new Set(counted.map((r) => r.outcome)).size === 1 && keys.every((k) => {
    const vs = counted.map((r) => (r.metrics || {})[k]);
    if (vs.every((v) => v == null)) return true;
    return vs.every((v) => typeof v === "number") && constant(vs);
  });
  return same ? { runs: [counted[0]], merged: true } : { runs: counted, merged: false };
}

export class ComparePage {
  constructor(store) {
    this.store = store;
    this.root = $("#view-compare");
    this.ids = [];
  }

  async show(ids) {
    this.ids = ids;
    this.root.replaceChildren(h("div", { class: "exp-head" }, h("h1", { id: "compare-title" }, `Compare experiments ${ids.map((i) => `#${i}`).join(", ")}`),
      h("a", { href: "#/experiments" }, "All experiments")), h("p", { class: "muted", role: "status" }, "Loading…"));
    if (ids.length < 2) {
      this.root.append(h("p", { class: "error" }, "Choose at least two experiments: tick them in the list of finished experiments, then Compare."));
      return;
    }
    try {
      const api = this.store.api;
      const data = await Promise.all(ids.map(async (id) => {
        const [d, m] = await Promise.all([this.store.detail(id, { fresh: true }), api.get(`/api/v1/experiments/${id}/metrics`)]);
        return { d, m };
      }));
      if (ids !== this.ids) return;
      this.render(data);
    } catch (err) {
      if (err.status === 404) {
        this.root.replaceChildren(h("div", { class: "panel" }, h("h1", {}, "Compare"),
          h("p", { class: "error" }, "One of these experiments was not found (it does not exist or is not yours)."),
          h("a", { href: "#/experiments" }, "All experiments")));
      } else report(err, "Compare");
    }
  }

  render(data) {
    const modes = [...new Set(data.flatMap(({ d }) => d.modes))].sort((a, b) => (a === "twb" ? -1 : b === "twb" ? 1 : a.localeCompare(b)));
    const label = ({ d }) => `#${d.id} ${plannerName(d, this.store.programs)}`;
    const means = this.means(data, modes, label);
    const note = clipNote("compare-means-note");
    showIfClipped(note, means);
    this.root.replaceChildren(
      h("div", { class: "exp-head" }, h("h1", { id: "compare-title" }, `Compare experiments ${data.map(({ d }) => `#${d.id}`).join(", ")}`),
        h("a", { href: "#/experiments" }, "All experiments")),
      h("div", { class: "panel" }, h("h2", {}, "Experiments"), h("div", { class: "table-scroll" }, this.facts(data))),
      h("div", { class: "panel" }, h("h2", {}, "Outcomes"),
        h("p", { class: "muted small" }, "Success rate over the runs that ended in the job's own outcome (completed or failed), with the server's Wilson 95% interval; a testbed error is not the planner's."),
        h("div", { class: "table-scroll" }, this.outcomes(data, modes, label))),
      h("div", { class: "panel" }, h("h2", {}, "Metric means"),
        h("p", { class: "muted small" }, "Mean over the completed runs with its 95% interval (Student's t) and over how many of the runs; failed runs' metrics are on each experiment's page."),
        h("div", { class: "table-scroll" }, means), note),
      h("div", { class: "panel" }, h("h2", {}, "Differences"),
        h("p", { class: "muted small" }, "a − b per pair and mode: the success rate's risk difference with Fisher's exact p; each metric's difference of means over completed runs with a studentized bootstrap 95% interval (seeded), paired by repetition when both ran the same problem with the same seed. These p-values are not corrected for multiplicity; for a whole study's tests with Holm's correction use twb study (docs/study.md)."),
        h("div", { class: "table-scroll" }, this.differences(data, modes))),
    );
  }

  facts(data) {
    const head = h("thead", {}, h("tr", {}, ["Experiment", "Status", "Environment", "Planner", "Start", "Goal", "Modes", "Reps", "Seed", "Jitter"]
      .map((t) => h("th", { scope: "col" }, t))));
    const body = h("tbody", {}, data.map(({ d }) => h("tr", { dataset: { experiment: d.id } },
      h("td", {}, h("a", { href: `#/experiments/${d.id}` }, `#${d.id}`)), h("td", {}, badge(d.status)),
      h("td", {}, d.environment), h("td", {}, plannerName(d, this.store.programs)), h("td", {}, pose(d.start)), h("td", {}, pose(d.goal)),
      h("td", {}, d.modes.join(" + ")), h("td", { class: "num" }, d.repetitions), h("td", { class: "num" }, d.seed),
      h("td", {}, d.jitter ? `${num(d.jitter.xy_m, 3)} m, ${num(d.jitter.theta_rad, 3)} rad` : "none"))));
    return h("table", { class: "grid", id: "compare-facts" }, head, body);
  }

  outcomes(data, modes, label) {
    const head = h("thead", {}, h("tr", {}, ["Experiment", "Mode", "Runs", "Success", "Collision", "Timeout", "Other failure", "Not counted", "Success rate (95% CI)"]
      .map((t, i) => h("th", { scope: "col", class: i > 1 && i < 8 ? "num" : null }, t))));
    const rows = [];
    for (const x of data) {
      for (const mode of modes) {
        if (!x.d.modes.includes(mode)) continue;
        const o = x.m.outcomes?.[mode] || { counts: {}, success: {} };
        const c = o.counts || {};
        const other = Object.entries(c).filter(([k]) => !["success", "collision", "timeout"].includes(k) && !NOT_COUNTED.has(k));
        const notCounted = Object.entries(c).filter(([k]) => NOT_COUNTED.has(k)).reduce((s, [, v]) => s + v, 0);
        const s = o.success || {};
        const rate = s.n ? `${s.k}/${s.n} (${pct(s.ci_low)}–${pct(s.ci_high)})` : "no counted run";
        const { merged } = distinct(modeRuns(x.d, x.m, mode));
        rows.push(h("tr", { dataset: { experiment: x.d.id, mode } }, h("td", {}, label(x)), h("td", {}, mode),
          h("td", { class: "num" }, o.runs ?? x.d.runs.filter((r) => r.mode === mode).length),
          h("td", { class: "num", dataset: { outcome: "success" } }, c.success || 0),
          h("td", { class: "num", dataset: { outcome: "collision" } }, c.collision || 0),
          h("td", { class: "num", dataset: { outcome: "timeout" } }, c.timeout || 0),
          h("td", { class: "num" }, other.reduce((sum, [, v]) => sum + v, 0) || 0, other.length ? h("span", { class: "muted small" }, ` (${other.map(([k, v]) => `${k} ${v}`).join(", ")})`) : ""),
          h("td", { class: "num" }, notCounted),
          h("td", { dataset: { rate: s.rate ?? "" } }, rate, merged ? h("div", { class: "muted small" }, `${IDENTICAL}: one distinct run`) : "")));
      }
    }
    return h("table", { class: "grid", id: "compare-outcomes" }, head, h("tbody", {}, rows));
  }

  means(data, modes, label) {
    const cols = data.flatMap((x) => modes.filter((md) => x.d.modes.includes(md)).map((md) => ({ x, md })));
    const head = h("thead", {}, h("tr", {}, h("th", { scope: "col" }, "Metric"),
      ...cols.map(({ x, md }) => h("th", { scope: "col", class: "num" }, `${label(x)} · ${md}`))));
    const body = h("tbody", {}, COMPARE_METRICS.map(([key, title, unit]) => h("tr", { dataset: { metric: key } },
      h("th", { scope: "row" }, `${title} (${unit})`),
      ...cols.map(({ x, md }) => {
        const all = x.d.runs.filter((r) => r.mode === md);
        const done = all.filter((r) => r.status === "completed");
        const a = x.m.aggregates?.[md]?.metrics?.[key];
        if (!done.length || !a || a.mean == null) return h("td", { class: "num none" }, `no completed run (0 of ${all.length})`);
        const over = h("div", { class: "muted small" }, `over ${done.length} completed of ${all.length} runs`);
        if (allEqual(a)) {
          return h("td", { class: "num" }, num(a.mean), h("div", { class: "muted small" }, md === "sim" ? IDENTICAL : "identical repetitions"), over);
        }
        return h("td", { class: "num" }, num(a.mean), a.ci_low == null ? "" : [" ", intervalText(key, a.ci_low, a.ci_high)], over);
      }))));
    return h("table", { class: "grid", id: "compare-means" }, head, body);
  }

  differences(data, modes) {
    const head = h("thead", {}, h("tr", {}, ["a", "b", "Mode", "Metric", "n a", "n b", "a − b", "95% CI", "Method", "p", "Note"]
      .map((t, i) => h("th", { scope: "col", class: i >= 4 && i <= 9 ? "num" : null }, t))));
    const rows = [];
    let seed = 1;
    for (let i = 0; i < data.length; i++) {
      for (let j = i + 1; j < data.length; j++) {
        const A = data[i];
        const B = data[j];
        const same = A.d.environment === B.d.environment && JSON.stringify(A.d.start) === JSON.stringify(B.d.start)
          && JSON.stringify(A.d.goal) === JSON.stringify(B.d.goal) && A.d.seed === B.d.seed;
        for (const mode of modes) {
          if (!A.d.modes.includes(mode) || !B.d.modes.includes(mode)) continue;
          const ra = modeRuns(A.d, A.m, mode);
          const rb = modeRuns(B.d, B.m, mode);
          const cell = (k, v, cls) => h("td", { class: cls || null, dataset: k ? { k } : null }, v);
          const tag = (metric) => ({ dataset: { a: A.d.id, b: B.d.id, mode, metric } });
          // success rate
          const da = distinct(ra);
          const db = distinct(rb);
          const ka = da.runs.filter((r) => r.outcome === "success").length;
          const kb = db.runs.filter((r) => r.outcome === "success").length;
          const merged = da.merged || db.merged;
          if (da.runs.length && db.runs.length) {
            const p = fisherExact(ka, da.runs.length, kb, db.runs.length);
            const iv = newcombe(ka, da.runs.length, kb, db.runs.length);
            const points = (v) => `${v > 0 ? "+" : ""}${Math.round(100 * v)}`;
            rows.push(h("tr", tag("success_rate"), cell(null, `#${A.d.id}`), cell(null, `#${B.d.id}`), cell(null, mode), cell(null, "success rate"),
              cell(null, da.runs.length, "num"), cell(null, db.runs.length, "num"),
              cell("diff", `${points(ka / da.runs.length - kb / db.runs.length)} points`, "num"),
              cell("ci", iv ? `[${points(iv[0])}, ${points(iv[1])}]` : "–", "num"),
              cell(null, "Fisher exact"), cell("p", fmtP(p), "num"), cell(null, `${ka}/${da.runs.length} vs ${kb}/${db.runs.length}${merged ? `; ${IDENTICAL}: counted once` : ""}`)));
          }
          for (const [key, title, unit] of COMPARE_METRICS) {
            const doneA = ra.filter((r) => r.status === "completed");
            const doneB = rb.filter((r) => r.status === "completed");
            let xa;
            let xb;
            let paired = false;
            let note = "";
            if (!doneA.length || !doneB.length) {
              note = `no completed run of ${!doneA.length ? `#${A.d.id}` : `#${B.d.id}`}`;
              xa = [];
              xb = [];
            } else if (same && A.d.repetitions === B.d.repetitions) {
              paired = true;
              const byRep = new Map(doneB.map((r) => [r.repetition, r]));
              const pairs = doneA.filter((r) => byRep.has(r.repetition)).map((r) => [r.metrics?.[key], byRep.get(r.repetition).metrics?.[key]])
                .filter(([x, y]) => typeof x === "number" && typeof y === "number");
              xa = pairs.map((p) => p[0]);
              xb = pairs.map((p) => p[1]);
              if (distinct(doneA).merged && distinct(doneB).merged && xa.length) {
                xa = xa.slice(0, 1);
                xb = xb.slice(0, 1);
                note = IDENTICAL;
              }
            } else {
              const ua = distinct(doneA);
              const ub = distinct(doneB);
              xa = ua.runs.map((r) => r.metrics?.[key]).filter((v) => typeof v === "number");
              xb = ub.runs.map((r) => r.metrics?.[key]).filter((v) => typeof v === "number");
              if (ua.merged || ub.merged) note = IDENTICAL;
            }
            let diff = "–";
            let ci = "–";
            if (xa.length && xb.length) {
              const d = mean(xa) - mean(xb);
              diff = `${num(d)} ${unit}`;
              const noSpread = paired ? constant(xa.map((x, k) => x - xb[k])) : constant(xa) && constant(xb);
              const iv = noSpread ? null : bootstrapDifference(xa, xb, { paired, seed: seed++ });
              if (iv) ci = `[${num(iv[0])}, ${num(iv[1])}]`;
              else if (!note) note = noSpread ? "no spread: no interval" : `fewer than ${MIN_BOOTSTRAP} values a side: no interval`;
              else note += ": no interval";
            }
            rows.push(h("tr", tag(key), cell(null, `#${A.d.id}`), cell(null, `#${B.d.id}`), cell(null, mode), cell(null, title),
              cell(null, xa.length, "num"), cell(null, xb.length, "num"), cell("diff", diff, "num"), cell("ci", ci, "num"),
              cell(null, `bootstrap, ${paired ? "paired" : "unpaired"}`), cell(null, "–", "num"), cell("note", note)));
          }
        }
      }
    }
    return h("table", { class: "grid", id: "compare-differences" }, head, h("tbody", {}, rows));
  }
}
