// The sticks: any gamepad or joystick through the standard Gamepad API, or the keyboard as a fallback.
// Each physics step samples one source and gets {raw, u}: raw is what the device said (the assigned axes, or
// for the keyboard the direction its held keys ask for), u the calibrated input the plant receives; both are
// recorded, with every raw event (key downs and ups, axis changes) in the trial's event list.

// The keyboard's stated ramp: a held key moves its stick by 1/KEY_STEPS per physics step toward ±1 (full
// deflection in 5 steps = 0.25 s at 20 Hz); a released one moves it back to 0 at the same rate. Counted in whole
// steps (u = level / KEY_STEPS), so the stick reaches 0.2, 0.4, … , 1 and 0 exactly, never 1e-16 off them.
export const KEY_STEPS = 5;
export const KEY_RAMP = 1 / KEY_STEPS;
export const KEYS = {
  u1: { minus: ["ArrowLeft", "KeyA"], plus: ["ArrowRight", "KeyD"] },
  u2: { minus: ["ArrowDown", "KeyS"], plus: ["ArrowUp", "KeyW"] },
};

// The standard mapping's default assignment: angular acceleration on the right stick's x axis, thrust on the
// left stick's y axis (pushed up = -1 on a standard pad, so its sign is flipped).
export const DEFAULT_AXES = [2, 1];
export const DEFAULT_SIGNS = [1, -1];
export const MIN_DEADZONE = 0.05;

function clip(v) { return Math.max(-1, Math.min(1, v)); }

export class EventLog {
  constructor() { this.t0 = null; this.events = []; }
  start(now) { this.t0 = now; this.events = []; }
  add(now, kind, code, value) {
    if (this.t0 === null) return;
    this.events.push([(now - this.t0) / 1000, kind, String(code), value]);
  }
}

export class Keyboard {
  constructor(log) {
    this.kind = "keyboard";
    this.log = log;
    this.held = new Set();
    this.level = [0, 0];
    this.onDown = (e) => {
      if (!this.codes().has(e.code)) return;
      e.preventDefault();
      if (!e.repeat) { this.held.add(e.code); this.log.add(performance.now(), "keydown", e.code, null); }
    };
    this.onUp = (e) => {
      if (!this.codes().has(e.code)) return;
      this.held.delete(e.code); this.log.add(performance.now(), "keyup", e.code, null);
    };
    this.onBlur = () => { this.held.clear(); };
    window.addEventListener("keydown", this.onDown);
    window.addEventListener("keyup", this.onUp);
    window.addEventListener("blur", this.onBlur);
  }
  codes() { return new Set(Object.values(KEYS).flatMap((k) => [...k.minus, ...k.plus])); }
  direction(axis) {
    const k = KEYS[axis];
    const plus = k.plus.some((c) => this.held.has(c)) ? 1 : 0;
    const minus = k.minus.some((c) => this.held.has(c)) ? 1 : 0;
    return plus - minus;
  }
  reset() { this.level = [0, 0]; }
  sample() {
    const raw = [this.direction("u1"), this.direction("u2")];
    for (let i = 0; i < 2; i++) this.level[i] += Math.sign(raw[i] * KEY_STEPS - this.level[i]);
    return { raw, u: this.level.map((l) => l / KEY_STEPS) };
  }
  describe() {
    return { kind: "keyboard", id: "keyboard", ramp_per_step: KEY_RAMP, ramp_steps: KEY_STEPS, keys: KEYS };
  }
  calibration() { return { kind: "keyboard", ramp_per_step: KEY_RAMP, ramp_steps: KEY_STEPS }; }
}

// The calibrated input of one axis: rest offset removed, each side of rest scaled by its own travel (to +1 it is
// 1 - offset, to -1 it is 1 + offset, so an off-centre stick still gives ±1 at full deflection both ways), sign
// applied, a dead zone around rest (rescaled so full deflection stays ±1), clipped to [-1, 1].
export function calibrate(raw, offset, sign, deadzone) {
  const d = raw - offset;
  const travel = d >= 0 ? 1 - offset : 1 + offset;
  const v = sign * (travel > 0 ? d / travel : 0);
  const a = Math.abs(v);
  if (a <= deadzone) return 0;
  return clip(Math.sign(v) * (a - deadzone) / (1 - deadzone));
}

export function firstPad() {
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  for (const p of pads) if (p && p.connected) return p;
  return null;
}

export class Pad {
  constructor(log, pad) {
    this.kind = "gamepad";
    this.log = log;
    this.index = pad.index;
    this.id = pad.id;
    this.mapping = pad.mapping;
    this.axes = DEFAULT_AXES.filter((a) => a < pad.axes.length).length === 2 ? DEFAULT_AXES.slice() : [0, 1];
    this.signs = DEFAULT_SIGNS.slice();
    this.offsets = new Array(pad.axes.length).fill(0);
    this.deadzone = MIN_DEADZONE;
    this.restNoise = null;
    this.lastAxes = null;
    this.lastTimestamp = null;
  }
  read() {
    const pads = navigator.getGamepads ? navigator.getGamepads() : [];
    const p = pads[this.index];
    return p && p.connected ? p : null;
  }
  sample() {
    const p = this.read();
    const now = performance.now();
    // a pad gone mid-trial reads as at rest (its sticks let go): raw = the rest offsets, u = 0; logged as such
    if (!p) {
      this.log.add(now, "disconnected", this.index, null);
      return { raw: this.axes.map((a) => this.offsets[a] ?? 0), u: [0, 0] };
    }
    const axes = Array.from(p.axes);
    if (this.lastAxes) {
      axes.forEach((v, j) => { if (v !== this.lastAxes[j]) this.log.add(now, "axis", j, v); });
    } else {
      axes.forEach((v, j) => this.log.add(now, "axis", j, v));
    }
    if (p.timestamp !== this.lastTimestamp) this.log.add(now, "pad_timestamp", "ms", p.timestamp);
    this.lastAxes = axes; this.lastTimestamp = p.timestamp;
    const raw = this.axes.map((a) => axes[a] ?? 0);
    const u = raw.map((r, i) => calibrate(r, this.offsets[this.axes[i]], this.signs[i], this.deadzone));
    return { raw, u };
  }
  reset() { this.lastAxes = null; this.lastTimestamp = null; }
  // Measure the rest offset of every axis from readings taken with the sticks let go; the dead zone is
  // twice the largest deviation seen at rest plus a margin, at least MIN_DEADZONE.
  setRest(readings) {
    const n = readings.length;
    if (!n) return;
    const m = readings[0].length;
    this.offsets = Array.from({ length: m }, (_, j) => readings.reduce((s, r) => s + r[j], 0) / n);
    const noise = Math.max(0, ...readings.flatMap((r) => r.map((v, j) => Math.abs(v - this.offsets[j]))));
    this.restNoise = noise;
    this.deadzone = Math.min(0.3, Math.max(MIN_DEADZONE, 2 * noise + 0.02));
  }
  describe() { return { kind: "gamepad", id: this.id, index: this.index, mapping: this.mapping }; }
  calibration() {
    return { kind: "gamepad", id: this.id, axes: this.axes, signs: this.signs, offsets: this.offsets,
             deadzone: this.deadzone, rest_noise: this.restNoise };
  }
}
