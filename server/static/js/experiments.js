// The experiment list (queued with estimated start, running, finished; tick finished ones and
// "Compare selected" opens compare.js) and the page of one experiment: facts, the uploaded program's
// execution and log (programrun.js), planned vs performed paths (a failed run up to where it stopped,
// with a ✕), sim-vs-twb charts, metrics tables, downloads.

import { saveBlob } from "./api.js";
import { barChart, lineChart, speedProfile } from "./charts.js";
import { $, TERMINAL, badge, debounce, duration, h, num, pose, report, toast, when } from "./dom.js";
import { COLORS, MapView } from "./fieldmap.js";
import { byRobot, fleetLayers, robotColor, robotsTable } from "./fleet.js";
import { obstacleLayers, trackedLayers } from "./moving.js";
import { METRICS, allEqual, clipNote, intervalText, metricLabel, showIfClipped } from "./metrics.js";
import { ProgramPanel } from "./programrun.js";
import { FIELD_SIZE, SUBFIELD_SIZE } from "./store.js";

const MODE_COLOR = { sim: COLORS.sim, twb: COLORS.twb };
const MODE_NAME = { sim: "sim (simulation)", twb: "twb (field)" };
/** The crash marker: a ✕ where a failed run stopped (its `stopped_at`). */
export const CRASH_COLOR = "#d81b60";
const CRASH_SIZE = 0.035; // m, half the ✕'s width

/** Two strokes of a ✕ centred on (x, y), as map paths. */
function crossPaths(x, y, color = CRASH_COLOR) {
  const r = CRASH_SIZE;
  return [[[x - r, y - r], [x + r, y + r]], [[x - r, y + r], [x + r, y - r]]]
    .map((points) => ({ points, color, width: 3.2 }));
}

/** What planned the job: a planner, an uploaded program (named when `programs`, id -> program, knows it), or an explicit path. */
export function plannerName(e, programs = null) {
  if (e.planner) return e.planner;
  if (e.program == null) return "explicit path";
  const p = programs?.get(e.program);
  return p ? `program ${p.name} (#${e.program})` : `uploaded program #${e.program}`;
}

async function cancel(store, id) {
  try {
    await store.api.post(`/api/v1/experiments/${id}/cancel`);
    toast(`Experiment ${id} cancelled`);
    store.refreshExperiments();
  } catch (err) {
    report(err, `Cancel ${id}`);
  }
}

export class ExperimentsPage {
  constructor(store) {
    this.store = store;
    this.selected = new Set(); // experiment ids ticked for comparison
    store.addEventListener("experiments", () => { if (this.visible) this.render(); });
    $("#compare-button").addEventListener("click", () => {
      if (this.selected.size >= 2) location.hash = `#/compare?ids=${[...this.selected].sort((a, b) => a - b).join(",")}`;
    });
  }

  updateCompare() {
    const n = this.selected.size;
    const button = $("#compare-button");
    button.disabled = n < 2;
    button.textContent = n ? `Compare selected (${n})` : "Compare selected";
    $("#compare-hint").textContent = n >= 2 ? "Outcomes, metric means and the comparisons, per problem and over problems."
      : "Tick two or more experiments to compare them side by side.";
  }

  show() {
    this.visible = true;
    this.render();
  }

  hide() {
    this.visible = false;
  }

  render() {
    const all = this.store.experiments;
    const queued = all.filter((e) => e.status === "queued").sort((a, b) => a.id - b.id);
    const running = all.filter((e) => e.status !== "queued" && !TERMINAL.has(e.status));
    const finished = all.filter((e) => TERMINAL.has(e.status));
    this.table($("#exp-queued"), queued, "Estimated start", (e) => duration(e.estimated_start_s), true);
    this.table($("#exp-running"), running, "Started", (e) => when(e.started_at || e.created_at), true);
    for (const id of [...this.selected]) if (!finished.some((e) => e.id === id)) this.selected.delete(id);
    this.table($("#exp-finished"), finished, "Finished", (e) => when(e.finished_at), false, true);
    this.updateCompare();
    const more = this.store.experimentCount - all.length;
    $("#exp-more").textContent = more > 0 ? `The ${all.length} newest of ${this.store.experimentCount} experiments are listed.` : "";
  }

