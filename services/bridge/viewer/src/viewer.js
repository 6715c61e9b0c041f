// The live viewer of a grains run: a zenoh client (over the remote-API plugin's WebSocket that
// grains-bridge hosts) that draws the solvers' views, shows the latest summary and sends
// commands. Settings come from the page's URL: ?ws=ws://HOST:PORT&run=RUN_ID
// Keys and payloads: protocol/README.md §9.
import { Session, Config, ReplyError, Duration } from "@eclipse-zenoh/zenoh-ts";

const params = new URLSearchParams(location.search);
const WS = params.get("ws") || "";
const RUN = params.get("run") || "";
const PREFIX = `grains/${RUN}`;
/** A command's query waits this long: the bridge answers within its 5 s wait for the run's
 *  acknowledgement (an error reply after that), so only a dropped command runs out. */
const QUERY_TIMEOUT_MS = 7000;
const RETRY_MS = 5000; // between attempts to (re)connect
const HEARTBEAT_MS = 3000; // between checks that the WebSocket still answers

const $ = (id) => document.getElementById(id);
const canvas = $("view");
const ctx = canvas.getContext("2d");

// What tests inspect: the latest summary document, the latest view of each role, frames drawn.
const viewer = {
  lastSummary: null,
  lastViews: {}, // role ("dem" | "mpm") → view document
  drawn: 0,
  config: null, // state/config: the bridge's effective settings
  status: "",
  acks: [], // the lines shown in #acks
};
window.grainsViewer = viewer;
document.title = `grains ${RUN}`;
// The same, for a test that only sees the DOM (chromium --dump-dom): <html data-viewer="ready"
// data-step="…" data-drawn="…">.
const mark = (k, v) => { document.documentElement.dataset[k] = String(v); };

let session = null;
// Sessions opened so far: the newest-step checks below hold within one session only (a
// bridge started again may serve a run from an earlier step, e.g. a restarted checkpoint).
let generation = 0;
const seenIn = new Map(); // "summary" | role → generation of the kept document

// ---------------------------------------------------------------------------------------
// Status line

function setStatus(text, kind) {
  viewer.status = text;
  const el = $("status");
  el.textContent = text;
  el.className = kind;
}

// ---------------------------------------------------------------------------------------
// Connecting

/** Resolves when a WebSocket to `url` opens (then closes it); rejects on error or after
 *  `ms`. zenoh-ts's own connect retries ten times with growing waits (tens of minutes when
 *  nothing listens), so the page first finds out quickly whether anything answers. */
function probe(url, ms) {
  return new Promise((resolve, reject) => {
    let ws;
    try {
      ws = new WebSocket(url);
    } catch (e) {
      reject(new Error(`bad WebSocket address ${url}: ${e.message}`));
      return;
    }
    const timer = setTimeout(() => { ws.close(); reject(new Error(`no answer from ${url}`)); }, ms);
    ws.onopen = () => { clearTimeout(timer); ws.close(); resolve(); };
    ws.onerror = () => { clearTimeout(timer); reject(new Error(`cannot reach ${url}`)); };
  });
}

function withTimeout(promise, ms, what) {
  return Promise.race([
    promise,
    new Promise((_, reject) => setTimeout(() => reject(new Error(`${what}: no answer within ${ms / 1000} s`)), ms)),
  ]);
}

async function connect() {
  if (!WS || !RUN) {
    setStatus("error: the page's URL must say ?ws=ws://HOST:PORT&run=RUN_ID", "error");
    return;
  }
  setStatus(`connecting to ${WS} …`, "connecting");
  for (let attempt = 1; ; attempt++) {
    try {
      await probe(WS, 3000);
      // Config takes the URL form "ws://host:port" as well as zenoh's "ws/host:port".
      const s = await withTimeout(Session.open(new Config(WS, 2000)), 15000, "opening the zenoh session");
      session = s;
      generation += 1;
      // Subscribe before asking for the latest state, so that nothing falls in between.
      await s.declareSubscriber(`${PREFIX}/state/**`, { handler: (sample) => onSample(sample) });
      setStatus(`connected to ${WS}, run ${RUN}`, "connected");
      queryState(s);
      await heartbeat(s);
      setStatus(`error: lost the connection to ${WS} (the run may have ended); reconnecting …`, "error");
    } catch (e) {
      setStatus(`error: ${e && e.message ? e.message : e} (attempt ${attempt}; retrying every ${RETRY_MS / 1000} s)`, "error");
    }
    if (session) {
      const s = session;
      session = null;
      s.close().catch(() => {});
    }
    await new Promise((r) => setTimeout(r, RETRY_MS));
  }
}

