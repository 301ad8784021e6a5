// eyehil live view: the page. Plain JavaScript, no libraries; everything is drawn on canvases.
// Server messages (drivers/view/payload.py): JSON text (hello, state, tick, script, calibration) and binary
// camera images (<u32 header length><JSON header><JPEG>). Image coordinates are full-sensor pixels (OpenCV:
// origin at the top-left pixel centre, x right, y down); screen positions are STIMULUS mm (top-left origin,
// x right, y down). The drawn state is in window.eyehilView (read by the browser tests).
"use strict";

const HISTORY_S = 10;
const TRAIL = 60, TRAIL_STEP_S = 0.05;   // 3 s of gaze
const JITTER = 6;   // images waiting per eye for an animation frame (a jitter buffer of at most 100 ms at 60 Hz)
const EYES = ["right", "left"];
const view = window.eyehilView = {
  socket: "closed", connected: false, streaming: false, calibrating: null, hello: null, state: null,
  eyes: { right: {}, left: {} },     // per eye: image (ImageBitmap), header, record, window, overlay, source
  overlay: {},                       // per eye: what the last drawing put where (canvas px), for the tests
  gaze: null, target: null, trail: [], script: { name: "none", points: [] }, calibration: null,
  history: [], stats: {}, imagesDrawn: 0, imagesReceived: 0, imagesSkipped: 0, ticks: 0, animationFrames: 0, fps: 0, ips: 0, drawnFrameIds: {},
};
const $ = (id) => document.getElementById(id);
let socket = null, dirty = true, eyesDirty = false;  // dirty: redraw all; eyesDirty: the eye images only

// --- connection ------------------------------------------------------------------------------
function connect() {
  const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws";
  socket = new WebSocket(url);
  socket.binaryType = "arraybuffer";
  view.socket = "connecting";
  socket.onopen = () => { view.socket = "open"; render(); };
  socket.onmessage = (event) => {
    if (typeof event.data === "string") onMessage(JSON.parse(event.data)); else onImage(event.data);
  };
  socket.onclose = () => {
    view.socket = "closed"; view.connected = false; view.streaming = false;
    $("error").textContent = "the view server is not reachable; retrying";
    showStatus(); setTimeout(connect, 1000);
  };
}

function send(command) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(command));
}

function onMessage(m) {
  if (m.type === "hello") {
    view.hello = m;
    $("device").textContent = `${m.model} ${m.firmware} on ${m.url}: ${m.sensor[0]} x ${m.sensor[1]} px, ` +
      `${m.rate_hz} Hz, ${m.leds} LED(s), stream ${m.stream}`;
    $("blink").disabled = !m.blink;
    $("blink").title = m.blink ? "" : "needs the emulator in the same process (eyehil emulate --view)";
  } else if (m.type === "state") {
    view.state = m; view.connected = m.connected; view.streaming = m.streaming; view.calibrating = m.calibrating;
    $("error").textContent = m.error || "";
    if (m.script !== null && $("script").value !== m.script) $("script").value = m.script;
    showStatus();
  } else if (m.type === "tick") {
    onTick(m);
  } else if (m.type === "script") {
    view.script = m; $("script").value = m.name;
  } else if (m.type === "calibration") {
    view.calibration = m; showCalibration();
  }
  dirty = true;
}

function onTick(m) {
  view.ticks += 1; view.stats = m.stats;
  for (const row of m.samples) view.history.push(row);
  const last = view.history.length ? view.history[view.history.length - 1][0] : 0;
  let cut = 0;
  while (cut < view.history.length && view.history[cut][0] < last - HISTORY_S) cut++;
  if (cut) view.history.splice(0, cut);
  for (const row of m.samples) {  // the trail: a gaze point every TRAIL_STEP_S of device time
    const lastAt = view.trail.length ? view.trail[view.trail.length - 1][2] : -Infinity;
    if (row[3] !== null && (row[0] - lastAt >= TRAIL_STEP_S || row[0] < lastAt)) view.trail.push([row[3], row[4], row[0]]);
  }
  if (view.trail.length > TRAIL) view.trail.splice(0, view.trail.length - TRAIL);
  view.gaze = m.gaze; view.target = m.target;
  for (const eye of EYES) {
    const e = view.eyes[eye];
    if (m.eyes[eye]) { e.tickRecord = m.eyes[eye]; }
  }
  showStats();
}

