// warp edit: the page. Plain JavaScript, no build step, nothing fetched but this server's own paths.
// Polygons are kept in image pixel coordinates (x right, y down); the server builds the real map at the
// preview's size and density and sends the target's mesh with each vertex's source point; WebGL draws it.
"use strict";

const token = new URLSearchParams(location.search).get("token") || "";
const $ = (id) => document.getElementById(id);
const SVGNS = "http://www.w3.org/2000/svg";

const editor = {
  ready: false, src: [], dst: null, closed: false, past: [], future: [], options: {},
  stats: [],            // one record per drawn preview: {latency, server, pending}
  eventLatencies: [],   // per input event: ms from the event to the frame that shows it
  frames: 0, lastHeader: null, lastError: "",
};
window.warpEditor = editor;

async function call(path, body) {
  const response = await fetch(path, {
    method: "POST", body: JSON.stringify(body),
    headers: { "X-Warp-Token": token, "Content-Type": "application/json" },
  });
  if (!response.ok) {
    // The server's errors are JSON ({"error": ...}): show its words, else the status line.
    let detail = `${response.status} ${response.statusText}`;
    try { const doc = await response.json(); if (doc && doc.error) detail = doc.error; } catch (e) { /* not JSON */ }
    const err = new Error(`${path}: ${detail}`);
    err.status = response.status;
    throw err;
  }
  return response;
}

// --- history -------------------------------------------------------------------------

function snapshot() { return JSON.stringify({ src: editor.src, dst: editor.dst, closed: editor.closed }); }
function remember() { editor.past.push(snapshot()); editor.future = []; updateButtons(); }
function restore(text) { const s = JSON.parse(text); editor.src = s.src; editor.dst = s.dst; editor.closed = s.closed; changed(); }
function undo() { if (editor.past.length) { editor.future.push(snapshot()); restore(editor.past.pop()); updateButtons(); } }
function redo() { if (editor.future.length) { editor.past.push(snapshot()); restore(editor.future.pop()); updateButtons(); } }
function updateButtons() {
  $("undo").disabled = !editor.past.length; $("redo").disabled = !editor.future.length;
  $("close").disabled = editor.closed || editor.src.length < 3;
}

// --- the overlays: polygons with numbered vertices -------------------------------------

let view = { w: 1, h: 1 };  // the overlays' coordinates: the part of the image the preview covers

function drawOverlay(svg, points, closed) {
  const scale = view.w / Math.max(1, svg.clientWidth);
  const r = 6 * scale;
  svg.replaceChildren();
  if (!points) return;
  const shape = document.createElementNS(SVGNS, closed ? "polygon" : "polyline");
  shape.setAttribute("points", points.map((p) => p.join(",")).join(" "));
  shape.setAttribute("stroke-width", 1.5 * scale);
  shape.style.fill = "none"; shape.style.stroke = "#ffd54a";
  svg.appendChild(shape);
  points.forEach((p, i) => {
    const c = document.createElementNS(SVGNS, "circle");
    c.setAttribute("cx", p[0]); c.setAttribute("cy", p[1]); c.setAttribute("r", r);
    c.setAttribute("stroke-width", scale);
    if (i === 0) c.setAttribute("class", "first");
    const t = document.createElementNS(SVGNS, "text");
    t.setAttribute("x", p[0] + 1.4 * r); t.setAttribute("y", p[1] - 1.4 * r);
    t.setAttribute("font-size", 13 * scale); t.setAttribute("stroke-width", 3 * scale);
    t.textContent = String(i);
    svg.append(c, t);
  });
}

function drawOverlays() {
  drawOverlay($("src-svg"), editor.src, editor.closed);
  drawOverlay($("dst-svg"), editor.closed ? editor.dst : null, true);
}

function toImage(svg, event) {
  const m = svg.getScreenCTM().inverse();
  const p = new DOMPoint(event.clientX, event.clientY).matrixTransform(m);
  return [Math.round(p.x * 100) / 100, Math.round(p.y * 100) / 100];
}

