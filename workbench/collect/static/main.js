// The subject's page: consent (with the subject ID; declining is recorded), the subject's fields, the sticks'
// calibration (rest measured and each assignment confirmed, or every key tried), then the steps the server hands
// out one at a time (messages, instructions, trials, breaks, fit breaks, practice, the end). Space starts and
// continues. The server keeps the state: a reloaded page (or a new browser) with ?subject=ID resumes at the
// first unfinished step.

import { Trial, blend, reason } from "./sim.js";
import { EventLog, Keyboard, Pad, firstPad, KEY_RAMP } from "./input.js";
import { View, drawSticks } from "./render.js";

const $ = (id) => document.getElementById(id);
const state = { config: null, spec: null, subject: null, status: null, device: null, keyboard: null,
                log: new EventLog(), screen: null, onSpace: null, trial: null, busy: false, last: null,
                gaps: null };
window.collect = state; // read by scripted subjects in the tests (and handy in the console)

// A protocol's text as paragraphs: a blank line separates them, a single line break inside one is a space (TOML's
// multi-line strings are wrapped for the file, not for the screen).
function paragraphs(element, text) {
  element.replaceChildren(...text.trim().split(/\n\s*\n/).map((t) => {
    const p = document.createElement("p");
    p.textContent = t.replace(/\s*\n\s*/g, " ");
    return p;
  }));
}

function show(name) {
  for (const s of document.querySelectorAll("main > section")) s.hidden = s.id !== `screen-${name}`;
  state.screen = name;
}

function fail(message) {
  const e = $("error");
  e.textContent = message; e.hidden = !message;
}

class ApiError extends Error {
  constructor(message, status, data) { super(message); this.status = status; this.data = data; }
}

async function api(path, body) {
  const res = await fetch(path, body === undefined ? {} : {
    method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body),
  });
  let data;
  try { data = await res.json(); } catch { data = { error: `${path}: the server answered ${res.status}` }; }
  if (!res.ok || data.error) throw new ApiError(data.error || `${path}: ${res.status}`, res.status, data);
  return data;
}

window.addEventListener("keydown", (e) => {
  if (e.code !== "Space" || e.repeat) return;
  const tag = (document.activeElement && document.activeElement.tagName) || "";
  if (["INPUT", "SELECT", "TEXTAREA", "BUTTON"].includes(tag)) return;
  e.preventDefault();
  if (state.onSpace && !state.busy) { const f = state.onSpace; state.onSpace = null; f(); }
});

// A gamepad's "A" button (0) works as Space too.
let padButton = false;
function pollPadButton() {
  const p = firstPad();
  const pressed = !!(p && p.buttons && p.buttons[0] && p.buttons[0].pressed);
  if (pressed && !padButton && state.onSpace && !state.busy) { const f = state.onSpace; state.onSpace = null; f(); }
  padButton = pressed;
  requestAnimationFrame(pollPadButton);
}

function whenSpace(f) { state.onSpace = f; }

// What interrupts a trial in flight: the page hidden, the window losing focus (recorded with their durations).
function watchInterruptions() {
  const since = {};
  const mark = (kind, on) => {
    if (!state.gaps || state.log.t0 === null) return;
    const t = (performance.now() - state.log.t0) / 1000;
    if (on) since[kind] = t;
    else if (since[kind] !== undefined) { state.gaps.push([since[kind], kind, t - since[kind]]); delete since[kind]; }
  };
  document.addEventListener("visibilitychange", () => mark("page hidden", document.hidden));
  window.addEventListener("blur", () => mark("focus lost", true));
  window.addEventListener("focus", () => mark("focus lost", false));
  window.addEventListener("gamepaddisconnected", () => mark("pad disconnected", true));
  window.addEventListener("gamepadconnected", () => mark("pad disconnected", false));
}

