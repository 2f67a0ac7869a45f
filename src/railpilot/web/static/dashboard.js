// railpilot dispatcher dashboard: plain JavaScript and SVG, no build step, no libraries.
// The server pushes a snapshot (docs/dashboard.md) over /ws when anything changes and at
// least every second; this script draws it. It decides nothing: every state shown comes
// from the ground. Text from the server is always set as text, never as HTML.
"use strict";

const SVGNS = "http://www.w3.org/2000/svg";
const TOKEN_KEY = "railpilot.dispatcherToken";
const FIELDS = ["start_km", "end_km", "limit_kmh", "valid_from_min", "valid_until_min", "reason"];
const DISPATCH_FIELDS = ["trains", "text"];
const RESTRICTION_FIELDS = ["reason", "block", "start_km", "end_km", "track"];
const STALE_AFTER_S = 3; // no push for this long: say so
const MAX_ALARMS_SHOWN = 100; // alarms listed one by one; the rest are counted
const LABEL_CHAR_PX = 6.6; // width of a character of a train's label on the line diagram

let latest = null; // the last snapshot
let lastMessageAt = 0; // performance.now() of the last snapshot [ms]
let staticKey = null; // which line the diagram's static layer was drawn for

// What the page drew, for load tests and tools (railpilot link loadtest --dashboard reads
// it): renders so far and, for the last PROBE_KEEP, when each snapshot was drawn
// [ms since the epoch], how long render() took [ms], how long until the next frame was
// painted [ms] and the snapshot's version. Nothing on the page reads it.
const PROBE_KEEP = 10000;
const probe = { renders: 0, at: [], renderMs: [], paintMs: [], versions: [] };
window.railpilot = probe;

// ------------------------------------------------------------------ small DOM helpers

function setAttrs(node, attrs) {
  for (const [key, value] of Object.entries(attrs || {})) {
    if (value === null || value === undefined || value === false) continue;
    if (key === "text") node.textContent = String(value);
    else if (key.startsWith("on")) node.addEventListener(key.slice(2), value);
    else node.setAttribute(key, value === true ? "" : String(value));
  }
  return node;
}

function kids(children) {
  return children.flat().filter((c) => c !== null && c !== undefined && c !== false)
    .map((c) => (typeof c === "object" ? c : document.createTextNode(String(c))));
}

function h(tag, attrs, ...children) {
  const node = setAttrs(document.createElement(tag), attrs);
  node.append(...kids(children));
  return node;
}

function s(tag, attrs, ...children) {
  const node = setAttrs(document.createElementNS(SVGNS, tag), attrs);
  node.append(...kids(children));
  return node;
}

const $ = (id) => document.getElementById(id);

function hhmmss(t) { return new Date(t * 1000).toISOString().slice(11, 19); }
function hhmm(t) { return new Date(t * 1000).toISOString().slice(11, 16); }
function fmt(x, digits) { return x === null || x === undefined ? "–" : Number(x).toFixed(digits); }

// against plan, as a cell's content (see "keyed tables")
function minutes(seconds) {
  if (seconds === null || seconds === undefined) return ["span", { class: "muted" }, "–"];
  const m = Math.round(seconds / 60);
  if (m === 0) return ["span", { class: "early" }, "on time"];
  return m > 0 ? ["span", { class: "late" }, `+${m} min late`]
    : ["span", { class: "early" }, `${-m} min early`];
}

// ------------------------------------------------------------------ keyed tables
// The tables with a row per train are updated in place: each row is kept by its key and a
// cell is rebuilt only when what it shows changed. A snapshot of 1,000 trains then changes
// a few thousand text nodes instead of building 15,000 new elements every second (and the
// browser lays out only what changed). A cell is described as data, [attrs, ...children],
// a child being text or [tag, attrs, ...children], so "changed" is a string comparison.

function build(child) {
  if (!Array.isArray(child)) return child;
  const [tag, attrs, ...children] = child;
  return h(tag, attrs, ...children.map(build));
}

function resetAttrs(node, attrs) {
  for (const name of node.getAttributeNames()) node.removeAttribute(name);
  setAttrs(node, attrs);
}