function nearest(points, p, svg) {
  const tolerance = 10 * view.w / Math.max(1, svg.clientWidth);
  let best = -1, bestD = tolerance;
  (points || []).forEach((q, i) => { const d = Math.hypot(q[0] - p[0], q[1] - p[1]); if (d <= bestD) { best = i; bestD = d; } });
  return best;
}

let drag = null;  // {side, index}

function onDown(side, event) {
  const svg = event.currentTarget;
  const p = toImage(svg, event);
  const points = side === "src" ? editor.src : editor.dst;
  const i = nearest(points, p, svg);
  if (!editor.closed && side === "src") {
    if (i === 0 && editor.src.length >= 3) { closePolygon(); return; }
    if (i < 0) { remember(); editor.src.push(p); changed(); return; }
  }
  if (i >= 0 && (editor.closed || side === "src")) {
    // The undo step is taken at the first move: a click on a vertex that does not move it is no step.
    drag = { side, index: i, moved: false, before: snapshot() };
    svg.setPointerCapture(event.pointerId);
  }
}

function onMove(side, event) {
  if (!drag || drag.side !== side) return;
  const p = toImage(event.currentTarget, event);
  if (!drag.moved) { editor.past.push(drag.before); editor.future = []; updateButtons(); }
  (side === "src" ? editor.src : editor.dst)[drag.index] = p;
  drag.moved = true;
  changed(event.timeStamp);
}

// Released: the map at the full preview density (the drag's previews have the dragged side coarser).
function onUp() { const was = drag; drag = null; if (was && was.moved) changed(); }

function closePolygon() {
  if (editor.closed || editor.src.length < 3) return;
  remember();
  editor.closed = true;
  if (!editor.dst || editor.dst.length !== editor.src.length) editor.dst = editor.src.map((p) => p.slice());
  changed();
}

function restart() { remember(); editor.src = []; editor.dst = null; editor.closed = false; changed(); }

// --- the preview: one request at a time, the newest state next ----------------------------

// The server maps one preview at a time and answers 503 (busy) to another (a second tab's, or
// one sent during a save or an export): the page asks again after this many ms, for its newest state.
const BUSY_RETRY_MS = 150;
let inFlight = false, wanted = null, pendingEvents = [];

function changed(eventTime) {
  drawOverlays(); updateButtons();
  if (eventTime !== undefined) pendingEvents.push(eventTime);
  if (!editor.closed) { clearPreview(); return; }
  wanted = { src: editor.src, dst: editor.dst, options: editor.options, drag: drag && drag.moved ? drag.side : null };
  if (!inFlight) sendPreview();
}

async function sendPreview() {
  const body = JSON.stringify(wanted);
  const events = pendingEvents; pendingEvents = [];
  wanted = null; inFlight = true;
  let busy = false;
  const t0 = performance.now();
  try {
    const response = await call("/api/preview", JSON.parse(body));
    const buffer = await response.arrayBuffer();
    const t1 = performance.now();
    showPreview(buffer);
    gl.finish();
    const drawn = performance.now();
    for (const t of events) editor.eventLatencies.push(drawn - t);
    // waited: from the newest event to the request (a preview was in flight); server: the request's
    // round trip; latency: from the request to the end of drawing.
    editor.stats.push({ latency: drawn - t0, server: t1 - t0, events: events.length,
      waited: events.length ? t0 - Math.max(...events) : 0 });
    editor.frames += 1;
  } catch (err) {
    if (err.status === 503) {  // busy: this state (unless a newer one is wanted) again, shortly
      busy = true;
      if (!wanted && editor.closed) wanted = JSON.parse(body);
      pendingEvents = events.concat(pendingEvents);
    } else showError(String(err.message || err));
  } finally {
    const next = () => { inFlight = false; if (wanted) sendPreview(); };
    if (busy) setTimeout(next, BUSY_RETRY_MS); else next();
  }
}

function showError(text) { editor.lastError = text; $("error").textContent = text; }

