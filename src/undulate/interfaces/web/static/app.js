// undulate web page: lines on the stretched fabric -> prediction -> simulation.
// Fabric coordinates are mm with y up; the SVG draws y down, so y is flipped when drawn.
"use strict";

const $ = (id) => document.getElementById(id);
const NUM = ["h", "b", "eps0", "E", "t", "nu", "E_B"];
let lines = [];          // [{id, points: [[x, y], ...]}]
let nextId = 0;
let job = null;          // id of the running simulation
let pollTimer = null;
let predictTimer = null;

function params() {
  const p = { lines: lines.map((l) => ({ id: l.id, points: l.points })) };
  for (const k of NUM) p[k] = Number($(k).value);
  return p;
}

const SVGNS = "http://www.w3.org/2000/svg";
let selected = null;     // id of the selected line (click a line; Delete removes it)
const past = [];         // undo: earlier states of `lines` (Ctrl+Z)
const future = [];       // redo (Ctrl+Shift+Z)

function lineLength(l) {
  let s = 0;
  for (let k = 1; k < l.points.length; k++) {
    s += Math.hypot(l.points[k][0] - l.points[k - 1][0], l.points[k][1] - l.points[k - 1][1]);
  }
  return s;
}

function lineAngle(l) {  // of the chord, to the stretch (x), in degrees, -90..90
  const [a, b] = [l.points[0], l.points[l.points.length - 1]];
  let deg = Math.atan2(b[1] - a[1], b[0] - a[0]) * 180 / Math.PI;
  if (deg > 90) deg -= 180;
  if (deg <= -90) deg += 180;
  return deg;
}

function draw() {
  const g = $("lines-layer");
  g.innerHTML = "";
  const b = Math.max(Number($("b").value) || 1, 0.3);
  for (const l of lines) {
    const pl = document.createElementNS(SVGNS, "polyline");
    pl.setAttribute("points", l.points.map(([x, y]) => `${x},${-y}`).join(" "));
    pl.setAttribute("class", l.id === selected ? "line selected" : "line");
    pl.setAttribute("fill", "none");
    pl.setAttribute("stroke-width", String(b));
    pl.dataset.id = l.id;
    g.appendChild(pl);
    // its length and angle beside it, in mm and degrees
    const [x, y] = l.points[l.points.length - 1];
    const t = document.createElementNS(SVGNS, "text");
    t.setAttribute("x", String(x + 2));
    t.setAttribute("y", String(-y - 2));
    t.setAttribute("class", "line-label");
    t.dataset.id = l.id;
    t.textContent = `${fmt(lineLength(l), 4)} mm, ${fmt(lineAngle(l), 3)}°`;
    g.appendChild(t);
  }
  $("undo").disabled = !past.length;
  $("redo").disabled = !future.length;
  $("delete").disabled = selected === null;
}

function setLines(newLines) {
  // every change of the lines goes through here: it can be undone
  past.push(lines);
  if (past.length > 200) past.shift();
  future.length = 0;
  lines = newLines;
  if (!lines.some((l) => l.id === selected)) selected = null;
  draw();
  schedulePredict();
}

function travel(from, to) {  // one step back (undo) or forward (redo) in the history
  if (!from.length) return;
  to.push(lines);
  lines = from.pop();
  if (!lines.some((l) => l.id === selected)) selected = null;
  draw();
  schedulePredict();
}

function undo() { travel(past, future); }
function redo() { travel(future, past); }

function deleteSelected() {
  if (selected === null) return;
  const id = selected;
  selected = null;
  setLines(lines.filter((l) => l.id !== id));
}

function gridStep() { return Number($("grid").value) || 0; }

function snapValue(v) {  // to the grid when it is on, else to 0.5 mm
  const g = gridStep() || 0.5;
  return Math.round(v / g) * g;
}