// rows: [{ key, attrs, cells: [[attrs, ...children], ...] }]; empty: the row shown when none
function syncTable(table, rows, empty) {
  const body = table.tBodies[0];
  const kept = table.railpilotRows || (table.railpilotRows = new Map());
  const order = [];
  const seen = new Set();
  for (const row of rows) {
    let entry = kept.get(row.key);
    if (!entry) {
      entry = { tr: document.createElement("tr"), attrs: null, cells: [] };
      kept.set(row.key, entry);
    }
    const attrs = JSON.stringify(row.attrs);
    if (attrs !== entry.attrs) { resetAttrs(entry.tr, row.attrs); entry.attrs = attrs; }
    row.cells.forEach((cell, i) => {
      const sig = JSON.stringify(cell);
      if (entry.cells[i] === sig) return;
      const td = entry.tr.children[i] || entry.tr.appendChild(document.createElement("td"));
      const [cellAttrs, ...children] = cell;
      resetAttrs(td, cellAttrs);
      td.replaceChildren(...kids(children.map(build)));
      entry.cells[i] = sig;
    });
    seen.add(row.key);
    order.push(entry.tr);
  }
  for (const key of [...kept.keys()]) if (!seen.has(key)) kept.delete(key);
  if (!order.length) order.push(empty);
  const now = body.children;
  let same = now.length === order.length;
  for (let i = 0; same && i < order.length; i++) same = now[i] === order[i];
  if (!same) body.replaceChildren(...order);
}

// ------------------------------------------------------------------ token

function token() { return sessionStorage.getItem(TOKEN_KEY) || ""; }

function showToken() {
  const set = token() !== "";
  $("token-state").textContent = set ? "✓ token in use (this tab)" : "no token: read only";
  $("token-state").className = set ? "set" : "muted";
  $("token").hidden = set;
  $("token-save").hidden = set;
  $("token-forget").hidden = !set;
}

$("token-form").addEventListener("submit", (event) => {
  event.preventDefault();
  const value = $("token").value.trim();
  $("err-token").textContent = value ? "" : "enter the token the server printed";
  if (value) sessionStorage.setItem(TOKEN_KEY, value);
  $("token").value = "";
  showToken();
});

$("token-forget").addEventListener("click", () => {
  sessionStorage.removeItem(TOKEN_KEY);
  showToken();
});

// ------------------------------------------------------------------ write actions

async function post(url, body) {
  const response = await fetch(url, {
    method: "POST",
    headers: { "Content-Type": "application/json", Authorization: `Bearer ${token()}` },
    body: JSON.stringify(body),
  });
  let data = {};
  try { data = await response.json(); } catch (_) { data = {}; }
  if (response.status === 401) {
    sessionStorage.removeItem(TOKEN_KEY);
    showToken();
  }
  return { status: response.status, data };
}

// A form's fields and where its inputs and their errors are (the token's error is shared).
const TSR_FORM = { fields: FIELDS, input: "f-", error: "err-" };
const DISPATCH_FORM = { fields: DISPATCH_FIELDS, input: "fd-", error: "errd-" };
const RESTRICTION_FORM = { fields: RESTRICTION_FIELDS, input: "fr-", error: "errr-" };

function showErrors(errors, form = TSR_FORM) {
  const errorOf = (name) => $(name === "token" ? "err-token" : `${form.error}${name}`);
  for (const name of [...form.fields, "form", "token"]) {
    const message = (errors && errors[name]) || "";
    errorOf(name).textContent = message;
    const input = $(`${form.input}${name}`);
    if (input) input.setAttribute("aria-invalid", message ? "true" : "false");
  }
  const known = new Set([...form.fields, "form", "token"]);
  const other = Object.entries(errors || {}).filter(([k]) => !known.has(k));
  if (other.length) errorOf("form").textContent = other.map(([k, v]) => `${k}: ${v}`).join("; ");
}

// A form: the token first, then its fields posted, the answer shown next to them. `form` is
// its spec (above); its elements are `${name}-form`, `${name}-submit` and `${name}-result`.
// `warned(warning, body, send)`, where given, shows an answer the ground sent nothing for
// until it is confirmed (`warned(null)` withdraws it: every new send does).
function sendForm(name, form, url, fields, done, clear, warned = null) {
  const send = async (body) => {
    $(`${name}-result`).textContent = "";
    if (warned) warned(null);
    if (!token()) {
      showErrors({ token: "enter the dispatcher token first" }, form);
      return;
    }
    $(`${name}-submit`).disabled = true;
    try {
      const { status, data } = await post(url, body);
      if (status === 200 && data.ok) {
        showErrors({}, form);
        $(`${name}-result`).textContent = done(data.ok);
        for (const field of clear) $(`${form.input}${field}`).value = "";
      } else if (warned && data.warning) {
        showErrors({}, form);
        warned(data.warning, body, send);
      } else {
        showErrors(data.errors || { form: `the server answered ${status}` }, form);
      }
    } catch (error) {
      showErrors({ form: `could not reach the server: ${error}` }, form);
    } finally {
      $(`${name}-submit`).disabled = false;
    }
  };
  $(`${name}-form`).addEventListener("submit", (event) => {
    event.preventDefault();
    send(fields());
  });
}