// -- start --------------------------------------------------------------------------------------------------
async function main() {
  state.config = await api("/api/config");
  state.spec = state.config.task;
  const p = state.config.protocol;
  $("title").textContent = p.title;
  document.title = p.title;
  state.keyboard = new Keyboard(state.log);
  requestAnimationFrame(pollPadButton);
  watchInterruptions();
  const wanted = new URLSearchParams(location.search).get("subject");
  if (wanted) {
    const s = await api(`/api/subject/${encodeURIComponent(wanted)}`).catch((e) => { fail(e.message); return null; });
    if (s && s.registered) return resumed(s);
  }
  consent(wanted || "");
}

function consent(subject) {
  const p = state.config.protocol;
  $("consent-title").textContent = p.title;
  paragraphs($("consent-text"), p.consent);
  show("consent");
  $("subject-id").value = subject;
  $("consent-form").onsubmit = (e) => {
    e.preventDefault();
    fail("");
    subjectForm($("subject-id").value.trim());
  };
  $("consent-decline").onclick = async () => {
    try {
      await api("/api/consent", { subject: $("subject-id").value.trim() || null, consent: { sha256: p.consent_sha256 } });
      fail("");
      message("Thank you", "You declined to take part. That you declined is recorded (with the time and your " +
              "subject ID, if you gave one); nothing else about you is. You can close this page.");
    } catch (err) { fail(err.message); }
  };
  if (!subject) $("subject-id").focus();
}

function subjectForm(subject) {
  const p = state.config.protocol;
  if (p.fields.length) show("subject"); // without fields, straight on (the screen only to confirm an ID)
  $("subject-line").textContent = `Subject ID: ${subject}`;
  $("confirm-box").hidden = true;
  $("subject-continue").hidden = false;
  const box = $("subject-fields");
  box.innerHTML = "";
  for (const f of p.fields) {
    const label = document.createElement("label");
    label.textContent = f.label + (f.required ? " *" : "");
    let input;
    if (f.type === "choice") {
      input = document.createElement("select");
      input.append(new Option("—", ""), ...f.choices.map((c) => new Option(c, c)));
    } else {
      input = document.createElement("input");
      input.type = f.type === "number" ? "number" : "text";
      if (f.type === "number") input.step = "any";
      else input.maxLength = 500;
    }
    input.name = f.name; input.required = f.required;
    label.append(input);
    box.append(label);
  }
  const first = box.querySelector("input, select");
  if (first) first.focus();
  const send = async (confirm) => {
    const fields = {};
    for (const f of p.fields) fields[f.name] = box.querySelector(`[name="${f.name}"]`).value;
    try {
      const s = await api("/api/subject", { subject, fields, consent: { sha256: p.consent_sha256 }, confirm });
      fail("");
      if (document.activeElement) document.activeElement.blur();
      resumed(s, !confirm || s.trials_done === 0);
    } catch (err) {
      if (err.status === 409 && err.data && err.data.confirm) {
        // an ID already registered, or not among the declared ones: the subject confirms or changes it
        show("subject");
        $("confirm-text").textContent = err.message;
        $("confirm-box").hidden = false;
        $("subject-continue").hidden = true;
        $("confirm-yes").onclick = () => send(true);
        $("confirm-no").onclick = () => consent("");
        fail("");
      } else fail(err.message);
    }
  };
  $("subject-form").onsubmit = (e) => { e.preventDefault(); send(false); };
  if (!p.fields.length) send(false);
}

function resumed(s, fresh = false) {
  state.subject = s.subject;
  state.status = s;
  state.last = s.last || null;
  $("who").textContent = `subject ${s.subject}`;
  if (!fresh && s.trials_done > 0) {
    $("resume-note").hidden = false;
    $("resume-note").textContent = `Welcome back, ${s.subject}: ${s.trials_done} of ${s.trials_total} trials are done. ` +
      "Check your sticks, then continue where you stopped.";
  }
  history.replaceState(null, "", `?subject=${encodeURIComponent(s.subject)}`);
  calibration();
}