async function onImage(buffer) {
  const length = new DataView(buffer).getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, length)));
  const blob = new Blob([new Uint8Array(buffer, 4 + length)], { type: "image/jpeg" });
  view.imagesReceived += 1;
  const bitmap = await createImageBitmap(blob);
  const e = view.eyes[header.eye];
  if (!e) { bitmap.close(); return; }
  // A jitter buffer: each animation frame shows the next image, so two images arriving within one frame are
  // both shown (one a frame later) instead of the first being overwritten; at most JITTER wait.
  e.queue = e.queue || [];
  e.queue.push({ bitmap, header });
  while (e.queue.length > JITTER) { e.queue.shift().bitmap.close(); view.imagesSkipped += 1; }
  eyesDirty = true;  // the screen and the chart change with the messages (ticks, 30 a second), not the images
}

function nextImage(e) {
  const next = e.queue && e.queue.shift();
  if (!next) return;
  if (e.image) e.image.close();
  e.image = next.bitmap; e.header = next.header; e.imageAt = performance.now();
}

// --- drawing ---------------------------------------------------------------------------------
function render() {
  view.animationFrames += 1;
  if (dirty || eyesDirty) {
    const all = dirty;
    dirty = eyesDirty = false;
    for (const eye of EYES) {
      const e = view.eyes[eye];
      nextImage(e);
      if (e.queue && e.queue.length) eyesDirty = true;  // more waiting: the next frame shows the next one
    }
    for (const eye of EYES) drawEye(eye);
    if (all) { drawScreen(); drawChart(); }
  }
  requestAnimationFrame(render);
}

function drawEye(eye) {
  const canvas = $("eye-" + eye), ctx = canvas.getContext("2d"), e = view.eyes[eye];
  canvas.parentElement.hidden = !e.image && !e.tickRecord;   // an eye the device does not stream
  const fresh = e.image && performance.now() - e.imageAt < 1000;
  let record, origin;
  if (fresh) {
    const h = e.header;
    if (canvas.width !== h.width || canvas.height !== h.height) { canvas.width = h.width; canvas.height = h.height; }
    ctx.drawImage(e.image, 0, 0);
    record = h.record || e.tickRecord; origin = [h.roi_x, h.roi_y];
    $("src-" + eye).textContent = `camera image, frame ${h.frame_id}`;
    if (view.drawnFrameIds[eye] !== h.frame_id) { view.imagesDrawn += 1; view.drawnFrameIds[eye] = h.frame_id; }
  } else {
    record = e.tickRecord;
    if (!record) { ctx.fillStyle = "#000"; ctx.fillRect(0, 0, canvas.width, canvas.height); return; }
    origin = featureWindow(e, record, canvas);
    drawFeatures(ctx, record, origin, canvas);
    $("src-" + eye).textContent = `rendering of the features, frame ${record.frame_id}`;
  }
  drawOverlay(ctx, eye, record, origin, fresh);
  if (fresh && e.header.truth) drawTruth(ctx, eye, e.header.truth, origin);
}

