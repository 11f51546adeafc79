// The unmesh painting studio: canvas, tools, input and the session connection.
import { Connection } from "./net.js";
import { Navigator } from "./nav.js";
import { BASE_PAINTS, Gauge, fromHex, hex } from "./panel.js";
import { Resampler, inputPoints, pressureOf, tiltOf } from "./pen.js";

const $ = (id) => document.getElementById(id);
const token = new URLSearchParams(location.search).get("token") || "";
const viewCanvas = $("view"), previewCanvas = $("preview"), overlay = $("overlay"), paletteCanvas = $("palette");
const viewCtx = viewCanvas.getContext("2d", { willReadFrequently: true }), overlayCtx = overlay.getContext("2d");
const previewCtx = previewCanvas.getContext("2d");
const paletteCtx = paletteCanvas.getContext("2d");
const gauge = new Gauge($("gauge"));

const tools = { brush: "round", size: 0.05, paint: "oil", color: [0.8, 0.1, 0.1], drying: 0.05, pressure: 0.6 };
// latencies: pointer event -> server frame drawn (ms); previewLatencies: pointer event -> dab preview
// drawn; stages: the split of each server frame's latency (see drawFrame); dropped: stale frames skipped.
const stats = { forces: 0, frames: 0, modelFrames: 0, tiles: 0, bytes: 0, latencies: [], previewLatencies: [],
                stages: [], dropped: 0, fps: 0, errors: [], replies: [] };
let server = { px_per_unit: 100, palette_px_per_unit: 173, presets: {}, width: 0, height: 0 };
let stroke = null;          // {target, resampler, toImage, k, radius, color, raw (samples from raw updates)}
let cursor = null;          // {x, y, p, tilt, over}
let drawing = Promise.resolve();
let strokeNo = 0, endedNo = 0;  // strokes begun and acknowledged ("ended"): their dab previews go then
const dabs = [];                // dab previews {k, t, x, y, r, color} in image pixels, until the server's frame shows them
const sentAt = new Map();       // pen event time stamp -> when its samples were sent
const latestFull = {};          // target -> seq of the newest whole frame received (older frames are stale)
let syncId = 0;
const syncWaiters = new Map();

// ---- connection ---------------------------------------------------------------------------
// While dragging, the newest view is sent once per animation frame (previews); a final view at once.
let pendingView = null;
function sendPendingView() {
  if (pendingView) conn.send({ type: "view", view: pendingView, preview: true });
  pendingView = null;
}
const nav = new Navigator((view, preview) => {
  if (!preview) { pendingView = null; conn.send({ type: "view", view, preview: false }); return; }
  if (pendingView === null) { requestAnimationFrame(sendPendingView); setTimeout(sendPendingView, 34); }
  pendingView = view;
});
const conn = new Connection(token, {
  onOpen: () => { sizeCanvas(); conn.send({ type: "hello", width: viewCanvas.width, height: viewCanvas.height, view: nav.view }); say("connected"); },
  onClose: (ev) => say(ev.code === 1009 ? "message too large: refused by the server" : "connection lost, reconnecting…", true),
  onMessage: onMessage,
  onFrame: (head, blobs, recv) => {
    if (head.full) latestFull[head.target] = Math.max(latestFull[head.target] || 0, head.seq);
    drawing = drawing.then(() => drawFrame(head, blobs, recv)).catch((e) => say(String(e), true));
  },
});

