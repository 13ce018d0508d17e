// A to-scale map on a <canvas>: world metres (x right, y up) to CSS pixels.
//
// The canvas exposes its mapping as data attributes (data-scale: px per metre,
// data-ox / data-oy: CSS px of the world origin, data-world: "w,h") so tools and
// tests can locate things on it.

export const COLORS = {
  sim: "#7b3fbf",
  twb: "#1f77b4",
  planned: "#2e9d4a",
  robot: "#ff6d00",
  robotGhost: "#ffb27a",
  block: "#4a5563",
  wall: "#1c2430",
  start: "#2e9d4a",
  goal: "#c62828",
  obstacle: "#00897b",
};

const STATE_FILL = {
  idle: "#ffffff",
  building: "#ffe8a3", // the gripper at work: hatched
  placing: "#ffe8a3",
  planning: "#ffe8a3",
  running: "#d6e9fb",
  analyzing: "#d6e9fb",
  reserved: "#ece4f7",
  offline: "#c9ced6",
};

export class MapView {
  /** world: [w, h] metres shown; padding: CSS px around it. */
  constructor(canvas, { world = [3.6, 3.6], padding = 18 } = {}) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.world = world;
    this.padding = padding;
    this.layers = {};
    this.frame = 0;
    this.observer = new ResizeObserver(() => this.render());
    this.observer.observe(canvas);
  }

  /** Stop following the canvas's size (before dropping the view). */
  destroy() {
    this.observer.disconnect();
    if (this.frame) cancelAnimationFrame(this.frame);
    this.frame = 0;
  }

  setWorld(world) {
    this.world = world;
    this.render();
  }

  /** Replace some layers and redraw on the next animation frame. */
  update(layers) {
    Object.assign(this.layers, layers);
    this.request();
  }

  request() {
    if (this.frame) return;
    this.frame = requestAnimationFrame(() => {
      this.frame = 0;
      this.render();
    });
  }

  geometry() {
    const cssW = this.canvas.clientWidth || 300;
    const cssH = this.canvas.clientHeight || cssW;
    const [w, h] = this.world;
    const p = this.padding;
    const scale = Math.max(1e-6, Math.min((cssW - 2 * p) / w, (cssH - 2 * p) / h));
    const ox = (cssW - w * scale) / 2;
    const oy = (cssH + h * scale) / 2; // y of the world origin (bottom)
    return { cssW, cssH, scale, ox, oy };
  }

  toPx(x, y) {
    const g = this.geometry();
    return [g.ox + x * g.scale, g.oy - y * g.scale];
  }

  toWorld(px, py) {
    const g = this.geometry();
    return [(px - g.ox) / g.scale, (g.oy - py) / g.scale];
  }

  render() {
    const { canvas, ctx } = this;
    const g = this.geometry();
    const dpr = window.devicePixelRatio || 1;
    const W = Math.round(g.cssW * dpr);
    const H = Math.round(g.cssH * dpr);
    if (canvas.width !== W || canvas.height !== H) {
      canvas.width = W;
      canvas.height = H;
    }
    Object.assign(canvas.dataset, {
      scale: g.scale.toFixed(4), ox: g.ox.toFixed(2), oy: g.oy.toFixed(2), world: this.world.join(","),
    });
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, g.cssW, g.cssH);
    const L = this.layers;
    const [w, h] = this.world;
    const X = (x) => g.ox + x * g.scale;
    const Y = (y) => g.oy - y * g.scale;

    // floor
    ctx.fillStyle = "#fbfcfd";
    ctx.fillRect(X(0), Y(h), w * g.scale, h * g.scale);

    // sub-field states
    for (const sf of L.subfields || []) {
      const [sx, sy] = sf.origin;
      const [sw, sh] = sf.size;
      ctx.fillStyle = STATE_FILL[sf.state] || "#ffffff";
      ctx.fillRect(X(sx), Y(sy + sh), sw * g.scale, sh * g.scale);
      if (sf.state === "offline" || sf.state === "building" || sf.state === "placing") this.hatch(X(sx), Y(sy + sh), sw * g.scale, sh * g.scale);
    }

    // 0.3 m grid
    ctx.strokeStyle = "#e6eaef";
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (let x = 0.3; x < w - 1e-9; x += 0.3) { ctx.moveTo(X(x), Y(0)); ctx.lineTo(X(x), Y(h)); }
    for (let y = 0.3; y < h - 1e-9; y += 0.3) { ctx.moveTo(X(0), Y(y)); ctx.lineTo(X(w), Y(y)); }
    ctx.stroke();

    // sub-field borders and labels
    for (const sf of L.subfields || []) {
      const [sx, sy] = sf.origin;
      const [sw, sh] = sf.size;
      ctx.strokeStyle = "#8a96a5";
      ctx.lineWidth = 1.5;
      ctx.setLineDash([6, 4]);
      ctx.strokeRect(X(sx), Y(sy + sh), sw * g.scale, sh * g.scale);
      ctx.setLineDash([]);
      if (sf.label) {
        ctx.font = "600 12px system-ui, sans-serif";
        ctx.fillStyle = "#3b4552";
        ctx.textBaseline = "top";
        ctx.fillText(sf.label, X(sx) + 6, Y(sy + sh) + 5);
      }
    }

    // blocks; planned ones (an environment being built) faint
    for (const [list, alpha] of [[L.plannedBlocks, 0.28], [L.blocks, 1]]) {
      ctx.fillStyle = COLORS.block;
      ctx.globalAlpha = alpha;
      for (const b of list || []) {
        ctx.save();
        ctx.translate(X(b.x), Y(b.y));
        ctx.rotate(-(b.angle || 0));
        ctx.fillRect((-b.w / 2) * g.scale, (-b.h / 2) * g.scale, b.w * g.scale, b.h * g.scale);
        ctx.restore();
      }
      ctx.globalAlpha = 1;
    }

    // field walls
    ctx.strokeStyle = COLORS.wall;
    ctx.lineWidth = 3;
    ctx.strokeRect(X(0), Y(h), w * g.scale, h * g.scale);

    // paths
    for (const p of L.paths || []) {
      if (!p.points || p.points.length < 2) continue;
      ctx.strokeStyle = p.color;
      ctx.globalAlpha = p.alpha ?? 1;
      ctx.lineWidth = p.width ?? 2;
      ctx.lineJoin = "round";
      ctx.setLineDash(p.dash || []);
      ctx.beginPath();
      p.points.forEach(([x, y], i) => (i ? ctx.lineTo(X(x), Y(y)) : ctx.moveTo(X(x), Y(y))));
      ctx.stroke();
      ctx.setLineDash([]);
      ctx.globalAlpha = 1;
    }

    // start / goal markers: a ring with a heading tick
    for (const m of L.markers || []) {
      const r = Math.max(6, (m.radius || 0.045) * g.scale);
      ctx.strokeStyle = m.color;
      ctx.fillStyle = m.color;
      ctx.lineWidth = m.active ? 3 : 2;
      ctx.beginPath();
      ctx.arc(X(m.x), Y(m.y), r, 0, 2 * Math.PI);
      ctx.stroke();
      if (Number.isFinite(m.theta)) {
        ctx.beginPath();
        ctx.moveTo(X(m.x), Y(m.y));
        ctx.lineTo(X(m.x) + 2 * r * Math.cos(m.theta), Y(m.y) - 2 * r * Math.sin(m.theta));
        ctx.stroke();
      }
      if (m.label) {
        ctx.font = "600 11px system-ui, sans-serif";
        ctx.textBaseline = "middle";
        const tw = ctx.measureText(m.label).width;
        const right = X(m.x) + r + 4 + tw < X(w) - 4;
        ctx.textAlign = right ? "left" : "right";
        ctx.fillText(m.label, right ? X(m.x) + r + 4 : X(m.x) - r - 4, Y(m.y) + r + 2);
        ctx.textAlign = "left";
      }
    }

    // moving obstacles: their tracks (dotted: exact; solid: where the tracker saw an obstacle robot) and the
    // discs at true size
    ctx.strokeStyle = COLORS.obstacle;
    ctx.lineWidth = 1;
    for (const tr of L.obstacleTracks || []) {
      if (tr.points.length < 2) continue;
      ctx.setLineDash(tr.solid ? [] : [2, 3]);
      ctx.beginPath();
      tr.points.forEach(([x, y], i) => (i ? ctx.lineTo(X(x), Y(y)) : ctx.moveTo(X(x), Y(y))));
      ctx.stroke();
    }
    ctx.setLineDash([]);
    for (const o of L.obstacles || []) {
      const rad = Math.max(4, o.radius * g.scale);
      ctx.fillStyle = COLORS.obstacle;
      ctx.strokeStyle = "#2f3640";
      ctx.lineWidth = 1.2;
      ctx.beginPath();
      ctx.arc(X(o.x), Y(o.y), rad, 0, 2 * Math.PI);
      ctx.fill();
      ctx.stroke();
      if (o.theta != null) { // an obstacle robot the tracker saw: its heading, as a robot's
        ctx.strokeStyle = "#ffffff";
        ctx.lineWidth = 1.5;
        ctx.beginPath();
        ctx.moveTo(X(o.x), Y(o.y));
        ctx.lineTo(X(o.x) + rad * Math.cos(o.theta), Y(o.y) - rad * Math.sin(o.theta));
        ctx.stroke();
      }
    }

    // robots: filled disc at true size (at least 6 px), white heading line
    for (const r of L.robots || []) {
      const rad = Math.max(6, (r.radius || 0.045) * g.scale);
      const cx = X(r.x);
      const cy = Y(r.y);
      ctx.fillStyle = r.color || (r.ghost ? COLORS.robotGhost : COLORS.robot);
      ctx.strokeStyle = "#5a2600";
      ctx.lineWidth = 1.5;
      ctx.setLineDash(r.ghost ? [3, 2] : []);
      ctx.beginPath();
      ctx.arc(cx, cy, rad, 0, 2 * Math.PI);
      ctx.fill();
      ctx.stroke();
      ctx.setLineDash([]);
      if (Number.isFinite(r.theta)) {
        ctx.strokeStyle = "#ffffff";
        ctx.lineWidth = 2;
        ctx.beginPath();
        ctx.moveTo(cx, cy);
        ctx.lineTo(cx + rad * Math.cos(r.theta), cy - rad * Math.sin(r.theta));
        ctx.stroke();
      }
      if (r.label) {
        ctx.font = "11px system-ui, sans-serif";
        ctx.fillStyle = "#222";
        ctx.textBaseline = "bottom";
        ctx.fillText(r.label, cx + rad + 2, cy - rad + 2);
      }
    }
  }

  hatch(x, y, w, h) {
    const { ctx } = this;
    ctx.save();
    ctx.beginPath();
    ctx.rect(x, y, w, h);
    ctx.clip();
    ctx.strokeStyle = "rgba(0,0,0,0.07)";
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (let d = -h; d < w; d += 12) { ctx.moveTo(x + d, y + h); ctx.lineTo(x + d + h, y); }
    ctx.stroke();
    ctx.restore();
  }

  /** PNG of what is drawn, as a Blob. */
  toBlob() {
    return new Promise((resolve) => this.canvas.toBlob(resolve, "image/png"));
  }
}