function drawGrid() {
  const g = $("grid-layer");
  g.innerHTML = "";
  const step = gridStep();
  if (!step) return;
  const major = step * (step < 5 ? 10 : 5);
  for (const [lo, hi, vertical] of [[-160, 160, true], [-110, 110, false]]) {
    for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9; v += step) {
      const ln = document.createElementNS(SVGNS, "line");
      const isMajor = Math.abs(v / major - Math.round(v / major)) < 1e-6;
      ln.setAttribute("class", isMajor ? "grid major" : "grid");
      if (vertical) {
        ln.setAttribute("x1", v); ln.setAttribute("x2", v);
        ln.setAttribute("y1", -110); ln.setAttribute("y2", 110);
      } else {
        ln.setAttribute("y1", -v); ln.setAttribute("y2", -v);
        ln.setAttribute("x1", -160); ln.setAttribute("x2", 160);
      }
      g.appendChild(ln);
    }
  }
}

function placeParallel() {
  const N = Math.round(Number($("N").value));
  const s = Number($("s").value);
  const L = Number($("L").value);
  const b = Number($("b").value);
  if (!(N >= 1 && N <= 50 && s >= 0 && L > 0 && b > 0)) {
    showError("N: 1..50, s >= 0, L > 0 and b > 0 to place parallel lines");
    return;
  }
  const pitch = b + s;
  const out = [];
  for (let k = 0; k < N; k++) {
    const y = (k - (N - 1) / 2) * pitch;
    out.push({ id: `line${nextId++}`, points: [[-L / 2, y], [L / 2, y]] });
  }
  setLines(out);
}

function showError(msg) { $("error").textContent = msg || ""; }

function fmt(v, d = 3) {
  if (v === null || v === undefined) return "-";
  return typeof v === "number" ? Number(v.toPrecision(d)).toString() : String(v);
}

function schedulePredict() {
  clearTimeout(predictTimer);
  predictTimer = setTimeout(predict, 150);
}

async function post(url, body) {
  const r = await fetch(url, { method: "POST", headers: { "Content-Type": "application/json" },
    body: JSON.stringify(body) });
  const data = r.headers.get("content-type")?.includes("json") ? await r.json() : await r.text();
  if (!r.ok) throw new Error(data.error || `HTTP ${r.status}`);
  return data;
}

async function predict() {
  const tbody = $("prediction").querySelector("tbody");
  if (!lines.length) {
    tbody.innerHTML = "";
    $("warnings").innerHTML = "";
    $("simulate").disabled = true;
    $("sim-note").textContent = "Place or draw at least one line.";
    showError("");
    return;
  }
  try {
    const r = await post("/api/predict", params());
    showError("");
    tbody.innerHTML = "";
    for (const l of r.lines) {
      const tr = document.createElement("tr");
      tr.dataset.id = l.id;
      for (const v of [l.id, fmt(l.L, 4), `${fmt(l.angle_deg, 2)}°`, l.n, fmt(l.l), fmt(l.a),
        l.family]) {
        const td = document.createElement("td");
        td.textContent = v;
        tr.appendChild(td);
      }
      tbody.appendChild(tr);
    }
    const ul = $("warnings");
    ul.innerHTML = "";
    for (const w of r.warnings) {
      const li = document.createElement("li");
      li.textContent = w;
      ul.appendChild(li);
    }
    drawAtlas(r.groups);
    $("simulate").disabled = !r.simulable || job !== null;
    $("sim-note").textContent = r.simulable ? "" : r.simulable_reason;
  } catch (e) {
    showError(e.message);
    tbody.innerHTML = "";
    $("simulate").disabled = true;
  }
}

// ---- the simulated phase diagram (GET /api/atlas) and where each group of lines sits -----
const FAMILY_COLOURS = { coherent: "#1f77b4", independent: "#2ca02c", rolls: "#d62728",
  bends: "#ff7f0e", waves: "#7f7f7f", flat: "#cccccc" };
const COLOUR_NAMES = { coherent: "blue", independent: "green", rolls: "red", bends: "orange",
  waves: "grey", flat: "light grey" };
// the diagrams by name (GET /api/atlas?name=...): the panel shows the one that answers the
// first placed group (undulate ships several: five rods at L = 100 mm and at L = 50 mm)
const atlases = {};
let atlas = null;
let lastGroups = [];