function showPreview(buffer) {
  const n = new DataView(buffer).getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, n)));
  editor.lastHeader = header;
  showError(header.ok ? "" : header.error);
  $("warnings").replaceChildren(...(header.warnings || []).map((w) => { const li = document.createElement("li"); li.textContent = w; return li; }));
  if (header.command) $("command").textContent = header.command;
  if (!header.ok) { clearPreview(); return; }
  $("timing").textContent = `(map ${Math.round(header.seconds * 1000)} ms, rebuilt: ${header.rebuilt.join(", ") || "nothing"})`;
  const verts = new Float32Array(buffer, 4 + n, header.vertices * 4);
  const tris = new Uint32Array(buffer, 4 + n + header.vertices * 16, header.triangles * 3);
  uploadMesh(verts, tris);
  render();
}

// --- WebGL ----------------------------------------------------------------------------------

let gl = null, program = null, meshBuffer = null, meshCount = 0, quadBuffer = null, texture = null, preview = null;

const VERTEX = `
attribute vec2 a_pos; attribute vec2 a_tex; attribute float a_dist;
uniform vec2 u_size; varying vec2 v_tex; varying float v_dist;
void main() {
  v_tex = a_tex; v_dist = a_dist;
  gl_Position = vec4(a_pos.x / u_size.x * 2.0 - 1.0, 1.0 - a_pos.y / u_size.y * 2.0, 0.0, 1.0);
}`;
const FRAGMENT = `
precision highp float;
uniform sampler2D u_image; uniform vec2 u_size; uniform float u_heatmap; uniform float u_grid;
varying vec2 v_tex; varying float v_dist;
vec3 ramp(float t) {
  vec3 blue = vec3(0.231, 0.298, 0.753), white = vec3(0.969), red = vec3(0.706, 0.016, 0.149);
  return t < 0.5 ? mix(blue, white, t * 2.0) : mix(white, red, t * 2.0 - 1.0);
}
void main() {
  vec4 c = texture2D(u_image, v_tex / u_size);
  if (u_heatmap > 0.5) c = vec4(ramp(clamp(log(v_dist) / log(4.0), 0.0, 1.0)), 1.0);
  if (u_grid > 0.0) {
    vec2 g = abs(fract(v_tex / u_grid + 0.5) - 0.5) * u_grid;
    if (min(g.x, g.y) < 0.6) c = vec4(mix(c.rgb, vec3(1.0, 1.0, 0.0), 0.8), 1.0);
  }
  gl_FragColor = c;
}`;

function initGL(canvas) {
  gl = canvas.getContext("webgl", { premultipliedAlpha: false, preserveDrawingBuffer: true, antialias: false });
  if (!gl) { showError("this browser has no WebGL: no preview"); return; }
  const shader = (kind, text) => {
    const s = gl.createShader(kind); gl.shaderSource(s, text); gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  };
  program = gl.createProgram();
  gl.attachShader(program, shader(gl.VERTEX_SHADER, VERTEX));
  gl.attachShader(program, shader(gl.FRAGMENT_SHADER, FRAGMENT));
  gl.linkProgram(program);
  gl.useProgram(program);
  meshBuffer = gl.createBuffer(); quadBuffer = gl.createBuffer();
  texture = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, texture);
  gl.pixelStorei(gl.UNPACK_PREMULTIPLY_ALPHA_WEBGL, false);
  gl.pixelStorei(gl.UNPACK_COLORSPACE_CONVERSION_WEBGL, gl.NONE);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, gl.RGBA, gl.UNSIGNED_BYTE, editor.image);
  for (const [k, v] of [[gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE],
    [gl.TEXTURE_MIN_FILTER, gl.LINEAR], [gl.TEXTURE_MAG_FILTER, gl.LINEAR]]) gl.texParameteri(gl.TEXTURE_2D, k, v);
  // The whole image, for outside = input: a quad whose every point shows itself.
  const w = preview.width, h = preview.height;
  gl.bindBuffer(gl.ARRAY_BUFFER, quadBuffer);
  gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([0, 0, 0, 0, 1, w, 0, w, 0, 1, 0, h, 0, h, 1,
    w, 0, w, 0, 1, w, h, w, h, 1, 0, h, 0, h, 1]), gl.STATIC_DRAW);
}