// A TSR over trains that already run above its limit there (or too close to it to slow
// down): the ground sends nothing and lists them. The page shows the list and asks again,
// as a cancel takes two clicks: "Set TSR anyway" sends the same fields confirmed; editing
// the form or "Don't send" withdraws the question.
const tsrWarning = h("div", { id: "tsr-warning", class: "warning", role: "alert", hidden: true });
$("tsr-result").before(tsrWarning);

function hideTsrWarning() {
  tsrWarning.hidden = true;
  tsrWarning.replaceChildren();
}

function askTsrConfirm(warning, body, send) {
  if (!warning) {
    hideTsrWarning();
    return;
  }
  const trains = warning.trains || [];
  tsrWarning.replaceChildren(
    h("p", { class: "error" }, `Not sent: ${trains.length} train(s) already above ` +
      `${fmt(warning.limit_kmh, 0)} km/h there or too close to slow down:`),
    h("ul", {}, trains.map((t) => h("li", { "data-train": t.train }, t.text))),
    h("button", {
      type: "button", id: "tsr-confirm", class: "armed",
      onclick: () => send({ ...body, confirm: true }),
    }, "Set TSR anyway"),
    " ",
    h("button", { type: "button", id: "tsr-dismiss", onclick: hideTsrWarning }, "Don't send"));
  tsrWarning.hidden = false;
}
$("tsr-form").addEventListener("input", hideTsrWarning);

sendForm("tsr", TSR_FORM, "/api/tsr",
  () => Object.fromEntries(FIELDS.map((name) => [name, $(`f-${name}`).value])),
  (tsr) => `TSR ${tsr.session} set: km ${fmt(tsr.start_km, 3)}–${fmt(tsr.end_km, 3)} at ` +
    `${fmt(tsr.limit_kmh, 0)} km/h, sent to ${tsr.deliveries.length} train(s)`,
  ["start_km", "end_km", "limit_kmh", "reason"], askTsrConfirm);

sendForm("restriction", RESTRICTION_FORM, "/api/restriction",
  () => { // a block, or a km span on a track: the fields left blank are not sent
    const fields = { reason: $("fr-reason").value };
    for (const name of ["block", "start_km", "end_km"]) {
      const value = $(`fr-${name}`).value.trim();
      if (value) fields[name] = value;
    }
    if (!fields.block) fields.track = $("fr-track").value;
    return fields;
  },
  (r) => `Restriction ${r.id} declared: ${r.blocks.length} block(s) held at red`,
  ["block", "start_km", "end_km"]);

sendForm("dispatch", DISPATCH_FORM, "/api/dispatch",
  () => Object.fromEntries(DISPATCH_FIELDS.map((name) => [name, $(`fd-${name}`).value])),
  (c) => `Command ${c.command} sent to ${c.trains.length} train(s)`,
  ["text"]);

// An action on one row that takes two clicks (a TSR's cancel, a restriction's clear): the
// first arms its button, the second posts. `armed[kind]` is the row whose button is armed.
const armed = { tsr: null, restriction: null };

async function twoClicks(kind, id, url, form, done) {
  if (armed[kind] !== id) { // first click: ask again
    armed[kind] = id;
    render();
    return;
  }
  armed[kind] = null;
  if (!token()) {
    showErrors({ token: "enter the dispatcher token first" }, form);
    render();
    return;
  }
  const { status, data } = await post(url, {});
  if (status === 200 && data.ok) {
    showErrors({}, form);
    $(`${kind}-result`).textContent = done(data.ok);
  } else {
    showErrors(data.errors || { form: `the server answered ${status}` }, form);
  }
  render();
}

const cancelTsr = (session) => twoClicks("tsr", session, `/api/tsr/${session}/cancel`, TSR_FORM,
  (tsr) => `TSR ${session} cancelled: cancel sent to ${tsr.deliveries.length} train(s)`);
const clearRestriction = (id) => twoClicks("restriction", id, `/api/restriction/${id}/clear`,
  RESTRICTION_FORM, () => `Restriction ${id} cleared`);

// ------------------------------------------------------------------ the line diagram

const LD = { width: 1560, left: 74, right: 14, rowKm: 100, rowH: 124 };
// y offsets inside a row
const Y = { names: 12, upLabel: 27, upSignal: 35, up: 45, between: 62, down: 71, downSignal: 81, downLabel: 98, ruler: 117 };

function lineRows(line) {
  const rows = [];
  for (let start = line.start_km, i = 0; start < line.end_km - 1e-9; start += LD.rowKm, i++) {
    rows.push({ start, end: Math.min(start + LD.rowKm, line.end_km), y: i * LD.rowH });
  }
  return rows;
}

function kmScale() { return (LD.width - LD.left - LD.right) / LD.rowKm; }
function xAt(row, km) { return LD.left + (km - row.start) * kmScale(); }

