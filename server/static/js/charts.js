// Inline SVG charts (no library): per-metric sim-vs-twb bars with CI whiskers and
// the individual runs as dots, and line charts over time.

import { num, s } from "./dom.js";

/** A tick step of 1, 2, 2.5 or 5 x 10^k giving about `count` steps up to `v`; [step, top, decimals]. */
function ticks(v, count = 4) {
  if (!(v > 0)) v = 1;
  const raw = v / count;
  const p = 10 ** Math.floor(Math.log10(raw));
  const m = [1, 2, 2.5, 5, 10].find((k) => k * p >= raw - 1e-12);
  const step = m * p;
  const top = Math.ceil(v / step - 1e-9) * step;
  const decimals = Math.max(0, -Math.floor(Math.log10(step) + 1e-9) + (m === 2.5 ? 1 : 0));
  return [step, top, decimals];
}

/**
 * groups: [{label, color, values: [..], agg: {mean, std, ci_low, ci_high, n}}]; ref: optional
 * {value, label} drawn as a dashed line (e.g. the planned path's value).
 */
export function barChart({ title, unit = "", groups, ref = null }) {
  const W = 240, H = 150, L = 40, R = 8, T = 12, B = 26;
  const all = groups.flatMap((g) => [...g.values, g.agg?.ci_high, g.agg?.mean]).concat(ref ? [ref.value] : [])
    .filter((v) => Number.isFinite(v));
  const lo = 0;
  const [step, hi, dec] = ticks(Math.max(...all, 0) * 1.08 || 1);
  const y = (v) => T + (H - T - B) * (1 - (v - lo) / (hi - lo || 1));
  const svg = s("svg", { viewBox: `0 0 ${W} ${H}`, role: "img", "aria-label": `${title}${unit ? ` (${unit})` : ""}: ` +
    groups.map((g) => `${g.label} mean ${num(g.agg?.mean)}`).join(", ") });
  svg.append(s("title", {}, title));
  // axis and ticks
  for (let v = 0; v <= hi + step / 2; v += step) {
    svg.append(s("line", { x1: L, x2: W - R, y1: y(v), y2: y(v), stroke: "#e3e7ec" }));
    svg.append(s("text", { x: L - 4, y: y(v) + 3, "text-anchor": "end", "font-size": 9, fill: "#5b6675" }, v.toFixed(dec)));
  }
  const slot = (W - L - R) / Math.max(groups.length, 1);
  groups.forEach((g, i) => {
    const cx = L + slot * (i + 0.5);
    const bw = Math.min(42, slot * 0.55);
    const m = g.agg?.mean;
    if (Number.isFinite(m)) {
      svg.append(s("rect", { x: cx - bw / 2, y: Math.min(y(m), y(0)), width: bw, height: Math.abs(y(0) - y(m)) || 1,
        fill: g.color, "fill-opacity": 0.35, stroke: g.color }));
      let clo = Number.isFinite(g.agg.ci_low) ? g.agg.ci_low : Number.isFinite(g.agg.std) ? m - g.agg.std : null;
      let chi = Number.isFinite(g.agg.ci_high) ? g.agg.ci_high : Number.isFinite(g.agg.std) ? m + g.agg.std : null;
      if (clo !== null && chi !== null) {
        // a t-interval of a few runs can reach below zero: draw it to the axis
        clo = Math.max(lo, clo);
        chi = Math.min(hi, chi);
        const note = clo > g.agg.ci_low ? ` (it reaches ${num(g.agg.ci_low)}; shown clipped at 0: the metric cannot be negative)` : "";
        svg.append(s("path", { d: `M${cx},${y(clo)}V${y(chi)}M${cx - 6},${y(clo)}H${cx + 6}M${cx - 6},${y(chi)}H${cx + 6}`,
          stroke: "#1c2430", "stroke-width": 1.2, fill: "none" },
        s("title", {}, `${g.label} 95% interval [${num(clo)}, ${num(chi)}]${note}`)));
      }
      svg.append(s("text", { x: cx, y: Math.max(T + 8, y(Math.max(m, chi ?? m)) - 4), "text-anchor": "middle", "font-size": 9.5, fill: "#1c2430" }, num(m)));
    }
    g.values.forEach((v, k) => {
      if (!Number.isFinite(v)) return;
      const jitter = g.values.length > 1 ? ((k / (g.values.length - 1)) - 0.5) * bw * 0.6 : 0;
      svg.append(s("circle", { cx: cx + jitter, cy: y(v), r: 2.6, fill: g.color }, s("title", {}, `${g.label} run ${k + 1}: ${num(v)}`)));
    });
    // a group without values says so on a line of its own, within its slot
    svg.append(s("text", { x: cx, y: g.note ? H - 14 : H - 9, "text-anchor": "middle", "font-size": 10.5, fill: "#1c2430" },
      g.note ? g.label : `${g.label} (n=${g.agg?.n ?? g.values.length})`));
    if (g.note) svg.append(s("text", { x: cx, y: H - 3, "text-anchor": "middle", "font-size": 9, fill: "#5b6675" }, g.note));
  });
  if (ref && Number.isFinite(ref.value)) {
    svg.append(s("line", { x1: L, x2: W - R, y1: y(ref.value), y2: y(ref.value), stroke: "#2e9d4a", "stroke-dasharray": "5 3", "stroke-width": 1.5 },
      s("title", {}, `${ref.label}: ${num(ref.value)}`)));
  }
  svg.append(s("line", { x1: L, x2: L, y1: T, y2: H - B, stroke: "#8a96a5" }));
  return svg;
}

