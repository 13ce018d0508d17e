// The submit form's robots of a multi-robot job (docs/server.md "Multi-robot jobs"): the list of robots, each
// with its start and goal (and, for an explicit path, its waypoints), which of them the map places, their map
// layers in the robots' colours (fleet.js), the checks made before sending, and where the server's 422 about
// `robots[i]` is shown.

import { $$, h } from "./dom.js";
import { robotColor, swatch } from "./fleet.js";

/** The planner a fleet is planned with by default (server/schemas.py FLEET_PLANNER); `lacam` plans fleets too
 * (server/schemas.py FLEET_PLANNERS): both are listed with `fleet_only`. */
export const FLEET_PLANNER = "prioritized";
/** The most robots of a job, on the whole field (contract/frames.py MAX_ROBOTS). */
export const MAX_ROBOTS = 64;

/** The planners to offer, from the server's list (`GET /api/v1/planners`): for several robots the ones that plan
 * fleets only (`prioritized`, `lacam`) first, then every other (each plans each robot alone); for one robot the others. */
export function plannerChoices(planners, multi) {
  const others = planners.filter((p) => !p.fleet_only);
  return multi ? [...planners.filter((p) => p.fleet_only), ...others] : others;
}

/** Which robot a server message is about: `{index, part}` for `robots[i]` (`part` "start", "goal", "path" or
 * null; the first robot named), `{index: null}` for the list as a whole ("robots: ..."), else null. */
export function robotOfMessage(msg) {
  const m = /robots\[(\d+)\](?:\.(start|goal|path)\b)?/.exec(msg);
  if (m) return { index: Number(m[1]), part: m[2] || null };
  return /^robots\b/.test(msg) ? { index: null, part: null } : null;
}

/** The same for a request-model error's location, `["body", "robots", 1, "start", 0]`. */
export function robotOfLoc(loc) {
  if (loc[0] !== "body" || loc[1] !== "robots") return null;
  const part = ["start", "goal", "path"].includes(loc[3]) ? loc[3] : null;
  return Number.isInteger(loc[2]) ? { index: loc[2], part } : { index: null, part: null };
}

const AXES = [["x", "x (m)", "x"], ["y", "y (m)", "y"], ["a", "θ (rad)", "θ"]];

/** The robots of the form and their rows in `box`.  A robot is `{start, goal, waypoints}`: poses `[x, y]` or
 * `[x, y, theta]` (m, rad) or null, waypoints `[[x, y], ...]` (m).  `active` is the one the map places;
 * `onChange()` is called after a robot was added, removed, chosen or typed. */
export class RobotList {
  constructor(box, { onChange }) {
    this.box = box;
    this.onChange = onChange;
    this.robots = [];
    this.active = 0;
  }

  get current() {
    return this.robots[this.active] || null;
  }

  /** Replace the robots (`{start, goal, waypoints?}` each; poses copied) and choose robot `active`. */
  set(robots, active = 0) {
    this.robots = robots.map((r) => ({ start: r.start ? [...r.start] : null, goal: r.goal ? [...r.goal] : null,
      waypoints: (r.waypoints || []).map((p) => [...p]) }));
    this.active = Math.min(active, Math.max(0, this.robots.length - 1));
    this.render();
  }

  add() {
    if (this.robots.length >= MAX_ROBOTS) return;
    this.robots.push({ start: null, goal: null, waypoints: [] });
    this.active = this.robots.length - 1;
    this.render();
  }

  remove(k) {
    this.robots.splice(k, 1);
    if (this.active >= k && this.active > 0) this.active -= 1;
    this.render();
  }

  /** Choose robot `k` for the map. */
  choose(k) {
    if (k < 0 || k >= this.robots.length) return;
    this.active = k;
    const radio = this.box.querySelector(`input[name="robot-pick"][value="${k}"]`);
    if (radio) radio.checked = true;
    this.onChange();
  }

  /** Show robot `k`'s `which` pose ("start" or "goal") in its inputs (after the map or a plan moved it). */
  showPose(k, which) {
    const p = this.robots[k]?.[which] || [];
    AXES.forEach(([c], i) => {
      const el = this.box.querySelector(`#f-r${k}-${which}-${c}`);
      if (el) el.value = Number.isFinite(p[i]) ? p[i].toFixed(3) : "";
    });
  }

  fromInputs(k, which) {
    const [x, y, a] = AXES.map(([c]) => parseFloat(this.box.querySelector(`#f-r${k}-${which}-${c}`).value));
    this.robots[k][which] = Number.isFinite(x) && Number.isFinite(y) ? [x, y, ...(Number.isFinite(a) ? [a] : [])] : null;
    this.onChange();
  }

