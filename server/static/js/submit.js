// The submit form: environment, start and goal placed on the map (click; drag for the
// heading; keys too), or several robots each with its own (fleetform.js), where the path comes from (a planner
// and its parameters, one of your uploaded programs, or an explicit path through waypoints), the robots'
// controller, modes, repetitions, seed.  The server validates; its message is shown next to the field it is about.

import { $, $$, TERMINAL, checkRadio, deg, h, num, radioValue, report, retoast, toast } from "./dom.js";
import { COLORS, MapView } from "./fieldmap.js";
import { FLEET_PLANNER, MAX_ROBOTS, RobotList, plannerChoices, robotOfLoc, robotOfMessage } from "./fleetform.js";
import { obstacleLayers } from "./moving.js";
import { programLabel } from "./programs.js";
import { FIELD_SIZE, SUBFIELD_SIZE } from "./store.js";

const KEYS = ["environment", "field", "start", "goal", "robots", "planner", "planner_params", "program", "path", "controller", "controller_params", "modes", "repetitions", "seed"];
const DRAG_PX = 8;
const TURN = Math.PI / 12;

/** Which form field a server message is about (pre-flight messages start with the field's name). */
export function fieldOfMessage(msg) {
  const m = msg.toLowerCase();
  if (/^path\b|^`path`/.test(m)) return "path";
  if (/^start\b/.test(m) || /`start`/.test(m)) return "start";
  if (/^goal\b|^the goal\b/.test(m) || /`goal`/.test(m)) return "goal";
  if (/^repetitions\b/.test(m)) return "repetitions";
  if (/^seed\b/.test(m)) return "seed";
  if (/^modes?\b/.test(m)) return "modes";
  if (/^controller_params/.test(m)) return "controller_params";
  if (/^controller/.test(m)) return "controller";
  if (/^parameter |has no parameter|planner_params/.test(m)) return "planner_params";
  if (/program|^uploads? /.test(m)) return "program";
  if (/planner/.test(m)) return "planner";
  if (/environment/.test(m)) return "environment";
  return null;
}

/** A planner's parameters as the server declares them (`parameters`: name, type, unit, default, range,
 * description), or, from a server that lists only `defaults`, each default's JSON type. */
export function plannerParams(planner) {
  if (Array.isArray(planner.parameters)) return planner.parameters;
  return Object.entries(planner.defaults || {}).map(([name, v]) => ({ name, default: v, unit: "", description: "", range: null,
    type: typeof v === "boolean" ? "boolean" : typeof v === "string" ? "string" : "number" }));  // 1.0 reads as 1 in JSON
}

/** Where a server message goes: a form field, `{robot, part}` for one robot of several, or null (the top of the
 * form); `loc`: a request-model error's location. */
export function errorKey(msg, loc = null) {
  const robot = loc && loc.length > 1 ? robotOfLoc(loc) : robotOfMessage(msg);
  if (robot) return robot.index === null ? "robots" : { robot: robot.index, part: robot.part };
  if (loc && loc.length > 1) return loc[0] === "body" && KEYS.includes(loc[1]) ? loc[1] : null;
  return fieldOfMessage(msg);
}

export class SubmitPage {
  constructor(store, { onSubmitted }) {
    this.store = store;
    this.onSubmitted = onSubmitted;
    this.form = $("#submit-form");
    this.map = new MapView($("#submit-canvas"), { world: SUBFIELD_SIZE, padding: 14 });
    // the one robot's start and goal and, for an explicit path, the [x, y] between them; several robots: robotList
    this.single = { start: null, goal: null, waypoints: [] };
    this.robotList = new RobotList($("#f-robots"), { onChange: () => this.onRobotList() });
    this.programs = [];
    this.uploads = null; // GET /programs/sandbox
    this.planners = [];
    this.envs = [];
    this.loaded = false;
    this.wire();
    this.onRobots(); // the browser may have restored the radios of an earlier visit
    this.onSource();
  }

