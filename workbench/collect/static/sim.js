// The task's simulation: the plant's discrete A, B from the server (never a copy), stepped at the plant's dt.
// step() sums each row as the server's workbench.collect.task.step does (A x left to right, then B u, then
// their sum), so the page and the server's replay give the same bits for the same state and inputs.

export function step(A, B, x, u) {
  const out = new Array(A.length);
  for (let i = 0; i < A.length; i++) {
    let ax = 0.0;
    for (let j = 0; j < x.length; j++) ax += A[i][j] * x[j];
    let bu = 0.0;
    for (let j = 0; j < u.length; j++) bu += B[i][j] * u[j];
    out[i] = ax + bu;
  }
  return out;
}

// The arbitration law of an assisted trial (workbench.collect.task.blend): (1 - alpha) pilot + alpha clip(K (x - target)).
export function blend(spec, K, alpha, x, pilot) {
  const out = new Array(K.length);
  for (let i = 0; i < K.length; i++) {
    let m = 0.0;
    for (let j = 0; j < x.length; j++) m += K[i][j] * (x[j] - spec.target[j]);
    m = Math.min(Math.max(m, spec.u_min[i]), spec.u_max[i]);
    out[i] = (1 - alpha) * pilot[i] + alpha * m;
  }
  return out;
}

// How a trial ends at sample k in state x, or null: the rules of workbench.collect.task.outcome.
export function outcome(spec, x, k) {
  const i = spec.index;
  const px = x[i.x], py = x[i.y], phi = x[i.attitude];
  if (py <= 0.0) {
    const speed = Math.hypot(x[i.vx], x[i.vy]);
    const onPad = Math.abs(px - spec.pad.x) <= spec.pad.half_width;
    const gentle = speed < spec.landing.speed && Math.abs(phi) < spec.landing.attitude;
    return onPad && gentle ? "landed" : "crashed";
  }
  if (!(spec.domain.x[0] <= px && px <= spec.domain.x[1] && py <= spec.domain.y[1])) return "left the domain";
  if (k >= spec.max_steps) return "time limit";
  return null;
}

// Why a trial ended as it did, with the numbers against the rules: the words of workbench.collect.task.reason.
export function reason(spec, x, end) {
  const i = spec.index, L = spec.landing;
  const speed = Math.hypot(x[i.vx], x[i.vy]);
  const tilt = (Math.abs(x[i.attitude]) * 180) / Math.PI, limitTilt = (L.attitude * 180) / Math.PI;
  const off = Math.abs(x[i.x] - spec.pad.x);
  if (end === "landed") {
    return `landed: ${speed.toFixed(2)} m/s < ${L.speed} m/s, ${tilt.toFixed(1)}° < ${limitTilt.toFixed(0)}°, ` +
      `${off.toFixed(2)} m from the pad's centre`;
  }
  if (end === "crashed") {
    const why = [];
    if (off > spec.pad.half_width) why.push(`${off.toFixed(2)} m from the pad's centre > ${spec.pad.half_width} m`);
    if (speed >= L.speed) why.push(`${speed.toFixed(3)} m/s ≥ ${L.speed} m/s`);
    if (tilt >= limitTilt) why.push(`${tilt.toFixed(2)}° ≥ ${limitTilt.toFixed(0)}°`);
    return `crashed: ${why.join(", ")}`;
  }
  if (end === "left the domain") {
    const [lo, hi] = spec.domain.x, top = spec.domain.y[1], px = x[i.x];
    const side = px < lo ? `x = ${px.toFixed(2)} m < ${lo} m` : px > hi ? `x = ${px.toFixed(2)} m > ${hi} m`
      : `height ${x[i.y].toFixed(2)} m > ${top} m`;
    return `left the area: ${side}`;
  }
  if (end === "time limit") return `out of time: ${spec.time_limit_s} s`;
  return String(end);
}

// One trial on a fixed physics step, independent of the display rate: advance(now) runs as many steps as the
// time since the last call holds (an accumulator), each one sampling the sticks, recording (x[k], u[k]),
// checking the end and stepping. Steps the display could not keep up with are run late and counted as
// dropped (more than maxCatchUp at once are not run: the trial's clock then lags, counted, never hidden).
export class Trial {
  constructor(spec, x0, sample, { maxCatchUp = 5 } = {}) {
    this.spec = spec;
    this.x = x0.slice();
    this.sample = sample; // (x) => {u, raw, pilot?}: the input at this step (pilot: the pilot's own, if assisted)
    this.xs = []; this.us = []; this.raws = []; this.pilots = []; this.stepWall = [];
    this.k = 0;
    this.ended = null;
    this.acc = 0;
    this.last = null;
    this.maxCatchUp = maxCatchUp;
    this.late = 0; // steps run more than one step behind the wall clock
    this.skipped = 0; // steps the wall clock passed that were never run (a stall longer than maxCatchUp steps)
    this.frames = []; // display frame times (s from start)
    this.t0 = null;
  }

  physicsStep(now) {
    const s = this.sample(this.x);
    this.xs.push(this.x.slice());
    this.us.push(s.u.slice());
    this.raws.push(s.raw.slice());
    this.pilots.push((s.pilot || s.u).slice());
    this.stepWall.push((now - this.t0) / 1000);
    const end = outcome(this.spec, this.x, this.k);
    if (end !== null) { this.ended = end; return; }
    this.x = step(this.spec.A, this.spec.B, this.x, s.u);
    this.k += 1;
  }

  advance(now) {
    if (this.ended) return 0;
    const dtMs = this.spec.dt * 1000;
    if (this.last === null) {
      this.last = now; this.t0 = now;
      this.frames.push(0);
      this.physicsStep(now);
      return 1;
    }
    this.frames.push((now - this.t0) / 1000);
    this.acc += now - this.last;
    this.last = now;
    let n = 0;
    while (this.acc >= dtMs && !this.ended) {
      if (n >= this.maxCatchUp) {
        const lost = Math.floor(this.acc / dtMs);
        this.skipped += lost;
        this.acc -= lost * dtMs;
        break;
      }
      this.acc -= dtMs;
      if (n >= 1) this.late += 1;
      this.physicsStep(now);
      n += 1;
    }
    return n;
  }

  timing() {
    const f = this.frames;
    const gaps = f.slice(1).map((t, j) => t - f[j]);
    const mean = gaps.length ? gaps.reduce((a, b) => a + b, 0) / gaps.length : 0;
    return {
      display_frames: f.length,
      display_interval_mean_s: mean,
      display_interval_max_s: gaps.length ? Math.max(...gaps) : 0,
      physics_steps: this.us.length,
      late_steps: this.late,
      dropped_steps: this.skipped,
      wall_duration_s: this.stepWall.length ? this.stepWall[this.stepWall.length - 1] : 0,
    };
  }
}