/** series: [{label, color, points: [[x, y], ...], dash}]; legend: [{label, color}] drawn top right. */
export function lineChart({ title, xLabel, yLabel, series, legend = [] }) {
  const W = 640, H = 220, L = 46, R = 10, T = 12, B = 34;
  const xs = series.flatMap((q) => q.points.map((p) => p[0])).filter(Number.isFinite);
  const ys = series.flatMap((q) => q.points.map((p) => p[1])).filter(Number.isFinite);
  const x0 = 0;
  const [xStep, x1, xDec] = ticks(Math.max(...xs, 1e-9), 6);
  const [yStep, y1, yDec] = ticks(Math.max(...ys, 1e-9) * 1.05);
  const X = (v) => L + ((W - L - R) * (v - x0)) / (x1 - x0 || 1);
  const Y = (v) => T + (H - T - B) * (1 - v / (y1 || 1));
  const svg = s("svg", { viewBox: `0 0 ${W} ${H}`, role: "img", "aria-label": `${title}: ${series.map((q) => q.label).join(", ")}` });
  svg.append(s("title", {}, title));
  for (let v = 0; v <= y1 + yStep / 2; v += yStep) {
    svg.append(s("line", { x1: L, x2: W - R, y1: Y(v), y2: Y(v), stroke: "#e3e7ec" }));
    svg.append(s("text", { x: L - 4, y: Y(v) + 3, "text-anchor": "end", "font-size": 10, fill: "#5b6675" }, v.toFixed(yDec)));
  }
  for (let v = 0; v <= x1 + xStep / 2; v += xStep) {
    svg.append(s("text", { x: X(v), y: H - B + 13, "text-anchor": "middle", "font-size": 10, fill: "#5b6675" }, v.toFixed(xDec)));
  }
  svg.append(s("text", { x: (L + W - R) / 2, y: H - 4, "text-anchor": "middle", "font-size": 11, fill: "#1c2430" }, xLabel));
  svg.append(s("text", { x: 12, y: (T + H - B) / 2, "text-anchor": "middle", "font-size": 11, fill: "#1c2430",
    transform: `rotate(-90 12 ${(T + H - B) / 2})` }, yLabel));
  for (const q of series) {
    if (q.points.length < 2) continue;
    const d = q.points.map(([a, b], i) => `${i ? "L" : "M"}${X(a).toFixed(1)},${Y(b).toFixed(1)}`).join("");
    svg.append(s("path", { d, fill: "none", stroke: q.color, "stroke-width": 1.6, "stroke-dasharray": q.dash || null,
      "stroke-opacity": q.alpha ?? 1 }, s("title", {}, q.label)));
  }
  svg.append(s("path", { d: `M${L},${T}V${H - B}H${W - R}`, stroke: "#8a96a5", fill: "none" }));
  if (legend.length) svg.append(chartLegend(legend, W - R - 8, T + 4));
  return svg;
}

/** A legend box of coloured lines and labels whose top right corner is (`right`, `top`). */
function chartLegend(items, right, top) {
  const width = 30 + Math.max(...items.map((it) => it.label.length)) * 6.2;
  const g = s("g", { class: "chart-legend", transform: `translate(${right - width},${top})` });
  g.append(s("rect", { x: 0, y: 0, width, height: 8 + items.length * 15, fill: "#ffffff", "fill-opacity": 0.9, stroke: "#d7dde5", rx: 3 }));
  items.forEach((it, i) => {
    const yy = 12 + i * 15;
    g.append(s("line", { x1: 6, x2: 22, y1: yy, y2: yy, stroke: it.color, "stroke-width": 2.2 }));
    g.append(s("text", { x: 27, y: yy + 3.5, "font-size": 10.5, fill: "#1c2430" }, it.label));
  });
  return g;
}

/** Speed over time (s since the run's start, m/s) from logged poses [[t, x, y, theta]], over >= `window` s. */
export function speedProfile(poses, t0 = null, window = 0.25, maxPoints = 300) {
  if (poses.length < 2) return [];
  const start = Number.isFinite(t0) ? t0 : poses[0][0];
  const arc = [0];
  for (let i = 1; i < poses.length; i++) arc.push(arc[i - 1] + Math.hypot(poses[i][1] - poses[i - 1][1], poses[i][2] - poses[i - 1][2]));
  const out = [];
  let j = 0;
  for (let i = 1; i < poses.length; i++) {
    while (j < i && poses[i][0] - poses[j + 1][0] >= window) j++;
    const dt = poses[i][0] - poses[j][0];
    if (dt >= window * 0.5) out.push([poses[i][0] - start, (arc[i] - arc[j]) / dt]);
  }
  const step = Math.max(1, Math.ceil(out.length / maxPoints));
  return out.filter((_, i) => i % step === 0 && out[i][0] >= 0);
}
