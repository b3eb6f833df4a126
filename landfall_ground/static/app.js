// Landfall ground: the page. It keeps one view per vehicle, built from the checked feed messages the
// ground station sends over /ws (landfall_ground/station.py lists the events), and draws the chosen one.
// Everything from the feed is put on the page as text (textContent), never as HTML.
"use strict";

const $ = (id) => document.getElementById(id);
const SVG = "http://www.w3.org/2000/svg";
const STALE_S = 5; // no telemetry for this long: the link to the vehicle is shown as lost

function el(tag, attrs, ...children) {
  const ns = ["svg", "rect", "text", "polyline", "circle", "image", "g", "line"].includes(tag);
  const node = ns ? document.createElementNS(SVG, tag) : document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v !== null && v !== undefined) node.setAttribute(k, v);
  }
  for (const c of children) node.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return node;
}

const fmt = (v, unit, digits = 1) => (typeof v === "number" ? `${v.toFixed(digits)} ${unit}` : "-");
const clock = (t) => new Date(t * 1000).toISOString().slice(11, 19);

// ---------------------------------------------------------------- the model
function newVehicle() {
  return { status: null, telemetry: null, heardAt: null, track: [], alarms: [], timeline: [],
           rounds: new Map(), faults: [], answers: [], outcome: null, sites: [] };
}

const page = { source: "", link: {}, alarms: {}, basemap: null, clock: null, vehicles: new Map(),
               selected: null, malformed: 0, recent: [] };

function vehicle(id) {
  if (!page.vehicles.has(id)) page.vehicles.set(id, newVehicle());
  return page.vehicles.get(id);
}

function round(v, n) {
  const key = typeof n === "number" ? n : 0;
  if (!v.rounds.has(key)) v.rounds.set(key, { rank: null, confirms: [] });
  return v.rounds.get(key);
}

function addPoint(v, pos) {
  if (!Array.isArray(pos) || pos.some((x) => typeof x !== "number")) return;
  const last = v.track[v.track.length - 1];
  if (!last || Math.hypot(last[0] - pos[0], last[1] - pos[1], last[2] - pos[2]) > 0.05) v.track.push(pos);
}

function take(m) {
  const v = vehicle(m.vehicle);
  const b = m.body;
  switch (m.leaf) {
    case "status": v.status = { ...b, t: m.t }; break;
    case "telemetry":
      v.telemetry = b; v.heardAt = Date.now() / 1000; addPoint(v, b.pos_ned_m); break;
    case "alarm": v.alarms.push({ ...b, t: m.t }); v.timeline.push({ t: m.t, kind: "alarm", b }); break;
    case "state":
      v.timeline.push({ t: m.t, kind: b.kind || "state", b });
      addPoint(v, b.pos_ned_m);
      if (b.kind === "outcome") v.outcome = { ...b, t: m.t };
      break;
    case "decision":
      if (b.stage === "rank") round(v, b.round).rank = b;
      else {
        round(v, b.round).confirms.push(b);
        if (Array.isArray(b.site_ned_m)) v.sites.push({ ned: b.site_ned_m, accept: b.accept === true });
      }
      break;
    case "fault": v.faults.push({ t: m.t, b }); break;
    case "alarm/result": v.answers.push({ t: m.t, b }); break;
  }
}

// ---------------------------------------------------------------- events from the station
function onEvent(e) {
  switch (e.type) {
    case "hello":
      Object.assign(page, { source: e.source, link: e.link, alarms: e.alarms, basemap: e.basemap,
                            clock: e.clock, malformed: e.malformed, recent: e.recent, vehicles: new Map() });
      for (const [id, msgs] of Object.entries(e.vehicles)) { vehicle(id); msgs.forEach(take); }
      break;
    case "msg": take(e); break;
    case "link": page.link = e; break;
    case "malformed": page.malformed = e.malformed; page.recent = e.recent; break;
    case "clock": page.clock = e; break;
    case "error": console.warn("ground station:", e.detail); break;
  }
  if (!page.selected || !page.vehicles.has(page.selected)) page.selected = page.vehicles.keys().next().value || null;
  schedule();
}

let pending = false;
function schedule() {
  if (!pending) { pending = true; requestAnimationFrame(() => { pending = false; render(); }); }
}

// ---------------------------------------------------------------- drawing
function render() {
  renderHeader();
  const v = page.selected ? page.vehicles.get(page.selected) : null;
  $("vehicle-name").textContent = page.selected || "-";
  renderStatus(v);
  renderAlarm(v);
  renderTimeline(v);
  renderRounds(v);
  renderTrack(v);
  renderReplay();
}