// An axis by what it is on a pad of the standard mapping (axes 0–3: the left and the right stick), else its number.
function axisName(pad, k) {
  const names = ["left stick, left–right", "left stick, up–down", "right stick, left–right", "right stick, up–down"];
  return pad.mapping === "standard" && k < names.length ? `axis ${k} (${names[k]})` : `axis ${k}`;
}

// -- calibration --------------------------------------------------------------------------------------------
// A gamepad: rest measured, then each input assigned by moving the stick and confirmed (the assignment stays on
// the screen until confirmed or redone). The keyboard: every arrow tried. Nothing continues before that.
function calibration() {
  show("calibration");
  const settings = state.config.protocol.input;
  $("ramp-line").textContent = `A held key moves its stick ${KEY_RAMP} per step (full deflection in ` +
    `${(state.spec.dt / KEY_RAMP).toFixed(2)} s) and soon tilts the quadrotor too far.`;
  let live = true;
  const pick = () => {
    const p = firstPad();
    if (p && (!state.device || state.device.kind !== "gamepad" || state.device.index !== p.index)) {
      state.device = new Pad(state.log, p, settings);
    } else if (!p && (!state.device || state.device.kind !== "keyboard")) {
      state.device = state.keyboard;
    }
    const pad = state.device.kind === "gamepad";
    const padOnly = settings.device === "gamepad";
    $("pad-steps").hidden = !pad; $("keys-help").hidden = pad || padOnly; $("pad-needed").hidden = pad || !padOnly;
    $("device-line").textContent = pad ? `Gamepad: ${state.device.id}` : "Input: the keyboard";
    if (!pad) {
      const k = state.keyboard.tried, mark = (key) => (k.has(key) ? "✓" : "○");
      $("tried-u1").textContent = `tried: ← ${mark("u1-")}  → ${mark("u1+")}`;
      $("tried-u2").textContent = `tried: ↑ ${mark("u2+")}  ↓ ${mark("u2-")}`;
    }
    const ready = pad ? state.device.ready : !padOnly && state.keyboard.ready;
    $("calibration-next").innerHTML = ready ? "Try the sticks, then press <kbd>Space</kbd> to continue."
      : pad ? "Measure the rest and confirm both sticks to continue." : padOnly ? ""
        : "Tap each arrow key once to continue.";
    return ready;
  };
  const loop = () => {
    if (!live) return;
    pick();
    const s = state.device.kind === "gamepad" ? state.device.preview() : state.device.sample();
    drawSticks($("sticks"), shown(s.raw), s.u, ["angular accel. u1", "thrust u2"]);
    setTimeout(loop, state.spec.dt * 1000);
  };
  loop();
  // buttons give the focus back at once: Space must go on meaning "continue", not "press this button again"
  $("measure-rest").onclick = async (e) => {
    e.currentTarget.blur();
    const pad = state.device;
    const readings = [];
    $("rest-result").textContent = "measuring… keep the sticks still";
    for (let j = 0; j < 20; j++) {
      const p = pad.read();
      if (p) readings.push(Array.from(p.axes));
      await new Promise((r) => setTimeout(r, 50));
    }
    pad.setRest(readings);
    $("rest-result").textContent = `✓ offsets ${pad.axes.map((a) => pad.offsets[a].toFixed(3)).join(", ")}; ` +
      `dead zone ${pad.deadzone.toFixed(3)}`;
  };
  const names = ["move the stick fully right now…", "push the stick fully up now…"];
  const assign = (i) => async (e) => {
    e.currentTarget.blur();
    const pad = state.device;
    pad.confirmed[i] = false;
    $(`confirm-u${i + 1}`).hidden = true;
    const rest = Array.from(pad.read().axes);
    $(`axis-u${i + 1}`).textContent = names[i];
    for (let j = 0; j < 100; j++) {
      await new Promise((r) => setTimeout(r, 50));
      const now = Array.from(pad.read().axes);
      const d = now.map((v, k) => v - rest[k]);
      const k = d.reduce((best, v, kk) => (Math.abs(v) > Math.abs(d[best]) ? kk : best), 0);
      if (Math.abs(d[k]) > 0.5) {
        pad.axes[i] = k; pad.signs[i] = Math.sign(d[k]);
        $(`axis-u${i + 1}`).textContent = `${axisName(pad, k)}${pad.signs[i] < 0 ? " (inverted)" : ""}: is this ` +
          "the stick you moved? Confirm, or press Assign again.";
        $(`confirm-u${i + 1}`).hidden = false;
        return;
      }
    }
    $(`axis-u${i + 1}`).textContent = "no stick moved far enough: press Assign and try again";
  };
  const confirmAxis = (i) => (e) => {
    e.currentTarget.blur();
    const pad = state.device;
    const other = pad.axes[1 - i];
    if (pad.confirmed[1 - i] && other === pad.axes[i]) {
      $(`axis-u${i + 1}`).textContent = `${axisName(pad, other)} is already the other input's: press Assign and use ` +
        "another stick";
      $(`confirm-u${i + 1}`).hidden = true;
      return;
    }
    pad.confirmed[i] = true;
    $(`confirm-u${i + 1}`).hidden = true;
    $(`axis-u${i + 1}`).textContent = `✓ ${axisName(pad, pad.axes[i])}${pad.signs[i] < 0 ? " (inverted)" : ""}`;
  };
  for (const i of [0, 1]) {
    $(`assign-u${i + 1}`).onclick = assign(i);
    $(`confirm-u${i + 1}`).onclick = confirmAxis(i);
  }
  const proceed = async () => {
    if (!pick()) { whenSpace(proceed); return; }
    live = false;
    try {
      await api("/api/calibration", { subject: state.subject, calibration: state.device.calibration() });
      fail("");
      next();
    } catch (err) { fail(err.message); live = true; loop(); whenSpace(proceed); }
  };
  whenSpace(proceed);
}

