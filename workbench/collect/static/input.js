// The sticks: any gamepad or joystick through the standard Gamepad API, or the keyboard as a fallback (when the
// protocol allows it). A gamepad is read at the display rate (poll(), once a frame, every read recorded); each
// physics step takes the reads since the previous step by the protocol's rule (latest, or their mean) and gets
// {raw, u}: raw is what the device said (the last read's assigned axes, or for the keyboard the direction its
// held keys ask for), u the calibrated input the plant receives. The server recomputes u from the reads
// (workbench/collect/checks.py) and refuses a trial where they differ.

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
// left stick's y axis (pushed up = -1 on a standard pad, so its sign is flipped). The calibration screen asks the
// subject to confirm or change both.
export const DEFAULT_AXES = [2, 1];
export const DEFAULT_SIGNS = [1, -1];
// "measured" dead zone: three times the largest deviation seen at rest, at most this (checks.measured_deadzone)
export const MEASURED_DEADZONE_MAX = 0.3;

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
    this.tried = new Set(); // the directions tapped on the calibration screen
    this.onDown = (e) => {
      if (!this.codes().has(e.code)) return;
      e.preventDefault();
      if (!e.repeat) {
        this.held.add(e.code); this.log.add(performance.now(), "keydown", e.code, null);
        for (const [axis, k] of Object.entries(KEYS)) {
          if (k.minus.includes(e.code)) this.tried.add(`${axis}-`);
          if (k.plus.includes(e.code)) this.tried.add(`${axis}+`);
        }
      }
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
  poll() {} // keys come as events, not reads
  sample() {
    const raw = [this.direction("u1"), this.direction("u2")];
    for (let i = 0; i < 2; i++) this.level[i] += Math.sign(raw[i] * KEY_STEPS - this.level[i]);
    return { raw, u: this.level.map((l) => l / KEY_STEPS) };
  }
  get ready() { return this.tried.size === 4; }
  describe() {
    return { kind: "keyboard", id: "keyboard", ramp_per_step: KEY_RAMP, ramp_steps: KEY_STEPS, keys: KEYS };
  }
  calibration() { return { kind: "keyboard", ramp_per_step: KEY_RAMP, ramp_steps: KEY_STEPS, confirmed: this.ready }; }
}

// The calibrated input of one axis: rest offset removed, each side of rest scaled by its own travel (to +1 it is
// 1 - offset, to -1 it is 1 + offset, so an off-centre stick still gives ±1 at full deflection both ways), sign
// applied, a dead zone around rest (rescaled so full deflection stays ±1), then the expo (1 - e) m + e m³.
// The same arithmetic in the same order as workbench/collect/checks.py calibrate: the same bits.
export function calibrate(raw, offset, sign, deadzone, expo) {
  const d = raw - offset;
  const travel = d >= 0 ? 1 - offset : 1 + offset;
  const v = sign * (travel > 0 ? d / travel : 0);
  const a = Math.abs(v);
  if (a <= deadzone) return 0;
  const m = Math.min(1, (a - deadzone) / (1 - deadzone));
  return (v < 0 ? -1 : 1) * ((1 - expo) * m + expo * m * m * m);
}

export function firstPad() {
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  for (const p of pads) if (p && p.connected) return p;
  return null;
}