function onMessage(msg) {
  if (msg.type !== "force") {
    stats.replies.push(msg.type);
    if (stats.replies.length > 200) stats.replies.shift();
  }
  switch (msg.type) {
    case "state":
      server = msg;
      $("outname").textContent = msg.out;
      $("strokes").textContent = msg.strokes;
      break;
    case "force": stats.forces += 1; gauge.set(msg.force); break;
    case "color": setColor(msg.color); say(`picked ${hex(msg.color)} from the palette`); break;
    case "error": stats.errors.push(msg.message); say(msg.message, true); break;
    case "ended": endedNo += 1; dropDabs((d) => d.k <= endedNo); break;
    case "saved": say(`saved ${msg.name}`); break;
    case "autosaved": say(`autosaved ${msg.name}`); break;
    case "loaded": say(`loaded ${msg.name}`); break;
    case "exported": say(`exported ${msg.name}`, false, msg.name); break;
    case "recorded": say(`recorded ${msg.name}`, false, msg.name); break;
    case "replayed": bump(msg.strokes); say(`replayed ${msg.strokes} strokes from ${msg.name}`); break;
    case "undone": bump(msg.ok ? -1 : 0); if (!msg.ok) say("nothing to undo"); break;
    case "redone": bump(msg.ok ? 1 : 0); if (!msg.ok) say("nothing to redo"); break;
    case "synced": {
      const done = syncWaiters.get(msg.id);
      if (done) { syncWaiters.delete(msg.id); drawing.then(done); }
      break;
    }
  }
}

function bump(k) { $("strokes").textContent = String(Math.max(0, Number($("strokes").textContent) + k)); }

// Draws a frame; a frame older than the newest whole frame of its target is skipped (stale).
// Latency split of a frame that shows pen events (ts = the newest event's time stamp):
// input = event -> samples sent (page-side handling: samples go out with their pointer event), wire = sent -> frame received,
// made of up (sent -> the server's event loop received it), the server's srv timings (queue,
// paint, render, encode) and down (encoded -> the page received the frame; server and page share
// the wall clock), and client = received -> decoded and drawn.
async function drawFrame(head, blobs, recv) {
  const model = head.target === "model";
  if (head.seq < (latestFull[head.target] || 0)) { stats.dropped += 1; return; }
  const canvas = model ? viewCanvas : paletteCanvas;
  const ctx = model ? viewCtx : paletteCtx;
  if (!head.full && (canvas.width !== head.w || canvas.height !== head.h)) return;
  if (head.full && model && (canvas.width !== head.w || canvas.height !== head.h)) return;  // stale size
  if (head.fmt === "rgba") {  // raw tiles of a painting frame: copied at once
    head.rects.forEach((r, i) => ctx.putImageData(blobs[i], r[0], r[1]));
  } else {
    const bitmaps = await Promise.all(blobs.map((b) => createImageBitmap(b)));
    head.rects.forEach((r, i) => {
      if (head.scale > 1) ctx.drawImage(bitmaps[i], 0, 0, head.w, head.h);
      else ctx.drawImage(bitmaps[i], r[0], r[1]);
      bitmaps[i].close();
    });
  }
  stats.frames += 1;
  stats.tiles += head.rects.length;
  stats.bytes += head.rects.reduce((a, r) => a + r[4], 0);
  if (model) stats.modelFrames += 1;
  if (head.ts !== undefined && head.ts !== null) {
    const drawn = performance.now(), sent = sentAt.get(head.ts), srv = head.srv || {};
    const wall = (t) => performance.timeOrigin + t;
    const known = (v) => v !== undefined && v !== null;
    stats.latencies.push(drawn - head.ts);
    stats.stages.push({ total: drawn - head.ts, input: known(sent) ? sent - head.ts : null,
                        wire: known(sent) ? recv - sent : null,
                        up: known(sent) && known(srv.received) ? srv.received - wall(sent) : null,
                        down: known(srv.done) ? wall(recv) - srv.done - (head.enc || 0) : null,
                        client: drawn - recv, srv: { ...srv, encode: head.enc } });
    for (const k of sentAt.keys()) if (k <= head.ts) sentAt.delete(k);
    for (const a of [stats.latencies, stats.stages]) if (a.length > 2000) a.shift();
    if (model) dropDabs((d) => d.t <= head.ts);
    showLatency();
  }
}

function showLatency() {
  const last = (a) => (a.length ? `${a[a.length - 1].toFixed(0)}` : "–");
  $("latency").textContent = `${last(stats.previewLatencies)} / ${last(stats.latencies)} ms`;
}