function drawLineStatic(line) {
  const svg = $("line");
  const rows = lineRows(line);
  const height = rows.length * LD.rowH;
  svg.setAttribute("viewBox", `0 0 ${LD.width} ${height}`);
  const base = s("g", { id: "line-static" });
  for (const row of rows) {
    const g = s("g", { transform: `translate(0 ${row.y})` });
    g.append(
      s("text", { class: "row-label", x: 4, y: Y.up + 4 }, "UP →"),
      s("text", { class: "row-label", x: 4, y: Y.down + 4 }, "← DOWN"),
      s("text", { class: "row-label", x: 4, y: Y.ruler }, `km ${row.start.toFixed(0)}`),
    );
    for (const st of line.stations) {
      if (st.km < row.start - 1 || st.km > row.end + 1) continue;
      const x = xAt(row, st.km);
      g.append(s("g", { class: "station" },
        s("rect", { x: x - 12, y: Y.names + 6, width: 24, height: Y.downLabel - Y.names - 14, rx: 3 }),
        s("text", { x, y: Y.names }, st.name)));
    }
    g.append(
      s("line", { class: "track", x1: xAt(row, row.start), x2: xAt(row, row.end), y1: Y.up, y2: Y.up }),
      s("line", { class: "track", x1: xAt(row, row.start), x2: xAt(row, row.end), y1: Y.down, y2: Y.down }),
    );
    for (let k = Math.ceil(row.start / 10) * 10; k <= row.end + 1e-9; k += 10) {
      const x = xAt(row, k);
      g.append(
        s("line", { class: "tick", x1: x, x2: x, y1: Y.ruler - 14, y2: Y.ruler - 9 }),
        s("text", { class: "tick-label", x, y: Y.ruler }, k.toFixed(0)),
      );
    }
    for (const sig of line.signals) {
      if (sig.km < row.start || sig.km > row.end) continue;
      const y = sig.direction === "up" ? Y.upSignal : Y.downSignal;
      g.append(s("circle", {
        class: "signal green", id: `sig-${sig.id}`, cx: xAt(row, sig.km), cy: y, r: 3.2,
      }, s("title", {}, `signal ${sig.id} (${sig.kind}, ${sig.direction}) km ${sig.km.toFixed(3)}`)));
    }
    base.append(g);
  }
  svg.replaceChildren(base, s("g", { id: "line-dynamic" }));
}

// the part of [a, b] (km) that lies in a row, or null
function clip(row, a, b) {
  const lo = Math.max(Math.min(a, b), row.start);
  const hi = Math.min(Math.max(a, b), row.end);
  return lo < hi ? [lo, hi] : null;
}

function trainClass(train) {
  const cls = ["train", train.direction];
  if (train.alarms.includes("overspeed") || train.alarms.includes("link")) cls.push("alarm");
  if (!train.valid) cls.push("stale");
  return cls.join(" ");
}