// Conformal distortion of f^-1 on each triangle (sigma_max / sigma_min of its affine part).
function distortion(p, t) {
  const a1 = p[2] - p[0], a2 = p[4] - p[0], b1 = p[3] - p[1], b2 = p[5] - p[1];
  const det = a1 * b2 - a2 * b1;
  if (det === 0) return 1;
  const u1 = t[2] - t[0], u2 = t[4] - t[0], w1 = t[3] - t[1], w2 = t[5] - t[1];
  const a = (u1 * b2 - u2 * b1) / det, b = (u2 * a1 - u1 * a2) / det, c = (w1 * b2 - w2 * b1) / det, d = (w2 * a1 - w1 * a2) / det;
  const q = Math.hypot((a + d) / 2, (c - b) / 2), r = Math.hypot((a - d) / 2, (c + b) / 2);
  return (q + r) / Math.max(Math.abs(q - r), 1e-12);
}

function uploadMesh(verts, tris) {
  const out = new Float32Array(tris.length * 5);
  const p = new Float64Array(6), t = new Float64Array(6);
  for (let k = 0; k < tris.length; k += 3) {
    for (let j = 0; j < 3; j++) {
      const v = tris[k + j] * 4;
      p[2 * j] = verts[v]; p[2 * j + 1] = verts[v + 1]; t[2 * j] = verts[v + 2]; t[2 * j + 1] = verts[v + 3];
    }
    const dist = distortion(p, t);
    for (let j = 0; j < 3; j++) {
      const o = (k + j) * 5;
      out[o] = p[2 * j]; out[o + 1] = p[2 * j + 1]; out[o + 2] = t[2 * j]; out[o + 3] = t[2 * j + 1]; out[o + 4] = dist;
    }
  }
  gl.bindBuffer(gl.ARRAY_BUFFER, meshBuffer);
  gl.bufferData(gl.ARRAY_BUFFER, out, gl.DYNAMIC_DRAW);
  meshCount = tris.length;
}

function drawBuffer(buffer, count, heatmap, grid) {
  gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
  const stride = 20;
  for (const [name, size, offset] of [["a_pos", 2, 0], ["a_tex", 2, 8], ["a_dist", 1, 16]]) {
    const loc = gl.getAttribLocation(program, name);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, size, gl.FLOAT, false, stride, offset);
  }
  gl.uniform1f(gl.getUniformLocation(program, "u_heatmap"), heatmap ? 1 : 0);
  gl.uniform1f(gl.getUniformLocation(program, "u_grid"), grid);
  gl.drawArrays(gl.TRIANGLES, 0, count);
}

function gridSpacing() { return $("grid").checked ? Math.max(8, Math.round(Math.max(preview.width, preview.height) / 16)) : 0; }

function render() {
  if (!gl) return;
  gl.viewport(0, 0, preview.width, preview.height);
  gl.clearColor(0, 0, 0, 0);
  gl.clear(gl.COLOR_BUFFER_BIT);
  gl.uniform2f(gl.getUniformLocation(program, "u_size"), preview.width, preview.height);
  // The filter the page chose, as far as the GPU has it: nearest, else (linear, cubic) bilinear.
  const filter = editor.options.interp === "nearest" ? gl.NEAREST : gl.LINEAR;
  gl.bindTexture(gl.TEXTURE_2D, texture);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, filter);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, filter);
  if (!editor.closed) return;
  // Within an outline the input is kept outside it (and the mesh covers the whole outline).
  if (editor.options.outside === "input" || editor.options.within) drawBuffer(quadBuffer, 6, false, 0);
  if (meshCount) drawBuffer(meshBuffer, meshCount, $("heatmap").checked, gridSpacing());
  $("legend").hidden = !$("heatmap").checked;
}

function clearPreview() { meshCount = 0; render(); }

function drawSource() {
  const canvas = $("src-canvas"), ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.drawImage(editor.image, 0, 0);
  const g = gridSpacing();
  if (g) {
    ctx.fillStyle = "rgba(255,255,0,0.8)";
    for (let x = g; x < canvas.width; x += g) ctx.fillRect(x - 0.6, 0, 1.2, canvas.height);
    for (let y = g; y < canvas.height; y += g) ctx.fillRect(0, y - 0.6, canvas.width, 1.2);
  }
}

