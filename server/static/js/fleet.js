// Multi-robot ("fleet") experiments on the dashboard (docs/server.md "Multi-robot jobs"): a colour per
// robot, a run's poses split by their robot column, the per-robot map layers and the per-robot table.

import { h, num } from "./dom.js";

/** A colour per robot of a fleet (up to 16), apart from the modes', the obstacles' and the markers'. */
export const ROBOT_COLORS = ["#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4", "#f032e6", "#9a6324",
  "#800000", "#469990", "#808000", "#000075", "#bfef45", "#dcbeff", "#fabed4", "#aaffc3"];

export function robotColor(k) {
  return ROBOT_COLORS[k % ROBOT_COLORS.length];
}

/** A colour swatch (CSSOM: the page's CSP refuses style attributes). */
export function swatch(color) {
  const el = h("span", { class: "swatch", "aria-hidden": "true" });
  el.style.background = color;
  return el;
}

/** A fleet run's poses `[t, x, y, theta, robot]` as one list of `[t, x, y, theta]` per robot. */
export function byRobot(poses) {
  const out = [];
  for (const p of poses || []) {
    const k = p.length > 4 && p[4] != null ? p[4] : 0;
    (out[k] ||= []).push(p.slice(0, 4));
  }
  return out;
}

/** The experiment map's layers of fleet experiment `d`: each robot's planned path dashed and its start and goal
 * in its colour, and each shown run's performed paths per robot (`poses`: run id -> logged poses; twb solid,
 * sim dotted) with where each robot ended. */
export function fleetLayers(d, runs, poses, hidden) {
  const planned = d.planning_info?.robots || [];
  const paths = [];
  const markers = [];
  const robots = [];
  (d.robots || []).forEach((r, k) => {
    const c = robotColor(k);
    const p = planned[k]?.path;
    if (p && !hidden.has("planned")) paths.push({ points: p.map((q) => [q[0], q[1]]), color: c, width: 1.6, dash: [7, 5], alpha: 0.8 });
    markers.push({ x: r.start[0], y: r.start[1], theta: r.start[2], color: c, label: `${k}`, radius: 0.04 });
    markers.push({ x: r.goal[0], y: r.goal[1], theta: r.goal[2], color: c, radius: 0.025 });
  });
  for (const run of runs) {
    if (hidden.has(`run-${run.id}`) || !poses.has(run.id)) continue;
    byRobot(poses.get(run.id)).forEach((track, k) => {
      if (!track || !track.length) return;
      paths.push({ points: track.map((q) => [q[1], q[2]]), color: robotColor(k), width: 2,
                   dash: run.mode === "sim" ? [2, 3] : [], alpha: 0.9 });
      const last = track[track.length - 1];
      robots.push({ x: last[1], y: last[2], theta: last[3], radius: 0.04, color: robotColor(k), label: `${k}` });
    });
  }
  return { paths, markers, robots };
}

/** The per-robot table of a fleet experiment's runs: how each robot ended, its time, length, closest approach,
 * time within the safety radius and what it hit (docs/metrics.md "Several robots"). */
export function robotsTable(runs) {
  const cols = [["time_s", "Time (s)"], ["path_length_m", "Length (m)"], ["robot_distance_min_m", "Closest robot (m)"],
    ["safety_time_s", "Within safety radius (s)"]];
  const head = h("thead", {}, h("tr", {}, ["Run", "Mode #", "Robot", "Outcome", ...cols.map(([, t]) => t), "Collision"]
    .map((t, i) => h("th", { scope: "col", class: i > 3 && i < 4 + cols.length ? "num" : null }, t))));
  const rows = runs.flatMap((r) => (r.metrics?.robots || []).map((m) => h("tr", { dataset: { run: r.id, robot: m.robot } },
    h("td", {}, r.id), h("td", {}, `${r.mode} #${r.repetition}`),
    h("td", {}, swatch(robotColor(m.robot)), ` ${m.robot}`),
    h("td", {}, m.done ? "arrived" : m.outcome === "TIMEOUT_SIM" ? "timeout" : (m.outcome || "–").toLowerCase()),
    ...cols.map(([k]) => h("td", { class: "num", dataset: { metric: k } }, num(m[k]))),
    h("td", {}, m.collision ? `with ${m.collision === "robot" ? "a robot" : m.collision === "moving" ? "a moving obstacle" : "a block or wall"}` : "–"))));
  return [head, h("tbody", {}, rows.length ? rows : h("tr", { class: "empty-row" }, h("td", { colspan: 5 + cols.length }, "No run measured yet.")))];
}