function drawLine(snap) {
  const line = snap.line;
  const key = `${line.name}|${line.start_km}|${line.end_km}|${line.signals.length}`;
  if (key !== staticKey) { drawLineStatic(line); staticKey = key; }
  for (const sig of line.signals) {
    const node = document.getElementById(`sig-${sig.id}`);
    if (node) node.setAttribute("class", `signal ${sig.aspect}`);
  }
  const rows = lineRows(line);
  const layer = s("g", {});
  for (const block of snap.blocks) {
    for (const row of rows) {
      const part = clip(row, block.start_km, block.end_km);
      if (!part) continue;
      const y = row.y + (block.direction === "up" ? Y.up : Y.down);
      layer.append(s("line", {
        class: `block ${block.state}`, "data-block": block.id, x1: xAt(row, part[0]), x2: xAt(row, part[1]), y1: y, y2: y,
      }, s("title", {}, `block ${block.id}: ${block.state}${block.reason ? ` (${block.reason})` : ""}`)));
    }
  }
  for (const tsr of snap.tsrs) {
    if (tsr.state !== "ACTIVE") continue;
    for (const row of rows) {
      const part = clip(row, tsr.start_km, tsr.end_km);
      if (!part) continue;
      const x1 = xAt(row, part[0]);
      const x2 = xAt(row, part[1]);
      layer.append(s("g", { class: "tsr" },
        s("rect", { x: x1, y: row.y + Y.up - 6, width: Math.max(x2 - x1, 2), height: Y.down - Y.up + 12 }),
        s("text", { x: (x1 + x2) / 2, y: row.y + (Y.up + Y.down) / 2 + 4 }, `TSR ${tsr.session} · ${fmt(tsr.limit_kmh, 0)}`),
        s("title", {}, `TSR ${tsr.session}: ${tsr.reason}`)));
    }
  }
  const labels = []; // drawn after the trains, where there is room (see placeLabels)
  for (const train of snap.trains) {
    if (!train.registered || train.km === null || train.direction === "unknown") continue;
    const up = train.direction === "up";
    if (train.target) {
      for (const row of rows) {
        if (train.target.km < row.start || train.target.km > row.end) continue;
        const x = xAt(row, train.target.km);
        const y = row.y + (up ? Y.up : Y.down);
        layer.append(s("g", { class: "target" },
          s("line", { x1: x, x2: x, y1: y - 9, y2: y + 9 }),
          s("title", {}, `target point of ${train.number}: signal ${train.target.signal} (${train.target.reason})`)));
      }
    }
    const length = train.length_km || 1.5;
    const tail = up ? train.km - length : train.km + length;
    for (const row of rows) {
      const part = clip(row, tail, train.km);
      if (!part) continue;
      const y = row.y + (up ? Y.up : Y.down);
      const xa = xAt(row, part[0]);
      const xb = xAt(row, part[1]);
      const headIn = train.km >= row.start && train.km <= row.end;
      let d;
      if (up) {
        const tip = headIn ? 7 : 0;
        d = `M${xa} ${y - 5} L${xb - tip} ${y - 5} L${xb} ${y} L${xb - tip} ${y + 5} L${xa} ${y + 5} Z`;
      } else {
        const tip = headIn ? 7 : 0;
        d = `M${xb} ${y - 5} L${xa + tip} ${y - 5} L${xa} ${y} L${xa + tip} ${y + 5} L${xb} ${y + 5} Z`;
      }
      const group = s("g", { class: trainClass(train), "data-train": train.id },
        s("path", { d }),
        s("title", {}, `${train.number} (id ${train.id}) km ${fmt(train.km, 3)}, ` +
          `${fmt(train.speed_kmh, 1)} km/h, MRSP ${fmt(train.mrsp_kmh, 1)} km/h`));
      layer.append(group);
      if (headIn) {
        const text = `${train.number} · ${fmt(train.speed_kmh, 0)} km/h ${up ? "▶" : "◀"}` +
          (train.alarms.length ? " ⚠" : "") + (train.valid ? "" : ` ${fmt(train.info_age_s, 0)} s old`);
        labels.push({ group, text, number: train.number, x: (xa + xb) / 2,
          y: row.y + (up ? Y.upLabel : Y.downLabel), between: row.y + Y.between,
          alarm: train.alarms.length > 0 });
      }
    }
  }
  placeLabels(labels);
  $("line-dynamic").replaceChildren(layer);
}

// Every train on the line is named. Its label (number, speed, way) goes above (UP) or below
// (DOWN) its track where it does not cover another label: trains in alarm first, then
// along the line. Where there is no room for it, the train's number alone goes there, or
// else between the two tracks; where even that is taken (trains nose to tail), the number
// goes above or below its track over the other label: a reader can still tell the trains
// apart by their tooltips, and never sees a train with no name.
function placeLabels(labels) {
  const taken = new Map(); // label row y -> [[x0, x1], ...] taken
  const spanOf = (label, text) => {
    const half = text.length * LABEL_CHAR_PX / 2 + 3;
    return [label.x - half, label.x + half];
  };
  const free = (y, span) => !(taken.get(y) || []).some(([a, b]) => span[0] < b && a < span[1]);
  labels.sort((a, b) => (b.alarm - a.alarm) || (a.x - b.x));
  for (const label of labels) {
    const tries = [[label.y, label.text], [label.y, label.number], [label.between, label.number]];
    const [y, text] = tries.find(([ty, tt]) => free(ty, spanOf(label, tt))) || tries[1];
    taken.set(y, [...(taken.get(y) || []), spanOf(label, text)]);
    label.group.append(s("text", { x: label.x, y }, text));
  }
}

// ------------------------------------------------------------------ time-distance graph

const TD = { width: 800, height: 600, left: 96, right: 44, top: 20, bottom: 26 };

// The distance axis: the whole line, or (the default) the stretch the trains' plans and runs
// in the graph's window cover, widened to the loop of a station at each end (a train's stop
// is in its station's loop, beyond the station's centre). Trains on 30 km of a 590 km line
// drew as a few pixels at the top of the whole-line graph.
let graphWholeLine = false;

function graphSpan(snap) {
  const line = snap.line;
  const whole = [line.start_km, line.end_km];
  if (graphWholeLine) return whole;
  let lo = Infinity;
  let hi = -Infinity;
  for (const series of snap.graph.trains) {
    for (const list of [series.plan, series.actual]) {
      for (const [, km] of list) {
        if (km < lo) lo = km;
        if (km > hi) hi = km;
      }
    }
  }
  if (lo > hi) return whole; // nothing to draw: the whole line
  let from = line.start_km;
  let to = line.end_km;
  for (const st of line.stations) {
    if (st.from_km <= lo && st.from_km > from) from = st.from_km;
    if (st.to_km >= hi && st.to_km < to) to = st.to_km;
  }
  return to > from ? [from, to] : whole;
}

