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

// -- Strokes workspace -------------------------------------------------------------------------
const S = { photo: null, source: [], target: [], order: [], drawing: null, savedAs: null };
const COLORS = ["#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4", "#f032e6", "#9a6324"];

function drawStrokes(canvas, strokes, background) {
  const ctx = canvas.getContext("2d");
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
      ctx.lineWidth = Math.max(2, canvas.width / 200);
    }
  });
}

function redrawStrokes() {
  drawStrokes($("s-source"), S.source, S.photo);
  drawStrokes($("s-target"), S.target, null);
  $("s-nsrc").textContent = S.source.length;
  $("s-ntgt").textContent = S.target.length;
}

function strokeCanvas(canvas, list) {
  canvas.addEventListener("pointerdown", (ev) => {
    canvas.setPointerCapture(ev.pointerId);
    S.drawing = { canvas, points: [canvasPoint(canvas, ev)] };
  });
  canvas.addEventListener("pointermove", (ev) => {
    if (!S.drawing || S.drawing.canvas !== canvas) return;
    const p = canvasPoint(canvas, ev);
    const last = S.drawing.points[S.drawing.points.length - 1];
    if (Math.hypot(p[0] - last[0], p[1] - last[1]) >= 2) {
      S.drawing.points.push(p);
      redrawStrokes();
    }
  });
  const end = () => {
    if (!S.drawing || S.drawing.canvas !== canvas) return;
    const pts = S.drawing.points;
    S.drawing = null;
    if (pts.length >= 2) {
      list().push(pts.map(([x, y]) => [Math.round(x * 10) / 10, Math.round(y * 10) / 10]));
      S.order.push(list());
    }
    redrawStrokes();
  };
  canvas.addEventListener("pointerup", end);
  canvas.addEventListener("pointercancel", end);
}
strokeCanvas($("s-source"), () => S.source);
strokeCanvas($("s-target"), () => S.target);

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
  const list = S.order.pop();
  if (list) list.pop();
  redrawStrokes();
};
$("s-clear").onclick = () => {
  S.source.length = S.target.length = S.order.length = 0;
  redrawStrokes();
};
$("s-save").onclick = guard(sMsg, async () => say(sMsg, `saved ${await saveStrokes()}`));
$("s-load").onclick = guard(sMsg, async () => {
  const path = $("s-file").value.trim();
  const doc = await api("GET", "/api/strokes?" + q({ path }));
  S.source = doc.pairs.map((p) => p.source);
  S.target = doc.pairs.map((p) => p.target);
  S.order = [];
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
const B = { width: 0, height: 0, n: 0, labels: null, brush: 0, painting: false, savedAs: null };
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

function paintAt(ev) {
  const [cx, cy] = canvasPoint($("b-canvas"), ev);
  const r = +$("b-brush").value / 2;
  for (let y = Math.max(0, Math.floor(cy - r)); y <= Math.min(B.height - 1, Math.ceil(cy + r)); y++) {
    for (let x = Math.max(0, Math.floor(cx - r)); x <= Math.min(B.width - 1, Math.ceil(cx + r)); x++) {
      if ((x - cx) ** 2 + (y - cy) ** 2 <= r * r) B.labels[y * B.width + x] = B.brush;
    }
  }
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

async function loadLabels(path) {
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
  let s;
  try {
    s = await runJob(req, bUi);
  } catch (e) {
    if (e.status !== 409 || !confirm(`${req.out} exists: replace it?`)) throw e;
    s = await runJob({ ...req, overwrite: true }, bUi);
  }
  if (s.state !== "done") throw new Error(`${s.kind} ${s.state}: ${s.message}`);
  await loadLabels(s.outputs[0]);
  say(bMsg, `wrote ${s.outputs[0]}: paint it, save it, make a texture`);
});
$("b-load").onclick = guard(bMsg, () => loadLabels($("b-file").value.trim()));
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
  if (B.labels) req.labels_in = await saveLabels();
  const s = await runJob(req, bUi);
  if (s.state !== "done") throw new Error(`${s.kind} ${s.state}: ${s.message}`);
  $("b-result").src = withToken("/api/file?" + q({ path: s.outputs[0] }));
  say(bMsg, `wrote ${s.outputs[0]} and its sidecar`);
});

// -- start -------------------------------------------------------------------------------------
(async () => {
  try {
    await imageList($("s-image"));
    await imageList($("b-image"));
    if ($("s-image").value) await showPhoto($("s-image").value);
    await showBarkPhoto();
  } catch (e) {
    say(sMsg, e.message, true);
  }
  document.body.dataset.ready = "1";
})();