export class Pad {
  constructor(log, pad, settings) {
    this.kind = "gamepad";
    this.log = log;
    this.index = pad.index;
    this.id = pad.id;
    this.mapping = pad.mapping;
    this.settings = settings;
    this.axes = DEFAULT_AXES.filter((a) => a < pad.axes.length).length === 2 ? DEFAULT_AXES.slice() : [0, 1];
    this.signs = DEFAULT_SIGNS.slice();
    this.confirmed = [false, false];
    this.offsets = new Array(pad.axes.length).fill(0);
    this.restNoise = null;
    this.deadzone = typeof settings.deadzone === "number" ? settings.deadzone : null; // measured: after setRest
    this.expo = settings.expo;
    this.rule = settings.gamepad_rule;
    this.reads = []; // [t_s, step, raw u1, raw u2] of the trial in flight
    this.window = []; // the reads since the previous physics step
    this.lastRaw = null;
    this.lastAxes = null;
    this.lastTimestamp = null;
  }
  get ready() { return this.restNoise !== null && this.deadzone !== null && this.confirmed[0] && this.confirmed[1]; }
  read() {
    const pads = navigator.getGamepads ? navigator.getGamepads() : [];
    const p = pads[this.index];
    return p && p.connected ? p : null;
  }
  // One read of the pad at a display frame, feeding physics step `step`; recorded with its time.
  poll(now, step) {
    const p = this.read();
    let raw;
    if (!p) {
      // a pad gone mid-trial reads as at rest (its sticks let go): raw = the rest offsets; logged as such
      this.log.add(now, "disconnected", this.index, null);
      raw = this.axes.map((a) => this.offsets[a] ?? 0);
    } else {
      const axes = Array.from(p.axes);
      if (this.lastAxes) {
        axes.forEach((v, j) => { if (v !== this.lastAxes[j]) this.log.add(now, "axis", j, v); });
      } else {
        axes.forEach((v, j) => this.log.add(now, "axis", j, v));
      }
      if (p.timestamp !== this.lastTimestamp) this.log.add(now, "pad_timestamp", "ms", p.timestamp);
      this.lastAxes = axes; this.lastTimestamp = p.timestamp;
      raw = this.axes.map((a) => axes[a] ?? 0);
    }
    if (this.log.t0 !== null) this.reads.push([(now - this.log.t0) / 1000, step, raw[0], raw[1]]);
    this.window.push(raw);
    this.lastRaw = raw;
    return raw;
  }
  calibrated(raw, i) { return calibrate(raw[i], this.offsets[this.axes[i]], this.signs[i], this.deadzone, this.expo); }
  // One physics step: the reads since the previous step by the rule (none new: the latest read before).
  sample() {
    if (!this.window.length) {
      if (!this.lastRaw) this.poll(performance.now(), 0);
      else this.window.push(this.lastRaw);
    }
    const w = this.window;
    this.window = [];
    const u = [0, 1].map((i) => {
      if (this.rule === "latest") return this.calibrated(w[w.length - 1], i);
      let s = 0.0;
      for (const r of w) s += this.calibrated(r, i);
      return s / w.length;
    });
    return { raw: w[w.length - 1].slice(), u };
  }
  // Outside a trial (the calibration screen's gauges): one read, calibrated.
  preview() {
    const raw = this.poll(performance.now(), 0);
    this.window = [];
    return { raw, u: this.deadzone === null ? [0, 0] : [0, 1].map((i) => this.calibrated(raw, i)) };
  }
  reset() { this.lastAxes = null; this.lastTimestamp = null; this.reads = []; this.window = []; this.lastRaw = null; }
  // Measure the rest offset of every axis from readings taken with the sticks let go; with a measured dead zone,
  // three times the largest deviation seen at rest (at most MEASURED_DEADZONE_MAX).
  setRest(readings) {
    const n = readings.length;
    if (!n) return;
    const m = readings[0].length;
    this.offsets = Array.from({ length: m }, (_, j) => readings.reduce((s, r) => s + r[j], 0) / n);
    const noise = Math.max(0, ...readings.flatMap((r) => r.map((v, j) => Math.abs(v - this.offsets[j]))));
    this.restNoise = noise;
    if (typeof this.settings.deadzone !== "number") this.deadzone = Math.min(MEASURED_DEADZONE_MAX, 3 * noise);
  }
  describe() { return { kind: "gamepad", id: this.id, index: this.index, mapping: this.mapping }; }
  calibration() {
    return { kind: "gamepad", id: this.id, axes: this.axes, signs: this.signs, offsets: this.offsets,
             deadzone: this.deadzone, expo: this.expo, rule: this.rule, rest_noise: this.restNoise,
             confirmed: this.confirmed };
  }
}
