// Drawing the task on a canvas: sky, ground, the pad, a metre grid with labels (the scale), the start box,
// the vehicle at its attitude with its thrust, an optional trail, and the sticks. World units are metres, y up.

const VEHICLE_HALF_WIDTH = 0.22; // m, drawn size only

export class View {
  constructor(canvas, spec) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.spec = spec;
    this.trail = [];
    this.showTrail = true;
    this.guide = null; // [[x, y], ...] drawn dashed, or null
  }

  fit() {
    const c = this.canvas, dpr = window.devicePixelRatio || 1;
    const w = c.clientWidth, h = c.clientHeight;
    if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
      c.width = Math.round(w * dpr); c.height = Math.round(h * dpr);
    }
    const [x0, x1] = this.spec.domain.x, [y0, y1] = this.spec.domain.y;
    const margin = 36;
    const scale = Math.min((w - 2 * margin) / (x1 - x0), (h - 2 * margin) / (y1 - y0 + 0.3));
    this.scale = scale;
    this.ox = w / 2 - ((x0 + x1) / 2) * scale;
    this.oy = h - margin - 0.15 * scale;
    this.dpr = dpr;
  }

  sx(x) { return this.ox + x * this.scale; }
  sy(y) { return this.oy - y * this.scale; }

  draw(x, u, info = {}) {
    this.fit();
    const ctx = this.ctx, s = this.spec, i = s.index;
    ctx.setTransform(this.dpr, 0, 0, this.dpr, 0, 0);
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    const sky = ctx.createLinearGradient(0, 0, 0, h);
    sky.addColorStop(0, "#dfe9f5"); sky.addColorStop(1, "#f7f9fc");
    ctx.fillStyle = sky; ctx.fillRect(0, 0, w, h);
    // the domain and a metre grid with labels
    const [x0, x1] = s.domain.x, [, y1] = s.domain.y;
    ctx.strokeStyle = "#c9d4e3"; ctx.lineWidth = 1; ctx.fillStyle = "#5b6b80"; ctx.font = "12px system-ui, sans-serif";
    for (let gx = Math.ceil(x0); gx <= x1; gx++) {
      ctx.beginPath(); ctx.moveTo(this.sx(gx), this.sy(0)); ctx.lineTo(this.sx(gx), this.sy(y1)); ctx.stroke();
    }
    for (let gy = 1; gy <= y1; gy++) {
      ctx.beginPath(); ctx.moveTo(this.sx(x0), this.sy(gy)); ctx.lineTo(this.sx(x1), this.sy(gy)); ctx.stroke();
      ctx.textAlign = "right"; ctx.fillText(`${gy} m`, this.sx(x0) - 4, this.sy(gy) + 4);
    }
    ctx.strokeStyle = "#8796ab"; ctx.setLineDash([6, 4]);
    ctx.strokeRect(this.sx(x0), this.sy(y1), (x1 - x0) * this.scale, y1 * this.scale);
    ctx.setLineDash([]);
    // the start box, labelled: where every trial starts
    const bx = this.sx(s.start.x[0]), by = this.sy(s.start.y[1]);
    const bw = (s.start.x[1] - s.start.x[0]) * this.scale, bh = (s.start.y[1] - s.start.y[0]) * this.scale;
    ctx.fillStyle = "rgba(90, 120, 200, 0.10)"; ctx.fillRect(bx, by, bw, bh);
    ctx.strokeStyle = "rgba(90, 120, 200, 0.45)"; ctx.setLineDash([3, 3]); ctx.strokeRect(bx, by, bw, bh);
    ctx.setLineDash([]);
    // labelled outside the box, on its left (no start is there, so the vehicle never covers the label)
    ctx.fillStyle = "#4a5f99"; ctx.textAlign = "right"; ctx.font = "12px system-ui, sans-serif";
    ctx.fillText("start box", bx - 6, by + bh / 2 + 4);
    // ground and pad
    ctx.fillStyle = "#6b7d5a"; ctx.fillRect(0, this.sy(0), w, h - this.sy(0));
    ctx.fillStyle = "#2e9e57";
    ctx.fillRect(this.sx(s.pad.x - s.pad.half_width), this.sy(0) - 5, 2 * s.pad.half_width * this.scale, 8);
    ctx.fillStyle = "#ffffff"; ctx.textAlign = "center"; ctx.font = "bold 12px system-ui, sans-serif";
    ctx.fillText("PAD", this.sx(s.pad.x), this.sy(0) + 18);
    // the horizontal scale, on the ground (after it, so the ground does not cover it)
    ctx.fillStyle = "#eef2e6"; ctx.font = "12px system-ui, sans-serif";
    for (let gx = Math.ceil(x0); gx <= x1; gx++) {
      if (Math.abs(gx - s.pad.x) > s.pad.half_width) ctx.fillText(`${gx} m`, this.sx(gx), this.sy(0) + 18);
    }
    // an assisted trial's guide: the model's predicted path from the start
    if (this.guide && this.guide.length > 1) {
      ctx.strokeStyle = "rgba(59, 111, 216, 0.9)"; ctx.lineWidth = 2; ctx.setLineDash([8, 6]); ctx.beginPath();
      this.guide.forEach(([gx, gy], j) => (j ? ctx.lineTo(this.sx(gx), this.sy(gy)) : ctx.moveTo(this.sx(gx), this.sy(gy))));
      ctx.stroke(); ctx.setLineDash([]);
    }
    if (!x) return;
    // trail
    if (this.showTrail && this.trail.length > 1) {
      ctx.strokeStyle = "rgba(40, 60, 110, 0.45)"; ctx.lineWidth = 2; ctx.beginPath();
      this.trail.forEach(([tx, ty], j) => (j ? ctx.lineTo(this.sx(tx), this.sy(ty)) : ctx.moveTo(this.sx(tx), this.sy(ty))));
      ctx.stroke();
    }
    this.drawVehicle(x[i.x], x[i.y], x[i.attitude], u ? u[1] : 0, info.outcome);
  }

  drawVehicle(px, py, phi, thrust, outcome) {
    const ctx = this.ctx, hw = VEHICLE_HALF_WIDTH * this.scale;
    ctx.save();
    ctx.translate(this.sx(px), this.sy(Math.max(py, 0)));
    ctx.rotate(phi); // positive attitude tilts the thrust toward +x: clockwise on a y-up screen
    // thrust: a flame under the body, longer for more thrust (0 = hover)
    const flame = Math.max(0, 0.5 + 0.5 * thrust) * 0.5 * hw;
    ctx.fillStyle = "rgba(255, 140, 0, 0.8)";
    ctx.beginPath(); ctx.moveTo(-0.25 * hw, 4); ctx.lineTo(0, 4 + flame); ctx.lineTo(0.25 * hw, 4); ctx.fill();
    ctx.fillStyle = outcome === "landed" ? "#2e9e57" : outcome ? "#c0392b" : "#1f2d4a";
    ctx.fillRect(-hw, -4, 2 * hw, 8);
    ctx.fillRect(-0.3 * hw, -10, 0.6 * hw, 8);
    ctx.strokeStyle = "#1f2d4a"; ctx.lineWidth = 3;
    for (const side of [-1, 1]) {
      ctx.beginPath(); ctx.moveTo(side * hw, -4); ctx.lineTo(side * hw, -9); ctx.stroke();
      ctx.beginPath(); ctx.moveTo(side * hw - 0.35 * hw, -10); ctx.lineTo(side * hw + 0.35 * hw, -10); ctx.stroke();
    }
    ctx.restore();
  }
}

// Two stick gauges: a bar per input from -1 to 1, the raw reading as a tick and the calibrated value as a bar.
export function drawSticks(canvas, raw, u, labels) {
  const ctx = canvas.getContext("2d"), dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  const rows = u.length, rh = h / rows;
  ctx.font = "12px system-ui, sans-serif";
  for (let r = 0; r < rows; r++) {
    const y = r * rh + rh / 2, left = 130, width = w - left - 10, mid = left + width / 2;
    ctx.fillStyle = "#1f2d4a"; ctx.textAlign = "left"; ctx.fillText(labels[r], 4, y + 4);
    ctx.fillStyle = "#e3e8f0"; ctx.fillRect(left, y - 7, width, 14);
    ctx.fillStyle = "#3b6fd8"; ctx.fillRect(mid, y - 7, (u[r] * width) / 2, 14);
    ctx.fillStyle = "#c0392b"; ctx.fillRect(mid + (raw[r] * width) / 2 - 1, y - 10, 2, 20);
    ctx.fillStyle = "#1f2d4a"; ctx.fillRect(mid, y - 10, 1, 20);
  }
}
