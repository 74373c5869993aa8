// phloem studio page: plain JavaScript over the studio's HTTP API (docs/studio.md).
"use strict";

const TOKEN = document.querySelector('meta[name="phloem-token"]').content;
const $ = (id) => document.getElementById(id);

// -- API -------------------------------------------------------------------------------------
function withToken(url) {
  return url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(TOKEN);
}

async function api(method, url, body) {
  const init = { method, headers: { "X-Phloem-Token": TOKEN } };
  if (body instanceof FormData) {
    init.body = body;
  } else if (body !== undefined) {
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const r = await fetch(url, init);
  const data = r.headers.get("content-type")?.includes("json") ? await r.json() : await r.text();
  if (!r.ok) {
    const err = new Error(typeof data === "object" && data.detail ? data.detail : `${r.status} ${r.statusText}`);
    err.status = r.status;
    throw err;
  }
  return data;
}

const q = (params) => new URLSearchParams(params).toString();

function say(el, text, error = false) {
  el.textContent = text;
  el.classList.toggle("error", error);
}

async function imageList(select, keep) {
  const files = await api("GET", "/api/files");
  select.innerHTML = "";
  for (const f of files.filter((f) => f.kind === "image")) {
    const o = document.createElement("option");
    o.value = o.textContent = f.path;
    select.appendChild(o);
  }
  if (keep) select.value = keep;
}

// Upload a picked file as photos/NAME; a name already taken gets -1, -2, ... (no silent overwrite).
async function upload(input) {
  const file = input.files[0];
  const base = file.name.replace(/[^A-Za-z0-9_.-]/g, "_").replace(/^[._-]+/, "") || "photo.png";
  const dot = base.lastIndexOf(".");
  for (let i = 0; i < 100; i++) {
    const name = "photos/" + (i ? `${base.slice(0, dot)}-${i}${base.slice(dot)}` : base);
    const form = new FormData();
    form.append("file", file);
    try {
      return await api("POST", "/api/upload?" + q({ path: name }), form);
    } catch (e) {
      if (e.status !== 409) throw e;
    }
  }
  throw new Error("file: too many files of that name");
}

function loadImage(path) {
  return new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => resolve(img);
    img.onerror = () => reject(new Error(`image: ${path} could not be shown`));
    img.src = withToken("/api/file?" + q({ path, v: Date.now() }));
  });
}

// A job: submit, follow its server-sent events, allow cancelling; resolves with its last state.
function runJob(request, ui) {
  return new Promise(async (resolve, reject) => {
    let job;
    try {
      job = await api("POST", "/api/jobs", request);
    } catch (e) {
      reject(e);
      return;
    }
    ui.cancel.disabled = false;
    ui.cancel.onclick = () => api("POST", `/api/jobs/${job.id}/cancel`).catch(() => {});
    const events = new EventSource(withToken(`/api/jobs/${job.id}/events`));
    events.onmessage = (ev) => {
      const s = JSON.parse(ev.data);
      ui.progress.max = s.total || 1;
      ui.progress.value = s.done;
      say(ui.msg, `${s.kind}: ${s.state}${s.total ? ` ${Math.round((100 * s.done) / s.total)}%` : ""}`);
      if (["done", "failed", "cancelled"].includes(s.state)) {
        events.close();
        ui.cancel.disabled = true;
        resolve(s);
      }
    };
    events.onerror = () => {
      events.close();
      ui.cancel.disabled = true;
      reject(new Error("job: lost the connection to the studio"));
    };
  });
}

// A job whose output file may exist: asks before replacing it; throws unless the job is done.
async function runJobReplacing(req, ui) {
  let s;
  try {
    s = await runJob(req, ui);
  } catch (e) {
    if (e.status !== 409 || !confirm(`${req.out} exists: replace it?`)) throw e;
    s = await runJob({ ...req, overwrite: true }, ui);
  }
  if (s.state !== "done") throw new Error(`${s.kind} ${s.state}: ${s.message}`);
  return s;
}

const fileUrl = (path) => withToken("/api/file?" + q({ path, v: Date.now() }));

// -- tabs ------------------------------------------------------------------------------------
for (const b of document.querySelectorAll("#tabs button")) {
  b.onclick = () => {
    for (const o of document.querySelectorAll("#tabs button")) o.classList.toggle("active", o === b);
    for (const ws of document.querySelectorAll(".ws")) ws.hidden = ws.id !== "ws-" + b.dataset.ws;
  };
}

// Pointer position in the canvas's own pixels (it may be shown scaled; its border is not drawn on).
function canvasPoint(canvas, ev) {
  const r = canvas.getBoundingClientRect();
  const x = ((ev.clientX - r.left - canvas.clientLeft) * canvas.width) / canvas.clientWidth;
  const y = ((ev.clientY - r.top - canvas.clientTop) * canvas.height) / canvas.clientHeight;
  return [Math.min(Math.max(x, 0), canvas.width - 1), Math.min(Math.max(y, 0), canvas.height - 1)];
}

// Pixels per CSS pixel of a canvas: hit radii and line widths stay the same size on screen.
const pxScale = (canvas) => canvas.width / (canvas.clientWidth || canvas.width);

// Hit tests on polylines (arrays of [x, y] points), shared by the Strokes and Branching editors:
// the nearest point within r as { b: line, v: point, d }, the first line winning a tie ...
function nearestPoint(lines, p, r) {
  let best = null;
  lines.forEach((pts, bi) => pts.forEach((q, vi) => {
    const d = Math.hypot(q[0] - p[0], q[1] - p[1]);
    if (d <= r && (!best || d < best.d)) best = { b: bi, v: vi, d };
  }));
  return best;
}

// ... and the nearest segment within r as { b: line, j: its end point, t: 0..1 along it, q: the
// point on it, d }.
function nearestSegment(lines, p, r) {
  let best = null;
  lines.forEach((pts, bi) => {
    for (let j = 1; j < pts.length; j++) {
      const [a, c] = [pts[j - 1], pts[j]];
      const dx = c[0] - a[0], dy = c[1] - a[1];
      const t = Math.max(0, Math.min(1, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy || 1)));
      const q = [a[0] + t * dx, a[1] + t * dy];
      const d = Math.hypot(q[0] - p[0], q[1] - p[1]);
      if (d <= r && (!best || d < best.d)) best = { b: bi, j, t, q, d };
    }
  });
  return best;
}

// A dot on each point of a polyline, none closer than 4 screen pixels to the last drawn (a drawn
// or traced line has a point every pixel or two); every point can still be grabbed.
function pointDots(ctx, pts, s) {
  ctx.beginPath();
  let last = null;
  pts.forEach(([x, y], j) => {
    if (last && j < pts.length - 1 && Math.hypot(x - last[0], y - last[1]) < 4 * s) return;
    ctx.moveTo(x + 2.2 * s, y);
    ctx.arc(x, y, 2.2 * s, 0, 2 * Math.PI);
    last = [x, y];
  });
  ctx.fill();
}

// A white ring outlined in black around the selected point, seen on a photo and on white.
function ringAt(ctx, [x, y], s) {
  ctx.beginPath();
  ctx.arc(x, y, 5 * s, 0, 2 * Math.PI);
  ctx.lineWidth = 4 * s;
  ctx.strokeStyle = "#000";
  ctx.stroke();
  ctx.lineWidth = 2 * s;
  ctx.strokeStyle = "#fff";
  ctx.stroke();
}