  /** params: the route's query (#/submit?program=ID preselects that program). */
  async show(params = new URLSearchParams()) {
    const wanted = params.get("program");
    if (wanted) this.wantProgram = wanted;
    this.loadPrograms().catch((err) => report(err, "Programs"));
    if (!this.loaded) {
      try {
        const [envs, planners] = await Promise.all([
          this.store.api.get("/api/v1/environments?limit=1000"),
          this.store.api.get("/api/v1/planners").catch(() => ({ data: ["fmm", "fm2", "prm", "astar"].map((name) => ({ name, description: "", defaults: {} })) })),
        ]);
        this.envs = envs.data;
        this.planners = planners.data;
        this.loadControllers().catch((err) => report(err, "Controllers"));
        this.loaded = true;
        this.fillSelects();
      } catch (err) {
        report(err, "Submit form");
        return;
      }
    }
    this.draw();
  }

  get env() {
    return this.envs.find((e) => e.name === $("#f-environment").value) || null;
  }

  get fieldMode() {
    return radioValue(this.form, "field");
  }

  get source() {
    return radioValue(this.form, "source");
  }

  set source(which) {
    checkRadio(this.form, "source", which);
    this.onSource();
  }

  /** Several robots ("robots" in the job) rather than one. */
  get multi() {
    return radioValue(this.form, "robots") === "fleet";
  }

  /** What the map and the plan buttons place: the one robot, or the robot chosen in the list (null: none). */
  target() {
    return this.multi ? this.robotList.current : this.single;
  }

  get pick() {
    return radioValue(this.form, "pick");
  }

  set pick(which) {
    checkRadio(this.form, "pick", which);
    this.draw();
  }

  fillSelects() {
    const envSel = $("#f-environment");
    envSel.replaceChildren(...this.envs.map((e) => h("option", { value: e.name }, `${e.name}${e.builtin ? "" : ` (${e.owner || "yours"})`}`)));
    this.fillPlanners(this.multi ? FLEET_PLANNER : null);
    this.onEnvironment(true);
  }

  /** The planners to choose from: the server's, and for several robots `prioritized` first. */
  plannerChoices() {
    return plannerChoices(this.planners, this.multi);
  }

  /** The planner select for one robot or several; `prefer` is chosen if given, else the choice is kept when it is
   * offered, else fm2 (one robot). */
  fillPlanners(prefer = null) {
    const plSel = $("#f-planner");
    const keep = prefer || plSel.value;
    const choices = this.plannerChoices();
    plSel.replaceChildren(...choices.map((p) => h("option", { value: p.name }, p.name)));
    const fallback = choices.some((p) => p.name === "fm2") ? "fm2" : plSel.value;
    plSel.value = choices.some((p) => p.name === keep) ? keep : fallback;
    this.onPlanner();
  }

  /** One robot or several: show that part of the form; several start as the one robot and a second to place. */
  onRobots() {
    const multi = this.multi;
    for (const el of $$("[data-robots]", this.form)) el.hidden = el.dataset.robots !== (multi ? "fleet" : "one");
    if (multi && !this.robotList.robots.length) {
      const { start, goal, waypoints } = this.single;
      this.robotList.set([{ start, goal, waypoints }, {}], start && goal ? 1 : 0);
      this.pick = "start";
    }
    if (this.loaded) this.fillPlanners(multi ? FLEET_PLANNER : null);
    this.renderPlans();
    this.showWaypoints();
    this.draw();
  }

  /** The robot list changed (a robot added, removed, chosen or typed). */
  onRobotList() {
    $("#add-robot").disabled = this.robotList.robots.length >= MAX_ROBOTS;
    if (this.waypointsOf !== this.target()) this.showWaypoints();
    this.draw();
  }

  /** The built-in scenario `swap` (its environment's plans A to D): four robots exchange diagonally opposite
   * corners of a sub-field, planned together. */
  fillSwap() {
    const env = this.envs.find((e) => e.name === "swap" && e.builtin);
    if (!env) {
      toast("This testbed has no built-in environment swap", true);
      return;
    }
    $("#f-environment").value = env.name;
    checkRadio(this.form, "field", "sub");
    this.onEnvironment(false);
    this.robotList.set(env.plans);
    this.fillPlanners(FLEET_PLANNER);
  }