// -- the steps ----------------------------------------------------------------------------------------------
async function next(status) {
  try {
    state.status = status || await api(`/api/subject/${encodeURIComponent(state.subject)}`);
  } catch (err) { fail(err.message); return; }
  const s = state.status, item = s.next;
  $("progress").textContent = `${s.trials_done} of ${s.trials_total} trials done`;
  if (item.kind === "instructions") return instructions(item);
  if (item.kind === "break") return pause(item);
  if (item.kind === "message") return briefing(item);
  if (item.kind === "fit") return fitBreak(item);
  if (item.kind === "practice") return practice(item);
  if (item.kind === "trial") return trial(item);
  return end(s);
}

function message(title, text, keys = "") {
  show("message");
  $("message-title").textContent = title;
  paragraphs($("message-text"), text);
  $("message-count").textContent = "";
  $("message-status").textContent = "";
  $("message-keys").innerHTML = keys;
  $("summary").hidden = true;
}

async function advance(item) {
  try { next(await api("/api/advance", { subject: state.subject, key: item.key })); } catch (err) { fail(err.message); }
}

function lastLine() {
  const last = state.last;
  state.last = null;
  return last ? `Your last trial: ${verdictText(last.outcome)} (${last.outcome_reason}). ` : "";
}

function instructions(item) {
  const role = item.role === "test" ? "test" : "training";
  const stop = item.stop_landed ? ` (it ends early once ${item.stop_landed} of them have landed)` : "";
  message(`Block: ${item.label}`, `${lastLine()}\n\n${item.instructions}`,
          `${item.n_trials} ${role} trial${item.n_trials === 1 ? "" : "s"}${stop}. Press <kbd>Space</kbd> to begin.`);
  whenSpace(() => advance(item));
}

function clock(s) {
  const m = Math.floor(s / 60), r = Math.ceil(s % 60);
  return r === 60 ? `${m + 1}:00` : `${m}:${String(r).padStart(2, "0")}`;
}