function drawGraphSpan(snap, [from, to]) {
  const whole = from <= snap.line.start_km && to >= snap.line.end_km;
  $("graph-span").textContent = whole ? "whole line" : `km ${fmt(from, 0)}–${fmt(to, 0)}`;
  const button = $("graph-whole");
  button.setAttribute("aria-pressed", String(graphWholeLine));
  button.textContent = graphWholeLine ? "Fit to the trains" : "Whole line";
}

$("graph-whole").addEventListener("click", () => {
  graphWholeLine = !graphWholeLine;
  if (latest) drawGraph(latest);
});

function drawGraph(snap) {
  const svg = $("graph");
  svg.setAttribute("viewBox", `0 0 ${TD.width} ${TD.height}`);
  const { from_s: t0, to_s: t1 } = snap.graph;
  const line = snap.line;
  const [kmFrom, kmTo] = graphSpan(snap);
  drawGraphSpan(snap, [kmFrom, kmTo]);
  const x = (t) => TD.left + (t - t0) / (t1 - t0) * (TD.width - TD.left - TD.right);
  const y = (km) => TD.top + (km - kmFrom) / (kmTo - kmFrom) * (TD.height - TD.top - TD.bottom);
  const g = s("g", {});
  for (const st of line.stations) {
    if (st.km < kmFrom || st.km > kmTo) continue;
    g.append(
      s("line", { class: "grid", x1: TD.left, x2: TD.width - TD.right, y1: y(st.km), y2: y(st.km) }),
      s("text", { class: "station-label", x: TD.left - 5, y: y(st.km) + 3 }, st.name),
    );
  }
  const step = 600;
  for (let t = Math.ceil(t0 / step) * step; t <= t1; t += step) {
    g.append(
      s("line", { class: "grid", x1: x(t), x2: x(t), y1: TD.top, y2: TD.height - TD.bottom }),
      s("text", { class: "time-label", x: x(t), y: TD.height - 8 }, hhmm(t)),
    );
  }
  // TSRs in force: their km over their validity, under the trains (as a train graph shows
  // its slow orders), clipped to the window and the axis
  for (const tsr of snap.tsrs) {
    if (tsr.state !== "ACTIVE") continue;
    const [ta, tb] = [Math.max(tsr.valid_from_s, t0), Math.min(tsr.valid_until_s, t1)];
    const [ka, kb] = [Math.max(tsr.start_km, kmFrom), Math.min(tsr.end_km, kmTo)];
    if (ta >= tb || ka >= kb) continue;
    const band = s("g", { class: "tsr", "data-session": tsr.session });
    band.append(
      s("rect", { x: x(ta), y: y(ka), width: x(tb) - x(ta), height: Math.max(y(kb) - y(ka), 1) }),
      s("text", { x: x(ta) + 3, y: y(ka) - 2 }, `TSR ${tsr.session} · ${fmt(tsr.limit_kmh, 0)}`),
    );
    g.append(band);
  }
  const byId = Object.fromEntries(snap.trains.map((t) => [t.id, t]));
  for (const series of snap.graph.trains) {
    const train = byId[series.id];
    const alarm = train && train.alarms.length ? " alarm" : "";
    const cls = `${series.direction}${alarm}`;
    const pts = (list) => list.map(([t, km]) => `${x(t).toFixed(1)},${y(km).toFixed(1)}`).join(" ");
    if (series.plan.length > 1) g.append(s("polyline", { class: `plan ${cls}`, points: pts(series.plan) }));
    if (series.actual.length > 1) g.append(s("polyline", { class: `actual ${cls}`, points: pts(series.actual) }));
    if (series.actual.length) {
      const [t, km] = series.actual[series.actual.length - 1];
      g.append(s("text", { class: `train-label ${cls}`, x: x(t) + 4, y: y(km) + 3 }, series.number));
    }
  }
  const now = snap.now_s;
  g.append(
    s("line", { class: "now", x1: x(now), x2: x(now), y1: TD.top, y2: TD.height - TD.bottom }),
    s("text", { class: "now-label", x: x(now), y: TD.top - 2 }, "now"),
  );
  svg.replaceChildren(g);
}

// ------------------------------------------------------------------ tables

function chip(state, attrs, ...label) {
  return h("li", { class: `chip state-${state}`, ...attrs }, ...label, h("span", { class: "state" }, state));
}