function drawTruth(ctx, eye, t, origin) {
  // The device's own features of the exposure when the host detected (on the emulator: the ground truth).
  const overlay = view.overlay[eye];
  ctx.save(); ctx.strokeStyle = "#f3f"; ctx.setLineDash([3, 3]); ctx.lineWidth = 1;
  if (t.detected && t.x !== null) {
    const x = t.x - origin[0], y = t.y - origin[1];
    ctx.beginPath(); ctx.ellipse(x, y, t.a / 2, t.b / 2, (t.angle || 0) * Math.PI / 180, 0, 2 * Math.PI); ctx.stroke();
    overlay.truth = { x: x, y: y, sensor_x: t.x, sensor_y: t.y };
  }
  ctx.setLineDash([]);
  for (const g of t.glints) {
    const x = g.x - origin[0], y = g.y - origin[1];
    ctx.beginPath(); ctx.moveTo(x - 3, y - 3); ctx.lineTo(x + 3, y + 3); ctx.moveTo(x + 3, y - 3); ctx.lineTo(x - 3, y + 3);
    ctx.stroke();
  }
  ctx.fillStyle = "#f3f"; ctx.font = "11px sans-serif"; ctx.fillText("dashed: device features (ground truth)", 6, ctx.canvas.height - 6);
  ctx.restore();
}

function featureWindow(e, record, canvas) {
  // A window the size of the canvas, recentred on the pupil when it leaves the middle half.
  const w = canvas.width, h = canvas.height;
  if (record.detected && record.x !== null) {
    const o = e.window;
    if (!o || Math.abs(record.x - (o[0] + w / 2)) > w / 4 || Math.abs(record.y - (o[1] + h / 2)) > h / 4) {
      e.window = [Math.round(record.x - w / 2), Math.round(record.y - h / 2)];
    }
  }
  return e.window || [0, 0];
}

function drawFeatures(ctx, r, origin, canvas) {
  ctx.fillStyle = "#8a8a8a"; ctx.fillRect(0, 0, canvas.width, canvas.height);
  if (!r.detected || r.x === null) return;
  const x = r.x - origin[0], y = r.y - origin[1];
  ctx.fillStyle = "#555"; ctx.beginPath(); ctx.arc(x, y, Math.max(r.a, 8) * 1.9, 0, 2 * Math.PI); ctx.fill();
  ctx.fillStyle = "#141414"; ctx.beginPath();
  ctx.ellipse(x, y, r.a / 2, r.b / 2, (r.angle || 0) * Math.PI / 180, 0, 2 * Math.PI); ctx.fill();
  ctx.fillStyle = "#fff";
  for (const g of r.glints) { ctx.beginPath(); ctx.arc(g.x - origin[0], g.y - origin[1], 2.5, 0, 2 * Math.PI); ctx.fill(); }
}

function drawOverlay(ctx, eye, r, origin, fromImage) {
  const overlay = { frame_id: r ? r.frame_id : null, origin: origin, scale: 1, source: fromImage ? "image" : "features",
                    width: ctx.canvas.width, height: ctx.canvas.height, pupil: null, glints: [], truth: null };
  view.overlay[eye] = overlay;
  if (!r) return;
  ctx.lineWidth = 1.5;
  if (r.detected && r.x !== null) {
    const x = r.x - origin[0], y = r.y - origin[1];
    ctx.strokeStyle = "#3f3"; ctx.beginPath();
    ctx.ellipse(x, y, r.a / 2, r.b / 2, (r.angle || 0) * Math.PI / 180, 0, 2 * Math.PI); ctx.stroke();
    ctx.beginPath(); ctx.moveTo(x - 4, y); ctx.lineTo(x + 4, y); ctx.moveTo(x, y - 4); ctx.lineTo(x, y + 4); ctx.stroke();
    overlay.pupil = { x: x, y: y, sensor_x: r.x, sensor_y: r.y, a: r.a, b: r.b, angle: r.angle };
  }
  ctx.font = "11px sans-serif";
  for (const g of r.glints) {
    const x = g.x - origin[0], y = g.y - origin[1];
    ctx.strokeStyle = "#fc3"; ctx.beginPath(); ctx.arc(x, y, 4, 0, 2 * Math.PI); ctx.stroke();
    ctx.fillStyle = "#fc3"; ctx.fillText("LED " + g.led, x + 6, y - 8 - 11 * g.led);
    overlay.glints.push({ led: g.led, x: x, y: y });
  }
  ctx.fillStyle = "rgba(0, 0, 0, 0.6)"; ctx.fillRect(0, 0, 112, 19);
  ctx.fillStyle = r.blink ? "#f66" : "#ddd";
  ctx.fillText(r.blink ? "blink" : `confidence ${r.confidence === null ? "-" : r.confidence.toFixed(2)}`, 6, 14);
}