  /** Your programs (re-read whenever the form is shown: you may just have uploaded one) and whether uploads are on. */
  async loadPrograms() {
    const api = this.store.api;
    const [sandbox, list] = await Promise.all([api.get("/api/v1/programs/sandbox"), api.get("/api/v1/programs?limit=500")]);
    this.uploads = sandbox;
    this.programs = list.data;
    this.store.notePrograms(list.data);
    const sel = $("#f-program");
    const keep = this.wantProgram || sel.value;
    this.wantProgram = null;
    sel.replaceChildren(...this.programs.map((p) => h("option", { value: p.id }, programLabel(p))));
    sel.hidden = !sandbox.uploads_enabled || !this.programs.length;
    if (this.programs.some((p) => String(p.id) === String(keep))) {
      sel.value = String(keep);
      if (keep && this.source !== "program") this.source = "program";
    }
    this.onProgram();
  }

  onProgram() {
    const desc = $("#program-desc");
    if (!this.uploads) {
      desc.textContent = "";
    } else if (!this.uploads.uploads_enabled) {
      desc.textContent = "Uploads are disabled on this testbed, so a job cannot use an uploaded program here. " +
        "Choose a planner or an explicit path.";
    } else if (!this.programs.length) {
      desc.replaceChildren("You have no programs yet. ", h("a", { href: "#/programs" }, "Upload one"), ".");
    } else {
      const p = this.programs.find((q) => String(q.id) === $("#f-program").value);
      desc.replaceChildren(p ? `${p.kind === "python" ? "Python" : "executable"}${p.interpreter ? ` run by ${p.interpreter}` : ""}, ${p.size} bytes` +
        (p.args.length ? `, arguments ${p.args.join(" ")}` : "") + ". It runs once, when the first run is planned: " +
        `at most ${num(this.uploads.limits?.wall_s, 0)} s. ` : "", h("a", { href: "#/programs" }, "Your programs"));
    }
  }

  onSource() {
    const source = this.source;
    for (const el of $$("[data-source]", this.form)) el.hidden = el.dataset.source !== source;
    if (source !== "path" && this.pick === "waypoint") this.pick = "start";
    this.draw();
  }

  wire() {
    for (const r of $$('input[name="source"]', this.form)) r.addEventListener("change", () => this.onSource());
    $("#f-program").addEventListener("change", () => this.onProgram());
    $("#f-path").addEventListener("input", () => this.fromPathText());
    $("#f-environment").addEventListener("change", () => this.onEnvironment(true));
    $("#f-planner").addEventListener("change", () => this.onPlanner());
    $("#f-controller").addEventListener("change", () => this.onController());
    for (const r of $$('input[name="field"]', this.form)) r.addEventListener("change", () => this.onEnvironment(false));
    for (const r of $$('input[name="pick"]', this.form)) r.addEventListener("change", () => this.draw());
    for (const r of $$('input[name="robots"]', this.form)) r.addEventListener("change", () => this.onRobots());
    $("#add-robot").addEventListener("click", () => { this.robotList.add(); this.pick = "start"; });
    $("#fill-swap").addEventListener("click", () => this.fillSwap());
    for (const which of ["start", "goal"]) {
      for (const c of ["x", "y", "a"]) {
        $(`#f-${which}-${c}`).addEventListener("input", () => this.fromInputs(which));
      }
    }
    this.form.addEventListener("submit", (ev) => {
      ev.preventDefault();
      this.submit().catch((err) => report(err, "Submit"));
    });
    const c = this.map.canvas;
    c.addEventListener("pointerdown", (ev) => this.pointerDown(ev));
    c.addEventListener("pointermove", (ev) => this.pointerMove(ev));
    c.addEventListener("pointerup", (ev) => this.pointerUp(ev));
    c.addEventListener("pointercancel", () => { this.drag = null; });
    c.addEventListener("keydown", (ev) => this.key(ev));
  }

  onEnvironment(applyPlan) {
    const env = this.env;
    $("#env-desc").textContent = env ? `${env.size[0]} x ${env.size[1]} m, ${env.blocks.length} blocks. ${env.description || ""}` : "";
    if (env && (env.size[0] > SUBFIELD_SIZE[0] + 1e-9 || env.size[1] > SUBFIELD_SIZE[1] + 1e-9)) {
      checkRadio(this.form, "field", "full");
    }
    const plans = this.renderPlans();
    if (applyPlan && !this.multi && plans.length && !this.single.start && !this.single.goal) this.applyPlan(plans[0]);
    this.draw();
  }