function renderHeader() {
  $("source").textContent = page.source === "replay" ? "replay" : "live";
  const link = $("link");
  const state = page.link.state || "connecting";
  link.textContent = page.source === "replay" ? page.link.detail : `broker ${state}`;
  link.className = "badge " + (state === "connected" ? "ok" : state === "down" ? "bad" : "warn");
  link.title = page.link.detail || "";
  const banner = $("banner");
  if (!socketUp) { banner.hidden = false; banner.textContent = "the ground station server is unreachable: reconnecting"; }
  else if (state !== "connected") { banner.hidden = false; banner.textContent = `broker ${state}: ${page.link.detail || ""}`; }
  else banner.hidden = true;
  const mal = $("malformed");
  mal.textContent = `${page.malformed} malformed`;
  mal.className = "badge " + (page.malformed > 0 ? "bad" : "quiet");
  $("malformed-card").hidden = page.recent.length === 0;
  $("malformed-list").replaceChildren(
    ...page.recent.slice().reverse().map((r) => el("li", {}, el("b", {}, r.topic), `: ${r.problem}`)));
  const select = $("vehicles");
  const ids = [...page.vehicles.keys()];
  if (select.dataset.ids !== ids.join("\n")) {
    select.dataset.ids = ids.join("\n");
    select.replaceChildren(...(ids.length ? ids : [""]).map((id) => el("option", { value: id }, id || "(none yet)")));
  }
  select.value = page.selected || "";
}

function renderStatus(v) {
  const s = $("st-status");
  const status = v && v.status ? v.status.state : null;
  s.textContent = page.source === "replay" ? "recorded" : status || "unknown";
  s.className = status === "online" ? "online" : status === "offline" ? "offline" : "";
  const t = v && v.telemetry;
  $("st-mode").textContent = t ? `${t.mode || (t.custom_mode === undefined ? "?" : "custom " + t.custom_mode)}${t.armed ? ", armed" : t.armed === false ? ", disarmed" : ""}` : "-";
  let alt = t ? t.agl_m : null;
  if (alt === null && v && v.track.length) alt = -v.track[v.track.length - 1][2];
  $("st-alt").textContent = t && typeof t.agl_m === "number" ? `${t.agl_m.toFixed(1)} m above ground` : fmt(alt, "m up (local frame)");
  $("st-battery").textContent = t ? fmt(t.battery_pct, "%", 0) : "-";
  const link = $("st-link");
  if (!t || page.source === "replay") { link.textContent = "-"; link.className = ""; return; }
  const silent = Date.now() / 1000 - v.heardAt;
  const autopilot = typeof t.link_age_s === "number" && t.link_age_s > STALE_S
    ? `, autopilot silent ${t.link_age_s.toFixed(0)} s` : "";
  link.textContent = (silent > STALE_S ? `no telemetry for ${silent.toFixed(0)} s` : "telemetry ok") + autopilot;
  link.className = silent > STALE_S || autopilot ? "offline" : "online";
}

function renderAlarm(v) {
  const last = v && v.alarms.length ? v.alarms[v.alarms.length - 1] : null;
  $("alarm-current").textContent = last
    ? `${last.reason} (${last.criticality || "?"}): ${last.result || "?"} at ${clock(last.t)}` : "none";
  const why = !page.alarms.enabled ? page.alarms.why
    : !v ? "no vehicle yet"
    : !(v.status && v.status.alarm_intake === true)
      ? `vehicle ${page.selected} does not take alarms over MQTT (its mqtt.alarm_intake is off)` : "";
  $("alarm-form").hidden = Boolean(why);
  $("alarm-off").textContent = why;
  $("alarm-answers").replaceChildren(...(v ? v.answers.slice(-5).reverse() : []).map((a) =>
    el("li", {}, `${clock(a.t)} ${a.b.reason ? a.b.reason + ": " : ""}${a.b.result}${a.b.error ? " (" + a.b.error + ")" : ""}`)));
}

function describe(entry) {
  const b = entry.b;
  if (entry.kind === "alarm") return `alarm '${b.reason}' (${b.criticality || "?"}): ${b.result || ""}`;
  if (entry.kind === "outcome") return `${b.state} after ${b.rounds} round(s): ${b.reason || ""}`;
  if (entry.kind === "note") return b.state;
  return `${b.state}${typeof b.round === "number" && b.round > 0 ? " (round " + b.round + ")" : ""}`;
}