/** Returns when the session stops answering (the bridge or its WebSocket is gone). */
async function heartbeat(s) {
  for (;;) {
    await new Promise((r) => setTimeout(r, HEARTBEAT_MS));
    try {
      await withTimeout(s.info(), 2500, "heartbeat");
    } catch {
      return;
    }
  }
}

/** The latest summary, settings and views (the bridge's queryable `state/**`). */
async function queryState(s) {
  try {
    const rx = await s.get(`${PREFIX}/state/**`);
    if (!rx) return;
    for await (const reply of rx) {
      const r = reply.result();
      if (!(r instanceof ReplyError)) onSample(r);
    }
  } catch (e) {
    console.warn("state query:", e);
  }
}

// ---------------------------------------------------------------------------------------
// Incoming state

function onSample(sample) {
  const key = sample.keyexpr().toString();
  let doc;
  try {
    doc = JSON.parse(sample.payload().toString());
  } catch (e) {
    console.warn(`${key}: not JSON`, e);
    return;
  }
  const tail = key.slice(PREFIX.length + "/state/".length);
  if (tail === "summary") {
    // A query's reply may come after a newer publication: keep the newest step.
    const last = seenIn.get("summary") === generation ? viewer.lastSummary : null;
    if (!last || doc.step > last.step || (doc.step === last.step && doc.paused !== last.paused)) {
      seenIn.set("summary", generation);
      viewer.lastSummary = doc;
      mark("step", doc.step);
      showSummary(doc);
    }
  } else if (tail === "config") {
    viewer.config = doc;
    showConfig(doc);
  } else if (tail.startsWith("view/")) {
    const role = tail.slice("view/".length);
    const last = seenIn.get(role) === generation ? viewer.lastViews[role] : null;
    if (!last || !(doc.step < last.step)) {
      seenIn.set(role, generation);
      viewer.lastViews[role] = doc;
      grow(doc);
      scheduleDraw();
    }
  }
}

const fmt = (x, digits = 4) => (x === null || x === undefined ? "–" : typeof x === "number" ? (Number.isInteger(x) ? String(x) : x.toPrecision(digits)) : String(x));
const pad = (s, n) => String(s).padEnd(n);

function showSummary(d) {
  const lines = [
    `run ${d.run}   scene ${d.scene}${d.paused ? "   PAUSED" : ""}`,
    `step ${d.step} / ${d.steps}   time ${fmt(d.time)} s   steps/s ${fmt(d.steps_per_s, 3)}`,
    `kinetic energy ${fmt(d.kinetic_energy)} J   mass ${fmt(d.mass)} kg`,
    `momentum [${(d.momentum || []).map((m) => fmt(m, 3)).join(", ")}] kg m/s`,
    `grains ${fmt(d.grains)}   points ${fmt(d.points)}   zone nodes ${fmt(d.zone_nodes)}   zone cells ${fmt(d.zone_cells)}`,
  ];
  const parts = Object.entries(d.participants || {});
  if (parts.length) {
    lines.push("", `${pad("", 8)}${pad("items", 8)}${pad("nodes", 8)}${pad("compute ms", 11)}${pad("wait ms", 9)}status`);
    for (const [role, p] of parts) {
      lines.push(`${pad(role, 8)}${pad(fmt(p.items), 8)}${pad(fmt(p.nodes), 8)}${pad(fmt(p.compute_ms, 3), 11)}${pad(fmt(p.wait_ms, 3), 9)}${p.status}`);
    }
  }
  $("summary").textContent = lines.join("\n");
}

function showConfig(c) {
  const off = c.steering === false;
  $("controls").classList.toggle("readonly", off);
  $("steering-note").textContent = off
    ? "Steering is off for this run: the bridge refuses every command (they are still sent)."
    : "";
}

// ---------------------------------------------------------------------------------------
// Drawing. World (x, y) → canvas with y up; z is not shown (a 3D run is seen along z).

/** The box around all material seen so far (positions ± sizes), in metres. */
const bounds = { x0: Infinity, y0: Infinity, x1: -Infinity, y1: -Infinity };

function grow(view) {
  const pos = view.position || [];
  const size = view.size || [];
  for (let i = 0; i < pos.length; i++) {
    const r = size[i] || 0;
    const [x, y] = pos[i];
    if (x - r < bounds.x0) bounds.x0 = x - r;
    if (x + r > bounds.x1) bounds.x1 = x + r;
    if (y - r < bounds.y0) bounds.y0 = y - r;
    if (y + r > bounds.y1) bounds.y1 = y + r;
  }
}

let drawScheduled = false;
function scheduleDraw() {
  if (drawScheduled) return;
  drawScheduled = true;
  requestAnimationFrame(draw);
}