  table(el, rows, lastTitle, last, cancellable, selectable = false) {
    const head = h("thead", {}, h("tr", {}, [...(selectable ? ["Compare"] : []), "ID", "Status", "Environment", "Planner", "Modes", "Reps",
      "Field", "Owner", "Submitted", lastTitle, cancellable ? "Action" : "Error"].map((t) => h("th", { scope: "col" }, t))));
    const pick = (e) => h("td", {}, h("input", { type: "checkbox", class: "compare-pick", checked: this.selected.has(e.id),
      "aria-label": `Compare experiment ${e.id}`, onchange: (ev) => {
        if (ev.target.checked) this.selected.add(e.id); else this.selected.delete(e.id);
        this.updateCompare();
      } }));
    const body = h("tbody", {}, rows.length ? rows.map((e) => h("tr", { dataset: { experiment: e.id } },
      selectable ? pick(e) : null,
      h("td", {}, h("a", { href: `#/experiments/${e.id}` }, `#${e.id}`)),
      h("td", {}, badge(e.status)),
      h("td", { class: "name" }, e.environment),
      h("td", { class: "name" }, plannerName(e, this.store.programs)),
      h("td", {}, e.modes.join(" + ")),
      h("td", { class: "num" }, e.repetitions),
      h("td", {}, e.field),
      h("td", { class: "name" }, e.owner),
      h("td", { class: "when" }, when(e.created_at)),
      h("td", { class: "when" }, last(e)),
      cancellable ? h("td", {}, h("button", { type: "button", class: "small", onclick: () => cancel(this.store, e.id),
        "aria-label": `Cancel experiment ${e.id}` }, "Cancel")) : h("td", { class: "reason" }, e.error || ""),
    )) : h("tr", { class: "empty-row" }, h("td", { colspan: selectable ? 12 : 11 }, "None")));
    el.replaceChildren(head, body);
  }
}

const RUN_COLUMNS = [
  ["length_m", "Length (m)"],
  ["execution_time_s", "Time (s)"],
  ["average_speed_m_s", "Speed (m/s)"],
  ["deviation_mean_m", "Dev. mean (m)"],
  ["deviation_max_m", "Dev. max (m)"],
  ["smoothness_rad", "κ' (rad)"],
  ["clearance_min_m", "Clear. min (m)"],
  ["length_ratio", "Length ratio"],
  ["goal_reached", "Goal"],
  ["collided", "Collided"],
];

/** A multi-robot run's columns: the fleet's metrics (docs/metrics.md "Several robots"). */
const FLEET_COLUMNS = [
  ["success_rate", "Arrived"],
  ["makespan_s", "Makespan (s)"],
  ["time_sum_s", "Time sum (s)"],
  ["path_length_sum_m", "Length sum (m)"],
  ["robot_distance_min_m", "Closest (m)"],
  ["safety_time_s", "Too close (s)"],
  ["collisions_robot", "Robot hits"],
  ["collisions_moving", "Obstacle hits"],
  ["collisions_static", "Block hits"],
  ["deadlock", "Deadlock"],
];

/** A run's planning in words (the runs table's tooltip): wall and CPU time, the median of k calls, the load, the seed. */
function planningTitle(r) {
  if (r.planning_time_s == null) return r.planner_seed == null ? "" : `planner seed ${r.planner_seed}`;
  const parts = [`wall ${num(r.planning_time_s * 1000, 2)} ms`];
  if (r.planning_cpu_s != null) parts.push(`CPU ${num(r.planning_cpu_s * 1000, 2)} ms`);
  if ((r.planning_repeats || 1) > 1) parts.push(`median of ${r.planning_repeats} calls`);
  if (r.planning_load != null) parts.push(`load ${num(r.planning_load, 2)} per CPU`);
  if (r.planner_seed != null) parts.push(`planner seed ${r.planner_seed}`);
  return `Planning of its repetition: ${parts.join(", ")}`;
}

/** How its runs' clocks ran: "lockstep at time scale 5x" (per run when they differ), or "not recorded". */
function clockText(d) {
  const seen = new Map();
  for (const r of d.runs) {
    if (r.clock == null) continue;
    const k = `${r.clock} at time scale ${r.time_scale == null ? "max" : `${r.time_scale}x`}`;
    if (!seen.has(k)) seen.set(k, []);
    seen.get(k).push(r.id);
  }
  if (!seen.size) return "not recorded";
  if (seen.size === 1) return [...seen.keys()][0];
  return [...seen].map(([k, ids]) => `${k} (runs ${ids.join(", ")})`).join("; ");
}

