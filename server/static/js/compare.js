// The compare page (#/compare?ids=1,2,...): two or more experiments side by side, as the server compares them
// (GET /api/v1/comparisons: the same numbers as a study's comparisons.csv, `twb results 1 2 3` and
// Client.compare). Each experiment is its label (the configuration) on its problem. The page shows how each
// configuration's runs ended (success rate with the server's Wilson interval over the distinct runs), each
// experiment's metric means (the server's aggregates), the comparisons over problems (when there are three
// or more: each problem one observation, how many problems favour each side, I²) and each problem's. It
// computes no statistics itself: every interval and p-value is the server's. docs/dashboard.md.

import { $, VOCABULARY, badge, h, num, pose, report } from "./dom.js";
import { plannerName } from "./experiments.js";
import { METRICS, allEqual, clipNote, intervalText, metricLabel, showIfClipped } from "./metrics.js";

/** The metrics of the means table: [key, name, unit]. */
export const COMPARE_METRICS = ["length_m", "execution_time_s", "average_speed_m_s", "deviation_mean_m", "smoothness_rad", "clearance_min_m"]
  .map((key) => [key, ...METRICS[key].slice(0, 2)]);
const IDENTICAL = "identical repetitions (deterministic simulation)";
/** The server's test names in words. */
const TESTS = {
  "paired-t": "paired t", "welch-t": "Welch's t", "mann-whitney-u": "Mann-Whitney U", wilcoxon: "Wilcoxon",
  "fisher-exact": "Fisher's exact", "problem-t": "t over problems", "problem-wilcoxon": "Wilcoxon over problems",
};

/** A share as a whole percentage, "57 %"; "–" for none. */
export function pct(v) {
  return v == null ? "–" : `${Math.round(100 * v)} %`;
}

/** A difference of rates in percentage points, signed: "+40". */
export function points(v) {
  return `${v > 0 ? "+" : ""}${Math.round(100 * v)}`;
}

/** A p-value: two significant digits, "< 0.001" below that; "–" for none. */
export function fmtP(p) {
  if (p == null || !Number.isFinite(p)) return "–";
  return p < 0.001 ? "< 0.001" : p.toPrecision(2);
}

/** The success rate of a configuration's runs: k/n distinct runs with the Wilson interval, saying when
 * identical repetitions were counted once. */
function rateText(o) {
  const s = o.success || {};
  if (!o.counted) return "no counted run";
  if (s.rate == null) return `${s.k}/${s.n}`;
  const ci = `(${pct(s.ci_low)}–${pct(s.ci_high)})`;
  if (o.identical) return `${o.counts.success || 0}/${o.counted} runs; ${IDENTICAL} counted once: ${s.k}/${s.n} ${ci}`;
  return `${s.k}/${s.n} ${ci}`;
}

/** One comparison row's cells: [key, text, raw value or null, numeric?]. */
function rowCells(r, pooled) {
  const rate = r.metric === "success_rate";
  const unit = rate ? "" : METRICS[r.metric]?.[1] ?? "";
  const mean = (v) => (rate ? pct(v) : num(v));
  const diff = r.diff == null ? "–" : rate ? `${points(r.diff)} points` : `${num(r.diff)}${unit ? ` ${unit}` : ""}`;
  const ci = r.ci_low == null || r.ci_high == null ? "–"
    : rate ? `[${points(r.ci_low)}, ${points(r.ci_high)}]` : `[${num(r.ci_low)}, ${num(r.ci_high)}]`;
  const cells = [
    ["mode", r.mode, null, false], ["metric", rate ? "success rate" : metricLabel(r.metric), null, false],
    ["a", r.a, null, false], ["b", r.b, null, false],
  ];
  if (!pooled) cells.push(["n_a", String(r.n_a), r.n_a, true], ["n_b", String(r.n_b), r.n_b, true]);
  cells.push(["mean_a", mean(r.mean_a), r.mean_a, true], ["mean_b", mean(r.mean_b), r.mean_b, true],
    ["diff", diff, r.diff, true], ["ci", ci, null, true],
    ["test", r.test ? TESTS[r.test] ?? r.test : "–", null, false],
    ["p", fmtP(r.p), r.p, true], ["p_holm", fmtP(r.p_holm), r.p_holm, true]);
  if (pooled) {
    cells.push(["favour", r.favour_a == null ? "–" : `${r.favour_a} / ${r.favour_b} of ${r.n_problems}`, null, true],
      ["i2", pct(r.heterogeneity_i2), r.heterogeneity_i2, true]);
  }
  cells.push(["note", r.note || "", null, false]);
  return cells;
}