// -- Strokes workspace -------------------------------------------------------------------------
// sel: the selected point in edit mode, { side: "source" | "target", s: stroke, v: point };
// history: the stroke lists as JSON before each edit, for Undo.
const S = { photo: null, source: [], target: [], history: [], drawing: null, drag: null, sel: null, savedAs: null };
const COLORS = ["#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4", "#f032e6", "#9a6324"];
const sMode = () => document.querySelector('input[name="s-mode"]:checked').value;
const roundTenth = (v) => Math.round(v * 10) / 10;

function drawStrokes(canvas, strokes, background, sel) {
  const ctx = canvas.getContext("2d");
  const s = pxScale(canvas);
  const edit = sMode() === "edit";
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (background) ctx.drawImage(background, 0, 0);
  const all = S.drawing && S.drawing.canvas === canvas ? [...strokes, S.drawing.points] : strokes;
  ctx.lineWidth = Math.max(2, canvas.width / 200);
  ctx.lineJoin = ctx.lineCap = "round";
  all.forEach((pts, i) => {
    ctx.strokeStyle = COLORS[i % COLORS.length];
    ctx.beginPath();
    pts.forEach(([x, y], j) => (j ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    ctx.stroke();
    if (pts.length) {
      // the number in the stroke's colour on a white outline, readable on any photo
      const color = ctx.strokeStyle;
      ctx.font = `bold ${Math.max(12, canvas.width / 30)}px sans-serif`;
      ctx.lineWidth = 3;
      ctx.strokeStyle = "#fff";
      ctx.strokeText(String(i + 1), pts[0][0] + 4, pts[0][1] - 6);
      ctx.fillStyle = color;
      ctx.fillText(String(i + 1), pts[0][0] + 4, pts[0][1] - 6);
      if (edit) pointDots(ctx, pts, s); // the control points, to grab
      ctx.lineWidth = Math.max(2, canvas.width / 200);
    }
  });
  if (edit && sel && strokes[sel.s]) ringAt(ctx, strokes[sel.s][sel.v], s);
}

function redrawStrokes() {
  const sel = (side) => (S.sel && S.sel.side === side ? S.sel : null);
  drawStrokes($("s-source"), S.source, S.photo, sel("source"));
  drawStrokes($("s-target"), S.target, null, sel("target"));
  $("s-nsrc").textContent = S.source.length;
  $("s-ntgt").textContent = S.target.length;
  const p = S.sel && S[S.sel.side][S.sel.s]?.[S.sel.v];
  $("s-sel").textContent = p ? `${S.sel.side} ${S.sel.s + 1} #${S.sel.v} (${p[0].toFixed(1)}, ${p[1].toFixed(1)})` : "none";
}

function rememberStrokes() {
  S.history.push(JSON.stringify([S.source, S.target]));
  if (S.history.length > 200) S.history.shift();
}

// Delete the selected point; a stroke keeps at least 2.
function deleteStrokePoint() {
  if (!S.sel) throw new Error("point: select one first (edit mode, click it)");
  const pts = S[S.sel.side][S.sel.s];
  if (pts.length <= 2) throw new Error("point: a stroke keeps at least 2 points");
  rememberStrokes();
  pts.splice(S.sel.v, 1);
  S.sel.v = Math.min(S.sel.v, pts.length - 1);
  redrawStrokes();
}

// Draw mode: a drag draws a stroke. Edit mode: a drag from (within 6 screen px of) a point moves it,
// a double click on a segment adds a point there, Delete or Backspace removes the selected point.
// Edits stay in the page, in the canvas's pixels (the image's), until Save or Render.
function strokeCanvas(canvas, side) {
  canvas.addEventListener("pointerdown", (ev) => {
    canvas.focus({ preventScroll: true }); // for the Delete key
    canvas.setPointerCapture(ev.pointerId);
    const p = canvasPoint(canvas, ev);
    if (sMode() === "draw") {
      S.drawing = { canvas, points: [p] };
      return;
    }
    const hit = nearestPoint(S[side], p, 6 * pxScale(canvas));
    S.sel = hit ? { side, s: hit.b, v: hit.v } : null;
    if (hit) {
      const orig = S[side][hit.b][hit.v];
      S.drag = { canvas, start: p, orig: [orig[0], orig[1]], moved: false };
    }
    redrawStrokes();
  });
  canvas.addEventListener("pointermove", (ev) => {
    const p = canvasPoint(canvas, ev);
    if (S.drag && S.drag.canvas === canvas) {
      const d = S.drag;
      if (!d.moved) rememberStrokes(); // a click without a move is no edit
      d.moved = true;
      const x = Math.min(Math.max(d.orig[0] + p[0] - d.start[0], 0), canvas.width - 1);
      const y = Math.min(Math.max(d.orig[1] + p[1] - d.start[1], 0), canvas.height - 1);
      S[side][S.sel.s][S.sel.v] = [roundTenth(x), roundTenth(y)];
      redrawStrokes();
      return;
    }
    if (!S.drawing || S.drawing.canvas !== canvas) return;
    const last = S.drawing.points[S.drawing.points.length - 1];
    if (Math.hypot(p[0] - last[0], p[1] - last[1]) >= 2) {
      S.drawing.points.push(p);
      redrawStrokes();
    }
  });
  const end = () => {
    S.drag = null;
    if (!S.drawing || S.drawing.canvas !== canvas) return;
    const pts = S.drawing.points;
    S.drawing = null;
    if (pts.length >= 2) {
      rememberStrokes();
      S[side].push(pts.map(([x, y]) => [roundTenth(x), roundTenth(y)]));
    }
    redrawStrokes();
  };
  canvas.addEventListener("pointerup", end);
  canvas.addEventListener("pointercancel", end);
  canvas.addEventListener("dblclick", (ev) => {
    if (sMode() !== "edit") return;
    const p = canvasPoint(canvas, ev);
    const e = nearestSegment(S[side], p, 6 * pxScale(canvas));
    if (!e) return;
    rememberStrokes();
    S[side][e.b].splice(e.j, 0, [roundTenth(e.q[0]), roundTenth(e.q[1])]);
    S.sel = { side, s: e.b, v: e.j };
    redrawStrokes();
  });
  canvas.addEventListener("keydown", (ev) => {
    if ((ev.key === "Delete" || ev.key === "Backspace") && sMode() === "edit" && S.sel?.side === side) {
      ev.preventDefault();
      guard(sMsg, deleteStrokePoint)();
    } else if (ev.key === "z" && (ev.ctrlKey || ev.metaKey)) {
      ev.preventDefault();
      $("s-undo").onclick();
    }
  });
}
strokeCanvas($("s-source"), "source");
strokeCanvas($("s-target"), "target");
for (const r of document.querySelectorAll('input[name="s-mode"]')) r.onchange = redrawStrokes;

function setTargetSize(w, h) {
  $("s-tw").value = w;
  $("s-th").value = h;
  $("s-target").width = w;
  $("s-target").height = h;
  redrawStrokes();
}
for (const id of ["s-tw", "s-th"]) {
  $(id).onchange = () => setTargetSize(+$("s-tw").value || 1, +$("s-th").value || 1);
}

async function showPhoto(path) {
  S.photo = await loadImage(path);
  $("s-source").width = S.photo.naturalWidth;
  $("s-source").height = S.photo.naturalHeight;
  if (!S.target.length) setTargetSize(S.photo.naturalWidth, S.photo.naturalHeight);
  redrawStrokes();
}

function strokeDocument() {
  if (!S.source.length || S.source.length !== S.target.length) {
    throw new Error(`strokes: draw as many target strokes as source strokes (${S.source.length} source, ${S.target.length} target)`);
  }
  return {
    format: "phloem.strokes",
    version: 1,
    source_shape: [$("s-source").height, $("s-source").width],
    target_size: [$("s-target").height, $("s-target").width],
    pairs: S.source.map((s, i) => ({ source: s, target: S.target[i] })),
  };
}

// PUT a document; replacing a file this page did not write itself (state.savedAs) asks first.
async function putFile(endpoint, path, body, state) {
  try {
    await api("PUT", `${endpoint}?` + q({ path, overwrite: state.savedAs === path }), body);
  } catch (e) {
    if (e.status !== 409 || !confirm(`${path} exists: replace it?`)) throw e;
    await api("PUT", `${endpoint}?` + q({ path, overwrite: true }), body);
  }
  state.savedAs = path;
  return path;
}

const saveStrokes = () => putFile("/api/strokes", $("s-file").value.trim(), strokeDocument(), S);

function guard(msg, f) {
  return async () => {
    try {
      await f();
    } catch (e) {
      say(msg, e.message, true);
    }
  };
}

const sMsg = $("s-msg");
$("s-image").onchange = guard(sMsg, () => showPhoto($("s-image").value));
$("s-upload").onchange = guard(sMsg, async () => {
  const saved = await upload($("s-upload"));
  await imageList($("s-image"), saved.path);
  await showPhoto(saved.path);
  say(sMsg, `saved ${saved.path} (${saved.width}×${saved.height})`);
});
$("s-undo").onclick = () => {
  const last = S.history.pop();
  if (last) [S.source, S.target] = JSON.parse(last);
  S.sel = null;
  redrawStrokes();
};
$("s-clear").onclick = () => {
  rememberStrokes();
  S.source = [];
  S.target = [];
  S.sel = null;
  redrawStrokes();
};
$("s-delete").onclick = guard(sMsg, deleteStrokePoint);
$("s-save").onclick = guard(sMsg, async () => say(sMsg, `saved ${await saveStrokes()}`));
$("s-load").onclick = guard(sMsg, async () => {
  const path = $("s-file").value.trim();
  const doc = await api("GET", "/api/strokes?" + q({ path }));
  S.source = doc.pairs.map((p) => p.source);
  S.target = doc.pairs.map((p) => p.target);
  S.history = [];
  S.sel = null;
  S.savedAs = path;
  if (doc.target_size) setTargetSize(doc.target_size[1], doc.target_size[0]);
  redrawStrokes();
  say(sMsg, `loaded ${path}: ${doc.pairs.length} stroke pairs`);
});
$("s-render").onclick = guard(sMsg, async () => {
  if (!S.photo) throw new Error("image: choose or upload the object photo first");
  const strokes = await saveStrokes();
  const ui = { msg: sMsg, progress: $("s-progress"), cancel: $("s-cancel") };
  const s = await runJob({ kind: "strokes-edit", image: $("s-image").value, strokes }, ui);
  if (s.state === "done") {
    $("s-result").src = withToken("/api/file?" + q({ path: s.outputs[0] }));
    say(sMsg, `wrote ${s.outputs[0]} and its sidecar`);
  } else {
    say(sMsg, `${s.kind} ${s.state}: ${s.message}`, s.state === "failed");
  }
});

// -- Bark workspace ----------------------------------------------------------------------------
const PALETTE = ["#3b2416", "#c8a26b", "#6b8e23", "#4682b4", "#d2691e", "#8b008b", "#20b2aa", "#b22222",
  "#ffd700", "#708090", "#ff69b4", "#00ced1", "#556b2f", "#9370db", "#f4a460", "#2f4f4f"];
// role: which map the canvas holds, the photo's ("in") or the new one a texture was painted by ("out")
const B = { width: 0, height: 0, n: 0, labels: null, brush: 0, painting: false, savedAs: null, role: "in", inPath: null,
  outPath: null };
const bMsg = $("b-msg");
const rgb = (hex) => [1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16));

function drawLabels() {
  const c = $("b-canvas");
  c.width = B.width;
  c.height = B.height;
  const ctx = c.getContext("2d");
  const img = ctx.createImageData(B.width, B.height);
  const cols = PALETTE.map(rgb);
  for (let i = 0; i < B.labels.length; i++) {
    const [r, g, b] = cols[B.labels[i]];
    img.data.set([r, g, b, 255], 4 * i);
  }
  ctx.putImageData(img, 0, 0);
}

function palette() {
  const p = $("b-palette");
  p.innerHTML = "";
  for (let j = 0; j < B.n; j++) {
    const b = document.createElement("button");
    b.style.background = PALETTE[j];
    b.title = `label ${j}`;
    b.classList.toggle("active", j === B.brush);
    b.onclick = () => {
      B.brush = j;
      palette();
    };
    p.appendChild(b);
  }
}

// A round brush of radius r dabbed along the segment a → b of a width × height label array, so
// that a fast pointer move leaves no gaps.
function brushLine(labels, width, height, a, b, r, value) {
  const steps = Math.max(1, Math.ceil(Math.hypot(b[0] - a[0], b[1] - a[1]) / Math.max(0.5, r / 2)));
  for (let i = steps === 1 ? 1 : 0; i <= steps; i++) {
    const cx = a[0] + ((b[0] - a[0]) * i) / steps, cy = a[1] + ((b[1] - a[1]) * i) / steps;
    for (let y = Math.max(0, Math.floor(cy - r)); y <= Math.min(height - 1, Math.ceil(cy + r)); y++) {
      for (let x = Math.max(0, Math.floor(cx - r)); x <= Math.min(width - 1, Math.ceil(cx + r)); x++) {
        if ((x - cx) ** 2 + (y - cy) ** 2 <= r * r) labels[y * width + x] = value;
      }
    }
  }
}

function paintAt(ev) {
  const p = canvasPoint($("b-canvas"), ev);
  brushLine(B.labels, B.width, B.height, p, p, +$("b-brush").value / 2, B.brush);
  drawLabels();
}

const bc = $("b-canvas");
bc.addEventListener("pointerdown", (ev) => {
  if (!B.labels) return;
  bc.setPointerCapture(ev.pointerId);
  B.painting = true;
  paintAt(ev);
});
bc.addEventListener("pointermove", (ev) => B.painting && paintAt(ev));
bc.addEventListener("pointerup", () => (B.painting = false));

async function loadLabels(path, role = "in") {
  B.role = role;
  $("b-role").textContent = role === "in" ? "photo's" : "new";
  if (role === "in") B.inPath = path;
  const m = await api("GET", "/api/labels?" + q({ path }));
  const raw = atob(m.data);
  B.labels = Uint8Array.from(raw, (c) => c.charCodeAt(0));
  Object.assign(B, { width: m.width, height: m.height, n: Math.max(m.n_labels, +$("b-n").value), brush: 0 });
  B.n = Math.min(B.n, 16);
  B.savedAs = path;
  $("b-file").value = path;
  palette();
  drawLabels();
}

function labelsFor(photo) {
  const dot = photo.lastIndexOf(".");
  return photo.slice(0, dot) + "_labels_in.png";
}

async function showBarkPhoto() {
  const path = $("b-image").value;
  if (!path) return;
  $("b-photo").src = withToken("/api/file?" + q({ path }));
  $("b-file").value = labelsFor(path);
}

function base64(bytes) {
  let text = "";
  for (let i = 0; i < bytes.length; i += 0x8000) text += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
  return btoa(text);
}

function saveLabels() {
  const body = { width: B.width, height: B.height, n_labels: B.n, data: base64(B.labels) };
  return putFile("/api/labels", $("b-file").value.trim(), body, B);
}

const bUi = { msg: bMsg, progress: $("b-progress"), cancel: $("b-cancel") };
$("b-image").onchange = guard(bMsg, showBarkPhoto);
$("b-upload").onchange = guard(bMsg, async () => {
  const saved = await upload($("b-upload"));
  await imageList($("b-image"), saved.path);
  await showBarkPhoto();
});
$("b-labels").onclick = guard(bMsg, async () => {
  const image = $("b-image").value;
  const req = { kind: "bark-labels", image, n_labels: +$("b-n").value, out: $("b-file").value.trim() };
  const s = await runJobReplacing(req, bUi);
  await loadLabels(s.outputs[0]);
  say(bMsg, `wrote ${s.outputs[0]}: paint it, save it, make a texture`);
});
$("b-load").onclick = guard(bMsg, () => {
  const path = $("b-file").value.trim();
  return loadLabels(path, path.endsWith("_labels_out.png") ? "out" : "in");
});
$("b-save").onclick = guard(bMsg, async () => say(bMsg, `saved ${await saveLabels()}`));
$("b-texture").onclick = guard(bMsg, async () => {
  const req = {
    kind: "bark-texture",
    image: $("b-image").value,
    size: [+$("b-th").value, +$("b-tw").value],
    n_labels: +$("b-n").value,
    tileable: $("b-tileable").checked,
    seed: +$("b-seed").value,
  };
  if (B.labels && B.role === "out") {
    req.labels_out = await saveLabels();
    if (B.inPath) req.labels_in = B.inPath;
  } else if (B.labels) {
    req.labels_in = await saveLabels();
  }
  const s = await runJob(req, bUi);
  if (s.state !== "done") throw new Error(`${s.kind} ${s.state}: ${s.message}`);
  $("b-result").src = withToken("/api/file?" + q({ path: s.outputs[0] }));
  B.outPath = s.outputs[1];
  $("b-labels-out").src = fileUrl(B.outPath);
  $("b-edit-out").disabled = false;
  say(bMsg, `wrote ${s.outputs[0]} and its sidecar, and the new label map ${s.outputs[1]}`);
});
$("b-edit-in").onclick = guard(bMsg, () => loadLabels(B.inPath || labelsFor($("b-image").value)));
$("b-edit-out").onclick = guard(bMsg, async () => {
  await loadLabels(B.outPath, "out");
  say(bMsg, `editing ${B.outPath}: paint it, then Make texture paints it`);
});

// -- Branching workspace -----------------------------------------------------------------------
// The skeleton is edited here, in image pixels, and only saved on request: a drag redraws the
// canvas and sends nothing (an edit shows within a frame).
const K = {
  img: null, shape: null, branches: [], sel: null, drag: null, guides: [], history: [],
  savedAs: null, example: null, grown: null, grownPath: null, extendSeed: 0,
};
const G = { savedAs: null }; // the guide file's save state
const kMsg = $("br-msg");
const kUi = { msg: kMsg, progress: $("br-progress"), cancel: $("br-cancel") };
const kc = $("br-canvas");
const DEPTH_COLORS = ["#ff3b1f", "#ffb000", "#35d0ff", "#b06bff", "#5ee05e"];

function depthOf(branches, i) {
  let d = 0;
  for (let p = branches[i].parent; p && d < 50; p = branches[p[0]].parent) d++;
  return d;
}

function drawSkeleton(canvas, branches, { background = null, sel = null, guides = [], vertices = true } = {}) {
  const ctx = canvas.getContext("2d");
  const s = pxScale(canvas);
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (background) ctx.drawImage(background, 0, 0);
  else {
    ctx.fillStyle = "#000";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
  }
  ctx.lineJoin = ctx.lineCap = "round";
  branches.forEach((b, i) => {
    const color = background ? DEPTH_COLORS[depthOf(branches, i) % DEPTH_COLORS.length] : "#fff";
    // the branch's thickness as a translucent band, then its centre line; one path per run of
    // edges of the same width (to half a pixel): thousands of separate strokes miss the frame
    ctx.globalAlpha = background ? 0.3 : 1;
    ctx.strokeStyle = color;
    for (let j = 1; j < b.points.length; ) {
      const width = Math.max(1, Math.round(2 * (b.thickness[j - 1] + b.thickness[j])) / 2);
      ctx.lineWidth = width;
      ctx.beginPath();
      ctx.moveTo(...b.points[j - 1]);
      for (; j < b.points.length && Math.max(1, Math.round(2 * (b.thickness[j - 1] + b.thickness[j])) / 2) === width; j++) {
        ctx.lineTo(...b.points[j]);
      }
      ctx.stroke();
    }
    ctx.globalAlpha = 1;
    if (!background) return;
    ctx.lineWidth = 1.5 * s;
    ctx.beginPath();
    b.points.forEach(([x, y], j) => (j ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    ctx.stroke();
    if (vertices) {
      ctx.fillStyle = color;
      pointDots(ctx, b.points, s);
    }
  });
  if (sel && branches[sel.b]) ringAt(ctx, branches[sel.b].points[sel.v], s);
  ctx.setLineDash([6 * s, 4 * s]);
  ctx.strokeStyle = "#00ffd0";
  ctx.lineWidth = 2.5 * s;
  for (const guide of guides) {
    ctx.beginPath();
    guide.forEach(([x, y], j) => (j ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    ctx.stroke();
  }
  ctx.setLineDash([]);
}

function redrawBranching() {
  drawSkeleton(kc, K.branches, { background: K.img, sel: K.sel, guides: K.guides });
  const t = $("br-thick");
  if (K.sel && K.branches[K.sel.b]) {
    const b = K.branches[K.sel.b];
    const [x, y] = b.points[K.sel.v];
    $("br-sel").textContent = `branch ${K.sel.b} #${K.sel.v} (${x.toFixed(1)}, ${y.toFixed(1)})`;
    t.disabled = false;
    if (document.activeElement !== t) t.value = (+b.thickness[K.sel.v]).toFixed(2);
  } else {
    K.sel = null;
    $("br-sel").textContent = "none";
    t.disabled = true;
    t.value = "";
  }
}

function remember() {
  K.history.push(JSON.stringify(K.branches));
  if (K.history.length > 200) K.history.shift();
}

function setSkeleton(doc) {
  K.branches = doc.branches.map((b) => ({
    points: b.points.map((p) => [p[0], p[1]]),
    thickness: Array.isArray(b.thickness) ? [...b.thickness] : b.points.map(() => b.thickness),
    parent: b.parent ? [b.parent[0], b.parent[1]] : null,
  }));
  if (doc.shape) K.shape = doc.shape;
  K.sel = null;
  redrawBranching();
}

function skeletonDocument() {
  if (!K.branches.length) throw new Error("skeleton: trace or load one, or shift-drag to draw a branch");
  const round = (v) => Math.round(v * 100) / 100;
  return {
    format: "phloem.skeleton",
    version: 1,
    shape: K.shape || [kc.height, kc.width],
    branches: K.branches.map((b) => ({
      points: b.points.map(([x, y]) => [round(x), round(y)]),
      thickness: b.thickness.map(round),
      parent: b.parent,
    })),
  };
}

// The branches attached to (b, v), and a new parent index for each child of b after vertex
// edits: children keep their vertex, renumbered.
function renumberChildren(b, map) {
  for (const o of K.branches) {
    if (o.parent && o.parent[0] === b) o.parent[1] = map(o.parent[1]);
  }
}

function insertVertex(e) {
  const b = K.branches[e.b];
  const th = b.thickness[e.j - 1] * (1 - e.t) + b.thickness[e.j] * e.t;
  b.points.splice(e.j, 0, e.q);
  b.thickness.splice(e.j, 0, th);
  renumberChildren(e.b, (v) => (v >= e.j ? v + 1 : v));
  return { b: e.b, v: e.j };
}

function deleteBranch(bi) {
  const gone = new Set([bi]);
  K.branches.forEach((o, i) => o.parent && gone.has(o.parent[0]) && gone.add(i)); // parents come first
  const index = [];
  let n = 0;
  K.branches.forEach((_, i) => (index[i] = gone.has(i) ? -1 : n++));
  K.branches = K.branches.filter((_, i) => !gone.has(i));
  for (const o of K.branches) if (o.parent) o.parent[0] = index[o.parent[0]];
  K.sel = null;
}

function deleteVertex() {
  if (!K.sel) throw new Error("vertex: select one first (click it)");
  remember();
  const { b, v } = K.sel;
  const br = K.branches[b];
  if (br.points.length <= 2) {
    deleteBranch(b);
  } else {
    br.points.splice(v, 1);
    br.thickness.splice(v, 1);
    renumberChildren(b, (u) => Math.min(u > v ? u - 1 : u, br.points.length - 1));
    K.sel = { b, v: Math.min(v, br.points.length - 1) };
  }
  redrawBranching();
}

const brMode = () => document.querySelector('input[name="br-mode"]:checked').value;

kc.addEventListener("pointerdown", (ev) => {
  if (!K.img) return;
  kc.focus({ preventScroll: true }); // for the Delete key; scrolling now would move the canvas under the pointer
  kc.setPointerCapture(ev.pointerId);
  const p = canvasPoint(kc, ev);
  const r = 7 * pxScale(kc);
  if (brMode() === "guide") {
    K.guides.push([p]);
    K.drag = { kind: "guide" };
    redrawBranching();
    return;
  }
  const hit = nearestPoint(K.branches.map((b) => b.points), p, r);
  if (ev.shiftKey) {
    remember();
    const from = hit ? K.branches[hit.b].points[hit.v] : p;
    const th = hit ? K.branches[hit.b].thickness[hit.v] : 2;
    K.branches.push({ points: [[from[0], from[1]]], thickness: [th], parent: hit ? [hit.b, hit.v] : null });
    K.drag = { kind: "draw", b: K.branches.length - 1 };
  } else if (hit) {
    remember();
    const pos = K.branches[hit.b].points[hit.v];
    // children starting on the vertex move with it
    const kids = K.branches.filter((o) => o.parent && o.parent[0] === hit.b && o.parent[1] === hit.v
      && Math.hypot(o.points[0][0] - pos[0], o.points[0][1] - pos[1]) < 0.5);
    K.sel = { b: hit.b, v: hit.v };
    K.drag = { kind: "move", start: p, orig: [pos[0], pos[1]], kids };
  } else {
    const e = nearestSegment(K.branches.map((b) => b.points), p, r);
    if (e) {
      remember();
      K.sel = insertVertex(e);
      K.drag = { kind: "move", start: p, orig: [e.q[0], e.q[1]], kids: [] };
    } else {
      K.sel = null;
    }
  }
  redrawBranching();
});

kc.addEventListener("pointermove", (ev) => {
  if (!K.drag) return;
  const p = canvasPoint(kc, ev);
  if (K.drag.kind === "move") {
    const at = [K.drag.orig[0] + p[0] - K.drag.start[0], K.drag.orig[1] + p[1] - K.drag.start[1]];
    K.branches[K.sel.b].points[K.sel.v] = at;
    for (const o of K.drag.kids) o.points[0] = [at[0], at[1]];
  } else {
    const pts = K.drag.kind === "guide" ? K.guides[K.guides.length - 1] : K.branches[K.drag.b].points;
    const last = pts[pts.length - 1];
    if (Math.hypot(p[0] - last[0], p[1] - last[1]) < 4 * pxScale(kc)) return;
    pts.push(p);
    if (K.drag.kind === "draw") {
      const b = K.branches[K.drag.b];
      b.thickness.push(b.thickness[b.thickness.length - 1]);
    }
  }
  redrawBranching();
});

function endDrag() {
  const d = K.drag;
  K.drag = null;
  if (d && d.kind === "draw") {
    const b = K.branches[d.b];
    if (b.points.length < 2) K.branches.pop();
    else K.sel = { b: d.b, v: b.points.length - 1 };
  }
  if (d && d.kind === "guide" && K.guides[K.guides.length - 1].length < 2) K.guides.pop();
  redrawBranching();
}
kc.addEventListener("pointerup", endDrag);
kc.addEventListener("pointercancel", endDrag);

kc.addEventListener("keydown", (ev) => {
  if (ev.key === "Delete" || ev.key === "Backspace") {
    ev.preventDefault();
    guard(kMsg, deleteVertex)();
  } else if (ev.key === "z" && (ev.ctrlKey || ev.metaKey)) {
    ev.preventDefault();
    $("br-undo").onclick();
  }
});

// The wheel over a selected vertex scales its thickness by 10 % a notch.
kc.addEventListener("wheel", (ev) => {
  if (!K.sel) return;
  ev.preventDefault();
  const b = K.branches[K.sel.b];
  const t = b.thickness[K.sel.v] * (ev.deltaY < 0 ? 1.1 : 1 / 1.1);
  b.thickness[K.sel.v] = Math.max(0.1, Math.min(1000, t));
  redrawBranching();
}, { passive: false });

$("br-thick").onchange = guard(kMsg, () => {
  const v = +$("br-thick").value;
  if (!K.sel) return;
  if (!(v >= 0 && v <= 1000)) throw new Error("thickness: expected a number of pixels from 0 to 1000");
  remember();
  K.branches[K.sel.b].thickness[K.sel.v] = v;
  redrawBranching();
});

$("br-undo").onclick = () => {
  const last = K.history.pop();
  if (last) {
    K.branches = JSON.parse(last);
    K.sel = null;
  }
  redrawBranching();
};
$("br-delete").onclick = guard(kMsg, deleteVertex);
$("br-delete-branch").onclick = guard(kMsg, () => {
  if (!K.sel) throw new Error("vertex: select a vertex of the branch first");
  remember();
  deleteBranch(K.sel.b);
  redrawBranching();
});
$("br-guide-clear").onclick = () => {
  K.guides = [];
  redrawBranching();
};

// The guide as --guide takes it: one path as its JSON points, several as a mask, white along them.
async function saveGuide() {
  const name = $("br-guide-file").value.trim().replace(/\.(json|png)$/i, "");
  const round = (v) => Math.round(v * 10) / 10;
  if (K.guides.length === 1) {
    return putFile("/api/guide", name + ".json", K.guides[0].map(([x, y]) => [round(x), round(y)]), G);
  }
  const [h, w] = K.shape;
  const c = document.createElement("canvas");
  c.width = w;
  c.height = h;
  const ctx = c.getContext("2d");
  ctx.strokeStyle = "#fff";
  ctx.lineWidth = 5;
  ctx.lineJoin = ctx.lineCap = "round";
  for (const guide of K.guides) {
    ctx.beginPath();
    guide.forEach(([x, y], j) => (j ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    ctx.stroke();
  }
  const px = ctx.getImageData(0, 0, w, h).data;
  const mask = new Uint8Array(w * h);
  for (let i = 0; i < mask.length; i++) mask[i] = px[4 * i] > 127 ? 1 : 0;
  return putFile("/api/mask", name + ".png", { width: w, height: h, n_labels: 2, data: base64(mask) }, G);
}

function skeletonFor(path) {
  const dot = path.lastIndexOf(".");
  return path.slice(0, dot) + "_skeleton.json";
}

async function showBranchingImage(path) {
  if (!path) return;
  K.img = await loadImage(path);
  kc.width = K.img.naturalWidth;
  kc.height = K.img.naturalHeight;
  K.shape = [kc.height, kc.width];
  $("br-file").value = skeletonFor(path);
  redrawBranching();
}

async function loadSkeleton(path) {
  setSkeleton(await api("GET", "/api/skeleton?" + q({ path })));
  K.history = [];
  K.savedAs = path;
  $("br-file").value = path;
}

const saveSkeleton = () => putFile("/api/skeleton", $("br-file").value.trim(), skeletonDocument(), K);

$("br-image").onchange = guard(kMsg, () => showBranchingImage($("br-image").value));
$("br-upload").onchange = guard(kMsg, async () => {
  const saved = await upload($("br-upload"));
  await imageList($("br-image"), saved.path);
  await showBranchingImage(saved.path);
  say(kMsg, `saved ${saved.path} (${saved.width}×${saved.height})`);
});
$("br-trace").onclick = guard(kMsg, async () => {
  const threshold = $("br-threshold").value.trim();
  const scale = $("br-threshold-scale").value.trim();
  const gap = $("br-gap").value.trim();
  const req = { kind: "branching-trace", image: $("br-image").value, trace_kind: $("br-kind").value,
    threshold: threshold === "" ? null : Number(threshold), threshold_scale: scale === "" ? 1 : Number(scale),
    gap: gap === "" ? null : Number(gap),
    subpixel: $("br-subpixel").checked, wide: $("br-wide").checked, edges: $("br-edges").checked, out: $("br-file").value.trim() };
  const s = await runJobReplacing(req, kUi);
  await loadSkeleton(s.outputs[0]);
  say(kMsg, `traced ${s.outputs[0]}: ${K.branches.length} branches; edit it with the mouse`);
});
$("br-load").onclick = guard(kMsg, async () => {
  await loadSkeleton($("br-file").value.trim());
  say(kMsg, `loaded ${K.savedAs}: ${K.branches.length} branches`);
});
$("br-save").onclick = guard(kMsg, async () => say(kMsg, `saved ${await saveSkeleton()}`));
$("br-extend").onclick = guard(kMsg, async () => {
  if (!K.sel) throw new Error("vertex: select a vertex of the branch to extend");
  const body = { skeleton: skeletonDocument(), branch: K.sel.b, steps: 1, seed: +$("br-seed").value + K.extendSeed++ };
  const doc = await api("POST", "/api/skeleton/extend", body);
  remember();
  const b = K.sel.b;
  setSkeleton(doc);
  K.sel = { b, v: K.branches[b].points.length - 1 };
  redrawBranching();
  say(kMsg, `extended branch ${b} to ${K.branches[b].points.length} vertices`);
});

function drawHistograms(h) {
  const c = $("br-hist");
  const ctx = c.getContext("2d");
  ctx.clearRect(0, 0, c.width, c.height);
  ctx.font = "12px sans-serif";
  [["angle (rad)", h.angle], ["thickness (px)", h.thickness]].forEach(([title, d], k) => {
    const x0 = 10 + (k * c.width) / 2, w = c.width / 2 - 20, top = 22, height = c.height - 44;
    const n = d.source.length, top1 = Math.max(...d.source, ...d.result) || 1;
    ctx.fillStyle = "#222";
    ctx.fillText(`${title}  L1 = ${d.distance.toFixed(3)}`, x0, 14);
    ctx.fillText(d.edges[0].toFixed(2), x0, c.height - 6);
    ctx.fillText(d.edges[n].toFixed(2), x0 + w - 30, c.height - 6);
    for (let i = 0; i < n; i++) {
      const bw = w / n;
      [[d.source[i], "#999"], [d.result[i], "#f08020"]].forEach(([v, col], j) => {
        const bh = (v / top1) * height;
        ctx.fillStyle = col;
        ctx.fillRect(x0 + i * bw + (j * bw) / 2, top + height - bh, bw / 2 - 1, bh);
      });
    }
    ctx.strokeStyle = "#555";
    ctx.strokeRect(x0, top, w, height);
  });
}

async function grow() {
  const skeleton = await saveSkeleton();
  const req = { kind: "branching-grow", skeleton, seed: +$("br-seed").value };
  const layout = $("br-layout").value; // empty: the example decides (on for one connected structure)
  if (layout !== "") req.layout = +layout;
  if (K.guides.length) req.guide = await saveGuide();
  const s = await runJobReplacing(req, kUi);
  K.example = skeleton;
  K.grownPath = s.outputs[0];
  K.grown = await api("GET", "/api/skeleton?" + q({ path: K.grownPath }));
  const g = $("br-grown");
  [g.height, g.width] = K.grown.shape;
  drawSkeleton(g, K.grown.branches, { vertices: false });
  $("br-grown-name").textContent = `${K.grownPath} (seed ${req.seed})`;
  drawHistograms(await api("GET", "/api/histograms?" + q({ source: skeleton, result: K.grownPath })));
  say(kMsg, `grew ${K.grownPath}: ${K.grown.branches.length} branches`);
}
$("br-grow").onclick = guard(kMsg, grow);
$("br-reroll").onclick = guard(kMsg, async () => {
  $("br-seed").value = +$("br-seed").value + 1;
  await grow();
});
$("br-edit-grown").onclick = guard(kMsg, async () => {
  if (!K.grownPath) throw new Error("grown: grow a skeleton first");
  await loadSkeleton(K.grownPath);
  say(kMsg, `editing ${K.grownPath}: select a branch and extend it`);
});
$("br-render").onclick = guard(kMsg, async () => {
  if (!K.grownPath) throw new Error("grown: grow a skeleton first");
  const req = { kind: "branching-render", image: $("br-image").value, skeleton: K.example,
    target: K.grownPath, seed: +$("br-seed").value };
  const s = await runJobReplacing(req, kUi);
  $("br-result").src = fileUrl(s.outputs[0]);
  $("br-fragments").src = fileUrl(s.outputs[1]);
  say(kMsg, `wrote ${s.outputs[0]} and its sidecar, and the fragment map ${s.outputs[1]}`);
});

// -- Leaves workspace --------------------------------------------------------------------------
// Scribbles are labels 0 (none) and 1..n over the training leaf's image, saved as the integer
// label PNG phloem leaves reads; the brush colours are the server's (the expanded layers use them).
const L = { img: null, width: 0, height: 0, labels: null, brush: 1, painting: null, savedAs: null, colours: [] };
const lMsg = $("lv-msg");
const lUi = { msg: lMsg, progress: $("lv-progress"), cancel: $("lv-cancel") };
const lc = $("lv-canvas");
let overlay = null; // an off-screen canvas of the scribbles, drawn over the leaf

function drawScribbles() {
  if (!L.labels) return;
  const ctx = lc.getContext("2d");
  ctx.clearRect(0, 0, lc.width, lc.height);
  ctx.drawImage(L.img, 0, 0);
  const o = overlay.getContext("2d");
  const img = o.createImageData(L.width, L.height);
  const cols = L.colours.map(rgb);
  for (let i = 0; i < L.labels.length; i++) {
    const k = L.labels[i];
    if (k) img.data.set([...cols[(k - 1) % cols.length], 255], 4 * i);
  }
  o.putImageData(img, 0, 0);
  ctx.drawImage(overlay, 0, 0);
}

function leafPalette() {
  const p = $("lv-palette");
  p.innerHTML = "";
  const n = Math.max(2, Math.min(8, +$("lv-n").value || 2));
  if (L.brush > n) L.brush = n;
  for (let k = 0; k <= n; k++) {
    const b = document.createElement("button");
    b.dataset.layer = k;
    if (k) b.style.background = L.colours[(k - 1) % L.colours.length];
    else b.textContent = "⌫";
    b.title = k ? `layer ${k}${k === n ? " (background)" : ""}` : "eraser";
    b.classList.toggle("active", k === L.brush);
    b.onclick = () => {
      L.brush = k;
      leafPalette();
    };
    p.appendChild(b);
  }
}

function scribbleTo(ev) {
  const p = canvasPoint(lc, ev);
  brushLine(L.labels, L.width, L.height, L.painting.last || p, p, +$("lv-brush").value / 2, L.brush);
  L.painting.last = p;
  drawScribbles();
}
lc.addEventListener("pointerdown", (ev) => {
  if (!L.labels) return;
  lc.setPointerCapture(ev.pointerId);
  L.painting = { last: null };
  scribbleTo(ev);
});
lc.addEventListener("pointermove", (ev) => L.painting && scribbleTo(ev));
lc.addEventListener("pointerup", () => (L.painting = null));
lc.addEventListener("pointercancel", () => (L.painting = null));

function scribblesFor(path) {
  const dot = path.lastIndexOf(".");
  return path.slice(0, dot) + "_scribbles.png";
}

async function showLeaf(path) {
  if (!path) return;
  L.img = await loadImage(path);
  L.width = lc.width = L.img.naturalWidth;
  L.height = lc.height = L.img.naturalHeight;
  overlay = document.createElement("canvas");
  overlay.width = L.width;
  overlay.height = L.height;
  L.labels = new Uint8Array(L.width * L.height);
  L.savedAs = null;
  $("lv-file").value = scribblesFor(path);
  $("lv-layers").removeAttribute("src");
  drawScribbles();
}

function saveScribbles() {
  const n = L.labels.reduce((a, k) => (k > a ? k : a), 0);
  const body = { width: L.width, height: L.height, n_labels: Math.max(n, 1) + 1, data: base64(L.labels) };
  return putFile("/api/scribbles", $("lv-file").value.trim(), body, L);
}

async function leafList() {
  const files = await api("GET", "/api/files");
  const sel = $("lv-leaves");
  const chosen = new Set([...sel.selectedOptions].map((o) => o.value));
  sel.innerHTML = "";
  for (const f of files.filter((f) => f.kind === "image")) {
    const o = document.createElement("option");
    o.value = o.textContent = f.path;
    o.selected = chosen.has(f.path);
    sel.appendChild(o);
  }
}

$("lv-n").onchange = leafPalette;
$("lv-image").onchange = guard(lMsg, () => showLeaf($("lv-image").value));
$("lv-upload").onchange = guard(lMsg, async () => {
  const saved = await upload($("lv-upload"));
  await imageList($("lv-image"), saved.path);
  await leafList();
  await showLeaf(saved.path);
  say(lMsg, `saved ${saved.path} (${saved.width}×${saved.height})`);
});
$("lv-clear").onclick = () => {
  if (L.labels) L.labels.fill(0);
  drawScribbles();
};
$("lv-save").onclick = guard(lMsg, async () => say(lMsg, `saved ${await saveScribbles()}`));
$("lv-load").onclick = guard(lMsg, async () => {
  const path = $("lv-file").value.trim();
  const m = await api("GET", "/api/scribbles?" + q({ path, image: $("lv-image").value }));
  L.labels = Uint8Array.from(atob(m.data), (c) => c.charCodeAt(0));
  L.savedAs = path;
  $("lv-n").value = Math.max(2, m.n_labels - 1);
  leafPalette();
  drawScribbles();
  say(lMsg, `loaded ${path}: ${m.n_labels - 1} layers`);
});
$("lv-expand").onclick = guard(lMsg, async () => {
  if (!L.labels) throw new Error("image: choose the training leaf first");
  const scribbles = await saveScribbles();
  const dot = scribbles.lastIndexOf(".");
  const req = { kind: "leaves-expand", image: $("lv-image").value, scribbles, out: scribbles.slice(0, dot) + "_layers.png" };
  const s = await runJobReplacing(req, lUi);
  $("lv-layers").src = fileUrl(s.outputs[0]);
  say(lMsg, `expanded the scribbles into ${s.outputs[0]}`);
});
$("lv-synth").onclick = guard(lMsg, async () => {
  if (!L.labels) throw new Error("image: choose the training leaf first");
  const training = $("lv-image").value;
  const others = [...$("lv-leaves").selectedOptions].map((o) => o.value).filter((p) => p !== training);
  if (!others.length) throw new Error("leaves: pick at least one other leaf of the species (Other leaves)");
  const req = { kind: "leaves-synthesize", leaves: [training, ...others], training, scribbles: await saveScribbles(),
    count: +$("lv-count").value, seed: +$("lv-seed").value };
  const s = await runJobReplacing(req, lUi);
  $("lv-sheet").src = fileUrl(s.outputs[0]);
  const gallery = $("lv-gallery");
  gallery.innerHTML = "";
  for (const path of s.outputs.slice(1)) {
    const img = document.createElement("img");
    img.src = fileUrl(path);
    img.title = img.alt = path;
    gallery.appendChild(img);
  }
  say(lMsg, `wrote ${s.outputs.length - 1} leaves, the model and ${s.outputs[0]}, each with its sidecar`);
});

// -- Trees workspace ---------------------------------------------------------------------------
const trMsg = $("tr-msg");
const trUi = { msg: trMsg, progress: $("tr-progress"), cancel: $("tr-cancel") };
let projectImages = [];

function gallery(el, paths) {
  el.innerHTML = "";
  for (const path of paths) {
    const img = document.createElement("img");
    img.src = fileUrl(path);
    img.title = img.alt = path;
    el.appendChild(img);
  }
}

// The folders holding images, as library choices; the chosen one's images as its gallery.
async function treeLibraries() {
  projectImages = (await api("GET", "/api/files")).filter((f) => f.kind === "image").map((f) => f.path);
  const sel = $("tr-library");
  const keep = sel.value;
  const folders = [...new Set(projectImages.filter((p) => p.includes("/")).map((p) => p.slice(0, p.lastIndexOf("/"))))];
  sel.innerHTML = "";
  for (const f of folders.sort()) {
    const o = document.createElement("option");
    o.value = o.textContent = f;
    sel.appendChild(o);
  }
  if (keep && folders.includes(keep)) sel.value = keep;
  else if (folders.includes("trees")) sel.value = "trees";
  showLibrary();
}

function showLibrary() {
  const folder = $("tr-library").value;
  gallery($("tr-library-gallery"), projectImages.filter((p) => p.slice(0, p.lastIndexOf("/")) === folder));
}
$("tr-library").onchange = showLibrary;
$("tr-run").onclick = guard(trMsg, async () => {
  const req = { kind: "trees-variations", library: $("tr-library").value, count: +$("tr-count").value,
    n_sources: +$("tr-sources").value, size: +$("tr-size").value, seed: +$("tr-seed").value };
  const s = await runJobReplacing(req, trUi);
  gallery($("tr-gallery"), s.outputs);
  say(trMsg, `wrote ${s.outputs.length} trees to ${s.outputs[0].slice(0, s.outputs[0].lastIndexOf("/"))}, each with its sidecar`);
});

// -- Textures workspace ------------------------------------------------------------------------
const X = { img: null, width: 0, height: 0, mask: null, painting: null, savedAs: null };
const xMsg = $("tx-msg");
const xUi = { msg: xMsg, progress: $("tx-progress"), cancel: $("tx-cancel") };
const xc = $("tx-canvas");

function drawMask() {
  if (!X.img) return;
  const ctx = xc.getContext("2d");
  ctx.drawImage(X.img, 0, 0);
  const over = ctx.getImageData(0, 0, X.width, X.height);
  for (let i = 0; i < X.mask.length; i++) {
    if (X.mask[i]) over.data.set([230, 25, 75, 255], 4 * i);
  }
  ctx.putImageData(over, 0, 0);
}

function maskTo(ev) {
  const p = canvasPoint(xc, ev);
  brushLine(X.mask, X.width, X.height, X.painting.last || p, p, +$("tx-brush").value / 2, $("tx-erase").checked ? 0 : 1);
  X.painting.last = p;
  drawMask();
}
xc.addEventListener("pointerdown", (ev) => {
  if (!X.img) return;
  xc.setPointerCapture(ev.pointerId);
  X.painting = { last: null };
  maskTo(ev);
});
xc.addEventListener("pointermove", (ev) => X.painting && maskTo(ev));
xc.addEventListener("pointerup", () => (X.painting = null));
xc.addEventListener("pointercancel", () => (X.painting = null));

async function showTextureImage(path) {
  if (!path) return;
  X.img = await loadImage(path);
  X.width = xc.width = X.img.naturalWidth;
  X.height = xc.height = X.img.naturalHeight;
  X.mask = new Uint8Array(X.width * X.height);
  X.savedAs = null;
  const dot = path.lastIndexOf(".");
  $("tx-file").value = path.slice(0, dot) + "_mask.png";
  drawMask();
}
$("tx-image").onchange = guard(xMsg, () => showTextureImage($("tx-image").value));
$("tx-upload").onchange = guard(xMsg, async () => {
  const saved = await upload($("tx-upload"));
  await imageList($("tx-image"), saved.path);
  await showTextureImage(saved.path);
  say(xMsg, `saved ${saved.path} (${saved.width}×${saved.height})`);
});
$("tx-clear").onclick = () => {
  if (X.mask) X.mask.fill(0);
  drawMask();
};
$("tx-run").onclick = guard(xMsg, async () => {
  const kind = $("tx-mode").value;
  const req = { kind, image: $("tx-image").value, seed: +$("tx-seed").value };
  if (kind === "texture-complete") {
    if (!X.mask || !X.mask.some((v) => v)) throw new Error("mask: paint the hole to fill on the image first");
    const body = { width: X.width, height: X.height, n_labels: 2, data: base64(X.mask) };
    req.mask = await putFile("/api/mask", $("tx-file").value.trim(), body, X);
  } else {
    req.size = [+$("tx-h").value, +$("tx-w").value];
  }
  const s = await runJob(req, xUi);
  if (s.state !== "done") throw new Error(`${s.kind} ${s.state}: ${s.message}`);
  $("tx-result").src = fileUrl(s.outputs[0]);
  if (s.outputs[1]) $("tx-sources").src = fileUrl(s.outputs[1]);
  else $("tx-sources").removeAttribute("src");
  say(xMsg, `wrote ${s.outputs.join(" and ")} and the sidecar${s.outputs.length > 1 ? "s" : ""}`);
});

// -- bark on a cylinder ------------------------------------------------------------------------
// Each column x of the preview looks at the angle asin((x - c) / r) on a trunk of radius r; the
// texture's width wraps half way round (the front), shaded by the cosine of that angle.
function cylinder(img) {
  const c = $("b-cylinder");
  const ctx = c.getContext("2d");
  const r = c.width / 2;
  const h = Math.min(c.height, (img.naturalHeight * c.width) / (img.naturalWidth / 2 || 1));
  ctx.clearRect(0, 0, c.width, c.height);
  for (let x = 0; x < c.width; x++) {
    const s = (x + 0.5 - r) / r;
    const angle = Math.asin(Math.max(-1, Math.min(1, s)));
    const u = ((angle / Math.PI + 0.5) * img.naturalWidth) % img.naturalWidth;
    ctx.globalAlpha = 1;
    ctx.drawImage(img, Math.floor(u), 0, 1, img.naturalHeight, x, 0, 1, h);
    ctx.globalAlpha = 1 - (0.25 + 0.75 * Math.cos(angle));
    ctx.fillStyle = "#000";
    ctx.fillRect(x, 0, 1, h);
  }
  ctx.globalAlpha = 1;
}
$("b-result").addEventListener("load", () => cylinder($("b-result")));

// -- start -------------------------------------------------------------------------------------
(async () => {
  try {
    const info = await api("GET", "/api/info");
    L.colours = info.layer_colours;
    leafPalette();
    for (const id of ["s-image", "b-image", "br-image", "lv-image", "tx-image"]) await imageList($(id));
    await leafList();
    await treeLibraries();
    await showTextureImage($("tx-image").value);
    if ($("s-image").value) await showPhoto($("s-image").value);
    await showBarkPhoto();
    await showBranchingImage($("br-image").value);
    await showLeaf($("lv-image").value);
  } catch (e) {
    say(sMsg, e.message, true);
  }
  document.body.dataset.ready = "1";
})();