/** The experiment's planning time: its runs' range (each repetition is timed), else repetition 1's. */
function planningRange(d) {
  const ts = d.runs.map((r) => r.planning_time_s).filter((t) => t != null);
  if (!ts.length) return d.planning_time_s == null ? "–" : `${num(d.planning_time_s * 1000, 1)} ms`;
  const lo = Math.min(...ts), hi = Math.max(...ts);
  return lo === hi ? `${num(lo * 1000, 1)} ms` : `${num(lo * 1000, 1)}–${num(hi * 1000, 1)} ms (per repetition, see the runs)`;
}

/** The charted metrics: [key, whether the planned path's value is drawn as a reference]. */
const CHARTS = [["length_m", true], ["execution_time_s", false], ["average_speed_m_s", false], ["deviation_mean_m", false],
  ["smoothness_rad", true], ["clearance_min_m", true]];
const FLEET_CHARTS = [["success_rate", false], ["makespan_s", false], ["time_sum_s", false], ["path_length_sum_m", false],
  ["robot_distance_min_m", false], ["safety_time_s", false]];

export class ExperimentPage {
  constructor(store) {
    this.store = store;
    this.root = $("#view-experiment");
    this.id = null;
    this.reload = debounce(() => this.load().catch((err) => report(err, "Experiment")), 350);
    store.addEventListener("experiment", (e) => { if (this.id !== null && e.detail === this.id) this.reload(); });
    store.addEventListener("pose", (e) => this.onPose(e.detail));
  }

  hide() {
    this.id = null;
  }

  async show(id) {
    if (this.id !== id) {
      this.id = id;
      this.poses = new Map(); // run id -> logged poses
      this.obstacles = new Map(); // field run id -> its stored obstacle robots [{radius, poses}], or null (none)
      this.live = new Map(); // run id -> live points (experiment frame)
      this.hidden = new Set();
      this.data = null;
      this.legendKey = null;
      this.program = new ProgramPanel(this.store);
      this.skeleton(id);
    }
    try {
      await this.load();
    } catch (err) {
      if (err.status === 404) this.root.replaceChildren(h("div", { class: "panel" }, h("h1", {}, `Experiment ${id}`),
        h("p", { class: "error" }, "Experiment not found (it does not exist or is not yours)."),
        h("a", { href: "#/experiments" }, "All experiments")));
      else report(err, "Experiment");
    }
  }

  skeleton(id) {
    this.els = {
      title: h("h1", { id: "experiment-title" }, `Experiment #${id}`),
      status: h("span", { role: "status" }),
      actions: h("span", {}),
      facts: h("dl", { class: "facts" }),
      error: h("p", { class: "error", role: "alert" }),
      canvas: h("canvas", { id: "experiment-canvas", tabindex: 0, role: "img", "aria-label": "Planned and performed paths" }),
      legend: h("div", { class: "legend", role: "group", "aria-label": "Paths shown" }),
      obstacleNote: h("p", { class: "muted small", id: "obstacle-note", hidden: true }),
      charts: h("div", { class: "charts", id: "experiment-charts" }),
      speed: h("div", { class: "wide-chart" }),
      runs: h("table", { class: "grid dense", id: "runs-table" }),
      robots: h("table", { class: "grid dense", id: "robots-table" }),
      aggregates: h("table", { class: "grid", id: "aggregates-table" }),
      aggNote: clipNote("aggregates-note"),
      direct: h("table", { class: "grid", id: "direct-table" }),
      downloads: h("div", { class: "downloads" }),
    };
    const e = this.els;
    this.root.replaceChildren(
      h("div", { class: "exp-head" }, e.title, e.status, e.actions, h("a", { href: "#/experiments" }, "All experiments")),
      h("div", { class: "panel" }, e.facts, e.error),
      this.program.el,
      h("div", { class: "exp-grid" },
        h("div", { class: "panel" }, h("h2", {}, "Planned vs performed paths"),
          h("div", { class: "canvas-box square" }, e.canvas), e.legend, e.obstacleNote),
        h("div", { class: "panel" }, h("h2", {}, "Simulation vs field"),
          h("p", { class: "muted small" }, "Bars: mean per mode; whiskers: 95% confidence interval; dots: runs; dashed green: the planned path."),
          e.charts, e.speed)),
      h("div", { class: "panel" }, h("h2", {}, "Runs"), h("div", { class: "table-scroll" }, e.runs)),
      e.robotsPanel = h("div", { class: "panel", hidden: true }, h("h2", {}, "Robots of each run"),
        h("div", { class: "table-scroll" }, e.robots)),
      h("div", { class: "panel" }, h("h2", {}, "Aggregates per mode"), h("div", { class: "table-scroll" }, e.aggregates), e.aggNote),
      h("div", { class: "panel" }, h("h2", {}, "Direct comparison, sim vs field per repetition"),
        h("div", { class: "table-scroll" }, e.direct)),
      h("div", { class: "panel" }, h("h2", {}, "Downloads"), e.downloads),
    );
    this.map?.destroy();
    this.map = new MapView(e.canvas, { world: SUBFIELD_SIZE });
  }