  /** The environment's plans as buttons (for several robots: the chosen robot's, and all of them as robots). */
  renderPlans() {
    const plans = this.env?.plans || [];
    const whose = this.multi ? " (the chosen robot)" : "";
    const all = this.multi && plans.length >= 2
      ? [h("button", { type: "button", class: "small", onclick: () => this.robotList.set(plans) }, `All ${plans.length} plans as robots`)]
      : [];
    $("#env-plans").replaceChildren(...plans.map((p) => h("button", { type: "button", class: "small",
      title: `Plan ${p.name}'s start and goal${whose}`, onclick: () => this.applyPlan(p) }, `Plan ${p.name}`)), ...all);
    return plans;
  }

  applyPlan(p) {
    this.setPose("start", [...p.start]);
    this.setPose("goal", [...p.goal]);
  }

  onPlanner() {
    const p = this.plannerChoices().find((q) => q.name === $("#f-planner").value);
    $("#planner-desc").textContent = p?.description || "";
    const box = $("#f-params");
    if (!p || p.defaults === null) {
      box.replaceChildren(h("label", { for: "f-params-json" }, "JSON object"),
        h("textarea", { id: "f-params-json", rows: 3, placeholder: "{}", "aria-describedby": "err-planner_params" }));
      return;
    }
    const params = plannerParams(p);
    box.replaceChildren(...(params.length ? params.map((q) => {
      const id = `f-param-${q.name}`;
      const [low, high] = q.range || [null, null];
      const title = q.description ? `${q.description}${q.unit ? ` (${q.unit})` : ""}` : null;
      const input = q.type === "boolean"
        ? h("select", { id, "data-param": q.name, "data-kind": "bool", title, "aria-describedby": "err-planner_params" },
          h("option", { value: "" }, `default (${q.default})`), h("option", { value: "true" }, "true"), h("option", { value: "false" }, "false"))
        : h("input", { id, "data-param": q.name, "data-kind": q.type === "string" ? "string" : q.type === "integer" ? "int" : "number",
          type: q.type === "string" ? "text" : "number", step: q.type === "integer" ? "1" : q.type === "string" ? null : "any",
          min: low, max: high, title, placeholder: String(q.default), "aria-describedby": "err-planner_params" });
      return h("label", { for: id }, q.name, input);
    }) : [h("p", { class: "muted small" }, "This planner takes no parameters.")]));
  }

  params() {
    const json = $("#f-params-json");
    if (json) {
      const text = json.value.trim();
      if (!text) return {};
      try {
        const v = JSON.parse(text);
        if (v && typeof v === "object" && !Array.isArray(v)) return v;
      } catch { /* below */ }
      throw Object.assign(new Error("planner parameters must be a JSON object"), { field: "planner_params" });
    }
    const out = {};
    for (const el of $$("[data-param]", $("#f-params"))) {
      const raw = el.value.trim();
      if (raw === "") continue;
      const kind = el.dataset.kind;
      out[el.dataset.param] = kind === "bool" ? raw === "true" : kind === "string" ? raw : Number(raw);
    }
    return out;
  }

  // ------------------------------------------------------------------ poses and map

  world() {
    if (this.fieldMode === "full") return FIELD_SIZE;
    return this.env ? this.env.size : SUBFIELD_SIZE;
  }

  setPose(which, p) {
    const target = this.target();
    if (!target) return;
    target[which] = p;
    if (this.multi) {
      this.robotList.showPose(this.robotList.active, which);
      this.draw();
      return;
    }
    const [x, y, a] = p || [];
    $(`#f-${which}-x`).value = Number.isFinite(x) ? x.toFixed(3) : "";
    $(`#f-${which}-y`).value = Number.isFinite(y) ? y.toFixed(3) : "";
    $(`#f-${which}-a`).value = Number.isFinite(a) ? a.toFixed(3) : "";
    $(`#${which}-deg`).textContent = Number.isFinite(a) ? `heading ${deg(a)}` : "heading: any";
    this.draw();
  }