// ---- dab previews: the brush's footprint drawn at once, replaced by the server's painted tiles --------
function dropDabs(gone) {
  let n = 0;
  for (const d of dabs) if (!gone(d)) dabs[n++] = d;
  if (n === dabs.length) return;
  dabs.length = n;
  drawDabs();
}

function drawDabs() {
  const ctx = previewCtx;
  ctx.clearRect(0, 0, previewCanvas.width, previewCanvas.height);
  for (const d of dabs) {
    ctx.fillStyle = d.color;
    ctx.beginPath(); ctx.arc(d.x, d.y, d.r, 0, 2 * Math.PI); ctx.fill();
  }
}

function onSurface(x, y) {  // the model image is not background (white) under the pen
  const xi = Math.floor(x), yi = Math.floor(y);
  if (xi < 0 || yi < 0 || xi >= viewCanvas.width || yi >= viewCanvas.height) return false;
  const px = viewCtx.getImageData(xi, yi, 1, 1).data;
  return !(px[0] >= 250 && px[1] >= 250 && px[2] >= 250);
}

let fpsCount = 0;
setInterval(() => {
  stats.fps = stats.modelFrames - fpsCount;
  fpsCount = stats.modelFrames;
  $("fps").textContent = `${stats.fps} /s`;
}, 1000);

function say(text, error = false, file = null) {
  const el = $("message");
  el.textContent = text;
  el.className = error ? "error" : "";
  if (file) {
    const a = document.createElement("a");
    a.href = `/api/file?token=${encodeURIComponent(token)}&name=${encodeURIComponent(file)}`;
    a.textContent = " download";
    a.style.color = "inherit";
    el.appendChild(a);
  }
}

// ---- canvas size ------------------------------------------------------------------------------
function sizeCanvas() {
  const stage = $("stage");
  const w = Math.max(16, Math.min(2048, Math.round(stage.clientWidth)));
  const h = Math.max(16, Math.min(2048, Math.round(stage.clientHeight)));
  const changed = viewCanvas.width !== w || viewCanvas.height !== h;
  for (const c of [viewCanvas, previewCanvas, overlay]) { c.width = w; c.height = h; }  // (clears them)
  cursorBox = null;
  return changed;
}
let resizeTimer = null;
new ResizeObserver(() => {
  clearTimeout(resizeTimer);
  resizeTimer = setTimeout(() => { if (sizeCanvas()) conn.send({ type: "resize", width: viewCanvas.width, height: viewCanvas.height }); }, 80);
}).observe($("stage"));

// ---- painting -----------------------------------------------------------------------------------
function imageMapper(canvas) {
  const rect = canvas.getBoundingClientRect();
  return (e) => [(e.clientX - rect.left) * canvas.width / rect.width, (e.clientY - rect.top) * canvas.height / rect.height];
}

function beginStroke(ev, target, canvas) {
  const pxPerUnit = target === "model" ? server.px_per_unit : server.palette_px_per_unit;
  const spacing = Math.max(1, 0.4 * tools.size * pxPerUnit);  // two fifths of the brush radius on screen
  strokeNo += 1;
  stroke = { target, resampler: new Resampler(spacing), toImage: imageMapper(canvas),
             k: strokeNo, radius: tools.size * pxPerUnit, color: hex(tools.color) };
  conn.send({ type: "begin", target, brush: { type: tools.brush, size: tools.size },
              paint: { type: tools.paint, color: tools.color, drying: tools.drying } });
  addSamples(ev);
}

// Samples are sent at once, one message per pointer event (its coalesced events, with its time
// stamp): the server takes every message queued while it was busy into one frame, so holding them
// here would only add latency. The model's dab previews are drawn at the next animation frame.
function addSamples(ev) {
  const rows = [];
  for (const pt of inputPoints(ev, stroke.toImage, tools.pressure)) rows.push(...stroke.resampler.push(pt));
  if (!rows.length) return;
  const ts = ev.timeStamp;
  conn.send({ type: "samples", samples: rows, ts });
  sentAt.set(ts, performance.now());
  if (stroke.target === "model") {
    for (const r of rows) {
      if (onSurface(r[1], r[2])) {
        // the footprint of the pressed brush: about 1.1 to 1.6 brush radii (what the engine paints)
        dabs.push({ k: stroke.k, t: r[0], x: r[1], y: r[2], r: Math.max(1.5, stroke.radius * (1.1 + 0.5 * r[3])),
                    color: stroke.color });
      }
    }
    scheduleDabs(ts);
  }
}