// A countdown of `seconds`; then `ready()` is asked (true: Space continues), every second until it says so.
function countdown(seconds, onOver) {
  const until = performance.now() + seconds * 1000;
  const tick = () => {
    const left = (until - performance.now()) / 1000;
    if (left > 0) { $("message-count").textContent = clock(left); setTimeout(tick, 200); return; }
    $("message-count").textContent = seconds > 0 ? "0:00" : "";
    onOver();
  };
  tick();
}

function pause(item) {
  message("Break", `${lastLine()}\n\nRest your hands. The next part starts when the break is over.`);
  countdown(item.duration_s, () => {
    $("message-keys").innerHTML = "The break is over. Press <kbd>Space</kbd> to continue.";
    whenSpace(() => advance(item));
  });
}

function briefing(item) {
  message(item.title || "Information", item.text);
  countdown(item.duration_s, () => {
    $("message-keys").innerHTML = "Press <kbd>Space</kbd> to continue.";
    whenSpace(() => advance(item));
  });
}

// A fit step: a break while the server fits this subject's model on their own trials (in a worker); Space
// continues once the break is over and the model is ready.
function fitBreak(item) {
  message("Break", `${lastLine()}\n\nRest your hands. A model of how you fly ${item.label} is being prepared ` +
          "from your trials; the next part uses it.");
  let over = false;
  const poll = async () => {
    if (state.screen !== "message" || !state.status || state.status.next.key !== item.key) return;
    let fit = state.status.next.fit || {};
    try { state.status = await api(`/api/subject/${encodeURIComponent(state.subject)}`); fit = state.status.next.fit || {}; }
    catch (err) { fail(err.message); }
    if (fit.state === "ready") {
      $("message-status").textContent = "✓ Your model is ready.";
      if (over) { $("message-keys").innerHTML = "Press <kbd>Space</kbd> to continue."; whenSpace(() => advance(item)); return; }
    } else if (fit.state === "failed") {
      $("message-status").textContent = `The model could not be prepared (${fit.reason}). Please call the experimenter.`;
    } else {
      $("message-status").textContent = "Preparing your model…";
    }
    setTimeout(poll, 1000);
  };
  countdown(item.duration_s, () => { over = true; });
  poll();
}

function end(s) {
  const last = state.last ? `Your last trial: ${verdictText(state.last.outcome)} (${state.last.outcome_reason}).\n\n` : "";
  state.last = null;
  message("Thank you!", `${last}The experiment is over and every trial is saved. You can close this page.`);
  const rows = {};
  for (const r of (s.summary || [])) rows[`${r.label} (${r.role}${r.assist !== "none" ? `, assisted: ${r.assist}` : ""})`] = r;
  const table = $("summary");
  table.innerHTML = "<tr><th>block</th><th>trials</th><th>landed</th></tr>" + Object.entries(rows)
    .map(([k, r]) => `<tr><td>${k}</td><td>${r.trials}</td><td>${r.landed}</td></tr>`).join("");
  table.hidden = !(s.summary || []).length;
  $("progress").textContent = `${s.trials_done} of ${s.trials_total} trials done`;
}

// The raw reading drawn in the direction of the input it feeds (an inverted axis flipped), so the red tick and
// the blue bar agree when the stick is calibrated well.
function shown(raw) {
  const signs = state.device && state.device.signs;
  return signs ? raw.map((v, j) => v * signs[j]) : raw;
}

// -- flying -------------------------------------------------------------------------------------------------
let view = null;

// The overlay (instructions, the last outcome) sits on the half of the scene away from the start, so that the
// start position and an assisted trial's predicted path stay in view before Space.
function taskScreen(label, overlay, x0 = null) {
  show("task");
  if (!view) view = new View($("scene"), state.spec);
  $("task-label").textContent = label;
  $("task-overlay").innerHTML = overlay;
  const across = x0 ? x0[state.spec.index.x] - state.spec.pad.x : 0;
  $("task-overlay").className = across > 0 ? "on-left" : "on-right";
}

// With the experimenter's view on, the states flown so far go to the server every LIVE_EVERY steps (not stored).
const LIVE_EVERY = 4;

