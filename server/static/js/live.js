// The field page: the 3.6 m field with its four sub-fields, blocks, robots, traces and
// planned paths; tables of sub-field states, the queue and the simulation pool.

import { $, TERMINAL, badge, duration, h } from "./dom.js";
import { plannerName } from "./experiments.js";
import { COLORS, MapView } from "./fieldmap.js";
import { robotColor } from "./fleet.js";
import { obstacleLayers, trackedLayers } from "./moving.js";
import { FIELD_SIZE } from "./store.js";

export class FieldPage {
  constructor(store) {
    this.store = store;
    this.map = new MapView($("#field-canvas"), { world: FIELD_SIZE });
    this.onField = () => this.drawSoon();
    this.onExperiments = () => this.renderQueue();
    store.addEventListener("field", this.onField);
    store.addEventListener("experiments", this.onExperiments);
    this.tableFrame = 0;
  }

  show() {
    this.draw();
    this.renderQueue();
  }

  drawSoon() {
    this.map.update(this.layers());
    if (this.tableFrame) return;
    this.tableFrame = requestAnimationFrame(() => {
      this.tableFrame = 0;
      this.renderTables();
    });
  }

  draw() {
    this.map.update(this.layers());
    this.renderTables();
  }

  /**
   * The state a sub-field shows.  The server's sub-field states are coarser than a run's and lag it: a
   * sub-field stays "building" (or "idle" until the gripper starts) while its run is placing or
   * planning, and "running" until its ended run has been stored.  The queue and the experiment page
   * show the run's status.  So while a run the dashboard knows is on the sub-field, its status is
   * shown (building, placing, planning, running, analyzing), and "idle" once it has ended and the
   * sub-field is being released; otherwise (another user's run, none) the sub-field's own state.
   */
  shownState(sf) {
    const run = this.knownRun(sf);
    if (!run) return sf.state;
    if (!TERMINAL.has(run.status)) return run.status;
    return sf.run_id === run.id ? "idle" : sf.state;
  }

  /** The run under way on sub-field `sf` that the dashboard knows (the gripper's or the robot's), if any. */
  activeRun(sf) {
    const run = this.knownRun(sf);
    return run && !TERMINAL.has(run.status) ? run : null;
  }

  /** The latest run the dashboard knows on sub-field `sf` (past its queue), ended or not. */
  knownRun(sf) {
    if (sf.state === "offline") return null;
    const runId = sf.run_id ?? this.store.subfieldRun.get(sf.id);
    const run = runId != null ? this.store.runs.get(runId) : null;
    return run && run.subfield === sf.id && run.status !== "queued" ? run : null;
  }

  layers() {
    const st = this.store;
    const subfields = st.subfields.map((sf) => ({
      origin: sf.origin, size: sf.size, state: this.shownState(sf),
      label: `${sf.id} · ${this.shownState(sf)}${sf.environment ? ` · ${sf.environment}` : ""}`,
    }));
    const blocks = [];
    const fullDone = new Set();
    for (const sf of st.subfields) {
      const run = sf.run_id != null ? st.runs.get(sf.run_id) : null;
      const d = run && st.details.get(run.experiment_id);
      if (sf.state === "building" && d && this.rebuilding(sf, d)) continue; // the gripper is replacing it
      const env = st.env(sf.environment);
      if (!env) continue;
      const full = / \(full\)$/.test(sf.environment);
      if (full && fullDone.has(env.name)) continue;
      if (full) fullDone.add(env.name);
      const [ox, oy] = full ? [0, 0] : sf.origin;
      for (const b of env.blocks) blocks.push({ ...b, x: b.x + ox, y: b.y + oy });
    }
    const plannedBlocks = [];
    const paths = [];
    const markers = [];
    const fleet = []; // the robots of multi-robot runs
    const obstacles = [];
    const obstacleTracks = [];
    const tracked = []; // runs whose obstacles are drawn as the tracker saw them, and as exact
    const exact = [];
    const seenRuns = new Set();
    for (const sf of st.subfields) {
      const runId = st.subfieldRun.get(sf.id);
      if (runId == null || seenRuns.has(runId)) continue;
      seenRuns.add(runId);
      const run = st.runs.get(runId);
      const trace = st.traces.get(runId);
      const active = sf.run_id === runId;
      if (trace) paths.push({ points: trace.points, color: COLORS.twb, width: 2, alpha: active ? 1 : 0.55 });
      // a multi-robot run: every robot's trace and where it is, in its colour
      (trace?.robots || []).forEach((r, k) => {
        if (!r) return;
        paths.push({ points: r.points, color: robotColor(k), width: 2, alpha: active ? 1 : 0.55 });
        if (r.last) fleet.push({ ...r.last, radius: 0.04, color: robotColor(k), label: `${trace.robot_id}/${k}` });
      });
      const d = run && st.details.get(run.experiment_id);
      const env = d && st.env(d.environment);
      if (trace?.obstacles && trace.t1 != null) {
        // a stored field run's obstacle robots where the tracker saw them at its last pose shown
        const o = trackedLayers(trace.obstacles, trace.t1);
        obstacles.push(...o.obstacles);
        obstacleTracks.push(...o.obstacleTracks);
        tracked.push(runId);
      } else if (env?.moving_tracks?.length && trace && trace.t1 != null) {
        // the moving obstacles on their exact tracks where they were at the last pose shown (their clock
        // starts with the path)
        const [ox, oy] = d.field === "full" ? [0, 0] : sf.origin;
        const t = trace.t1 - (trace.robots ? 0 : (run?.t_start ?? trace.t0 ?? trace.t1));
        const shifted = env.moving_tracks.map((tr) => ({ ...tr, waypoints: tr.waypoints.map(([x, y]) => [x + ox, y + oy]) }));
        const o = obstacleLayers(shifted, t);
        obstacles.push(...o.obstacles);
        obstacleTracks.push(...o.obstacleTracks);
        exact.push(runId);
      }
      if (d && active && run.robot_id && d.robots) {
        const [ox, oy] = st.originOf(run.robot_id);
        (d.planning_info?.robots || []).forEach((r, k) => r.path && paths.push({
          points: r.path.map(([x, y]) => [x + ox, y + oy]), color: robotColor(k), width: 1.5, dash: [7, 5], alpha: 0.7 }));
      } else if (d && active && run.robot_id) {
        const [ox, oy] = st.originOf(run.robot_id);
        if (sf.state === "building" && this.rebuilding(sf, d)) {
          const target = st.env(d.environment);
          for (const b of target ? target.blocks : []) plannedBlocks.push({ ...b, x: b.x + ox, y: b.y + oy });
        }
        if (d.planned_path) {
          paths.push({ points: d.planned_path.map(([x, y]) => [x + ox, y + oy]), color: COLORS.planned, width: 2, dash: [7, 5] });
        }
        markers.push({ x: d.start[0] + ox, y: d.start[1] + oy, theta: d.start[2], color: COLORS.start });
        markers.push({ x: d.goal[0] + ox, y: d.goal[1] + oy, theta: d.goal[2], color: COLORS.goal });
      }
    }
    const robots = [];
    const unknown = []; // field robots the testbed has not seen since it started: not drawn
    for (const r of st.robots) {
      if (r.pool !== "field") continue;
      const p = st.poses.get(r.robot_id);
      if (!p) unknown.push(r.robot_id + (r.status === "offline" ? " (offline)" : ""));
      else robots.push({ x: p.x, y: p.y, theta: p.theta, label: r.robot_id, ghost: r.status === "offline" });
    }
    robots.push(...fleet);
    this.describe(robots, unknown);
    this.sayObstacles(tracked, exact);
    return { subfields, blocks, plannedBlocks, paths, markers, robots, obstacles, obstacleTracks };
  }

