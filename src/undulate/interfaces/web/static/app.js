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

function draw() {
  const g = $("lines-layer");
  g.innerHTML = "";
  const b = Math.max(Number($("b").value) || 1, 0.3);
  for (const l of lines) {
    const pl = document.createElementNS("http://www.w3.org/2000/svg", "polyline");
    pl.setAttribute("points", l.points.map(([x, y]) => `${x},${-y}`).join(" "));
    pl.setAttribute("class", "line");
    pl.setAttribute("fill", "none");
    pl.setAttribute("stroke-width", String(b));
    pl.dataset.id = l.id;
    g.appendChild(pl);
  }
}

function setLines(newLines) {
  lines = newLines;
  draw();
  schedulePredict();
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
    $("simulate").disabled = !r.simulable || job !== null;
    $("sim-note").textContent = r.simulable ? "" : r.simulable_reason;
  } catch (e) {
    showError(e.message);
    tbody.innerHTML = "";
    $("simulate").disabled = true;
  }
}

// ---- drawing ---------------------------------------------------------------------------
function toFabric(evt) {
  const svg = $("fabric");
  const pt = svg.createSVGPoint();
  pt.x = evt.clientX;
  pt.y = evt.clientY;
  const p = pt.matrixTransform(svg.getScreenCTM().inverse());
  return [Math.round(p.x * 2) / 2, Math.round(-p.y * 2) / 2];
}

let start = null;
$("fabric").addEventListener("pointerdown", (e) => {
  start = toFabric(e);
  const r = $("rubber");
  r.setAttribute("x1", start[0]); r.setAttribute("y1", -start[1]);
  r.setAttribute("x2", start[0]); r.setAttribute("y2", -start[1]);
  r.setAttribute("visibility", "visible");
});
$("fabric").addEventListener("pointermove", (e) => {
  if (!start) return;
  let [x, y] = toFabric(e);
  if ($("snap").checked) y = start[1];
  $("rubber").setAttribute("x2", x); $("rubber").setAttribute("y2", -y);
});
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
$("svg-file").addEventListener("change", async (e) => {
  const f = e.target.files[0];
  if (!f) return;
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
  const pics = $("pictures");
  pics.innerHTML = "";
  const ul = $("files");
  ul.innerHTML = "";
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

$("simulate").addEventListener("click", simulate);
$("cancel").addEventListener("click", async () => {
  if (job) await fetch(`/api/jobs/${job}`, { method: "DELETE" });
});
$("gcode").addEventListener("click", async () => {
  try {
    const r = await fetch("/api/gcode", { method: "POST",
      headers: { "Content-Type": "application/json" }, body: JSON.stringify(params()) });
    if (!r.ok) throw new Error((await r.json()).error);
    const blob = await r.blob();
    const a = document.createElement("a");
    a.href = URL.createObjectURL(blob);
    a.download = "undulate.gcode";
    document.body.appendChild(a);
    a.click();
    a.remove();
  } catch (e) { showError(`G-code: ${e.message}`); }
});
$("place").addEventListener("click", placeParallel);
$("clear").addEventListener("click", () => setLines([]));
for (const k of NUM) $(k).addEventListener("input", () => { draw(); schedulePredict(); });

placeParallel();
