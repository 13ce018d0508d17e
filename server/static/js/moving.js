// Moving obstacles (docs/planners.md "Moving obstacles"): where a disc is at obstacle time t (s from its
// run's path start), from the server's `moving_tracks` (waypoints as it moves, random walks expanded).
// The same arithmetic as planners/moving.py `positions`: until delay_s at the first waypoint, then along
// the polyline at `speed`; "once" stops at its end, "loop" closes the polyline, "pingpong" turns back.

/** The centre [x, y] (m) of `track` at obstacle time `t` (s). */
export function obstacleAt(track, t) {
  const pts = track.waypoints.slice();
  if (track.repeat === "loop" && pts.length > 1) pts.push(pts[0]);
  const cum = [0];
  for (let i = 1; i < pts.length; i++) cum.push(cum[i - 1] + Math.hypot(pts[i][0] - pts[i - 1][0], pts[i][1] - pts[i - 1][1]));
  const length = cum[cum.length - 1];
  const d = track.speed * Math.max(t - (track.delay_s || 0), 0);
  let s = 0;
  if (length > 0) {
    if (track.repeat === "loop") s = d % length;
    else if (track.repeat === "pingpong") {
      const r = d % (2 * length);
      s = r > length ? 2 * length - r : r;
    } else s = Math.min(d, length);
  }
  let i = 1;
  while (i < cum.length - 1 && cum[i] < s) i++;
  if (pts.length < 2) return pts[0].slice();
  const seg = cum[i] - cum[i - 1];
  const u = seg > 0 ? Math.min(Math.max((s - cum[i - 1]) / seg, 0), 1) : 0;
  return [pts[i - 1][0] + u * (pts[i][0] - pts[i - 1][0]), pts[i - 1][1] + u * (pts[i][1] - pts[i - 1][1])];
}

/** The map layers of `tracks` at obstacle time `t` (s): each track dashed, each disc where it is. */
export function obstacleLayers(tracks, t) {
  return {
    obstacleTracks: (tracks || []).map((tr) => ({ points: tr.repeat === "loop" ? [...tr.waypoints, tr.waypoints[0]] : tr.waypoints })),
    obstacles: (tracks || []).map((tr) => {
      const [x, y] = obstacleAt(tr, t);
      return { x, y, radius: tr.radius };
    }),
  };
}

/** Where an obstacle robot was at time `t` (s, its poses' clock) and its heading, `[x, y, theta]` (m, m, rad):
 * `poses` `[[t, x, y, theta], ...]`, oldest first (a field run's stored obstacle tracks, GET
 * /api/v1/runs/{id}/obstacles), interpolated (the heading of the pose before); held before the first and after
 * the last. */
export function trackedAt(poses, t) {
  const n = poses.length;
  if (t <= poses[0][0]) return [poses[0][1], poses[0][2], poses[0][3]];
  if (t >= poses[n - 1][0]) return [poses[n - 1][1], poses[n - 1][2], poses[n - 1][3]];
  let lo = 0;
  let hi = n - 1;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (poses[mid][0] <= t) lo = mid;
    else hi = mid;
  }
  const [a, b] = [poses[lo], poses[hi]];
  const u = b[0] > a[0] ? (t - a[0]) / (b[0] - a[0]) : 0;
  return [a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2]), a[3]];
}

/** The map layers of a run's stored obstacle robots (`obstacles`: `[{radius, poses}]`) at time `t` (s, the run's
 * clock): each one's track solid up to `t`, and the robot where it was then, with its heading. */
export function trackedLayers(obstacles, t) {
  const shown = (obstacles || []).filter((o) => o.poses.length);
  return {
    obstacleTracks: shown.map((o) => ({ points: o.poses.filter((p) => p[0] <= t).map((p) => [p[1], p[2]]), solid: true })),
    obstacles: shown.map((o) => {
      const [x, y, theta] = trackedAt(o.poses, t);
      return { x, y, theta, radius: o.radius };
    }),
  };
}