  async load() {
    const id = this.id;
    if (id === null) return;
    const api = this.store.api;
    const [d, m] = await Promise.all([this.store.detail(id, { fresh: true }), api.get(`/api/v1/experiments/${id}/metrics`)]);
    if (id !== this.id) return;
    const want = d.runs.filter((r) => r.t_start != null && TERMINAL.has(r.status) && !this.poses.has(r.id)).slice(0, 40);
    const moving = (await this.store.envAsync(d.environment))?.moving_tracks?.length;
    const field = moving ? d.runs.filter((r) => r.mode === "twb" && r.t_start != null && TERMINAL.has(r.status)
      && !this.obstacles.has(r.id)).slice(0, 40) : [];
    await Promise.all([...want.map((r) => api.get(`/api/v1/runs/${r.id}/poses`).then((p) => this.poses.set(r.id, p.poses))),
      ...field.map((r) => api.get(`/api/v1/runs/${r.id}/obstacles`).then((o) => this.obstacles.set(r.id, o.exact ? null : o.obstacles))),
      this.program.load(d)]);
    if (id !== this.id) return;
    this.data = { d, m };
    this.render();
  }

  onPose(ev) {
    if (this.id === null || !this.data || ev.run_id == null || ev.robot != null) return; // a fleet's: drawn when stored
    const run = this.data.d.runs.find((r) => r.id === ev.run_id);
    if (!run || this.poses.has(run.id)) return;
    const [ox, oy] = this.store.originOf(ev.robot_id);
    if (!this.live.has(run.id)) this.live.set(run.id, []);
    this.live.get(run.id).push([ev.x - ox, ev.y - oy]);
    this.drawMap();
  }

  render() {
    const { d, m } = this.data;
    const e = this.els;
    e.status.replaceChildren(badge(d.status));
    e.actions.replaceChildren(TERMINAL.has(d.status) ? "" :
      h("button", { type: "button", onclick: () => cancel(this.store, d.id) }, "Cancel experiment"));
    const facts = [
      ["Environment", d.environment], ["Field", d.field], ["Planner", plannerName(d, this.store.programs)],
      ["Parameters", d.program != null ? "see the program below" : Object.keys(d.planner_params || {}).length ? JSON.stringify(d.planner_params) : "defaults"],
      ["Controller", (d.controller || "schema") + (Object.keys(d.controller_params || {}).length ? ` ${JSON.stringify(d.controller_params)}` : "")],
      ...(d.robots ? [["Robots", `${d.robots.length}, each its colour on the map`]]
        : [["Start (x, y, θ)", pose(d.start)], ["Goal (x, y, θ)", pose(d.goal)]]),
      ["Modes", d.modes.join(" + ")],
      ["Repetitions", d.repetitions], ["Seed", d.seed],
      ["Planner seed", d.planner_seed == null ? "the seed (each repetition's derives from it)" : `${d.planner_seed} (each repetition's derives from it)`],
      ["Plans", d.planner_stochastic ? "one per repetition: a randomised planner, each repetition its own draw (both modes drive it)"
        : "one path for every run (timed again per repetition)"],
      ["Owner", d.owner],
      ["Submitted", when(d.created_at)], ["Finished", when(d.finished_at)],
      ["Planning time", planningRange(d)],
      ["Clock", clockText(d)],
      ["Robot radius + margin", `${num(d.robot_radius, 3)} + ${num(d.planning_margin, 3)} m`],
    ];
    if (d.status === "queued") facts.push(["Estimated start", duration(d.estimated_start_s)]);
    e.facts.replaceChildren(...facts.map(([k, v]) => h("div", {}, h("dt", {}, k), h("dd", {}, v))));
    e.error.textContent = d.error || "";
    this.program.render(d);
    this.map.setWorld(d.field === "full" ? FIELD_SIZE : SUBFIELD_SIZE);
    const legendKey = d.runs.map((r) => r.id).join(",");
    if (legendKey !== this.legendKey) {
      // rebuilt only when the runs change, so keyboard focus on a toggle survives live updates
      this.legendKey = legendKey;
      this.renderLegend();
    }
    this.drawMap();
    this.renderRuns(d, m);
    this.renderAggregates(m, d);
    this.renderDirect(m);
    this.renderCharts(d, m);
    this.renderDownloads(d);
  }