function drawTsrs(snap) {
  const rows = snap.tsrs.slice().reverse().map((tsr) => {
    const asks = armed.tsr === tsr.session;
    const button = tsr.state === "ACTIVE"
      ? h("button", {
        type: "button", class: asks ? "armed" : "", "data-cancel": tsr.session,
        onclick: () => cancelTsr(tsr.session),
      }, asks ? "Confirm cancel" : "Cancel…")
      : null;
    return h("tr", { "data-session": tsr.session },
      h("td", { class: "num" }, tsr.session),
      h("td", { class: "num" }, `${fmt(tsr.start_km, 3)}–${fmt(tsr.end_km, 3)}`),
      h("td", { class: "num" }, `${fmt(tsr.limit_kmh, 0)} km/h`),
      h("td", { class: "num" }, `${hhmm(tsr.valid_from_s)}–${hhmm(tsr.valid_until_s)}`),
      h("td", {}, tsr.reason, h("br"), h("small", {}, tsr.set_by)),
      h("td", {}, h("span", { class: `chip state-${tsr.state}` }, tsr.state), h("br"), button),
      h("td", {}, tsr.deliveries.length
        ? h("ul", { class: "chips" }, tsr.deliveries.map((d) => chip(d.state,
          { "data-session": tsr.session, "data-train": d.train, title: `train id ${d.train}` },
          h("b", {}, d.number))))
        : h("span", { class: "muted" }, "no train concerned yet")));
  });
  if (!rows.length) rows.push(h("tr", {}, h("td", { colspan: 7, class: "muted" }, "no TSR set")));
  $("tsrs").tBodies[0].replaceChildren(...rows);
}

function drawRestrictions(snap) {
  const rows = snap.restrictions.map((r) => {
    const asks = armed.restriction === r.id;
    return h("tr", { "data-restriction": r.id },
      h("td", { class: "num" }, r.id),
      h("td", {}, r.reason.replaceAll("_", " ")),
      h("td", { class: "num" }, r.block ? `block ${r.block}` : `km ${fmt(r.start_km, 3)}–${fmt(r.end_km, 3)}`),
      h("td", {}, r.track),
      h("td", {}, r.blocks.join(", ")),
      h("td", {}, h("button", {
        type: "button", class: asks ? "armed" : "", "data-clear": r.id,
        onclick: () => clearRestriction(r.id),
      }, asks ? "Confirm clear" : "Clear…")));
  });
  if (!rows.length) rows.push(h("tr", {}, h("td", { colspan: 6, class: "muted" }, "none declared")));
  $("restrictions").tBodies[0].replaceChildren(...rows);
}

function drawTrains(snap) {
  const rows = snap.trains.map((t) => {
    const rejections = Object.entries(t.link.rejections).map(([check, n]) => `${check} ${n}`).join(" · ");
    const link = t.link.connected
      ? ["span", { class: "ok" }, "up"]
      : ["span", { class: "bad" }, t.link.failures ? `failed (${t.link.failures})` : "down"];
    const report = t.info_age_s === null ? "–"
      : ["span", { class: t.valid ? "" : "bad" }, `${fmt(t.info_age_s, 0)} s ago`];
    const target = t.target
      ? `${t.target.signal || "line end"} km ${fmt(t.target.km, 3)} (${t.target.reason})` : "";
    const classes = [t.alarms.length ? "alarm" : "", t.registered ? "" : "gone"].join(" ").trim();
    return { key: t.id, attrs: { class: classes, "data-train": t.id }, cells: [
      [{}, ["b", {}, t.number], " ", ["small", {}, `id ${t.id}`],
        t.category ? ["small", { class: "category" }, ` · ${t.category}`] : null,
        t.registered ? null : ["small", {}, " (left the line)"]],
      [{ class: `dir-${t.direction}` }, t.direction === "up" ? "UP ▶" : t.direction === "down" ? "◀ DOWN" : "?"],
      [{ class: "num" }, fmt(t.km, 3)],
      [{ class: `num ${t.alarms.includes("overspeed") ? "bad" : ""}` }, `${fmt(t.speed_kmh, 0)} km/h`],
      [{ class: "num" }, `${fmt(t.mrsp_kmh, 0)} km/h`],
      [{ class: "num" }, minutes(t.deviation_s)],
      [{ class: "num" }, report],
      [{}, link],
      [{ class: "num" }, t.link.timeouts],
      [{}, rejections || ["span", { class: "muted" }, "none"]],
      [{}, target],
      [{ class: "bad" }, t.alarms.length ? `⚠ ${t.alarms.join(", ")}` : ""],
    ] };
  });
  syncTable($("trains"), rows, h("tr", {}, h("td", { colspan: 12, class: "muted" }, "no train")));
}