function renderTimeline(v) {
  const items = v ? v.timeline.slice(-200) : [];
  $("timeline").replaceChildren(...items.map((e) =>
    el("li", { class: e.kind }, el("span", { class: "t" }, clock(e.t)), describe(e))));
  const out = $("outcome");
  out.textContent = v && v.outcome ? `${v.outcome.state}: ${v.outcome.reason || ""}` : "no outcome yet";
  out.className = v && v.outcome ? (v.outcome.state === "landed" ? "online" : "offline") : "quiet";
  const faults = v ? v.faults : [];
  $("fault-count").textContent = String(faults.length);
  $("faults").replaceChildren(...faults.slice(-20).reverse().map((f) =>
    el("li", {}, el("span", { class: "t" }, clock(f.t)), `${f.b.kind || "fault"}: ${f.b.error || JSON.stringify(f.b)}`)));
}

function frame(rank) {
  if (!rank.thumbnail_jpeg_b64) return el("div", { class: "noframe quiet" }, "no frame");
  const img = el("img", { src: "data:image/jpeg;base64," + rank.thumbnail_jpeg_b64, alt: `round ${rank.round} frame` });
  const box = el("div", { class: "frame" }, img);
  const size = Array.isArray(rank.frame_px) ? rank.frame_px : null;
  const cands = Array.isArray(rank.candidates) ? rank.candidates : [];
  const draw = (w, h) => {
    const svg = el("svg", { viewBox: `0 0 ${w} ${h}`, preserveAspectRatio: "none" });
    cands.forEach((c, k) => {
      const [x0, y0, x1, y1] = c.box;
      const g = c.geometry || {};
      const title = `candidate ${k}: ${fmt(g.landable_area_m2, "m2 landable", 0)}, slope ${fmt(g.slope_deg, "deg")}`;
      svg.append(el("rect", { x: x0, y: y0, width: x1 - x0, height: y1 - y0, "data-k": k,
                              class: k === rank.chosen ? "candidate chosen" : "candidate" }, el("title", {}, title)));
    });
    box.append(svg);
  };
  if (size) draw(size[0], size[1]);
  else img.addEventListener("load", () => draw(img.naturalWidth * 3, img.naturalHeight * 3)); // 960 / 320
  return box;
}

function confirmation(c) {
  const k = c.check || {};
  const lidar = typeof k.points === "number"
    ? `LiDAR ${k.points} returns, ${fmt(typeof k.roughness_m === "number" ? k.roughness_m * 100 : null, "cm rough", 0)}, obstacle ${fmt(k.obstacle_m, "m")}, edge ${typeof k.edge_distance_m === "number" ? fmt(k.edge_distance_m, "m") : "none in view"}`
    : "no LiDAR check";
  return el("div", { class: "confirm " + (c.accept ? "accept" : "reject") },
    el("b", {}, c.accept ? "confirmed" : "rejected"), ` by ${c.tier || "?"} in ${fmt(c.latency_s, "s", 2)}: `,
    el("span", { class: "rationale" }, c.rationale || ""), el("div", { class: "quiet lidar" }, lidar,
      Array.isArray(k.reasons) && k.reasons.length ? ` (${k.reasons.join(", ")})` : ""));
}

const drawn = new Map(); // round key -> [signature, node]: frames are decoded once, not on every event
function renderRounds(v) {
  const keys = v ? [...v.rounds.keys()].sort((a, b) => b - a) : [];
  $("rounds-empty").hidden = keys.length > 0;
  const nodes = keys.map((key) => {
    const r = v.rounds.get(key);
    const sig = `${page.selected}/${key}/${r.rank ? 1 : 0}/${r.confirms.length}`;
    const cached = drawn.get(key);
    if (cached && cached[0] === sig) return cached[1];
    const rank = r.rank;
    const head = el("h3", {}, `round ${key}`);
    const body = rank
      ? [frame(rank), el("div", { class: "meta" },
          el("div", {}, `chosen: candidate ${rank.chosen ?? "none"} of ${(rank.candidates || []).length}`,
             ` · tier ${rank.tier || "?"} · ${fmt(rank.latency_s, "s", 2)}`),
          el("p", { class: "rationale" }, rank.rationale || ""),
          ...r.confirms.map(confirmation))]
      : [el("div", { class: "noframe quiet" }, "no ranking"), el("div", { class: "meta" }, ...r.confirms.map(confirmation))];
    const node = el("div", { class: "round", "data-round": key }, head, ...body);
    drawn.set(key, [sig, node]);
    return node;
  });
  $("rounds").replaceChildren(...nodes);
}