  runs() {
    return [...this.data.d.runs].sort((a, b) => a.mode.localeCompare(b.mode) || a.repetition - b.repetition || a.id - b.id);
  }

  renderLegend() {
    const items = [{ key: "planned", label: "planned", cls: "planned" },
      ...this.runs().map((r) => ({ key: `run-${r.id}`, cls: r.mode,
        label: `${r.mode} #${r.repetition} (run ${r.id})${r.status === "failed" ? ` ✕ ${r.failure || "failed"}` : ""}` }))];
    this.els.legend.replaceChildren(...items.map((it) => h("label", { class: "check" },
      h("input", { type: "checkbox", checked: !this.hidden.has(it.key), onchange: (ev) => {
        if (ev.target.checked) this.hidden.delete(it.key); else this.hidden.add(it.key);
        this.drawMap();
      } }), h("span", { class: `swatch ${it.cls}` }), it.label)));
  }

  drawMap() {
    if (!this.data) return;
    const { d } = this.data;
    const env = this.store.env(d.environment);
    if (!env) this.store.envAsync(d.environment).then(() => this.drawMap()).catch(() => {});
    const runs = this.runs();
    if (d.robots) {
      const fleet = fleetLayers(d, runs, this.poses, this.hidden);
      this.map.update({ blocks: env ? env.blocks : [], ...this.movingLayers(env, runs), ...fleet });
      return;
    }
    const paths = [];
    for (const r of runs) {
      if (this.hidden.has(`run-${r.id}`)) continue;
      const logged = this.poses.get(r.id);
      const pts = logged ? logged.map((p) => [p[1], p[2]]) : this.live.get(r.id);
      if (pts) paths.push({ points: pts, color: MODE_COLOR[r.mode] || "#555", width: 1.8, alpha: runs.length > 4 ? 0.6 : 0.9 });
    }
    // failed runs: a ✕ where each stopped, drawn over the paths
    const crashes = runs.filter((r) => r.status === "failed" && !this.hidden.has(`run-${r.id}`)).flatMap((r) => {
      const logged = this.poses.get(r.id);
      const at = r.stopped_at || (logged && logged.length ? [logged[logged.length - 1][1], logged[logged.length - 1][2]] : null);
      return at ? crossPaths(at[0], at[1]) : [];
    });
    if (!this.hidden.has("planned")) {
      // each shown run's own planned path (its repetition's; a deterministic planner's are one path, drawn once)
      const plans = new Map();
      for (const r of runs) {
        if (r.planned_path && !this.hidden.has(`run-${r.id}`)) plans.set(JSON.stringify(r.planned_path), r.planned_path);
      }
      if (!plans.size && d.planned_path) plans.set("", d.planned_path);
      for (const pp of plans.values()) {
        paths.push({ points: pp.map((p) => [p[0], p[1]]), color: COLORS.planned, width: plans.size > 1 ? 1.6 : 2.2, dash: [7, 5] });
      }
    }
    paths.push(...crashes);
    this.map.update({
      blocks: env ? env.blocks : [],
      ...this.movingLayers(env, runs),
      paths,
      markers: [{ x: d.start[0], y: d.start[1], theta: d.start[2], color: COLORS.start, label: "start" },
        { x: d.goal[0], y: d.goal[1], theta: d.goal[2], color: COLORS.goal, label: "goal" }],
    });
  }