function drawScreen() {
  const canvas = $("screen"), ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  const size = view.hello && view.hello.screen;
  if (!size) {
    ctx.fillStyle = "#aaa"; ctx.font = "13px sans-serif";
    ctx.fillText("no geometry file: the screen is unknown (--geometry)", 12, 24); return;
  }
  const k = Math.min((canvas.width - 20) / size[0], (canvas.height - 20) / size[1]);
  const ox = (canvas.width - size[0] * k) / 2, oy = (canvas.height - size[1] * k) / 2;
  const at = (p) => [ox + p[0] * k, oy + p[1] * k];
  view.screenTransform = { ox: ox, oy: oy, k: k };
  ctx.fillStyle = "#3a3a3a"; ctx.fillRect(ox, oy, size[0] * k, size[1] * k);
  ctx.fillStyle = "#777";
  for (const p of view.script.points || []) { const q = at(p); ctx.fillRect(q[0] - 2, q[1] - 2, 4, 4); }
  const cal = view.calibration;
  if (cal && cal.ok) {
    ctx.font = "11px sans-serif";
    for (const p of cal.points) {
      if (!p.target) continue;
      const t = at(p.target);
      ctx.strokeStyle = "#6af"; cross(ctx, t, 6);
      if (p.estimate) {
        const e = at(p.estimate);
        ctx.strokeStyle = "#fa5"; ctx.beginPath(); ctx.moveTo(t[0], t[1]); ctx.lineTo(e[0], e[1]); ctx.stroke();
        ctx.beginPath(); ctx.arc(e[0], e[1], 3, 0, 2 * Math.PI); ctx.stroke();
      }
      ctx.fillStyle = "#fa5"; ctx.fillText(p.error_deg === null ? "-" : p.error_deg.toFixed(2) + "°", t[0] + 8, t[1] + 14);
    }
  }
  if (view.target) {
    const t = at(view.target);
    ctx.strokeStyle = "#f44"; ctx.lineWidth = 2; ctx.beginPath(); ctx.arc(t[0], t[1], 8, 0, 2 * Math.PI); ctx.stroke();
    ctx.lineWidth = 1;
  }
  ctx.fillStyle = "rgba(80, 255, 120, 0.35)";
  for (const p of view.trail) { const q = at(p); ctx.fillRect(q[0] - 1.5, q[1] - 1.5, 3, 3); }
  if (view.gaze) {
    const g = at(view.gaze);
    ctx.fillStyle = "#5f8"; ctx.beginPath(); ctx.arc(g[0], g[1], 5, 0, 2 * Math.PI); ctx.fill();
  } else if (!cal || !cal.ok) {
    ctx.fillStyle = "#aaa"; ctx.font = "12px sans-serif"; ctx.fillText("not calibrated: no gaze estimate", ox + 6, oy + 16);
  }
}

function cross(ctx, p, r) {
  ctx.beginPath(); ctx.moveTo(p[0] - r, p[1]); ctx.lineTo(p[0] + r, p[1]);
  ctx.moveTo(p[0], p[1] - r); ctx.lineTo(p[0], p[1] + r); ctx.stroke();
}

function drawChart() {
  const canvas = $("chart"), ctx = canvas.getContext("2d"), w = canvas.width, h = canvas.height;
  ctx.fillStyle = "#111"; ctx.fillRect(0, 0, w, h);
  ctx.strokeStyle = "#333"; ctx.fillStyle = "#777"; ctx.font = "10px sans-serif";
  for (const level of [0, 0.5, 1]) {
    const y = h - 10 - level * (h - 20);
    ctx.beginPath(); ctx.moveTo(24, y); ctx.lineTo(w, y); ctx.stroke(); ctx.fillText(level.toFixed(1), 2, y + 3);
  }
  if (!view.history.length) return;
  const end = view.history[view.history.length - 1][0];
  for (const [column, colour] of [[1, "#f66"], [2, "#6af"]]) {
    ctx.strokeStyle = colour; ctx.beginPath();
    let pen = false;
    for (const row of view.history) {
      if (row[column] === null) { pen = false; continue; }
      const x = w - (end - row[0]) / HISTORY_S * w, y = h - 10 - row[column] * (h - 20);
      if (pen) ctx.lineTo(x, y); else ctx.moveTo(x, y);
      pen = true;
    }
    ctx.stroke();
  }
}