function renderTrack(v) {
  const svg = $("track");
  const pts = v ? v.track : [];
  const sites = v ? v.sites : [];
  const all = [...pts.map((p) => [p[0], p[1]]), ...sites.map((s) => [s.ned[0], s.ned[1]])];
  if (!all.length) { svg.replaceChildren(); $("track-scale").textContent = "no position yet"; return; }
  const ns = all.map((p) => p[0]), es = all.map((p) => p[1]);
  const half = Math.max(40, (Math.max(...ns) - Math.min(...ns)) / 2 + 20, (Math.max(...es) - Math.min(...es)) / 2 + 20);
  const cn = (Math.max(...ns) + Math.min(...ns)) / 2, ce = (Math.max(...es) + Math.min(...es)) / 2;
  svg.setAttribute("viewBox", `${ce - half} ${-cn - half} ${2 * half} ${2 * half}`);
  const w = half / 100; // stroke width in metres, so lines look alike at any zoom
  const kids = [];
  const bm = page.basemap;
  if (bm) {
    kids.push(el("image", { href: bm.url, x: bm.east_m[0], y: -bm.north_m[1], width: bm.east_m[1] - bm.east_m[0],
                            height: bm.north_m[1] - bm.north_m[0], preserveAspectRatio: "none" }));
  }
  kids.push(el("polyline", { class: "path", "stroke-width": w, points: pts.map((p) => `${p[1]},${-p[0]}`).join(" ") }));
  for (const s of sites) {
    kids.push(el("circle", { class: "site" + (s.accept ? "" : " rejected"), cx: s.ned[1], cy: -s.ned[0], r: 3 * w, "stroke-width": w }));
  }
  const last = pts[pts.length - 1];
  if (last) {
    const landed = v.outcome && v.outcome.state === "landed";
    kids.push(el("circle", { class: landed ? "touchdown" : "vehicle", id: landed ? "touchdown" : null,
                             cx: last[1], cy: -last[0], r: (landed ? 4 : 2.5) * w, "stroke-width": w / 2 }));
  }
  svg.replaceChildren(...kids);
  const here = last ? `N ${last[0].toFixed(1)} m, E ${last[1].toFixed(1)} m, ${(-last[2]).toFixed(1)} m up` : "";
  $("track-scale").textContent = `${(2 * half).toFixed(0)} m across${bm ? " over " + bm.name : ""}; ${here}`;
}

function renderReplay() {
  const replaying = page.source === "replay" && page.clock;
  $("replay").hidden = !replaying;
  document.body.classList.toggle("replaying", Boolean(replaying));
  if (!replaying) return;
  const c = page.clock;
  const slider = $("slider");
  slider.min = 0; slider.max = c.t1 - c.t0; // seconds into the record: small numbers keep their precision
  if (!sliding) slider.value = c.t - c.t0;
  $("clock").textContent = `${(c.t - c.t0).toFixed(1)} / ${(c.t1 - c.t0).toFixed(1)} s`;
  $("play").textContent = c.playing ? "pause" : "play";
  $("speed").value = String(c.speed);
}

// ---------------------------------------------------------------- the connection and the controls
let socket = null, socketUp = false, retryMs = 500, sliding = false;

function connect() {
  socket = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  socket.onopen = () => { socketUp = true; retryMs = 500; schedule(); };
  socket.onmessage = (m) => {
    let e;
    try { e = JSON.parse(m.data); } catch (err) { console.warn("bad event", err); return; }
    onEvent(e);
  };
  socket.onclose = () => {
    socketUp = false; schedule();
    setTimeout(connect, retryMs);
    retryMs = Math.min(retryMs * 2, 5000);
  };
}

function send(msg) { if (socket && socketUp) socket.send(JSON.stringify(msg)); }

$("vehicles").addEventListener("change", (ev) => { page.selected = ev.target.value; drawn.clear(); schedule(); });
$("play").addEventListener("click", () => send({ type: page.clock && page.clock.playing ? "pause" : "play" }));
$("back").addEventListener("click", () => send({ type: "step", by: -1 }));
$("forward").addEventListener("click", () => send({ type: "step", by: 1 }));
$("speed").addEventListener("change", (ev) => send({ type: "speed", speed: Number(ev.target.value) }));
$("slider").addEventListener("input", (ev) => {
  sliding = true;
  if (page.clock) send({ type: "seek", t: page.clock.t0 + Number(ev.target.value) });
});
$("slider").addEventListener("change", () => { sliding = false; });
$("alarm-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const body = { vehicle: page.selected, reason: $("alarm-reason").value, criticality: $("alarm-criticality").value };
  const said = $("alarm-sent");
  said.textContent = "sending...";
  try {
    const r = await fetch("api/alarm", { method: "POST", headers: { "content-type": "application/json" }, body: JSON.stringify(body) });
    const answer = await r.json();
    said.textContent = r.ok ? `sent '${body.reason}' (${body.criticality}): the vehicle's answer comes below` : `not sent: ${answer.error}`;
  } catch (err) {
    said.textContent = `not sent: ${err}`;
  }
});
setInterval(() => { if (page.source === "live") schedule(); }, 1000); // "no telemetry for N s" keeps counting
connect();