function sendLive(trial, slot, from) {
  const x = trial.xs.slice(from);
  if (!x.length) return from;
  fetch("/api/live", { method: "POST", headers: { "Content-Type": "application/json" },
                       body: JSON.stringify({ subject: state.subject, slot, k0: from, x }) }).catch(() => {});
  return from + x.length;
}

function fly(x0, onEnd, slot = -1, help = null) {
  const device = state.device;
  let sent = 0;
  device.reset();
  // an assisted trial blends the pilot's input with the model's by the stated law; both are recorded
  const sample = help && help.kind === "blend" ? (x) => {
    const s = device.sample();
    return { raw: s.raw, pilot: s.u, u: blend(state.spec, help.K, help.alpha, x, s.u) };
  } : () => device.sample();
  const trial = new Trial(state.spec, x0, sample);
  state.trial = trial;
  state.gaps = [];
  view.trail = [];
  state.log.start(performance.now());
  $("task-overlay").innerHTML = "";
  const i = state.spec.index;
  const frame = (now) => {
    if (!trial.ended) device.poll(now, trial.xs.length); // the pad at the display rate, every read recorded
    trial.advance(now);
    if (state.config.live && (trial.ended || trial.xs.length - sent >= LIVE_EVERY)) sent = sendLive(trial, slot, sent);
    const x = trial.ended ? trial.xs[trial.xs.length - 1] : trial.x;
    view.trail.push([x[i.x], x[i.y]]);
    const last = trial.us.length ? trial.us[trial.us.length - 1] : [0, 0];
    const raw = trial.raws.length ? trial.raws[trial.raws.length - 1] : [0, 0];
    view.draw(x, last, { outcome: trial.ended });
    drawSticks($("task-sticks"), shown(raw), last, ["angular accel. u1", "thrust u2"]);
    hud(x, trial.k);
    if (trial.ended) { state.trial = null; onEnd(trial); return; }
    requestAnimationFrame(frame);
  };
  requestAnimationFrame(frame);
}

// The numbers above the scene: time against the limit, height, and speed and attitude green once within the
// landing limits.
function hud(x, k) {
  const i = state.spec.index, L = state.spec.landing;
  const speed = Math.hypot(x[i.vx], x[i.vy]), phi = x[i.attitude];
  const mark = (ok, text) => `<span class="${ok ? "ok" : "notok"}">${text}</span>`;
  $("task-hud").innerHTML = `time ${(k * state.spec.dt).toFixed(1)} of ${state.spec.time_limit_s} s · ` +
    `height ${x[i.y].toFixed(2)} m · ` + mark(speed < L.speed, `speed ${speed.toFixed(2)} m/s`) + " · " +
    mark(Math.abs(phi) < L.attitude, `attitude ${((phi * 180) / Math.PI).toFixed(1)}°`);
}

function verdictText(outcome) {
  const text = { landed: "Landed!", crashed: "Crashed", "left the domain": "Left the area", "time limit": "Out of time" };
  return text[outcome] || outcome;
}

function verdict(outcome, why) {
  const cls = outcome === "landed" ? "landed" : outcome === "crashed" ? "crashed" : "left";
  const detail = why ? `<div class="why">${why.replace(/^[^:]*: /, "")}</div>` : "";
  return `<div class="big ${cls}">${verdictText(outcome)}</div>${detail}`;
}

function payload(trial, extra) {
  const d = state.device;
  return {
    subject: state.subject, x: trial.xs, u: trial.us, raw: trial.raws, pilot: trial.pilots, outcome: trial.ended,
    device: d.describe(), calibration: d.calibration(), timing: trial.timing(), events: state.log.events,
    frames: trial.frames, sampled: trial.stepWall, interruptions: state.gaps || [],
    ...(d.kind === "gamepad" ? { reads: d.reads } : {}), ...extra,
  };
}