  /**
   * The moving obstacles' map layers: their exact tracks dotted, and where they stand when a path starts; each
   * shown field run's stored obstacle robots as the tracker saw them, their tracks solid and each where it was
   * when its run ended (then the exact discs only while a shown run has none stored).  The note under the
   * legend says which is which.
   */
  movingLayers(env, runs) {
    const exact = obstacleLayers(env?.moving_tracks, 0);
    const note = this.els.obstacleNote;
    note.hidden = !exact.obstacleTracks.length;
    if (note.hidden) return exact;
    const shown = runs.filter((r) => !this.hidden.has(`run-${r.id}`));
    const tracked = shown.filter((r) => this.obstacles.get(r.id));
    const discs = tracked.length < shown.length || !shown.length; // a shown run's obstacles are the exact ones
    const layers = { obstacleTracks: [...exact.obstacleTracks], obstacles: discs ? exact.obstacles : [] };
    for (const r of tracked) {
      const o = trackedLayers(this.obstacles.get(r.id), r.t_end ?? Infinity);
      layers.obstacleTracks.push(...o.obstacleTracks);
      layers.obstacles.push(...o.obstacles);
    }
    const ids = tracked.map((r) => r.id).join(", ");
    note.textContent = `Moving obstacles: dotted, their exact tracks${discs ? ", each disc where it stands when a path starts" : ""}`
      + (ids ? `; solid, the obstacle robots of field run${tracked.length > 1 ? "s" : ""} ${ids} as the tracker saw them, each where it was when its run ended.` : ".");
    return layers;
  }

  renderRuns(d, m) {
    const columns = d.robots ? FLEET_COLUMNS : RUN_COLUMNS;
    const head = h("thead", {}, h("tr", {}, ["Run", "Mode #", "Status", "Robot", "Sub-field", ...columns.map(([, t]) => t),
      "Downloads"].map((t, i) => h("th", { scope: "col", class: i > 4 && i < 5 + columns.length ? "num" : null }, t))));
    const rows = this.runs().map((r) => {
      const mt = r.metrics || {};
      return h("tr", { dataset: { run: r.id, mode: r.mode, status: r.status } },
        h("td", {}, r.id), h("td", {}, `${r.mode} #${r.repetition}`), h("td", {}, badge(r.status),
          r.error ? h("div", { class: "muted small run-error" }, r.error) : "",
          r.stopped_at ? h("div", { class: "muted small stopped" }, `✕ stopped at ${pose(r.stopped_at)}`) : "",
          // its repetition's planning time (the tooltip: wall and CPU, median of k, load, planner seed)
          r.planning_time_s == null ? "" : h("div", { class: "muted small planning", title: planningTitle(r),
            dataset: { metric: "planning_time_s" } }, `plan ${num(r.planning_time_s * 1000, 1)} ms`)),
        h("td", {}, r.robot_id || "–"), h("td", {}, r.subfield ?? "–"),
        ...columns.map(([k]) => h("td", { class: "num", dataset: { metric: k } }, num(mt[k]))),
        h("td", {}, r.t_start == null ? "–" : h("span", { class: "downloads" },
          this.dl(`/api/v1/runs/${r.id}/poses?format=csv`, `run-${r.id}-poses.csv`, "CSV", `Download poses of run ${r.id} as CSV`),
          this.dl(`/api/v1/runs/${r.id}/poses?format=json`, `run-${r.id}-poses.json`, "JSON", `Download poses of run ${r.id} as JSON`),
          this.dl(`/api/v1/runs/${r.id}/messages?limit=10000`, `run-${r.id}-messages.json`, "messages", `Download protocol messages of run ${r.id}`)),
          // for Foxglove and ROS 2 tools (docs/exports.md): on a line of their own, so the column stays narrow
          r.t_start == null ? "" : h("span", { class: "downloads exports" },
            this.dl(`/api/v1/runs/${r.id}/export?format=mcap`, `run-${r.id}.mcap`, "MCAP", `Download run ${r.id} as MCAP (Foxglove)`),
            this.dl(`/api/v1/runs/${r.id}/export?format=rosbag2`, `run-${r.id}.zip`, "ROS 2 bag", `Download run ${r.id} as a ROS 2 bag (zipped)`))));
    });
    if (m.planned) {
      rows.unshift(h("tr", { class: "planned-row" }, h("td", {}, "–"), h("td", {}, d.planner_stochastic ? "planned (rep. 1)" : "planned"), h("td", {}, ""),
        h("td", {}, ""), h("td", {}, ""), ...columns.map(([k]) => h("td", { class: "num" }, num(m.planned[k]))), h("td", {}, "")));
    }
    this.els.runs.replaceChildren(head, h("tbody", {}, rows));
    this.els.robotsPanel.hidden = !d.robots;
    if (d.robots) this.els.robots.replaceChildren(...robotsTable(this.runs()));
  }