  fromInputs(which) {
    const x = parseFloat($(`#f-${which}-x`).value);
    const y = parseFloat($(`#f-${which}-y`).value);
    const a = parseFloat($(`#f-${which}-a`).value);
    this.single[which] = Number.isFinite(x) && Number.isFinite(y) ? [x, y, ...(Number.isFinite(a) ? [a] : [])] : null;
    $(`#${which}-deg`).textContent = Number.isFinite(a) ? `heading ${deg(a)}` : "heading: any";
    this.draw();
  }

  setWaypoints(points) {
    const target = this.target();
    if (!target) return;
    target.waypoints = points;
    this.showWaypoints();
    this.draw();
  }

  /** The waypoints box shows the one robot's waypoints, or the chosen robot's. */
  showWaypoints() {
    const target = this.target();
    this.waypointsOf = target;
    $("#f-path").value = (target?.waypoints || []).map(([x, y]) => `${x.toFixed(3)}, ${y.toFixed(3)}`).join("\n");
    $("#path-whose").textContent = this.multi ? `robot ${this.robotList.active}'s start and goal` : "start and goal";
  }

  /** The waypoints typed (one "x, y" or "x y" a line); null when a line is not a point. */
  parsePath() {
    const pts = [];
    for (const line of $("#f-path").value.split("\n")) {
      if (!line.trim()) continue;
      const v = line.trim().split(/[\s,;]+/).map(Number);
      if (v.length < 2 || v.length > 3 || !v.every(Number.isFinite)) return null;
      pts.push(v.slice(0, 2));
    }
    return pts;
  }

  fromPathText() {
    const pts = this.parsePath();
    const target = this.target();
    if (pts && target) target.waypoints = pts;
    this.draw();
  }

  draw() {
    const [w, hgt] = this.world();
    this.map.world = [w, hgt];
    const env = this.env;
    const withPath = this.source === "path";
    const { markers, paths } = this.multi ? this.robotList.layers(this.pick, withPath) : this.singleLayers(withPath);
    this.map.update({ blocks: env ? env.blocks : [], ...obstacleLayers(env?.moving_tracks, 0), markers, paths,
      subfields: this.fieldMode === "full" ? [[0, 0], [1.8, 0], [0, 1.8], [1.8, 1.8]].map((o) => ({ origin: o, size: SUBFIELD_SIZE, state: "idle" })) : [] });
    const target = this.target();
    const whose = this.multi ? `robot ${this.robotList.active}'s` : "the";
    if (!target) {
      $("#map-readout").textContent = "No robot to place: add one.";
    } else if (this.pick === "waypoint") {
      const n = target.waypoints.length;
      const last = target.waypoints[n - 1];
      $("#map-readout").textContent = `Placing ${this.multi ? `${whose} ` : ""}waypoints: ${n} so far` +
        (last ? `, the last at (${last[0].toFixed(2)}, ${last[1].toFixed(2)}) m` : "") + ".";
    } else {
      const p = target[this.pick];
      $("#map-readout").textContent = `Placing ${whose} ${this.pick}` + (p ? ` at (${p[0].toFixed(2)}, ${p[1].toFixed(2)}) m` +
        (Number.isFinite(p[2]) ? `, heading ${deg(p[2])}` : "") : "") + ".";
    }
  }

  /** The one robot's map layers: start (green) and goal (red) and an explicit path through its waypoints. */
  singleLayers(withPath) {
    const { start, goal, waypoints } = this.single;
    const markers = [];
    for (const [which, p] of [["start", start], ["goal", goal]]) {
      if (p) markers.push({ x: p[0], y: p[1], theta: p[2], color: which === "start" ? COLORS.start : COLORS.goal, label: which,
        active: this.pick === which });
    }
    const paths = [];
    if (withPath) {
      waypoints.forEach(([x, y], i) => markers.push({ x, y, radius: 0.02, color: COLORS.planned, label: String(i + 1),
        active: this.pick === "waypoint" && i === waypoints.length - 1 }));
      const pts = [start, ...waypoints, goal].filter(Boolean);
      paths.push({ points: pts.map((q) => [q[0], q[1]]), color: COLORS.planned, width: 2, dash: [7, 5] });
    }
    return { markers, paths };
  }

