// What the server's metrics (docs/metrics.md) are called on the dashboard, and how a 95% interval of
// one is shown: a Student-t interval of a few runs can reach below 0 (or above 1 for a share) where the
// metric cannot go; it is shown clipped to the metric's range, marked with *, its tooltip giving the
// computed bound.

import { h, num } from "./dom.js";

/** Each metric the server reports: [name, unit, [lowest, highest] it can take]. */
export const METRICS = {
  length_m: ["Path length", "m", [0, Infinity]],
  execution_time_s: ["Execution time", "s", [0, Infinity]],
  average_speed_m_s: ["Average speed", "m/s", [0, Infinity]],
  smoothness_rad: ["Smoothness κ'", "rad", [0, Infinity]],
  aol_rad_per_m: ["Angle over length", "rad/m", [0, Infinity]],
  max_curvature_rad_per_m: ["Max. curvature", "rad/m", [0, Infinity]],
  clearance_min_m: ["Minimum clearance", "m", [0, Infinity]],
  clearance_mean_m: ["Mean clearance", "m", [0, Infinity]],
  deviation_mean_m: ["Mean deviation", "m", [0, Infinity]],
  deviation_max_m: ["Max. deviation", "m", [0, Infinity]],
  hausdorff_m: ["Hausdorff distance", "m", [0, Infinity]],
  frechet_m: ["Fréchet distance", "m", [0, Infinity]],
  length_ratio: ["Length ratio", "", [0, Infinity]],
  smoothness_ratio: ["Smoothness ratio", "", [0, Infinity]],
  clearance_ratio: ["Clearance ratio", "", [0, Infinity]],
  goal_reached: ["Goal reached", "share", [0, 1]],
  collided: ["Collided", "share", [0, 1]],
  planning_time_s: ["Planning time", "s", [0, Infinity]],
  cross_track_error_mean_m: ["Mean cross-track error", "m", [0, Infinity]],
  cross_track_error_max_m: ["Max. cross-track error", "m", [0, Infinity]],
  heading_error_rms_rad: ["Heading error RMS", "rad", [0, Math.PI]],
  time_to_goal_s: ["Time to goal", "s", [0, Infinity]],
  jerk_linear_rms_m_s3: ["Linear jerk RMS", "m/s³", [0, Infinity]],
  jerk_angular_rms_rad_s3: ["Angular jerk RMS", "rad/s³", [0, Infinity]],
  velocity_smoothness_m_s2: ["Velocity smoothness", "m/s²", [0, Infinity]],
  stop_count: ["Stops", "", [0, Infinity]],
  collision_count: ["Collisions", "", [0, Infinity]],
  spl: ["SPL", "", [0, 1]],
  barn_score: ["BARN score", "", [0, 0.5]],
  collisions_obstacle: ["Collisions with moving obstacles", "", [0, Infinity]],
  collisions_block: ["Collisions with blocks and walls", "", [0, Infinity]],
  obstacle_distance_min_m: ["Closest approach to a moving obstacle", "m", [-Infinity, Infinity]],
  obstacle_time_within_s: ["Time near a moving obstacle", "s", [0, Infinity]],
  success_rate: ["Robots arrived", "share", [0, 1]],
  makespan_s: ["Makespan", "s", [0, Infinity]],
  time_sum_s: ["Sum of robots' times", "s", [0, Infinity]],
  path_length_sum_m: ["Sum of path lengths", "m", [0, Infinity]],
  robot_distance_min_m: ["Closest approach of two robots", "m", [0, Infinity]],
  safety_time_s: ["Time robots were too close", "s", [0, Infinity]],
  collisions_robot: ["Robot-robot collisions", "", [0, Infinity]],
  collisions_moving: ["Collisions with moving obstacles", "", [0, Infinity]],
  collisions_static: ["Collisions with blocks and walls", "", [0, Infinity]],
  deadlock: ["Deadlocked", "share", [0, 1]],
  no_progress_max_s: ["Longest time without progress", "s", [0, Infinity]],
  controller_steps: ["Controller steps", "", [0, Infinity]],
  controller_cpu_s: ["Controller CPU time", "s", [0, Infinity]],
  controller_cpu_per_step_ms: ["Controller CPU per step", "ms", [0, Infinity]],
  controller_response_ms_median: ["Controller response (median)", "ms", [0, Infinity]],
  controller_response_ms_p95: ["Controller response (95th pct.)", "ms", [0, Infinity]],
};

/** A metric's name ("Path length"); an unknown key as it comes. */
export function metricName(key) {
  return METRICS[key]?.[0] ?? key;
}

/** A metric's name with its unit ("Path length (m)"); an unknown key as it comes. */
export function metricLabel(key) {
  const m = METRICS[key];
  if (!m) return key;
  return m[1] ? `${m[0]} (${m[1]})` : m[0];
}

/** The interval [lo, hi] of metric `key` within the values the metric can take; `clipped` when it was cut. */
export function clipInterval(key, lo, hi) {
  const [min, max] = METRICS[key]?.[2] ?? [-Infinity, Infinity];
  const shown = [Math.max(min, lo), Math.min(max, hi)];
  return { lo: shown[0], hi: shown[1], clipped: shown[0] !== lo || shown[1] !== hi };
}

/** A 95% interval of metric `key` as text, or as a span marked * with the computed bounds in its tooltip
 * when it had to be clipped to the metric's range; "–" when there is none. */
export function intervalText(key, lo, hi) {
  if (lo == null || hi == null) return "–";
  const c = clipInterval(key, lo, hi);
  const text = `[${num(c.lo)}, ${num(c.hi)}]`;
  if (!c.clipped) return text;
  return h("span", { class: "clipped", dataset: { ciLow: lo, ciHigh: hi },
    title: `The Student-t interval is [${num(lo)}, ${num(hi)}]; ${metricName(key)} cannot be ` +
      `${lo < c.lo ? `below ${num(c.lo)}` : `above ${num(c.hi)}`}, so it is shown clipped.` },
  text, h("span", { class: "clip-mark", "aria-hidden": "true" }, "*"));
}

/** The note under a table with clipped intervals (hidden until `showIfClipped(note, table)`). */
export function clipNote(id) {
  return h("p", { class: "muted small clip-note", id, hidden: true }, "* The 95% interval reaches beyond what the metric " +
    "can take (below 0, or above 1 for a share): it is shown clipped; its tooltip gives the computed bounds.");
}

/** Show `note` when `table` has a clipped interval. */
export function showIfClipped(note, table) {
  note.hidden = !table.querySelector(".clipped");
}

/** Whether an aggregate ({n, mean, std}) is of two or more equal values, up to rounding (the simulation's
 * repeated runs; times are clock differences): a zero-width interval would be a fake certainty. */
export function allEqual(a) {
  return a != null && a.n >= 2 && a.std != null && a.std <= 1e-9 * Math.max(1, Math.abs(a.mean ?? 0));
}