const MODEL_COLOUR = { dem: "#c28a40", mpm: "#4682c8" };
const SPEED_BINS = 32;
const LOW = [20, 30, 110]; // dark blue
const HIGH = [255, 225, 40]; // yellow
const ramp = (t) => `rgb(${LOW.map((a, k) => Math.round(a + (HIGH[k] - a) * t)).join(",")})`;
const RAMP = Array.from({ length: SPEED_BINS }, (_, i) => ramp(i / (SPEED_BINS - 1)));
const speed = (v) => Math.hypot(v[0], v[1], v[2] || 0);
const NO_VALUE = "#6b7480"; // grey: an item the colour's quantity says nothing of (NaN: a solver that does not say)
const UNITS = { speed: "m/s", pressure: "Pa" };
/** The coloured quantity of item i of view v, or null. */
const quantity = {
  speed: (v, i) => (v.velocity && v.velocity[i] ? speed(v.velocity[i]) : null),
  pressure: (v, i) => (v.pressure && Number.isFinite(v.pressure[i]) ? v.pressure[i] : null),
};

function draw() {
  drawScheduled = false;
  // Match the canvas's pixels to its size on screen.
  const dpr = window.devicePixelRatio || 1;
  const w = Math.max(1, Math.round(canvas.clientWidth * dpr));
  const h = Math.max(1, Math.round(canvas.clientHeight * dpr));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
  ctx.fillStyle = "#101418";
  ctx.fillRect(0, 0, w, h);
  const views = ["mpm", "dem"].map((r) => viewer.lastViews[r]).filter(Boolean); // grains on top
  if (!views.length || !(bounds.x1 >= bounds.x0)) {
    ctx.fillStyle = "#8a96a3";
    ctx.font = `${14 * dpr}px sans-serif`;
    ctx.fillText("waiting for a view of the run …", 12 * dpr, 24 * dpr);
    return;
  }

  // Fit the box (5% margin, at least 1 mm wide) below the legend, keeping the aspect ratio.
  const mode = $("colour").value; // "model" | "speed" | "pressure"
  const ramped = mode in quantity;
  const top = (views.length + (ramped ? 2 : 1)) * 16 * dpr + 8 * dpr;
  const bw = Math.max(bounds.x1 - bounds.x0, 1e-3);
  const bh = Math.max(bounds.y1 - bounds.y0, 1e-3);
  const scale = Math.max(1e-9, Math.min(w / (bw * 1.1), (h - top) / (bh * 1.1)));
  const cx = (bounds.x0 + bounds.x1) / 2;
  const cy = (bounds.y0 + bounds.y1) / 2;
  const X = (x) => w / 2 + (x - cx) * scale;
  const Y = (y) => top + (h - top) / 2 - (y - cy) * scale;

  ctx.strokeStyle = "#3a4450";
  ctx.lineWidth = 1;
  ctx.strokeRect(X(bounds.x0), Y(bounds.y1), bw * scale, bh * scale);

  // The ramp spans the values shown (speeds from 0).
  let lo = mode === "speed" ? 0 : Infinity;
  let hi = -Infinity;
  if (ramped) {
    for (const v of views) {
      for (let i = 0; i < (v.position || []).length; i++) {
        const q = quantity[mode](v, i);
        if (q !== null) [lo, hi] = [Math.min(lo, q), Math.max(hi, q)];
      }
    }
  }
  for (const v of views) {
    const disk = v.role === "dem";
    const pos = v.position || [];
    const size = v.size || [];
    // One path per colour (the ramp's bins, then "no value"): a few fill calls for thousands
    // of shapes.
    const paths = ramped ? [...RAMP, NO_VALUE].map(() => new Path2D()) : [new Path2D()];
    for (let i = 0; i < pos.length; i++) {
      const px = X(pos[i][0]);
      const py = Y(pos[i][1]);
      const r = (size[i] || 0) * scale;
      let bin = 0;
      if (ramped) {
        const q = quantity[mode](v, i);
        if (q === null) bin = SPEED_BINS;
        else if (hi > lo) bin = Math.min(SPEED_BINS - 1, Math.floor(((q - lo) / (hi - lo)) * SPEED_BINS));
      }
      const p = paths[bin];
      if (disk) {
        const rr = Math.max(r, 0.75);
        p.moveTo(px + rr, py);
        p.arc(px, py, rr, 0, 2 * Math.PI);
      } else {
        const half = Math.max(r, 0.75);
        p.rect(px - half, py - half, 2 * half, 2 * half);
      }
    }
    paths.forEach((p, k) => {
      ctx.fillStyle = ramped ? (k < SPEED_BINS ? RAMP[k] : NO_VALUE) : MODEL_COLOUR[v.role] || "#ccc";
      ctx.fill(p);
    });
  }

  // Legend: what is shown, of how many, and the scale.
  ctx.fillStyle = "#d8dee4";
  ctx.font = `${12 * dpr}px sans-serif`;
  let ty = 16 * dpr;
  for (const v of views) {
    ctx.fillText(`${v.role}: ${v.count} of ${v.total} shown, step ${v.step}`, 8 * dpr, ty);
    ty += 16 * dpr;
  }
  ctx.fillText(`x ${fmt(bounds.x0, 3)} … ${fmt(bounds.x1, 3)} m, y ${fmt(bounds.y0, 3)} … ${fmt(bounds.y1, 3)} m`, 8 * dpr, ty);
  if (ramped) {
    ty += 16 * dpr;
    const gw = 120 * dpr;
    const g = ctx.createLinearGradient(8 * dpr, 0, 8 * dpr + gw, 0);
    g.addColorStop(0, ramp(0));
    g.addColorStop(1, ramp(1));
    ctx.fillStyle = g;
    ctx.fillRect(8 * dpr, ty - 10 * dpr, gw, 10 * dpr);
    ctx.fillStyle = "#d8dee4";
    const range = hi >= lo ? `${fmt(lo, 3)} … ${fmt(hi, 3)} ${UNITS[mode]}` : `no ${mode} in the views`;
    ctx.fillText(range, 16 * dpr + gw, ty);
  }

  viewer.drawn += 1;
  mark("drawn", viewer.drawn);
  frameTimes.push(performance.now());
}