// Preview pixels for tests: RGBA rows top to bottom, base64.
editor.previewPixels = () => {
  const w = preview.width, h = preview.height, data = new Uint8Array(w * h * 4);
  gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, data);
  const rows = new Uint8Array(w * h * 4);
  for (let y = 0; y < h; y++) rows.set(data.subarray((h - 1 - y) * w * 4, (h - y) * w * 4), y * w * 4);
  let text = "";
  for (let i = 0; i < rows.length; i += 0x8000) text += String.fromCharCode.apply(null, rows.subarray(i, i + 0x8000));
  return btoa(text);
};
editor.idle = () => !inFlight && !wanted;

// --- saving and exporting ----------------------------------------------------------------------

function files() {
  return { src: editor.src, dst: editor.dst, options: editor.options,
    src_name: $("src-name").value, dst_name: $("dst-name").value, output_name: $("output-name").value };
}

async function saveOrExport(path, what) {
  $("status").textContent = `${what}...`;
  try {
    const result = await (await call(path, files())).json();
    if (!result.ok) { showError(result.error); $("status").textContent = ""; return result; }
    showError("");
    $("command").textContent = result.command;
    $("status").textContent = result.output ? `wrote ${result.saved.join(", ")} and ${result.output}` : `wrote ${result.saved.join(", ")}`;
    return result;
  } catch (err) { showError(String(err.message || err)); $("status").textContent = ""; return null; }
}

// A polygon file chosen on the page: read here, parsed by the server as the CLI parses files.
async function loadFile(side, input) {
  const file = input.files[0];
  input.value = "";
  if (!file) return null;
  try {
    const result = await (await call("/api/load", { name: file.name, text: await file.text() })).json();
    if (!result.ok) { showError(result.error); return result; }
    if (side === "dst" && editor.closed && editor.src.length && editor.src.length !== result.points.length) {
      // The target goes with the source vertex for vertex: another count would replace the source.
      showError(`${file.name}: has ${result.points.length} vertices, but the source has ${editor.src.length}; load a target with as many, or load its source first`);
      return result;
    }
    remember();
    if (side === "src") {
      editor.src = result.points;
      if (!editor.dst || editor.dst.length !== editor.src.length) editor.dst = editor.src.map((p) => p.slice());
    } else {
      editor.dst = result.points;
      if (editor.src.length !== editor.dst.length) editor.src = editor.dst.map((p) => p.slice());
    }
    editor.closed = true;
    showError("");
    changed();
    return result;
  } catch (err) { showError(String(err.message || err)); return null; }
}

// --- within: none, the image, a margin, or the command line's own outline file --------------------------

function withinValue() {
  const kind = $("within-kind").value;
  if (kind === "") return null;
  if (kind === "margin") return String(Math.max(1, Number($("within-margin").value) || 20));
  return kind;  // "image", or the command line's file
}

function setupWithin(given) {
  const kind = $("within-kind"), margin = $("within-margin");
  if (given !== null && given !== "image") {
    if (/^\s*[0-9.eE+-]+\s*$/.test(given) && Number(given) > 0) { kind.value = "margin"; margin.value = given.trim(); }
    else {  // a polygon file named on the command line: the page can choose it back, never name another
      const o = document.createElement("option");
      o.value = given; o.textContent = `file ${given.split(/[\\/]/).pop()}`; kind.appendChild(o); kind.value = given;
    }
  } else kind.value = given || "";
  const update = () => {
    margin.hidden = kind.value !== "margin";
    editor.options = Object.assign({}, editor.options, { within: withinValue() });
    // Within keeps the input outside the outline: the menu shows it, and gives back its own choice after.
    $("outside").disabled = editor.options.within !== null;
    $("outside").value = editor.options.within !== null ? "input" : editor.options.outside;
    changed();
  };
  margin.hidden = kind.value !== "margin";
  $("outside").disabled = given !== null;
  if (given !== null) $("outside").value = "input";
  kind.addEventListener("change", update);
  margin.addEventListener("change", update);
}