  local(ev) {
    const r = this.map.canvas.getBoundingClientRect();
    return [ev.clientX - r.left, ev.clientY - r.top];
  }

  pointerDown(ev) {
    if (ev.button !== 0) return;
    const [px, py] = this.local(ev);
    const [x, y] = this.map.toWorld(px, py);
    const [w, hgt] = this.world();
    const target = this.target();
    if (!target || x < 0 || y < 0 || x > w || y > hgt) return;
    ev.preventDefault();
    this.map.canvas.focus();
    const which = this.pick;
    if (which === "waypoint") {
      this.setWaypoints([...target.waypoints, [round(x), round(y)]]);
      return;
    }
    this.map.canvas.setPointerCapture?.(ev.pointerId);
    const old = target[which];
    this.drag = { which, px, py };
    this.setPose(which, [round(x), round(y), ...(old && Number.isFinite(old[2]) ? [old[2]] : [])]);
  }

  pointerMove(ev) {
    if (!this.drag) return;
    const [px, py] = this.local(ev);
    const dx = px - this.drag.px;
    const dy = py - this.drag.py;
    if (Math.hypot(dx, dy) < DRAG_PX) return;
    const p = this.target()[this.drag.which];
    this.setPose(this.drag.which, [p[0], p[1], round(Math.atan2(-dy, dx), 3)]);
  }

  pointerUp(ev) {
    if (!this.drag) return;
    this.pointerMove(ev);
    const which = this.drag.which;
    this.drag = null;
    if (which === "start") this.pick = "goal"; // then the goal, as one places them
    else if (this.multi) this.nextUnplaced();
  }

  /** After a robot's goal: on to the next robot without a start, if there is one. */
  nextUnplaced() {
    const list = this.robotList;
    const k = list.robots.findIndex((r, i) => i > list.active && !r.start);
    if (k < 0) return;
    list.choose(k);
    this.pick = "start";
  }