// --- text ------------------------------------------------------------------------------------
function showStatus() {
  const s = view.state, body = document.body;
  const text = view.socket !== "open" ? "disconnected (view server)" : !view.connected ? "disconnected"
    : view.calibrating ? "calibrating (" + view.calibrating + ")" : view.streaming ? "streaming" : "connected, idle";
  $("status").textContent = text;
  body.className = !view.connected ? "disconnected" : view.calibrating ? "connected calibrating" : "connected";
  if (s && !s.connected && view.socket === "open") $("error").textContent = s.error || "";
}

function showStats() {
  const s = view.stats, ms = (v) => (v === null || v === undefined ? "-" : v.toFixed(1) + " ms");
  $("rate").textContent = s.rate_hz.toFixed(0) + " Hz";
  $("latency").textContent = ms(s.latency_p50_ms) + " / " + ms(s.latency_p99_ms);
  // lost: frames the link lost (sequence gaps, incomplete images); dropped: samples the device or the host discarded;
  // images not sent: what the device skips by design when it cannot render every exposure (STATUS frames_dropped)
  $("lost").textContent = String((s.lost_frames || 0) + (s.images_incomplete || 0));
  $("dropped").textContent = String((s.samples_dropped || 0) + (s.samples_overflowed || 0));
  $("dropped").title = `device: ${s.samples_dropped || 0}; host: ${s.samples_overflowed || 0}`;
  $("skipped").textContent = String(s.frames_dropped || 0);
  $("view-dropped").textContent = String(s.view_dropped || 0);
  $("view-dropped").title = `${s.images_skipped || 0} images received but not sent (faster than the view's image rate), ` +
    `${view.imagesSkipped} not drawn (newer ones waiting)`;
}

function showCalibration() {
  const c = view.calibration, box = $("calibration");
  if (!c.ok) { box.textContent = `calibration (${c.method}) failed: ${c.error}`; return; }
  const rows = c.points.map((p, i) => `<tr><td>${i + 1}</td><td>${p.target.map((v) => v.toFixed(0)).join(", ")}</td>` +
    `<td>${p.error_deg === null ? "-" : p.error_deg.toFixed(2)}°</td></tr>`).join("");
  box.innerHTML = `<b>${c.method}</b>: mean validation error <span id="mean-error">${c.mean_error_deg.toFixed(2)}</span>°` +
    `<table><tr><th>#</th><th>target (mm)</th><th>error</th></tr>${rows}</table>`;
}

// --- controls and the frame-rate report ------------------------------------------------------
$("start").onclick = () => send({ cmd: "start" });
$("stop").onclick = () => send({ cmd: "stop" });
$("script").onchange = () => send({ cmd: "script", name: $("script").value });
$("blink").onclick = () => send({ cmd: "blink", duration_s: 0.3 });
$("calibrate").onclick = () => send({ cmd: "calibrate", method: $("method").value });

let counted = { drawn: 0, received: 0, at: performance.now() };
setInterval(() => {
  const now = performance.now(), dt = (now - counted.at) / 1000;
  view.fps = (view.imagesDrawn - counted.drawn) / dt;
  view.ips = (view.imagesReceived - counted.received) / dt;
  counted = { drawn: view.imagesDrawn, received: view.imagesReceived, at: now };
  $("fps").textContent = view.fps.toFixed(1) + " /s";
  $("ips").textContent = view.ips.toFixed(1);
  send({ cmd: "fps", value: view.fps });
  dirty = true;
}, 1000);

connect();
requestAnimationFrame(render);