// --- start ---------------------------------------------------------------------------------------

async function start() {
  const state = await (await fetch("/api/state", { headers: { "X-Warp-Token": token } })).json();
  editor.state = state;
  preview = state.preview;
  view = { w: preview.width * preview.factor, h: preview.height * preview.factor };
  $("image-name").textContent = `${state.image.name} (${state.image.width}x${state.image.height}, preview ${preview.width}x${preview.height})`;
  $("directory").textContent = state.directory;
  const base = (p) => p.split(/[\\/]/).pop();
  $("src-name").value = base(state.names.src); $("dst-name").value = base(state.names.dst); $("output-name").value = base(state.names.output);
  for (const [key, values] of Object.entries(state.choices)) {
    const select = $(key);
    const all = values.includes(state.options[key]) ? values : values.concat([state.options[key]]);
    for (const v of all) { const o = document.createElement("option"); o.value = o.textContent = v; if (state.help[key] && state.help[key][v]) o.title = state.help[key][v]; select.appendChild(o); }
    select.value = state.options[key];
    select.addEventListener("change", () => { editor.options = Object.assign({}, editor.options, { [key]: select.value }); changed(); });
  }
  editor.options = Object.assign({}, state.options);
  setupWithin(state.options.within);
  editor.image = new Image();
  editor.image.src = `/image.png?token=${encodeURIComponent(token)}`;
  await editor.image.decode();
  for (const id of ["src-canvas", "dst-canvas"]) { $(id).width = preview.width; $(id).height = preview.height; }
  for (const id of ["src-svg", "dst-svg"]) $(id).setAttribute("viewBox", `0 0 ${view.w} ${view.h}`);
  drawSource();
  initGL($("dst-canvas"));
  for (const side of ["src", "dst"]) {
    const svg = $(`${side}-svg`);
    svg.addEventListener("pointerdown", (e) => onDown(side, e));
    // pointerrawupdate (where there is one) comes as soon as the mouse moves, not at the next frame.
    svg.addEventListener("onpointerrawupdate" in window ? "pointerrawupdate" : "pointermove", (e) => onMove(side, e));
    svg.addEventListener("pointerup", onUp);
    svg.addEventListener("pointercancel", onUp);
  }
  $("undo").onclick = undo; $("redo").onclick = redo; $("close").onclick = closePolygon; $("restart").onclick = restart;
  $("heatmap").onchange = render;
  for (const side of ["src", "dst"]) $(`load-${side}`).onchange = (e) => loadFile(side, e.currentTarget);
  $("grid").onchange = () => { drawSource(); render(); };
  $("save").onclick = () => saveOrExport("/api/save", "saving");
  $("export").onclick = () => saveOrExport("/api/export", "exporting");
  editor.save = () => saveOrExport("/api/save", "saving");
  editor.export = () => saveOrExport("/api/export", "exporting");
  document.addEventListener("keydown", (e) => {
    // Text fields keep their own keys; a checkbox, a file button or a menu clicked last does not take them.
    const t = e.target;
    if (t.tagName === "TEXTAREA" || (t.tagName === "INPUT" && !["checkbox", "radio", "button", "file", "range"].includes(t.type))) return;
    if (drag) return;  // mid-drag, an undo would restore a state the drag then goes on editing
    if ((e.ctrlKey || e.metaKey) && e.key.toLowerCase() === "z") { e.preventDefault(); e.shiftKey ? redo() : undo(); }
    else if ((e.ctrlKey || e.metaKey) && e.key.toLowerCase() === "y") { e.preventDefault(); redo(); }
    else if (e.key === "Enter") closePolygon();
  });
  window.addEventListener("resize", drawOverlays);
  if (state.src) {
    editor.src = state.src; editor.closed = true;
    editor.dst = state.dst && state.dst.length === state.src.length ? state.dst : state.src.map((p) => p.slice());
  }
  changed();
  editor.ready = true;
}

start().catch((err) => showError(String(err.message || err)));