  key(ev) {
    const which = this.pick;
    if (ev.key === "s" || ev.key === "g") {
      this.pick = ev.key === "s" ? "start" : "goal";
      ev.preventDefault();
      return;
    }
    if (ev.key === "r" && this.multi && this.robotList.robots.length) {
      this.robotList.choose((this.robotList.active + 1) % this.robotList.robots.length);
      ev.preventDefault();
      return;
    }
    const target = this.target();
    if (!target) return;
    const moves = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, 1], ArrowDown: [0, -1] };
    const [w, hgt] = this.world();
    const wps = target.waypoints;
    if (ev.key === "w" && this.source === "path") {
      const last = wps[wps.length - 1] || target.start || [w / 2, hgt / 2];
      checkRadio(this.form, "pick", "waypoint");
      this.setWaypoints([...wps, [round(clamp(last[0] + 0.1, 0, w)), round(last[1])]]);
      ev.preventDefault();
      return;
    }
    if (which === "waypoint") {
      const n = wps.length;
      if (n && moves[ev.key]) {
        const step = ev.shiftKey ? 0.1 : 0.01;
        const [dx, dy] = moves[ev.key];
        const [x, y] = wps[n - 1];
        this.setWaypoints([...wps.slice(0, -1), [round(clamp(x + dx * step, 0, w)), round(clamp(y + dy * step, 0, hgt))]]);
        ev.preventDefault();
      } else if (n && (ev.key === "Delete" || ev.key === "Backspace")) {
        this.setWaypoints(wps.slice(0, -1));
        ev.preventDefault();
      }
      return;
    }
    const p = target[which] || [w / 2, hgt / 2];
    if (moves[ev.key]) {
      const step = ev.shiftKey ? 0.1 : 0.01;
      const [dx, dy] = moves[ev.key];
      this.setPose(which, [round(clamp(p[0] + dx * step, 0, w)), round(clamp(p[1] + dy * step, 0, hgt)), ...p.slice(2)]);
      ev.preventDefault();
    } else if (ev.key === "[" || ev.key === "]") {
      const a = Number.isFinite(p[2]) ? p[2] : 0;
      let na = a + (ev.key === "[" ? TURN : -TURN);
      na = Math.atan2(Math.sin(na), Math.cos(na));
      this.setPose(which, [p[0], p[1], round(na, 3)]);
      ev.preventDefault();
    }
  }

  // ------------------------------------------------------------------ submit

  clearErrors() {
    $("#submit-error").textContent = "";
    for (const k of KEYS) {
      const el = $(`#err-${k}`);
      if (el) el.textContent = "";
    }
    this.robotList.clearErrors();
    for (const el of $$("[aria-invalid]", this.form)) el.removeAttribute("aria-invalid");
  }

  /** The controllers the robots offer (GET /api/v1/controllers) in the form's select; the default first. */
  async loadControllers() {
    const listed = await this.store.api.get("/api/v1/controllers");
    const sel = $("#f-controller");
    const keep = sel.value;
    sel.replaceChildren(...listed.data.map((c) => h("option", { value: c.name, title: c.description }, c.name)));
    sel.value = listed.data.some((c) => c.name === keep) ? keep : "schema";
    this.controllers = listed.data;
    this.onController();
  }

  /** One number input per parameter of the chosen controller: empty keeps the default (its placeholder);
   * the range and unit are in the input's limits and title; integer ones (a switch such as `replan`) step by 1. */
  onController() {
    const c = (this.controllers || []).find((q) => q.name === $("#f-controller").value);
    $("#controller-desc").textContent = c ? `${c.description}${c.source ? ` (${c.source})` : ""}` : "";
    const box = $("#f-controller-params");
    const params = c?.parameters || [];
    box.replaceChildren(...(params.length ? params.map((p) => {
      const id = `f-cparam-${p.name}`;
      const [low, high] = p.range || [null, null];
      const input = h("input", { id, type: "number", step: p.integer ? "1" : "any", "data-cparam": p.name, placeholder: String(p.default),
        min: low, max: high, title: `${p.description} (${p.unit}; ${low} to ${high})`,
        "aria-describedby": "err-controller_params" });
      return h("label", { for: id }, `${p.name}`, input);
    }) : [h("p", { class: "muted small" }, c ? "This controller takes no parameters." : "")]));
  }

  /** The controller parameters typed in (the others keep their defaults). */
  controllerParams() {
    const out = {};
    for (const el of $$("[data-cparam]", $("#f-controller-params"))) {
      const raw = el.value.trim();
      if (raw !== "") out[el.dataset.cparam] = Number(raw);
    }
    return out;
  }

  /** Show `message` under the field `key` (a robot's: `{robot, part}`; null: the top of the form) with its inputs
   * marked; the element to focus. */
  showError(key, message) {
    if (key && typeof key === "object") return this.robotList.showError(key.robot, key.part, message) || this.showError("robots", message);
    const target = key && $(`#err-${key}`);
    if (!target) {
      $("#submit-error").textContent = message;
      return $("#submit-error");
    }
    target.textContent = message;
    const inputs = {
      environment: ["#f-environment"], planner: ["#f-planner"], repetitions: ["#f-repetitions"], seed: ["#f-seed"],
      controller: ["#f-controller"], controller_params: ["#f-controller-params input"],
      start: ["#f-start-x", "#f-start-y", "#f-start-a"], goal: ["#f-goal-x", "#f-goal-y", "#f-goal-a"],
      planner_params: ["#f-params input", "#f-params select", "#f-params textarea"],
      program: ["#f-program"], path: ["#f-path"],
      modes: ['input[name="modes"]'], field: ['input[name="field"]'],
    }[key] || [];
    const els = inputs.flatMap((sel) => $$(sel, this.form));
    const param = /parameter \w+\.(\w+)/.exec(message)?.[1];
    const cparam = /^controller_params\.(\w+)/.exec(message)?.[1];
    for (const el of els) {
      if (key === "controller_params" ? !cparam || el.dataset.cparam === cparam
        : key !== "planner_params" || !param || el.dataset.param === param) el.setAttribute("aria-invalid", "true");
    }
    return els.find((el) => el.getAttribute("aria-invalid")) || els[0] || target;
  }

  body() {
    const modes = $$('input[name="modes"]:checked', this.form).map((el) => el.value);
    const problems = [];
    const multi = this.multi;
    const { start, goal } = this.single;
    if (multi) {
      for (const [k, msg] of this.robotList.problems()) problems.push(k === null ? ["robots", msg] : [{ robot: k }, msg]);
    } else {
      if (!start) problems.push(["start", "place the start on the map or type x and y"]);
      if (!goal) problems.push(["goal", "place the goal on the map or type x and y"]);
    }
    if (!modes.length) problems.push(["modes", "choose at least one mode"]);
    const source = {};
    if (this.source === "planner") {
      source.planner = $("#f-planner").value;
      try {
        source.planner_params = this.params();
      } catch (err) {
        problems.push(["planner_params", err.message]);
      }
    } else if (this.source === "program") {
      if (this.uploads && !this.uploads.uploads_enabled) problems.push(["program", "uploads are disabled on this testbed"]);
      else if (!$("#f-program").value) problems.push(["program", "upload a program first (Programs page)"]);
      else source.program = Number($("#f-program").value);
    } else {
      const pts = this.parsePath();
      if (!pts) problems.push(["path", "each line must be one point: x, y in metres"]);
      else if (!multi && start && goal) source.path = [start, ...pts, goal];
    }
    const intOf = (sel) => {
      const v = $(sel).value.trim();
      return v === "" ? NaN : Number(v);
    };
    return {
      problems,
      body: {
        environment: $("#f-environment").value,
        ...(multi ? { robots: this.robotList.body(this.source === "path") } : { start, goal }),
        ...source,
        controller: $("#f-controller").value || "schema",
        controller_params: this.controllerParams(),
        modes,
        repetitions: intOf("#f-repetitions"),
        seed: intOf("#f-seed"),
        field: this.fieldMode,
      },
    };
  }

  /** Keep the "Experiment #N queued" toast true: it shows each new status while it is up, and stops following
   * when the experiment has finished or the toast has gone. */
  followToast(id, status) {
    const key = `experiment-${id}`;
    let last = status;
    const check = () => {
      const e = this.store.experiments.find((x) => x.id === id) || this.store.details.get(id);
      if (!e || e.status === last) return;
      last = e.status;
      if (!retoast(key, `Experiment #${id} ${e.status}`) || TERMINAL.has(e.status)) stop();
    };
    const stop = () => {
      this.store.removeEventListener("experiments", check);
      this.store.removeEventListener("experiment", check);
    };
    this.store.addEventListener("experiments", check);
    this.store.addEventListener("experiment", check);
  }

  async submit() {
    this.clearErrors();
    const { problems, body } = this.body();
    if (problems.length) {
      const first = problems.map(([k, msg]) => this.showError(k, msg))[0];
      first?.focus?.();
      return;
    }
    // NaN would not survive JSON; send null and let the server say what is wrong
    for (const k of ["repetitions", "seed"]) if (!Number.isFinite(body[k])) body[k] = null;
    const button = $("#submit-button");
    button.disabled = true;
    try {
      const exp = await this.store.api.post("/api/v1/experiments", body);
      toast(`Experiment #${exp.id} ${exp.status}`, false, `experiment-${exp.id}`);
      this.followToast(exp.id, exp.status);
      this.store.refreshExperiments();
      this.onSubmitted(exp.id);
    } catch (err) {
      if (err.status === 422 || err.status === 429 || err.status === 413 || (err.status === 403 && body.program)) {
        let first = null;
        const pyd = (err.errors || []).filter((e) => Array.isArray(e.loc));
        if (pyd.length) {
          for (const e of pyd) {
            const msg = e.msg.replace(/^Value error, /, "");
            const key = errorKey(msg, e.loc);
            const el = this.showError(key, key ? msg : err.detail);
            first = first || el;
          }
        } else {
          first = this.showError(errorKey(err.detail), err.detail);
        }
        first?.focus?.();
      } else {
        report(err, "Submit");
      }
    } finally {
      button.disabled = false;
    }
  }
}

function round(v, digits = 3) {
  const f = 10 ** digits;
  return Math.round(v * f) / f;
}

function clamp(v, lo, hi) {
  return Math.min(hi, Math.max(lo, v));
}