function rulesLine() {
  const L = state.spec.landing;
  const keys = state.device.kind === "keyboard"
    ? "<p class=\"tap\"><b>Keyboard: tap the keys, do not hold them</b> (a held key tilts too far).</p>" : "";
  return `<p class="keys">Land on the green pad slower than ${L.speed} m/s and flatter than ` +
    `${Math.round((L.attitude * 180) / Math.PI)}°, within ${state.spec.time_limit_s} s.</p>${keys}`;
}

function trial(item) {
  const role = item.role === "test" ? "test" : "training";
  const label = `${item.label} · ${role} trial ${item.trial} of ${item.n_trials}`;
  const last = state.last ? verdict(state.last.outcome, state.last.outcome_reason) : "";
  state.last = null;
  const help = item.help || null;
  const assisted = !help ? "" : help.kind === "show"
    ? "<p><b>Assisted:</b> the dashed blue line is the path your model predicts.</p>"
    : `<p><b>Assisted:</b> your input is blended with your model's (its share ${help.alpha}).</p>`;
  taskScreen(label, `${last}<p>${item.instructions}</p>${assisted}${rulesLine()}` +
                    `<p>Press <kbd>Space</kbd> to start ${role} trial ${item.trial} of ${item.n_trials}.</p>`, item.x0);
  view.guide = help && help.kind === "show" ? help.path : null;
  view.trail = [];
  view.draw(item.x0, [0, 0]);
  hud(item.x0, 0);
  drawSticks($("task-sticks"), [0, 0], [0, 0], ["angular accel. u1", "thrust u2"]);
  whenSpace(() => {
    // the start is recorded by the server (its time, and earlier starts of this slot that were lost); the trial
    // does not wait for the answer
    api("/api/start", { subject: state.subject, slot: item.slot }).catch((err) => fail(err.message));
    fly(item.x0, async (t) => {
      state.busy = true;
      const why = reason(state.spec, t.xs[t.xs.length - 1], t.ended);
      $("task-overlay").innerHTML = `${verdict(t.ended, why)}<p>Saving…</p>`;
      try {
        const s = await api("/api/trial", payload(t, { slot: item.slot, x0: item.x0 }));
        state.last = { outcome: s.outcome, outcome_reason: s.outcome_reason };
        state.busy = false;
        fail("");
        next(s);
      } catch (err) {
        state.busy = false;
        fail(err.message);
        $("task-overlay").innerHTML = `${verdict(t.ended, why)}<p>Not saved. Press <kbd>Space</kbd> to fly this trial again.</p>`;
        whenSpace(() => trial(item));
      }
    }, item.slot, help);
  });
}

function practiceStart() {
  const s = state.spec, x0 = new Array(s.state_names.length).fill(0);
  x0[s.index.x] = s.start.x[0] + Math.random() * (s.start.x[1] - s.start.x[0]);
  x0[s.index.y] = s.start.y[0] + Math.random() * (s.start.y[1] - s.start.y[0]);
  return x0;
}

function practice(item) {
  const until = performance.now() + item.duration_s * 1000;
  const round = (last) => {
    const left = (until - performance.now()) / 1000;
    if (left <= 0) {
      taskScreen("Practice", `${last}<p>Practice is over.</p><p>Press <kbd>Space</kbd> to continue.</p>`);
      whenSpace(() => advance(item));
      return;
    }
    const x0 = practiceStart();
    taskScreen(`Practice · ${clock(left)} left`, `${last}<p>Practice: land on the pad.</p>${rulesLine()}` +
               "<p>Press <kbd>Space</kbd> to start.</p>", x0);
    view.guide = null;
    view.trail = [];
    view.draw(x0, [0, 0]);
    hud(x0, 0);
    whenSpace(() => fly(x0, async (t) => {
      try { await api("/api/practice", payload(t, { x0 })); } catch (err) { fail(err.message); }
      round(verdict(t.ended, reason(state.spec, t.xs[t.xs.length - 1], t.ended)));
    }));
  };
  round("");
}

main().catch((err) => { show("loading"); fail(err.message); });