  renderAggregates(m, d) {
    const modes = Object.keys(m.aggregates || {});
    if (!modes.length) {
      this.els.aggregates.replaceChildren(h("tbody", {}, h("tr", { class: "empty-row" }, h("td", {},
        TERMINAL.has(d.status) ? "No run completed: nothing to aggregate." : "No completed runs yet."))));
      return;
    }
    const keys = [...new Set(modes.flatMap((md) => Object.keys(m.aggregates[md].metrics)))];
    const head = h("thead", {}, h("tr", {}, h("th", { scope: "col" }, "Metric"),
      ...modes.flatMap((md) => [h("th", { scope: "col", class: "num" }, `${md} mean ± std`), h("th", { scope: "col", class: "num" }, `${md} 95% CI`),
        h("th", { scope: "col", class: "num" }, "n")])));
    const body = h("tbody", {}, keys.map((k) => h("tr", { dataset: { metric: k } }, h("th", { scope: "row", title: k }, metricLabel(k)),
      ...modes.flatMap((md) => {
        const a = m.aggregates[md].metrics[k] || {};
        // identical repetitions (the deterministic simulation): a zero-width interval would be a fake certainty
        const same = allEqual(a);
        // a spread below the mean's rounding is floating-point noise of equal values (e.g. 1.99e-12): shown as 0
        const std = Number.isFinite(a.std) && Math.abs(a.std) <= 1e-9 * Math.max(1, Math.abs(a.mean)) ? 0 : a.std;
        return [h("td", { class: "num" }, `${num(a.mean)} ± ${num(std)}`),
          h("td", { class: same ? "num said" : "num" }, same ? (md === "sim" && !d.jitter ? "identical repetitions (deterministic simulation)" : "all equal: no interval")
            : intervalText(k, a.ci_low, a.ci_high)),
          h("td", { class: "num" }, a.n ?? "–")];
      }))));
    this.els.aggregates.replaceChildren(head, body);
    showIfClipped(this.els.aggNote, this.els.aggregates);
  }

  renderDirect(m) {
    const rows = m.direct || [];
    const keys = ["deviation_mean_m", "deviation_max_m", "hausdorff_m", "frechet_m"];
    const head = h("thead", {}, h("tr", {}, ["Repetition", "sim run", "twb run", ...keys.map(metricLabel)].map((t, i) =>
      h("th", { scope: "col", class: i > 2 ? "num" : null, title: i > 2 ? keys[i - 3] : null }, t))));
    const body = h("tbody", {}, rows.length ? rows.map((r) => h("tr", {}, h("td", {}, r.repetition), h("td", {}, r.sim_run_id), h("td", {}, r.twb_run_id),
      ...keys.map((k) => h("td", { class: "num" }, num(r[k]))))) :
      h("tr", { class: "empty-row" }, h("td", { colspan: 7 }, this.data?.d.robots
        ? "Not for multi-robot jobs: compare their sim and twb runs by the fleet's metrics above."
        : "Needs a completed sim and twb run of the same repetition.")));
    this.els.direct.replaceChildren(head, body);
  }