function loadAtlas(name) {
  if (atlases[name]) return;
  atlases[name] = "loading";
  fetch(`/api/atlas?name=${encodeURIComponent(name)}`).then((r) => r.json())
    .then((a) => { atlases[name] = a; drawAtlas(lastGroups); })
    .catch(() => { delete atlases[name]; });
}
loadAtlas("phase_diagram");

function drawAtlas(groups) {
  lastGroups = groups || [];
  const placed = lastGroups.find((g) => g.atlas && g.atlas.atlas);
  const want = placed ? placed.atlas.atlas : (atlas ? atlas.name : "phase_diagram");
  if (typeof atlases[want] === "object") atlas = atlases[want];
  else loadAtlas(want);
  const svg = $("atlas");
  if (!atlas || !svg) return;
  svg.dataset.atlas = atlas.name;
  svg.innerHTML = "";
  const m = atlas.meta;
  const [h0, h1] = [0, Math.max(m.h_range[1] + m.h_step, 0.5)];
  const [s0, s1] = [m.s_range[0] - m.s_step, m.s_range[1] + m.s_step];
  const X = (h) => 36 + (h - h0) / (h1 - h0) * 254;
  const Y = (s) => 185 - (s - s0) / (s1 - s0) * 175;
  const el = (tag, attrs, text) => {
    const e = document.createElementNS(SVGNS, tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    svg.appendChild(e);
    return e;
  };
  el("line", { x1: 36, y1: 185, x2: 290, y2: 185, class: "atlas-axis" });
  el("line", { x1: 36, y1: 185, x2: 36, y2: 10, class: "atlas-axis" });
  for (let h = 0; h <= h1 + 1e-9; h += 0.5) {
    el("text", { x: X(h), y: 197, class: "atlas-tick", "text-anchor": "middle" }, fmt(h));
  }
  for (let s = 0; s <= s1 + 1e-9; s += 10) {
    el("text", { x: 31, y: Y(s) + 3, class: "atlas-tick", "text-anchor": "end" }, fmt(s));
  }
  el("text", { x: 163, y: 208, class: "atlas-tick", "text-anchor": "middle" }, "h [mm]");
  el("text", { x: 8, y: 100, class: "atlas-tick", transform: "rotate(-90 8 100)",
    "text-anchor": "middle" }, "s [mm]");
  // each point's cell as wide as the gap to its nearest simulated neighbour (a refined
  // diagram has finer rows at the thin end)
  const gaps = (vals) => {
    const u = [...new Set(vals)].sort((a, b) => a - b);
    const g = {};
    u.forEach((v, i) => {
      const d = [i > 0 ? v - u[i - 1] : Infinity, i < u.length - 1 ? u[i + 1] - v : Infinity];
      g[v] = Math.min(...d) === Infinity ? 1 : Math.min(...d);
    });
    return g;
  };
  const hGap = gaps(atlas.points.map((p) => p.h));
  const sGap = gaps(atlas.points.map((p) => p.s));
  for (const p of atlas.points) {
    const w = Math.max(2, (X(hGap[p.h]) - X(0)) * 0.8);
    const hgt = Math.max(2, (Y(0) - Y(sGap[p.s])) * 0.8);
    const r = el("rect", { x: X(p.h) - w / 2, y: Y(p.s) - hgt / 2, width: w, height: hgt,
      fill: FAMILY_COLOURS[p.family] || "#999", class: "atlas-point" });
    const t = document.createElementNS(SVGNS, "title");
    t.textContent = `h = ${p.h} mm, s = ${p.s} mm: ${p.family}, n = ${p.n}`;
    r.appendChild(t);
  }
  const lines = [];
  for (const g of lastGroups) {
    if (!g.atlas) continue;
    lines.push(`group ${g.index}: ${g.atlas.summary}`);
    if (g.atlas.design_h === undefined || g.atlas.atlas !== atlas.name) continue;
    el("circle", { cx: X(g.atlas.design_h), cy: Y(g.atlas.design_s), r: 5,
      class: g.atlas.inside ? "atlas-design" : "atlas-design outside" });
  }
  const fams = [...new Set(atlas.points.map((p) => p.family))];
  $("atlas-where").textContent = lines.join("; ") + (lines.length ? ". " : "") +
    `Simulated: ${m.points} points (${m.runs} runs), N = ${m.N}, L = ${m.L} mm, ` +
    `eps0 = ${m.eps0}, E_B = ${m.E_B} MPa; colours: ` +
    fams.map((f) => `${f} (${COLOUR_NAMES[f] || "grey"})`).join(", ") + ".";
}

// ---- drawing ---------------------------------------------------------------------------
function toFabric(evt) {
  const svg = $("fabric");
  const pt = svg.createSVGPoint();
  pt.x = evt.clientX;
  pt.y = evt.clientY;
  const p = pt.matrixTransform(svg.getScreenCTM().inverse());
  return [snapValue(p.x), snapValue(-p.y)];
}

let start = null;
let moving = null;       // {id, from: [x, y], points, moved}: dragging the selected line
$("fabric").addEventListener("pointerdown", (e) => {
  $("fabric").setPointerCapture?.(e.pointerId);  // the drag goes on outside the drawing
  const id = e.target.dataset ? e.target.dataset.id : undefined;
  if (id !== undefined) {  // on a line (or its label): select it, a drag moves it
    selected = id;
    const l = lines.find((q) => q.id === id);
    moving = { id, from: toFabric(e), points: l.points, moved: false };
    draw();
    return;
  }
  if (selected !== null) { selected = null; draw(); }
  start = toFabric(e);
  const r = $("rubber");
  r.setAttribute("x1", start[0]); r.setAttribute("y1", -start[1]);
  r.setAttribute("x2", start[0]); r.setAttribute("y2", -start[1]);
  r.setAttribute("visibility", "visible");
});
$("fabric").addEventListener("pointermove", (e) => {
  if (moving) {
    const [x, y] = toFabric(e);
    const dx = x - moving.from[0], dy = y - moving.from[1];
    if (dx || dy) moving.moved = true;
    const shifted = moving.points.map(([px, py]) => [px + dx, py + dy]);
    // shown while dragging; one undoable change when the button is released
    lines = lines.map((q) => (q.id === moving.id ? { ...q, points: shifted } : q));
    draw();
    return;
  }
  if (!start) return;
  let [x, y] = toFabric(e);
  if ($("snap").checked) y = start[1];
  $("rubber").setAttribute("x2", x); $("rubber").setAttribute("y2", -y);
});
$("fabric").addEventListener("pointerup", () => {
  if (!moving) return;
  const m = moving;
  moving = null;
  if (!m.moved) return;
  const now = lines;
  lines = lines.map((q) => (q.id === m.id ? { ...q, points: m.points } : q));
  setLines(now);
}, true);
$("fabric").addEventListener("pointerup", (e) => {
  if (!start) return;
  let [x, y] = toFabric(e);
  if ($("snap").checked) y = start[1];
  $("rubber").setAttribute("visibility", "hidden");
  const a = start;
  start = null;
  if (Math.hypot(x - a[0], y - a[1]) < 2) return;
  const p = x < a[0] ? [[x, y], a] : [a, [x, y]];
  setLines(lines.concat([{ id: `line${nextId++}`, points: p }]));
});

// ---- SVG upload ------------------------------------------------------------------------
let maxBody = 5000000;   // the server's limit on a request's body (GET /api/defaults)
fetch("/api/defaults").then((r) => r.json()).then((d) => { maxBody = d.max_body || maxBody; })
  .catch(() => {});

$("svg-file").addEventListener("change", async (e) => {
  const f = e.target.files[0];
  if (!f) return;
  e.target.value = "";  // the same file again is a new upload
  if (f.size > maxBody) {
    showError(`SVG: ${f.name} is ${(f.size / 1e6).toFixed(1)} MB; the page takes files of ` +
      `at most ${maxBody / 1e6} MB`);
    return;
  }
  try {
    const r = await post("/api/pattern/svg", { svg: await f.text(), b: Number($("b").value) });
    setLines(r.lines.map((l) => ({ id: l.id, points: l.points })));
  } catch (err) { showError(`SVG: ${err.message}`); }
});

// ---- simulation ------------------------------------------------------------------------
async function simulate() {
  try {
    const body = Object.assign(params(), { quality: $("quality").value });
    const st = await post("/api/jobs", body);
    job = st.id;
    $("simulate").disabled = true;
    $("cancel").hidden = false;
    $("job").hidden = false;
    $("results").hidden = true;
    showJob(st);
    pollTimer = setInterval(poll, 500);
  } catch (e) { showError(e.message); }
}

function showJob(st) {
  $("progress").value = st.progress || 0;
  const where = st.queue_position ? ` (number ${st.queue_position} in the queue)` : "";
  $("job-status").textContent = `${st.status}${where}: ${st.stage || ""}` +
    (st.error ? ` — ${st.error}` : "");
  $("job-status").dataset.status = st.status;
}

async function poll() {
  if (!job) return;
  let st;
  try {
    const r = await fetch(`/api/jobs/${job}`);
    st = await r.json();
    if (!r.ok) throw new Error(st.error);
  } catch (e) { showError(e.message); return; }
  showJob(st);
  if (["done", "failed", "cancelled", "interrupted"].includes(st.status)) {
    clearInterval(pollTimer);
    $("cancel").hidden = true;
    const finished = job;
    job = null;
    if (st.status === "done") showResults(finished, st);
    schedulePredict();
  }
}

function showResults(id, st) {
  $("results").hidden = false;
  const m = st.metrics || {};
  const keys = ["n", "l", "lam", "a", "R"];
  const cols = keys.map((k) => JSON.parse(m[`rods_${k}`] || "[]"));
  const tbody = $("sim-table").querySelector("tbody");
  tbody.innerHTML = "";
  for (let i = 0; i < cols[0].length; i++) {
    const tr = document.createElement("tr");
    for (const v of [i].concat(cols.map((c) => fmt(c[i])))) {
      const td = document.createElement("td");
      td.textContent = v;
      tr.appendChild(td);
    }
    tbody.appendChild(tr);
  }
  $("sim-family").textContent = `family: ${m.family}; ${m.newton_iterations} Newton ` +
    `iterations, ${fmt(m.wall_time_s)} s`;
  loadShape(id);
  const pics = $("pictures");
  pics.innerHTML = "";
  const ul = $("files");
  ul.innerHTML = "";
  // the final state as a 3D model for design tools (undulate export), then the run's files
  const models = [["glb", "3D model (.glb: Blender, three.js)"], ["obj", "3D model (.obj: Rhino)"],
    ["stl", "3D model (.stl)"]];
  for (const [fmtName, label] of models) {
    const li = document.createElement("li");
    const a = document.createElement("a");
    a.href = `/api/jobs/${id}/model.${fmtName}`;
    a.textContent = label;
    a.id = `model-${fmtName}`;
    a.setAttribute("download", `undulate-${id}.${fmtName}`);
    li.appendChild(a);
    ul.appendChild(li);
  }
  for (const f of st.files) {
    const url = `/api/jobs/${id}/files/${encodeURIComponent(f)}`;
    if (f === "rod_0_side.png") {
      const img = document.createElement("img");
      img.src = url;
      img.alt = f;
      pics.appendChild(img);
    }
    const li = document.createElement("li");
    const a = document.createElement("a");
    a.href = url;
    a.textContent = f;
    a.setAttribute("download", f);
    li.appendChild(a);
    ul.appendChild(li);
  }
}

// ---- 3D view of the final shape: the run's .glb in three.js (view3d.js, a module) --------
function model3dReady() {  // the module loads after this script: wait for it (3 s at most)
  return new Promise((resolve) => {
    if (window.undulate3d) { resolve(); return; }
    window.addEventListener("undulate3d-ready", () => resolve(), { once: true });
    setTimeout(resolve, 3000);
  });
}

async function loadShape(id) {
  await model3dReady();
  const cv = $("view3d");
  const ok = window.undulate3d && await window.undulate3d.show(`/api/jobs/${id}/model.glb`, cv);
  cv.hidden = !ok;
  $("view3d-note").textContent = ok
    ? "Final shape: drag to turn, right-drag to pan, wheel to zoom, double-click to reset."
    : "No 3D view here (this browser has no WebGL): download the .glb below and open it in " +
      "Blender or any glTF viewer.";
}

$("simulate").addEventListener("click", simulate);
$("cancel").addEventListener("click", async () => {
  if (job) await fetch(`/api/jobs/${job}`, { method: "DELETE" });
});
async function download(url, filename, what) {
  try {
    const r = await fetch(url, { method: "POST",
      headers: { "Content-Type": "application/json" }, body: JSON.stringify(params()) });
    if (!r.ok) throw new Error((await r.json()).error);
    const blob = await r.blob();
    const a = document.createElement("a");
    a.href = URL.createObjectURL(blob);
    a.download = filename;
    document.body.appendChild(a);
    a.click();
    a.remove();
  } catch (e) { showError(`${what}: ${e.message}`); }
}
$("gcode").addEventListener("click", () => download("/api/gcode", "undulate.gcode", "G-code"));
$("svg-print").addEventListener("click",
  () => download("/api/drawing?frame=print", "lines-print.svg", "SVG"));
$("svg-relaxed").addEventListener("click",
  () => download("/api/drawing?frame=relaxed", "lines-relaxed.svg", "SVG"));
$("dxf-print").addEventListener("click",
  () => download("/api/drawing?frame=print&fmt=dxf", "lines-print.dxf", "DXF"));
$("dxf-relaxed").addEventListener("click",
  () => download("/api/drawing?frame=relaxed&fmt=dxf", "lines-relaxed.dxf", "DXF"));
$("place").addEventListener("click", placeParallel);
$("undo").addEventListener("click", undo);
$("redo").addEventListener("click", redo);
$("delete").addEventListener("click", deleteSelected);
$("grid").addEventListener("change", drawGrid);
document.addEventListener("keydown", (e) => {
  const typing = ["INPUT", "SELECT", "TEXTAREA"].includes(document.activeElement?.tagName);
  const mod = e.ctrlKey || e.metaKey;
  if (mod && e.key.toLowerCase() === "z" && !typing) {
    e.preventDefault();
    if (e.shiftKey) redo(); else undo();
  } else if (mod && e.key.toLowerCase() === "y" && !typing) {
    e.preventDefault();
    redo();
  } else if ((e.key === "Delete" || e.key === "Backspace") && !typing && selected !== null) {
    e.preventDefault();
    deleteSelected();
  }
});
$("clear").addEventListener("click", () => setLines([]));
for (const k of NUM) $(k).addEventListener("input", () => { draw(); schedulePredict(); });

// ---- after a reload: this browser's latest job again (the server keeps its jobs) ---------
async function restoreLatestJob() {
  let st;
  try {
    const r = await fetch("/api/jobs");
    const list = await r.json();
    if (!r.ok || !list.length || job) return;
    const latest = list[list.length - 1];  // the list is oldest first
    const rs = await fetch(`/api/jobs/${latest.id}`);
    st = await rs.json();
    if (!rs.ok) return;
  } catch (e) { return; }
  $("job").hidden = false;
  showJob(st);
  if (["queued", "running"].includes(st.status)) {
    job = st.id;
    $("simulate").disabled = true;
    $("cancel").hidden = false;
    pollTimer = setInterval(poll, 500);
  } else if (st.status === "done") {
    showResults(st.id, st);
  }
}

drawGrid();
placeParallel();
past.length = 0;  // the first lines are the page's start, not a change to undo
draw();
restoreLatestJob();