let dabsPending = null;  // the newest pen event time stamp whose dab previews wait for the next animation frame
function scheduleDabs(ts) {
  const first = dabsPending === null;
  dabsPending = ts;
  if (!first) return;
  requestAnimationFrame(flushDabs);
  setTimeout(flushDabs, 34);  // when animation frames are throttled (hidden page)
}

function flushDabs() {
  if (dabsPending === null) return;
  const ts = dabsPending;
  dabsPending = null;
  drawDabs();
  stats.previewLatencies.push(performance.now() - ts);
  if (stats.previewLatencies.length > 2000) stats.previewLatencies.shift();
}

function endStroke() {
  if (!stroke) return;
  conn.send({ type: "end" });
  if (stroke.target === "model") bump(1);
  stroke = null;
}

overlay.addEventListener("contextmenu", (e) => e.preventDefault());
paletteCanvas.addEventListener("contextmenu", (e) => e.preventDefault());

overlay.addEventListener("pointerdown", (ev) => {
  overlay.setPointerCapture(ev.pointerId);
  if (ev.button === 2 && !ev.shiftKey) nav.start(ev, "rotate");
  else if (ev.button === 1 || ev.button === 2) nav.start(ev, "pan");
  else if (ev.button === 0) beginStroke(ev, "model", overlay);
  ev.preventDefault();
});
// Pen samples come from pointerrawupdate where the browser fires it (secure contexts such as
// 127.0.0.1): it is dispatched when the input arrives, while pointermove waits for the next
// animation frame (about 8-16 ms). A stroke that gets raw updates takes its samples only from
// them; otherwise (no raw updates) from pointermove's coalesced events as before.
function penRaw(target) {
  return (ev) => { if (stroke && stroke.target === target) { stroke.raw = true; addSamples(ev); } };
}
overlay.addEventListener("pointerrawupdate", penRaw("model"));
overlay.addEventListener("pointermove", (ev) => {
  cursor = { x: ev.clientX, y: ev.clientY, p: pressureOf(ev, tools.pressure), tilt: tiltOf(ev), over: true };
  if (stroke && stroke.target === "model") { if (!stroke.raw) addSamples(ev); }
  else if (nav.drag) nav.move(ev, overlay.height);
  drawCursor();
});
for (const type of ["pointerup", "pointercancel"]) {
  overlay.addEventListener(type, (ev) => {
    if (stroke) endStroke();
    nav.end();
    if (ev.pointerType !== "mouse") { cursor = null; drawCursor(); }
  });
}
overlay.addEventListener("pointerleave", () => { cursor = null; drawCursor(); });
overlay.addEventListener("wheel", (ev) => {
  ev.preventDefault();
  if (stroke) setPressure(tools.pressure - ev.deltaY * 0.001);
  else nav.wheel(ev);
}, { passive: false });

paletteCanvas.addEventListener("pointerdown", (ev) => {
  const [x, y] = imageMapper(paletteCanvas)(ev);
  if (ev.altKey || ev.button === 2) { conn.send({ type: "pick_color", x: Math.floor(x), y: Math.floor(y) }); return; }
  if (ev.button !== 0) return;
  paletteCanvas.setPointerCapture(ev.pointerId);
  beginStroke(ev, "palette", paletteCanvas);
});
paletteCanvas.addEventListener("pointerrawupdate", penRaw("palette"));
paletteCanvas.addEventListener("pointermove", (ev) => { if (stroke && stroke.target === "palette" && !stroke.raw) addSamples(ev); });
for (const type of ["pointerup", "pointercancel"]) paletteCanvas.addEventListener(type, () => endStroke());