  renderCharts(d, m) {
    const modes = d.modes;
    const done = (m.runs || []).filter((r) => r.status === "completed");
    // nothing to chart: one line instead of empty charts
    const charts = !done.length ? [h("p", { class: "empty-row" }, TERMINAL.has(d.status)
      ? "No run completed: no metrics to chart." : "Charts appear when the first run completes.")]
      : (d.robots ? FLEET_CHARTS : CHARTS).map(([key, withRef]) => {
      const [title, unit] = METRICS[key];
      const groups = modes.map((md) => ({
        // a mode whose runs all failed says so instead of showing an empty slot
        label: md,
        note: done.some((r) => r.mode === md) || !d.runs.some((r) => r.mode === md) ? "" : "none completed",
        color: MODE_COLOR[md],
        values: done.filter((r) => r.mode === md).map((r) => r.metrics[key]).filter((v) => typeof v === "number"),
        agg: m.aggregates?.[md]?.metrics?.[key] || null,
      }));
      const ref = withRef && m.planned && typeof m.planned[key] === "number" ? { value: m.planned[key], label: "planned" } : null;
      return h("figure", { dataset: { metric: key } }, h("figcaption", {}, `${title} (${unit})`), barChart({ title, unit, groups, ref }));
    });
    this.els.charts.replaceChildren(...charts);
    // a fleet's runs: one line per robot (its colour), each from its own poses
    const series = this.runs().filter((r) => this.poses.has(r.id)).flatMap((r) => (d.robots
      ? byRobot(this.poses.get(r.id)).map((track, k) => ({ label: `${r.mode} #${r.repetition} robot ${k}`, color: robotColor(k),
        alpha: r.mode === "sim" ? 0.5 : 0.85, mode: r.mode, points: speedProfile(track || [], r.t_start) }))
      : [{ label: `${r.mode} #${r.repetition}`, color: MODE_COLOR[r.mode], alpha: 0.85, mode: r.mode,
        points: speedProfile(this.poses.get(r.id), r.t_start) }]));
    this.els.speed.replaceChildren(series.length ? h("figure", {}, h("figcaption", { class: "small" }, "Speed over time (m/s against s since EV,START)"),
      lineChart({ title: "Speed over time", xLabel: "time since start (s)", yLabel: "speed (m/s)", series,
        legend: d.robots ? d.robots.map((_, k) => ({ label: `robot ${k}`, color: robotColor(k) }))
          : [...new Set(series.map((q) => q.mode))].map((md) => ({ label: MODE_NAME[md] || md, color: MODE_COLOR[md] })) })) : "");
  }

  dl(path, filename, label, aria) {
    return h("button", { type: "button", class: "small", "aria-label": aria, title: aria, onclick: () =>
      this.store.api.download(path, filename).catch((err) => report(err, "Download")) }, label);
  }

  renderDownloads(d) {
    const id = d.id;
    this.els.downloads.replaceChildren(
      this.dl(`/api/v1/experiments/${id}`, `experiment-${id}.json`, "Experiment (JSON)", "Download the experiment as JSON"),
      this.dl(`/api/v1/experiments/${id}/metrics`, `experiment-${id}-metrics.json`, "Metrics (JSON)", "Download the metrics as JSON"),
      this.dl(`/api/v1/experiments/${id}/export?format=mcap`, `experiment-${id}.mcap`, "All runs (MCAP)",
        "Download every run as one MCAP file (Foxglove)"),
      this.dl(`/api/v1/experiments/${id}/export?format=rosbag2`, `experiment-${id}.zip`, "All runs (ROS 2 bag)",
        "Download every run as one ROS 2 bag (zipped)"),
      h("button", { type: "button", class: "small", onclick: async () => {
        const blob = await this.map.toBlob();
        if (blob) saveBlob(blob, `experiment-${id}-paths.png`);
      } }, "Path figure (PNG)"),
      h("button", { type: "button", class: "small", onclick: () => this.saveCharts(id) }, "Charts (SVG)"),
      h("span", { class: "muted small" }, "Per-run poses, messages, MCAP and ROS 2 bags: in the runs table. A run's replay GIF: ",
        h("code", {}, `twb replay ${this.runs().find((r) => r.t_start != null)?.id ?? "RUN_ID"} -o run.gif`), " on your machine."),
    );
  }

  saveCharts(id) {
    const svgs = [...this.els.charts.querySelectorAll("svg"), ...this.els.speed.querySelectorAll("svg")];
    if (!svgs.length) return toast("No charts yet", true);
    // stack the charts into one SVG document
    let y = 0;
    const parts = svgs.map((svg) => {
      const [, , w, hgt] = svg.getAttribute("viewBox").split(" ").map(Number);
      const g = `<svg x="0" y="${y}" width="${w}" height="${hgt}" viewBox="0 0 ${w} ${hgt}">${svg.innerHTML}</svg>`;
      y += hgt + 10;
      return { g, w };
    });
    const width = Math.max(...parts.map((p) => p.w));
    const doc = `<?xml version="1.0" encoding="UTF-8"?>\n<svg xmlns="http://www.w3.org/2000/svg" width="${width}" height="${y}" ` +
      `font-family="sans-serif">${parts.map((p) => p.g).join("")}</svg>\n`;
    saveBlob(new Blob([doc], { type: "image/svg+xml" }), `experiment-${id}-charts.svg`);
  }
}
