// The dashboard's shared state: what the server said, kept fresh by the event stream
// (and by polling while the stream is down).  Views listen to its events:
//   "field"       sub-fields, robots, robot poses or traces changed
//   "experiments" the experiment list changed (or the names of the programs it uses arrived)
//   "experiment"  detail = experiment id whose runs or status changed
//   "pose"        detail = a raw pose event (field frame)
//   "stream"      detail = stream state
//   "unauthorized" the token stopped working

import { byRobot } from "./fleet.js";
import { EventStream } from "./api.js";
import { TERMINAL, report } from "./dom.js";

export const SUBFIELD_SIZE = [1.8, 1.8];
export const FIELD_SIZE = [3.6, 3.6];
const MAX_TRACE = 20000; // points of one live trace
const MAX_TRACES = 64;
const MAX_DETAILS = 200;

export class Store extends EventTarget {
  constructor(api) {
    super();
    this.api = api;
    this.user = null;
    this.subfields = [];
    this.robots = [];
    this.experiments = [];
    this.experimentCount = 0;
    this.envs = new Map(); // name -> environment (resolved)
    this.envPending = new Map(); // name -> Promise
    this.details = new Map(); // experiment id -> ExperimentPublic
    this.runs = new Map(); // run id -> RunPublic
    this.programs = new Map(); // program id -> ProgramPublic (names for the lists)
    // robot id -> {x, y, theta, t, run_id, source: live (an event) | log (its run's stored poses) | server (where
    // the testbed last saw it: /robots)}; a field robot the testbed has not seen since it started is absent
    this.poses = new Map();
    this.poseToldAt = new Map(); // robot id -> when a live pose event last told where it is (performance.now())
    // run id -> {robot_id, points: [[x, y]] field frame, exact, t0, t1 (s, first and last pose time seen);
    // a multi-robot run's: robots, one {points, last: {x, y, theta}} per robot; a stored field run's: obstacles,
    // its obstacle robots' tracks [{radius, poses}] field frame, or null}
    this.traces = new Map();
    this.subfieldRun = new Map(); // sub-field id -> its latest run since the testbed started (that the user may see)
    this.traceAsked = new Set(); // ended runs whose stored trace was asked for once (noteSubfieldRuns)
    // when an event last told a run's or a sub-field's state (performance.now()): an API answer asked for
    // before that is older than what the dashboard shows, and does not overwrite it
    this.runToldAt = new Map();
    this.subfieldToldAt = new Map();
    this.streamState = "stopped";
    this.timers = [];
    this.pending = new Map();
    this.stream = new EventStream(api, {
      onEvent: (type, data) => this.onEvent(type, data),
      onState: (state) => this.onStreamState(state),
    });
  }

  emit(topic, detail) {
    this.dispatchEvent(new CustomEvent(topic, { detail }));
  }

  start() {
    this.refreshExperiments();
    this.refreshField();
    this.stream.start();
    this.timers.push(setInterval(() => this.poll(), 2000));
  }

  stop() {
    this.stream.stop();
    this.timers.forEach(clearInterval);
    this.timers = [];
    for (const t of this.pending.values()) clearTimeout(t);
    this.pending.clear();
  }

  /** Run `fn` once, `ms` from now, however often this is called meanwhile. */
  later(key, ms, fn) {
    if (this.pending.has(key)) return;
    this.pending.set(key, setTimeout(() => {
      this.pending.delete(key);
      fn();
    }, ms));
  }

  onStreamState(state) {
    const was = this.streamState;
    this.streamState = state;
    this.emit("stream", state);
    if (state === "unauthorized") this.emit("unauthorized");
    if (state === "live" && was !== "connecting" && was !== "stopped") {
      // back after a gap: catch up on what the stream missed
      this.refreshField();
      this.refreshExperiments();
    }
  }

  poll() {
    this.tick = (this.tick || 0) + 1;
    const live = this.streamState === "live";
    if (live && this.tick % 8) return; // live: a safety refresh every 16 s
    this.refreshField();
    this.refreshExperiments();
    if (!live) {
      // no stream: follow running robots through their logged poses
      for (const sf of this.subfields) if (sf.run_id != null) this.loadTrace(sf.run_id).catch(() => {});
    }
  }

  // ------------------------------------------------------------------ loading