// The brush at the pen position with its shadow (5.7): the shadow falls away from the tilt.
// Drawn at every pointer move, so kept cheap for the browser: only the last cursor's box is
// cleared (the compositor redraws that much of the layer, not the whole canvas), and the soft
// shadow is the canvas's own shadow of a shape drawn off the canvas (a blur of the shape's box;
// a blur filter on the context filters the whole canvas: ~0.25 core at 60 moves per second).
const SHADOW_SIGMA = 3;              // px: the shadow's Gaussian blur (shadowBlur is twice sigma)
let cursorBox = null;                // [x, y, w, h] of the drawn cursor
function drawCursor() {
  const ctx = overlayCtx;
  if (cursorBox) ctx.clearRect(...cursorBox);
  cursorBox = null;
  if (!cursor || nav.drag) return;
  const rect = overlay.getBoundingClientRect();
  const x = (cursor.x - rect.left) * overlay.width / rect.width, y = (cursor.y - rect.top) * overlay.height / rect.height;
  const r = Math.max(2, tools.size * server.px_per_unit * (0.55 + 0.45 * cursor.p));
  const sx = 5 + cursor.tilt[1] * 0.15, sy = 7 + cursor.tilt[0] * 0.15;
  const far = overlay.width + 4 * r + 100;  // the shape lies this far left of its shadow, off the canvas
  ctx.save();
  ctx.shadowColor = "rgba(0, 0, 0, 0.28)";
  ctx.shadowBlur = 2 * SHADOW_SIGMA;
  ctx.shadowOffsetX = far;
  ctx.fillStyle = "#000";
  ctx.beginPath(); ctx.ellipse(x + sx - far, y + sy, r * 1.05, r * 0.8, 0.3, 0, 2 * Math.PI); ctx.fill();
  ctx.restore();
  ctx.lineWidth = 2;
  ctx.strokeStyle = hex(tools.color);
  ctx.beginPath(); ctx.arc(x, y, r, 0, 2 * Math.PI); ctx.stroke();
  ctx.lineWidth = 1;
  ctx.strokeStyle = "rgba(255, 255, 255, 0.9)";
  ctx.beginPath(); ctx.arc(x, y, r + 1.5, 0, 2 * Math.PI); ctx.stroke();
  ctx.fillStyle = "rgba(20, 20, 20, 0.8)";
  ctx.fillRect(x - 0.5, y - 0.5, 1.5, 1.5);
  // what was drawn: the rings (r + 2) and the shadow (1.05 r + 3 sigma around its offset centre)
  const reach = Math.max(r + 2, 1.05 * r + Math.hypot(sx, sy) + 3 * SHADOW_SIGMA) + 2;
  cursorBox = [Math.floor(x - reach), Math.floor(y - reach), Math.ceil(2 * reach) + 1, Math.ceil(2 * reach) + 1];
}

// ---- tools ----------------------------------------------------------------------------------------
function choose(attr, value) {
  document.querySelectorAll(`[data-${attr}]`).forEach((b) => b.classList.toggle("on", b.dataset[attr] === value));
  tools[attr] = value;
}
document.querySelectorAll("[data-brush]").forEach((b) => b.addEventListener("click", () => choose("brush", b.dataset.brush)));
document.querySelectorAll("[data-paint]").forEach((b) => b.addEventListener("click", () => choose("paint", b.dataset.paint)));
document.querySelectorAll("[data-view]").forEach((b) => b.addEventListener("click", () => nav.preset(b.dataset.view, server.presets)));

function bindSlider(id, key, digits) {
  const input = $(id), out = $(id + "-out");
  const update = () => { tools[key] = Number(input.value); out.textContent = tools[key].toFixed(digits); drawCursor(); };
  input.addEventListener("input", update);
  update();
}
bindSlider("size", "size", 3);
bindSlider("drying", "drying", 2);
bindSlider("pressure", "pressure", 2);

function setPressure(p) {
  const input = $("pressure");
  input.value = String(Math.max(Number(input.min), Math.min(1, p)));
  input.dispatchEvent(new Event("input"));
}

