// The experimenter's page: every subject's progress, order of conditions, consent, warnings, fits (with the
// model's held-out error) and trials, refreshed every few seconds; a trial can be excluded with a note, and a
// failed fit asked for again. Needs the experimenter's key (in the link the command printed, then a cookie).

const $ = (id) => document.getElementById(id);

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") e.className = v; else if (k.startsWith("on")) e[k] = v; else e.setAttribute(k, v);
  }
  for (const c of children) e.append(c instanceof Node ? c : document.createTextNode(String(c ?? "")));
  return e;
}

function fail(message) { $("error").textContent = message; $("error").hidden = !message; }

async function api(path, body) {
  const res = await fetch(path, body === undefined ? {} : {
    method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body),
  });
  let data;
  try { data = await res.json(); } catch { data = { error: `${path}: the server answered ${res.status}` }; }
  if (!res.ok || data.error) throw new Error(data.error || `${path}: ${res.status}`);
  return data;
}

function fitCell(label, f) {
  // the server says what a fit that has not started waits for: its block's trials, flown so far
  if (!f || f.state === "waiting") return el("span", { class: "muted" }, `${label} fit: ${f?.waiting_for || "not started"}`);
  if (f.state === "fitting") return el("span", {}, `${label}: fitting…`);
  if (f.state === "failed") {
    return el("span", { class: "notok" }, `${label}: not fitted (${f.reason}) `,
              el("button", { type: "button", class: "secondary", onclick: async () => {
                try { await api("/api/experimenter/refit", { subject: f.subject, label }); refresh(); }
                catch (err) { fail(err.message); } } }, "fit again"));
  }
  const metric = f.metric === "rmse_position" ? "position RMSE" : f.metric;
  const err = f.held_out_error == null ? "not checked (no held-out trials)" :
    `held-out ${metric} ${f.held_out_error.toFixed(3)} m over ${f.held_out.length} trial(s) (${f.horizon_s} s ` +
    "predictions from each start)";
  return el("span", { class: "ok" }, `${label}: fitted on ${f.n_train} landed trials; ${err}; digest ${f.digest.slice(0, 12)}`);
}

function trialRow(r) {
  const note = el("input", { type: "text", value: r.exclusion_note || "", placeholder: "why", maxlength: "1000" });
  const box = el("input", { type: "checkbox" });
  box.checked = !!r.excluded;
  const save = el("button", { type: "button", class: "secondary", onclick: async () => {
    if (box.checked && !note.value.trim()) { fail("an exclusion needs a note saying why"); return; }
    try { await api("/api/experimenter/exclude", { trial: r.id, excluded: box.checked, note: note.value }); fail(""); refresh(); }
    catch (err) { fail(err.message); }
  } }, "save");
  const tr = el("tr", { class: r.excluded ? "excluded" : "" },
    el("td", {}, r.id), el("td", {}, r.label), el("td", {}, r.role),
    el("td", { class: `outcome ${String(r.outcome).replace(/ /g, "-")}` }, r.outcome_reason || r.outcome),
    el("td", {}, (r.started || "").slice(11, 19)), el("td", {}, r.attempts),
    el("td", {}, r.interruptions || ""), el("td", {}, r.assist === "none" ? "" : `${r.assist} ${r.blend}`),
    el("td", {}, box, " excluded"), el("td", {}, note), el("td", {}, save));
  return tr;
}

function subjectBlock(s) {
  const fits = Object.entries(s.fits || {}).map(([label, f]) => el("li", {}, fitCell(label, f)));
  const warnings = (s.warnings || []).map((w) => el("li", { class: "notok" }, `${w.at.slice(11, 19)} ${w.text}`));
  const head = el("tr", {}, ...["trial", "label", "role", "outcome", "started", "starts", "interruptions", "assist",
                                 "", "note", ""].map((h) => el("th", {}, h)));
  return el("div", { class: "subject" },
    el("h2", {}, `${s.subject}: ${s.trials_done} of ${s.trials_total} trials; next: ${s.next.kind}` +
                 (s.next.label ? ` ${s.next.label}` : "")),
    el("p", { class: "muted" }, `order ${(s.order?.conditions || []).join(", ")} (${s.order?.why || ""}); consent ` +
                                `${s.consent?.agreed ? "given" : "?"} ${(s.consent?.at || "").slice(0, 19)}`),
    warnings.length ? el("ul", {}, ...warnings) : "",
    fits.length ? el("ul", { class: "fits" }, ...fits) : "",
    el("table", { class: "trials" }, head, ...s.rows.map(trialRow)));
}

async function refresh() {
  const editing = document.activeElement && document.activeElement.tagName === "INPUT";
  if (editing) return;
  try {
    const o = await api("/api/experimenter/session");
    fail("");
    $("session-line").textContent = `Protocol ${o.protocol} (fingerprint ${o.fingerprint.slice(0, 12)}), session ` +
      `${o.out}: ${o.subjects.length} subject(s).`;
    $("progress").textContent = o.subjects.map((s) => `${s.subject} ${s.trials_done}/${s.trials_total}`).join(" · ");
    $("subjects").replaceChildren(...o.subjects.map((s) => {
      s.rows = s.rows || [];
      for (const f of Object.values(s.fits || {})) f.subject = s.subject;
      return subjectBlock(s);
    }));
    $("updated").textContent = `updated ${new Date().toLocaleTimeString()}`;
  } catch (err) { fail(err.message); }
}

refresh();
setInterval(refresh, 3000);