  /** The legend's line on moving obstacles: whose are drawn as the tracker saw them, whose on exact tracks. */
  sayObstacles(tracked, exact) {
    const item = $("#legend-obstacle");
    const runs = (ids) => `run${ids.length > 1 ? "s" : ""} ${ids.join(", ")}`;
    const parts = [];
    if (tracked.length) parts.push(`as tracked (solid; ${runs(tracked)})`);
    if (exact.length) parts.push(`on exact tracks (dotted; ${runs(exact)})`);
    const text = `moving obstacle, ${parts.join("; ")}`;
    item.hidden = parts.length === 0;
    const label = item.querySelector(".text");
    if (label.textContent !== text) label.textContent = text;
  }

  /** Whether the gripper is building another environment than the one the sub-field reports. */
  rebuilding(sf, d) {
    const want = d.field === "full" ? `${d.environment} (full)` : d.environment;
    return sf.environment !== want;
  }

  /** The canvas's text alternative: what a sighted user sees on it. */
  describe(robots, unknown) {
    const parts = this.store.subfields.map((sf) => `sub-field ${sf.id} ${this.shownState(sf)}${sf.environment ? ` with ${sf.environment}` : ""}`);
    const rs = robots.map((r) => `${r.label} at (${r.x.toFixed(2)}, ${r.y.toFixed(2)}) m heading ${Math.round((r.theta * 180) / Math.PI)}°`);
    if (unknown.length) rs.push(`${unknown.join(", ")} where unknown`);
    const text = `Field 3.6 by 3.6 m: ${parts.join("; ")}. Robots: ${rs.join("; ") || "none known"}.`;
    const c = this.map.canvas;
    if (c.getAttribute("aria-label") !== text) c.setAttribute("aria-label", text);
  }

  renderTables() {
    const st = this.store;
    const body = $("#subfield-table tbody");
    body.replaceChildren(...st.subfields.map((sf) => {
      const runId = sf.run_id ?? this.activeRun(sf)?.id;
      const run = runId != null ? st.runs.get(runId) : null;
      const runCell = runId == null ? "–"
        : run ? h("a", { href: `#/experiments/${run.experiment_id}` }, `run ${runId}`) : `run ${runId}`;
      const state = this.shownState(sf);
      return h("tr", { dataset: { subfield: sf.id, state } },
        h("td", {}, sf.id), h("td", {}, badge(state)), h("td", {}, sf.environment || "–"),
        h("td", {}, sf.robot_id || "–"), h("td", {}, runCell));
    }));
    const pool = st.robots.filter((r) => r.pool !== "field");
    $("#pool-list").replaceChildren(...pool.map((r) => h("li", { title: `${r.backend} robot, ${r.profile}` }, `${r.robot_id}: ${r.status}`)));
  }

  renderQueue() {
    const exps = this.store.experiments.filter((e) => !TERMINAL.has(e.status))
      .sort((a, b) => (a.status === "queued") - (b.status === "queued") || a.id - b.id);
    $("#queue-table tbody").replaceChildren(...exps.map((e) => h("tr", {},
      h("td", {}, h("a", { href: `#/experiments/${e.id}` }, `#${e.id} ${e.environment}`), " ",
        h("span", { class: "muted small" }, `${plannerName(e, this.store.programs)} · ${e.owner}`)),
      h("td", {}, badge(e.status)),
      h("td", {}, e.status === "queued" ? duration(e.estimated_start_s) : "started"))));
    $("#queue-table").hidden = exps.length === 0;
    $("#queue-empty").hidden = exps.length > 0;
  }
}