function setColor(rgb) {
  tools.color = rgb.map(Number);
  $("chip").style.background = hex(tools.color);
  $("chip-text").textContent = hex(tools.color);
  $("picker").value = hex(tools.color);
  document.querySelectorAll("#swatches button").forEach((b) => b.classList.toggle("on", b.dataset.hex === hex(tools.color)));
  drawCursor();
}
for (const [name, rgb] of BASE_PAINTS) {
  const b = document.createElement("button");
  b.title = name;
  b.dataset.hex = hex(rgb);
  b.style.background = hex(rgb);
  b.addEventListener("click", () => setColor(rgb));
  $("swatches").appendChild(b);
}
$("picker").addEventListener("input", (e) => setColor(fromHex(e.target.value)));
setColor(BASE_PAINTS[3][1]);

$("undo").addEventListener("click", () => conn.send({ type: "undo" }));
$("redo").addEventListener("click", () => conn.send({ type: "redo" }));
$("save").addEventListener("click", () => conn.send({ type: "save" }));
$("export").addEventListener("click", () => conn.send({ type: "export" }));
$("record").addEventListener("click", () => conn.send({ type: "record" }));

let fileAction = null;
$("load").addEventListener("click", () => { fileAction = "load"; $("file").accept = ".ply"; $("file").click(); });
$("replay").addEventListener("click", () => { fileAction = "replay"; $("file").accept = ".json"; $("file").click(); });
$("file").addEventListener("change", async (e) => {
  const file = e.target.files[0];
  e.target.value = "";
  if (!file) return;
  const name = await upload(file);
  if (name) conn.send({ type: fileAction, name });
});

async function upload(file) {
  let name = file.name.replace(/[^A-Za-z0-9._-]/g, "_").replace(/^[^A-Za-z0-9]+/, "") || "upload";
  const res = await fetch(`/api/upload?token=${encodeURIComponent(token)}&name=${encodeURIComponent(name)}`,
                          { method: "POST", body: file });
  if (!res.ok) { say(`upload refused (${res.status}): ${(await res.text()).trim()}`, true); return null; }
  name = (await res.json()).name;
  return name;
}

// keys a focused slider uses itself (they do not turn the view then)
const SLIDER_KEYS = new Set(["ArrowLeft", "ArrowRight", "ArrowUp", "ArrowDown", "Home", "End", "PageUp", "PageDown"]);
window.addEventListener("keydown", (ev) => {
  if (ev.target instanceof HTMLInputElement && ev.target.type !== "range") return;
  if (ev.target instanceof HTMLInputElement && SLIDER_KEYS.has(ev.key)) return;
  const ctrl = ev.ctrlKey || ev.metaKey;
  if (ctrl && ev.key.toLowerCase() === "z") { conn.send({ type: ev.shiftKey ? "redo" : "undo" }); ev.preventDefault(); return; }
  if (ctrl && ev.key.toLowerCase() === "y") { conn.send({ type: "redo" }); ev.preventDefault(); return; }
  if (ctrl && ev.key.toLowerCase() === "s") { conn.send({ type: "save" }); ev.preventDefault(); return; }
  if (ctrl) return;
  if (ev.key === "1" || ev.key === "2" || ev.key === "3") { choose("brush", ["round", "flat", "pencil"][Number(ev.key) - 1]); return; }
  if (ev.key === "[" || ev.key === "]") {
    const input = $("size");
    input.value = String(Number(input.value) * (ev.key === "]" ? 1.25 : 0.8));
    input.dispatchEvent(new Event("input"));
    return;
  }
  if (nav.key(ev, server.presets)) ev.preventDefault();
});

// ---- test and benchmark hooks --------------------------------------------------------------
window.studio = {
  stats, tools, nav,
  get server() { return server; },
  get connected() { return conn.open; },
  send: (msg) => conn.send(msg),
  setColor, choose,
  // resolves once every earlier message was handled and its frames are on the canvas
  sync() {
    const id = ++syncId;
    return new Promise((resolve) => { syncWaiters.set(id, resolve); conn.send({ type: "sync", id }); });
  },
};