// Frame rate: frames drawn over the last 5 s.
const frameTimes = [];
const startedAt = performance.now();
setInterval(() => {
  const now = performance.now();
  while (frameTimes.length && frameTimes[0] < now - 5000) frameTimes.shift();
  const span = Math.min(5000, now - startedAt) / 1000;
  $("fps").textContent = span > 0 ? (frameTimes.length / span).toFixed(1) : "0.0";
}, 500);

$("colour").addEventListener("change", scheduleDraw);
window.addEventListener("resize", scheduleDraw);

// ---------------------------------------------------------------------------------------
// Commands: a query on grains/<run>/control whose payload is the command's JSON. The bridge
// answers with a reply (the run's acknowledgement) or an error reply (why it refused); a
// command that zenoh's access control drops (a reader's) gets no answer at all.

function ackLine(text) {
  const t = new Date().toLocaleTimeString();
  const line = `${t} ${text}`;
  viewer.acks.push(line);
  const el = $("acks");
  const div = document.createElement("div");
  div.textContent = line;
  el.appendChild(div);
  while (el.childNodes.length > 100) el.removeChild(el.firstChild);
  el.scrollTop = el.scrollHeight;
}

/** Sends `cmd`; its line in #acks starts with `what` (by default the command's name). */
async function send(cmd, what = cmd.command) {
  const text = JSON.stringify(cmd);
  const s = session;
  if (!s) {
    ackLine(`${what}: no answer (not connected)`);
    return;
  }
  const result = await new Promise((resolve) => {
    let done = false;
    const finish = (r) => { if (!done) { done = true; clearTimeout(timer); resolve(r); } };
    // In case the query's end never comes back (the WebSocket died meanwhile).
    const timer = setTimeout(() => finish("no answer"), QUERY_TIMEOUT_MS + 2000);
    s.get(`${PREFIX}/control`, {
      payload: text,
      timeout: Duration.milliseconds.of(QUERY_TIMEOUT_MS),
      // [on each reply, on the query's end]: the first reply decides.
      handler: [(reply) => finish(describe(reply)), () => finish("no answer")],
    }).catch((e) => finish(`no answer (${e && e.message ? e.message : e})`));
  });
  ackLine(`${what}: ${result}`);
}

/** A reply as a line: the acknowledgement's JSON, or "refused: <reason>". */
function describe(reply) {
  const r = reply.result();
  const body = r.payload().toString();
  if (!(r instanceof ReplyError)) return body;
  try {
    const j = JSON.parse(body);
    return `refused: ${j.error !== undefined ? j.error : body}`;
  } catch {
    return `refused: ${body}`;
  }
}

for (const c of ["pause", "resume", "stop", "snapshot"]) {
  $(`btn-${c}`).addEventListener("click", () => send({ command: c }));
}
// The values go as typed: the bridge checks them (a non-number goes as null and is refused).
function set(key, input) {
  const t = $(input).value.trim();
  const value = t === "" ? null : Number(t);
  send({ command: "set", key, value }, `set ${key} ${t || "(empty)"}`);
}
$("btn-gravity").addEventListener("click", () => set("gravity.y", "gravity-y"));
$("btn-wall").addEventListener("click", () =>
  set(`wall.${$("wall-index").value.trim() || "0"}.velocity.${$("wall-axis").value}`, "wall-velocity"));

scheduleDraw();
mark("viewer", "ready");
connect();