  async refreshField() {
    try {
      const asked = performance.now();
      const [subs, robots] = await Promise.all([this.api.get("/api/v1/subfields"), this.api.get("/api/v1/robots")]);
      this.subfields = subs.data.map((sf) => this.newer(this.subfieldToldAt, asked, sf, this.subfields.find((s) => s.id === sf.id)));
      this.robots = robots.data;
      this.placeRobots(asked);
      for (const sf of this.subfields) this.noteSubfieldRuns(sf);
      this.emit("field");
      await this.ensureRunning();
    } catch (err) {
      this.failed(err, "Field");
    }
  }

  async refreshExperiments() {
    try {
      const page = await this.api.get("/api/v1/experiments?limit=200");
      const before = new Map(this.experiments.map((e) => [e.id, e.status]));
      const first = this.experimentsLoaded !== true;
      this.experiments = page.data;
      this.experimentCount = page.count;
      this.experimentsLoaded = true;
      this.emit("experiments");
      this.learnPrograms();
      if (!first) {
        for (const e of page.data) {
          if (before.get(e.id) !== e.status && e.modes.includes("twb") && e.status !== "queued") this.followFieldRuns(e.id);
        }
      }
    } catch (err) {
      this.failed(err, "Experiments");
    }
  }

  /** Remember uploaded programs (their names label program jobs). */
  notePrograms(list) {
    for (const p of list) this.programs.set(p.id, p);
  }

  /** Read the program list when an experiment names a program not seen yet (at most every 10 s). */
  async learnPrograms() {
    if (!this.experiments.some((e) => e.program != null && !this.programs.has(e.program))) return;
    if (Date.now() - (this.programsAt || 0) < 10000) return;
    this.programsAt = Date.now();
    try {
      this.notePrograms((await this.api.get("/api/v1/programs?limit=500")).data);
      this.emit("experiments");
    } catch (err) {
      this.failed(err, "Programs");
    }
  }

  failed(err, what) {
    if (err && err.status === 401) this.emit("unauthorized");
    else if (err && err.status === 0) { /* server away: the stream state shows it */ }
    else report(err, what);
  }

  robot(id) {
    return this.robots.find((r) => r.robot_id === id);
  }

  isFieldRobot(id) {
    const r = this.robot(id);
    return r ? r.pool === "field" : /^field-/.test(id);
  }

  /** Offset from a run's (= its robot's) frame to field coordinates. */
  originOf(robotId) {
    const r = this.robot(robotId);
    return r ? r.origin : [0, 0];
  }

  env(name) {
    if (!name) return null;
    const clean = name.replace(/ \(full\)$/, "");
    if (this.envs.has(clean)) return this.envs.get(clean);
    if (!this.envPending.has(clean)) {
      const p = this.api.get(`/api/v1/environments/${encodeURIComponent(clean)}`)
        .then((e) => { this.envs.set(clean, e); this.emit("field"); return e; })
        .catch((err) => { this.envPending.delete(clean); this.failed(err, `Environment ${clean}`); return null; });
      this.envPending.set(clean, p);
    }
    return null;
  }

  async envAsync(name) {
    const e = this.env(name);
    return e || (await this.envPending.get(name.replace(/ \(full\)$/, "")));
  }

  /** An experiment's detail; finished ones are cached for good, others re-read when `fresh`. */
  async detail(id, { fresh = false } = {}) {
    const have = this.details.get(id);
    if (have && !fresh) return have;
    const asked = performance.now();
    const d = await this.api.get(`/api/v1/experiments/${id}`);
    d.runs = d.runs.map((r) => this.newer(this.runToldAt, asked, r, this.runs.get(r.id)));
    this.details.set(id, d);
    for (const r of d.runs) this.runs.set(r.id, r);
    return d;
  }

  async run(id) {
    if (this.runs.has(id)) return this.runs.get(id);
    const asked = performance.now();
    const r = this.newer(this.runToldAt, asked, await this.api.get(`/api/v1/runs/${id}`), this.runs.get(id));
    this.runs.set(id, r);
    return r;
  }

  /** `fetched` (asked for at `asked`), or `known` when an event told about it since (`toldAt`: id -> time). */
  newer(toldAt, asked, fetched, known) {
    return known && (toldAt.get(fetched.id) ?? -Infinity) > asked ? known : fetched;
  }

  /** Planned paths of what is running on the field. */
  async ensureRunning() {
    for (const sf of this.subfields) {
      if (sf.run_id == null) continue;
      try {
        const run = await this.run(sf.run_id);
        const d = this.details.get(run.experiment_id);
        if (!d || d.planned_path == null) {
          await this.detail(run.experiment_id, { fresh: true });
          this.emit("field");
        }
      } catch (err) {
        this.failed(err, "Running experiment");
      }
    }
  }