  render() {
    this.box.replaceChildren(...this.robots.map((_, k) => this.row(k)));
    for (const which of ["start", "goal"]) this.robots.forEach((_, k) => this.showPose(k, which));
    this.onChange();
  }

  row(k) {
    const err = `err-robots-${k}`;
    const poses = ["start", "goal"].map((which) => h("div", { class: "robot-pose", role: "group", "aria-label": `robot ${k} ${which}` },
      h("span", { class: "small" }, which),
      AXES.map(([c, unit, hint]) => h("input", { id: `f-r${k}-${which}-${c}`, type: "number", step: "0.01", inputmode: "decimal",
        placeholder: hint, "aria-label": `robot ${k} ${which} ${unit}`, "aria-describedby": err, dataset: { robot: k, pose: which },
        oninput: () => this.fromInputs(k, which) }))));
    return h("fieldset", { class: "robot", dataset: { robot: k } },
      h("legend", { class: "robot-head" },
        h("label", { class: "check" },
          h("input", { type: "radio", name: "robot-pick", value: k, checked: k === this.active,
            onchange: () => this.choose(k) }),
          swatch(robotColor(k)), `Robot ${k}`),
        h("button", { type: "button", class: "small link", "aria-label": `Remove robot ${k}`, onclick: () => this.remove(k) },
          "Remove")),
      poses, h("p", { class: "error", id: err }));
  }

  clearErrors() {
    for (const el of $$(".robot .error", this.box)) el.textContent = "";
  }

  /** Show `message` under robot `k`, its `part` ("start"/"goal"; null or "path": both) marked; the element to
   * focus, or null when there is no robot `k`. */
  showError(k, part, message) {
    const target = this.box.querySelector(`#err-robots-${k}`);
    if (!target) return null;
    target.textContent = message;
    const els = $$(`input[data-robot="${k}"]`, this.box).filter((el) => !part || part === "path" || el.dataset.pose === part);
    for (const el of els) el.setAttribute("aria-invalid", "true");
    return els[0] || target;
  }

  /** The mistakes worth catching before sending: `[k or null, message]` each (null: the list). */
  problems() {
    const out = [];
    if (this.robots.length < 2) out.push([null, `a multi-robot job has at least 2 robots; add ${2 - this.robots.length} more`]);
    this.robots.forEach((r, k) => {
      const missing = ["start", "goal"].filter((which) => !r[which]);
      if (missing.length) out.push([k, `robot ${k}: place its ${missing.join(" and ")} on the map or type x and y`]);
    });
    return out;
  }

  /** The robots as the job's `robots` (m, rad); with `paths`, each robot's `path` start → waypoints → goal. */
  body(paths) {
    return this.robots.map((r) => ({ start: r.start, goal: r.goal,
      ...(paths ? { path: [r.start, ...r.waypoints, r.goal] } : {}) }));
  }

  /** The map layers, as the experiment page draws a fleet: every robot's start (a ring, numbered) and goal (a
   * smaller ring) in its colour, the one being placed drawn thicker, and each robot's way: its explicit path
   * dashed (`paths`), else a faint line pairing start and goal. */
  layers(pick, paths) {
    const markers = [];
    const lines = [];
    this.robots.forEach((r, k) => {
      const color = robotColor(k);
      const active = k === this.active;
      if (r.start) markers.push({ x: r.start[0], y: r.start[1], theta: r.start[2], color, label: `${k}`, radius: 0.045,
        active: active && pick === "start" });
      if (r.goal) markers.push({ x: r.goal[0], y: r.goal[1], theta: r.goal[2], color, radius: 0.025,
        active: active && pick === "goal" });
      if (paths) {
        r.waypoints.forEach(([x, y], i) => markers.push({ x, y, radius: 0.02, color, label: active ? String(i + 1) : null,
          active: active && pick === "waypoint" && i === r.waypoints.length - 1 }));
        const pts = [r.start, ...r.waypoints, r.goal].filter(Boolean).map((q) => [q[0], q[1]]);
        lines.push({ points: pts, color, width: 2, dash: [7, 5] });
      } else if (r.start && r.goal) {
        lines.push({ points: [r.start, r.goal].map((q) => [q[0], q[1]]), color, width: 1, dash: [2, 4], alpha: 0.5 });
      }
    });
    return { markers, paths: lines };
  }
}