function drawDispatch(snap) {
  const targets = snap.trains.filter((t) => t.target).map((t) => ({
    key: t.id, attrs: { "data-train": t.id }, cells: [
      [{}, ["b", {}, t.number]],
      [{}, t.target.signal || "line end"],
      [{ class: "num" }, fmt(t.target.km, 3)],
      [{}, t.target.reason],
      [{}, t.target.state ? ["span", { class: `chip state-${t.target.state}` }, t.target.state] : "–"],
    ],
  }));
  syncTable($("targets"), targets,
    h("tr", {}, h("td", { colspan: 5, class: "muted" }, "no train held by a red signal")));
  const commands = snap.dispatch.slice().reverse().map((c) => h("tr", { "data-command": c.command, "data-train": c.train },
    h("td", { class: "num" }, c.command),
    h("td", {}, h("b", {}, c.number)),
    h("td", {}, c.text),
    h("td", {}, h("span", { class: `chip state-${c.state}` }, c.state))));
  if (!commands.length) commands.push(h("tr", {}, h("td", { colspan: 4, class: "muted" }, "none sent")));
  $("dispatch").tBodies[0].replaceChildren(...commands);
}

function drawAlarms(snap) {
  // a mass outage (hundreds of trains) lists the first MAX_ALARMS_SHOWN and counts the rest
  const items = snap.alarms.slice(0, MAX_ALARMS_SHOWN).map((a) => h("li", { "data-alarm": a.kind, "data-train": a.train },
    h("b", {}, `${a.kind === "link" ? "LINK" : "OVERSPEED"} ${a.number}`), a.text));
  const more = snap.alarms.length - items.length;
  if (more > 0) items.push(h("li", { class: "more" }, `and ${more} more (the trains table shows every train)`));
  if (!items.length) items.push(h("li", { class: "none" }, "no alarm"));
  $("alarms").replaceChildren(...items);
  $("alarm-count").textContent = snap.alarms.length;
  $("alarm-count").className = snap.alarms.length ? "count" : "count zero";
  $("alarms-panel").className = snap.alarms.length ? "" : "none";
}

function drawHeader(snap) {
  $("line-name").textContent = `· line ${snap.line.name}`;
  $("clock").textContent = `${hhmmss(snap.now_s)} UTC`;
  const running = snap.trains.filter((t) => t.registered).length;
  $("counts").textContent = `${running} trains on the line · ${snap.tsrs.filter((t) => t.state === "ACTIVE").length} TSRs in force`;
}

function render() {
  if (!latest) return;
  drawHeader(latest);
  drawAlarms(latest);
  drawLine(latest);
  drawGraph(latest);
  drawTsrs(latest);
  drawRestrictions(latest);
  drawTrains(latest);
  drawDispatch(latest);
}

// ------------------------------------------------------------------ the feed

function receive(snap) {
  latest = snap;
  lastMessageAt = performance.now();
  document.body.dataset.version = snap.version;
  const t0 = performance.now();
  render();
  const t1 = performance.now();
  if (probe.at.length >= PROBE_KEEP) {
    for (const list of [probe.at, probe.renderMs, probe.paintMs, probe.versions]) list.shift();
  }
  probe.renders += 1;
  probe.at.push(performance.timeOrigin + t0);
  probe.renderMs.push(t1 - t0);
  probe.versions.push(snap.version);
  const i = probe.paintMs.push(null) - 1;
  const base = probe.renders - probe.at.length; // entries dropped so far
  // the frame after this one has been laid out and painted: style, layout and paint included
  requestAnimationFrame(() => setTimeout(() => {
    const j = i - (probe.renders - probe.at.length - base);
    if (j >= 0) probe.paintMs[j] = performance.now() - t0;
  }, 0));
}

function setStatus(live, text) {
  $("status").className = `status ${live ? "live" : "down"}`;
  $("status").textContent = text;
}

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(`${scheme}://${location.host}/ws`);
  ws.onopen = () => setStatus(true, "live");
  ws.onmessage = (event) => receive(JSON.parse(event.data));
  ws.onclose = (event) => {
    // a reason is the server's (1013: the ground is starting, restoring from its store)
    setStatus(false, `${event.reason || "disconnected"}: retrying`);
    setTimeout(connect, 1000);
  };
}

setInterval(() => {
  if (!lastMessageAt) return;
  const age = (performance.now() - lastMessageAt) / 1000;
  if (age > STALE_AFTER_S) setStatus(false, `no update for ${age.toFixed(0)} s`);
}, 1000);

showToken();
fetch("/api/snapshot")
  .then(async (r) => {
    const body = await r.json();
    if (r.ok) {
      if (!latest) receive(body);
    } else { // 503 while the ground restores from its store: the WebSocket retries
      setStatus(false, Object.values(body.errors || {}).join("; ") || `answer ${r.status}`);
    }
  })
  .catch(() => setStatus(false, "server not reachable"));
connect();
