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