  /** Logged poses of a run as its trace (field frame); the robot's last pose from them; a field run's stored
   * obstacle robots as `obstacles` (`[{radius, poses}]`, field frame; null: none stored, the exact tracks hold). */
  async loadTrace(runId) {
    const run = await this.run(runId);
    if (!run.robot_id) return;
    const [res, obs] = await Promise.all([this.api.get(`/api/v1/runs/${runId}/poses`),
      run.mode === "twb" ? this.api.get(`/api/v1/runs/${runId}/obstacles`) : null]);
    const [ox, oy] = this.originOf(run.robot_id);
    const obstacles = obs && !obs.exact
      ? obs.obstacles.map((o) => ({ radius: o.radius, poses: o.poses.map(([t, x, y, a]) => [t, x + ox, y + oy, a]) })) : null;
    const times = { t0: res.poses[0]?.[0] ?? null, t1: res.poses[res.poses.length - 1]?.[0] ?? null };
    if ((res.columns || []).includes("robot")) {
      // a multi-robot run: its robots' paths and where each ended; the field robot itself did not move
      const robots = byRobot(res.poses).map((track) => ({
        points: (track || []).map(([, x, y]) => [x + ox, y + oy]),
        last: track?.length ? { x: track[track.length - 1][1] + ox, y: track[track.length - 1][2] + oy, theta: track[track.length - 1][3] } : null,
      }));
      this.traces.set(runId, { robot_id: run.robot_id, points: [], robots, exact: true, obstacles, ...times });
      this.prune();
      this.emit("field");
      return;
    }
    const points = res.poses.map(([, x, y]) => [x + ox, y + oy]);
    const old = this.traces.get(runId);
    if (!old || old.points.length <= points.length) this.traces.set(runId, { robot_id: run.robot_id, points, exact: true, obstacles, ...times });
    this.prune();
    const last = res.poses[res.poses.length - 1];
    const cur = this.poses.get(run.robot_id);
    if (last && this.isFieldRobot(run.robot_id) && cur && cur.run_id === runId) {
      // the run's exact last pose replaces the sampled live one (an older run's says nothing of where it is now)
      this.poses.set(run.robot_id, { x: last[1] + ox, y: last[2] + oy, theta: last[3], t: last[0], run_id: runId,
                                     source: "log" });
    }
    this.emit("field");
  }

  /** Forget traces no sub-field shows and old experiment details, so a long session stays small. */
  prune() {
    const shown = new Set(this.subfieldRun.values());
    for (const id of this.traces.keys()) {
      if (this.traces.size <= MAX_TRACES) break;
      if (!shown.has(id)) this.traces.delete(id);
    }
    for (const id of this.details.keys()) {
      if (this.details.size <= MAX_DETAILS) break;
      this.details.delete(id);
    }
  }

  /** Field robots where the testbed last saw them (`/robots`, asked for at `asked`): the pose its tracker
   * gave when the robot joined, or its last tracked one since; none known, not drawn.  A live event since
   * `asked` is newer and stays. */
  placeRobots(asked) {
    for (const r of this.robots) {
      if (r.pool !== "field" || (this.poseToldAt.get(r.robot_id) ?? -Infinity) > asked) continue;
      const cur = this.poses.get(r.robot_id);
      if (!r.last_pose) {
        this.poses.delete(r.robot_id);
        continue;
      }
      const [t, x, y, theta] = r.last_pose;
      if (cur && cur.t === t && cur.x === x && cur.y === y) continue; // the same pose: keep which run it was
      this.poses.set(r.robot_id, { x, y, theta, t, run_id: null, source: "server" });
    }
  }

  /** The runs sub-field `sf` names (under way, last since the start) as its latest; an ended one's stored
   * trace is loaded once (a dashboard opened after it ended draws it too). */
  noteSubfieldRuns(sf) {
    for (const id of [sf.last_run_id, sf.run_id]) {
      if (id == null || (this.subfieldRun.get(sf.id) ?? -1) > id) continue;
      this.subfieldRun.set(sf.id, id);
      if (id !== sf.run_id && !this.traces.has(id) && !this.traceAsked.has(id)) {
        this.traceAsked.add(id);
        this.loadTrace(id).catch((err) => this.failed(err, "Poses"));
      }
    }
  }

  /** An experiment moved on: its field runs' traces and robots (what events would have told, when polling). */
  async followFieldRuns(id) {
    try {
      const d = await this.detail(id, { fresh: true });
      const shown = new Set(this.subfieldRun.values()); // its runs on the field now (the sub-fields name them)
      for (const r of d.runs) {
        if (r.mode !== "twb" || r.t_start == null || !r.robot_id || !shown.has(r.id)) continue;
        if (TERMINAL.has(r.status) && !this.traces.get(r.id)?.exact) await this.loadTrace(r.id);
      }
      this.emit("field");
    } catch (err) {
      this.failed(err, "Experiment");
    }
  }