function comparisonTable(rows, pooled, attrs) {
  const names = {
    mode: "Mode", metric: "Metric", a: "a", b: "b", n_a: "n a", n_b: "n b", mean_a: "Mean a", mean_b: "Mean b",
    diff: "a − b", ci: "95% CI", test: "Test", p: "p", p_holm: "Holm p", favour: "Problems favouring a / b", i2: "I²", note: "Note",
  };
  const template = rowCells(rows[0], pooled);
  const head = h("thead", {}, h("tr", {}, template.map(([k, , , numeric]) => h("th", { scope: "col", class: numeric ? "num" : null }, names[k]))));
  const body = h("tbody", {}, rows.map((r) => h("tr", { dataset: { metric: r.metric, mode: r.mode, a: r.a, b: r.b, problem: r.problem } },
    rowCells(r, pooled).map(([k, text, raw, numeric]) => h("td", {
      class: [numeric ? "num" : null, k === "note" ? "note" : null].filter(Boolean).join(" ") || null,
      dataset: raw == null ? { k } : { k, v: String(raw) },
    }, text)))));
  return h("table", { class: "grid compact", ...attrs }, head, body);
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
      const [cmp, data] = await Promise.all([
        api.get(`/api/v1/comparisons?experiments=${ids.join(",")}`),
        Promise.all(ids.map(async (id) => {
          const [d, m] = await Promise.all([this.store.detail(id, { fresh: true }), api.get(`/api/v1/experiments/${id}/metrics`)]);
          return { d, m };
        })),
      ]);
      if (ids !== this.ids) return;
      this.render(cmp, data);
    } catch (err) {
      if (ids !== this.ids) return;
      if (err.status === 404 || err.status === 422) {
        this.root.replaceChildren(h("div", { class: "panel" }, h("h1", {}, "Compare"),
          h("p", { class: "error" }, err.status === 404
            ? "One of these experiments was not found (it does not exist or is not yours)."
            : `These experiments cannot be compared: ${err.detail}`),
          h("a", { href: "#/experiments" }, "All experiments")));
      } else report(err, "Compare");
    }
  }

  render(cmp, data) {
    const byId = new Map(cmp.experiments.map((e) => [e.id, e]));
    const modes = [...new Set(data.flatMap(({ d }) => d.modes))].sort((a, b) => (a === "twb" ? -1 : b === "twb" ? 1 : a.localeCompare(b)));
    const label = ({ d }) => `#${d.id} ${byId.get(d.id)?.configuration ?? plannerName(d, this.store.programs)}`;
    const means = this.means(data, modes, label);
    const note = clipNote("compare-means-note");
    showIfClipped(note, means);
    this.root.replaceChildren(
      h("div", { class: "exp-head" }, h("h1", { id: "compare-title" }, `Compare experiments ${data.map(({ d }) => `#${d.id}`).join(", ")}`),
        h("a", { href: "#/experiments" }, "All experiments")),
      h("div", { class: "panel" }, h("h2", {}, "Experiments"),
        h("p", { class: "muted small" }, "Each experiment is its configuration (its label) on its problem; experiments with the same label are one configuration, pooled over their problems."),
        h("div", { class: "table-scroll" }, this.facts(data, byId))),
      h("div", { class: "panel" }, h("h2", {}, "Outcomes"),
        h("p", { class: "muted small" }, "Per configuration and mode: how its runs ended, and the success rate over the runs that ended in the job's own outcome (completed or failed) with the server's Wilson 95% interval; identical repetitions of a problem count once, and a testbed error is not the planner's."),
        h("div", { class: "table-scroll" }, this.outcomes(cmp))),
      h("div", { class: "panel" }, h("h2", {}, "Metric means"),
        h("p", { class: "muted small" }, "Each experiment's mean over its completed runs with its 95% interval (Student's t) and over how many of the runs; failed runs' metrics are on each experiment's page."),
        h("div", { class: "table-scroll" }, means), note),
      this.pooled(cmp),
      this.perProblem(cmp),
      h("p", { class: "muted small", id: "compare-method" }, cmp.method),
    );
  }

  facts(data, byId) {
    const head = h("thead", {}, h("tr", {}, ["Experiment", "Status", "Configuration", "Problem", "Planner", "Start", "Goal", "Modes", "Reps", "Seed", "Jitter"]
      .map((t) => h("th", { scope: "col" }, t))));
    const body = h("tbody", {}, data.map(({ d }) => h("tr", { dataset: { experiment: d.id } },
      h("td", {}, h("a", { href: `#/experiments/${d.id}` }, `#${d.id}`)), h("td", {}, badge(d.status)),
      h("td", {}, byId.get(d.id)?.configuration ?? ""), h("td", {}, byId.get(d.id)?.problem ?? ""),
      h("td", {}, plannerName(d, this.store.programs)), h("td", {}, pose(d.start)), h("td", {}, pose(d.goal)),
      h("td", {}, d.modes.join(" + ")), h("td", { class: "num" }, d.repetitions), h("td", { class: "num" }, d.seed),
      h("td", {}, d.jitter ? `${num(d.jitter.xy_m, 3)} m, ${num(d.jitter.theta_rad, 3)} rad` : "none"))));
    return h("table", { class: "grid", id: "compare-facts" }, head, body);
  }

  outcomes(cmp) {
    const notCounted = VOCABULARY.notCounted;
    const head = h("thead", {}, h("tr", {}, ["Configuration", "Experiments", "Mode", "Runs", "Success", "Collision", "Timeout", "Other failure", "Not counted", "Success rate (95% CI)"]
      .map((t, i) => h("th", { scope: "col", class: i > 2 && i < 9 ? "num" : null }, t))));
    const rows = cmp.outcomes.map((o) => {
      const c = o.counts || {};
      const other = Object.entries(c).filter(([k]) => !["success", "collision", "timeout"].includes(k) && !notCounted.has(k));
      const s = o.success || {};
      return h("tr", { dataset: { configuration: o.configuration, mode: o.mode, experiments: o.experiments.join(",") } },
        h("td", {}, o.configuration), h("td", {}, o.experiments.map((i) => `#${i}`).join(" ")), h("td", {}, o.mode),
        h("td", { class: "num" }, o.runs),
        h("td", { class: "num", dataset: { outcome: "success" } }, c.success || 0),
        h("td", { class: "num", dataset: { outcome: "collision" } }, c.collision || 0),
        h("td", { class: "num", dataset: { outcome: "timeout" } }, c.timeout || 0),
        h("td", { class: "num" }, other.reduce((sum, [, v]) => sum + v, 0), other.length ? h("span", { class: "muted small" }, ` (${other.map(([k, v]) => `${k} ${v}`).join(", ")})`) : ""),
        h("td", { class: "num" }, o.runs - o.counted),
        h("td", { dataset: { rate: s.rate ?? "", k: s.k ?? "", n: s.n ?? "", ciLow: s.ci_low ?? "", ciHigh: s.ci_high ?? "" } }, rateText(o)));
    });
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

  pooled(cmp) {
    const rows = cmp.rows.filter((r) => r.problem === "");
    const n = cmp.problems.length;
    const panel = h("div", { class: "panel", id: "compare-pooled-panel" }, h("h2", {}, "Over problems"));
    if (!rows.length) {
      panel.append(h("p", { id: "compare-no-verdict" }, `No verdict over problems: these experiments are on ${n} problem${n === 1 ? "" : "s"}, `
        + `and a verdict over problems needs at least ${cmp.min_problems} that both configurations ran. `
        + `Each problem's comparisons below answer for that problem alone; they say nothing about other problems.`));
      return panel;
    }
    const most = Math.max(...rows.map((r) => r.n_problems));
    panel.append(h("p", { class: "muted small" }, `Over ${most} problems: each problem is one observation — the difference of its means — `
        + "and the interval and test are over those differences (each problem's repetitions say how a configuration varies on that problem, not on others). "
        + "Problems favouring a / b count the problems whose difference favours each side; I² is how much the problems disagree beyond their own noise. "
        + "p-values are Holm-adjusted within each metric (Holm p)."),
    h("div", { class: "table-scroll" }, comparisonTable(rows, true, { id: "compare-pooled" })));
    return panel;
  }

  perProblem(cmp) {
    const panel = h("div", { class: "panel", id: "compare-differences" }, h("h2", {}, "Per problem"),
      h("p", { class: "muted small" }, "On each problem, a − b per pair and mode: the success rate's difference with Fisher's exact test (over the counted runs), each metric's difference of means over the completed runs with a studentized bootstrap 95% interval, paired by repetition when both ran the same repetitions with the same seed (paired t), else Welch's t; identical repetitions count once. Holm p: adjusted within each metric's per-problem comparisons."));
    for (const problem of cmp.problems) {
      const rows = cmp.rows.filter((r) => r.problem === problem);
      const section = h("section", { class: "compare-problem", dataset: { problem } }, h("h3", {}, `On ${problem}`));
      section.append(rows.length ? h("div", { class: "table-scroll" }, comparisonTable(rows, false, { "data-problem": problem }))
        : h("p", { class: "muted" }, "No two configurations both ran this problem: nothing to compare on it."));
      panel.append(section);
    }
    return panel;
  }
}