  // ------------------------------------------------------------------ live events

  onEvent(type, data) {
    if (type === "pose") this.onPose(data);
    else if (type === "run") this.onRun(data.run);
    else if (type === "experiment") this.onExperiment(data.experiment);
    else if (type === "subfield") this.onSubfield(data.subfield);
    else if (type === "robot") this.later("field", 300, () => this.refreshField());
  }

  onPose(ev) {
    if (ev.robot != null) return this.onFleetPose(ev);
    if (this.isFieldRobot(ev.robot_id)) {
      this.poses.set(ev.robot_id, { x: ev.x, y: ev.y, theta: ev.theta, t: ev.t, run_id: ev.run_id, source: "live" });
      this.poseToldAt.set(ev.robot_id, performance.now());
    }
    if (ev.run_id != null) {
      let tr = this.traces.get(ev.run_id);
      if (!tr) {
        tr = { robot_id: ev.robot_id, points: [], exact: false };
        this.traces.set(ev.run_id, tr);
        this.prune();
      }
      if (!tr.exact && tr.points.length < MAX_TRACE) tr.points.push([ev.x, ev.y]);
      if (!tr.exact) {
        tr.t0 ??= ev.t;
        tr.t1 = ev.t;
      }
    }
    this.emit("field");
    this.emit("pose", ev);
  }

  /** A pose of robot `ev.robot` of a multi-robot run (its id `<assigned robot>/<k>`, field frame). */
  onFleetPose(ev) {
    if (ev.run_id == null) return;
    let tr = this.traces.get(ev.run_id);
    if (!tr) {
      tr = { robot_id: ev.robot_id.split("/")[0], points: [], robots: [], exact: false, t0: ev.t, t1: ev.t };
      this.traces.set(ev.run_id, tr);
      this.prune();
    }
    if (tr.exact) return;
    const r = (tr.robots[ev.robot] ||= { points: [], last: null });
    if (r.points.length < MAX_TRACE) r.points.push([ev.x, ev.y]);
    r.last = { x: ev.x, y: ev.y, theta: ev.theta };
    tr.t1 = Math.max(tr.t1 ?? ev.t, ev.t);
    this.emit("field");
    this.emit("pose", ev);
  }

  onRun(run) {
    if (!run) return;
    this.runs.set(run.id, run);
    this.runToldAt.set(run.id, performance.now());
    if (run.mode === "twb" && run.subfield != null && run.status !== "queued") this.subfieldRun.set(run.subfield, run.id);
    const d = this.details.get(run.experiment_id);
    if (d) {
      const i = d.runs.findIndex((r) => r.id === run.id);
      if (i >= 0) d.runs[i] = run;
      if (run.status === "running" && d.planned_path == null) this.details.delete(run.experiment_id);
    }
    if (TERMINAL.has(run.status) && run.robot_id && this.isFieldRobot(run.robot_id) && run.t_start != null) {
      // the exact performed path replaces the sampled live trace
      this.later(`trace-${run.id}`, 150, () => this.loadTrace(run.id).catch((err) => this.failed(err, "Poses")));
    }
    if (TERMINAL.has(run.status) || run.status === "running") {
      // sub-fields are released without an event of their own
      this.later("field", 400, () => this.refreshField());
      this.later("field-again", 1500, () => this.refreshField());
    }
    this.later("experiments", 300, () => this.refreshExperiments());
    this.emit("experiment", run.experiment_id);
    this.emit("field");
  }

  onExperiment(exp) {
    if (!exp) return;
    const i = this.experiments.findIndex((e) => e.id === exp.id);
    if (i >= 0) this.experiments[i] = { ...this.experiments[i], ...exp };
    const d = this.details.get(exp.id);
    if (d && d.status !== exp.status) this.details.delete(exp.id);
    this.later("experiments", 300, () => this.refreshExperiments());
    this.emit("experiments");
    this.emit("experiment", exp.id);
  }

  onSubfield(sf) {
    if (!sf) return;
    this.subfieldToldAt.set(sf.id, performance.now());
    const i = this.subfields.findIndex((s) => s.id === sf.id);
    if (i >= 0) this.subfields[i] = sf;
    else this.subfields.push(sf);
    this.noteSubfieldRuns(sf);
    if (sf.run_id != null) this.ensureRunning();
    this.emit("field");
  }
}
