// jaxskin edit: the page. Plain JavaScript, no build step, nothing fetched but this server.
// The server renders every image (the renderer is the CLI's); this page only sends changes,
// shows images and draws overlays (arrows, the brush, edit markers).
"use strict";

const $ = (id) => document.getElementById(id);
const CLIENT = Math.random().toString(36).slice(2);
const PX_PER_UNIT = 60;  // a drag of 60 image pixels sets |d| = 1

let S = null;            // the server's state
let tool = localStorage.getItem("jaxskin.tool") || "fields";
let selected = -1;       // the selected field edit
let arrows = null;       // {arrows, edits} from /api/fields
let drag = null;         // the pointer gesture in progress

// --- the server --------------------------------------------------------------------------

async function api(method, path, body) {
  const opts = {method, headers: {}};
  if (body !== undefined) {
    opts.body = JSON.stringify(body);
    opts.headers["Content-Type"] = "application/json";
  }
  const r = await fetch(path, opts);
  const isJson = (r.headers.get("Content-Type") || "").includes("json");
  const data = isJson ? await r.json() : null;
  if (!r.ok) {
    const e = new Error((data && data.error) || r.statusText);
    e.status = r.status; e.key = data && data.key; e.data = data;
    throw e;
  }
  return data;
}

function message(text, kind) {
  const m = $("message");
  m.textContent = text || "";
  m.className = kind || "";
}

function fail(e) {
  message(e.key ? `${e.key}: ${e.message}` : e.message, "error");
  clearParamErrors();  // only the latest refusal stands under its field
  showParamError(e.key, e.message);
}

// --- rendering: one request in flight, the latest wins ----------------------------------

const R = {inFlight: false, want: null, then: null, busyTimer: null, lastUrl: null};

function requestRender(preview) {
  // `preview`: one sample per pixel while something is dragged; a final render replaces it.
  // "progressive": a preview now, the final render after it (a field edit: its new furrows
  // show at the preview's cost).
  document.body.dataset.idle = "0";
  if (preview === "progressive") {
    R.want = true;
    R.then = false;
  } else if (R.want === null || R.want === true) {
    R.want = preview;
    if (preview === false) R.then = null;
  }
  pump();
}

async function pump() {
  if (!R.inFlight && R.want === null && R.then !== null && R.then !== undefined) {
    R.want = R.then; R.then = null;
  }
  if (R.inFlight || R.want === null) return;
  const preview = R.want;
  R.want = null;
  R.inFlight = true;
  clearTimeout(R.busyTimer);
  R.busyTimer = setTimeout(() => { $("busy").hidden = false; }, 200);
  const t0 = performance.now();
  try {
    const r = await fetch(`/api/render?client=${CLIENT}&preview=${preview ? 1 : 0}`);
    if (r.status === 409) return;  // overtaken by a newer request (another tab of ours)
    if (!r.ok) {
      const data = await r.json().catch(() => ({error: r.statusText}));
      message(data.error, "error");
      return;
    }
    const blob = await r.blob();
    const url = URL.createObjectURL(blob);
    const img = $("view");
    await new Promise((ok) => { img.onload = ok; img.onerror = ok; img.src = url; });
    if (R.lastUrl) URL.revokeObjectURL(R.lastUrl);
    R.lastUrl = url;
    img.dataset.version = r.headers.get("X-Version");
    img.dataset.preview = preview ? "1" : "0";
    const server = parseFloat(r.headers.get("X-Render-Seconds")) * 1000;
    $("timing").textContent = `${preview ? "preview" : "render"} ${server.toFixed(0)} ms server, ` +
      `${(performance.now() - t0).toFixed(0)} ms shown`;
    sizeOverlay();
    if (R.want === null && $("show-arrows").checked && tool === "fields") loadArrows();
    else draw();
  } catch (e) {
    message(`render failed: ${e.message}`, "error");
  } finally {
    R.inFlight = false;
    clearTimeout(R.busyTimer);
    if (R.want === null && (R.then === null || R.then === undefined)) {
      $("busy").hidden = true;
      document.body.dataset.idle = "1";
    }
    pump();
  }
}

// --- state, URL and changes --------------------------------------------------------------

function queryOf(state) {
  const q = new URLSearchParams();
  q.set("scene", state.source);
  for (const [k, v] of state.query) q.append(k, v);
  return q;
}

function adopt(state) {
  S = state;
  history.replaceState(null, "", "?" + queryOf(state).toString());
  localStorage.setItem("jaxskin.last", location.search);
  $("scene-name").textContent = `${state.name} — ${state.source}` +
    (state.modified ? " (modified)" : "");
  if (!$("save-name").value || $("save-name").dataset.auto === "1") {
    $("save-name").value = state.name;
    $("save-name").dataset.auto = "1";
  }
  // the render command's warnings on what the view shows, as long as they hold
  const warnings = state.warnings || [];
  $("warnings").textContent = warnings.map((w) => `warning: ${w}`).join(" · ");
  $("warnings").hidden = !warnings.length;
  $("undo-btn").disabled = !state.undo;
  $("redo-btn").disabled = !state.redo;
  if (selected >= state.edits.length) selected = -1;
  buildParams();
  buildEdits();
  buildLayers();
  const [w, h] = state.image;
  $("view").width = w; $("view").height = h;
  fitStage();
}

// Changes are sent one request at a time; those made meanwhile are merged and sent next.
const C = {inFlight: false, pending: null, render: null};

function change(values, preview) {
  document.body.dataset.idle = "0";
  P.shownPx = 0;  // the view or the scene changes: the texels' size on screen may too
  C.pending = Object.assign(C.pending || {}, values);
  C.render = preview === "progressive" || C.render === "progressive" ? "progressive" :
    (C.render === false || preview === false) ? false : true;
  sendChanges();
}

async function sendChanges() {
  if (C.inFlight || C.pending === null) return;
  const values = C.pending, preview = C.render;
  C.pending = null; C.render = null;
  C.inFlight = true;
  C.sent = values;  // what the server will hold once it answers (the wheel builds on it)
  try {
    const state = await api("POST", "/api/set", {changes: values});
    clearParamErrors();
    message("");
    adopt(state);
    requestRender(preview);
  } catch (e) {
    fail(e);
    const state = await api("GET", "/api/state").catch(() => null);
    if (state) adopt(state);  // the controls show the values that hold
    document.body.dataset.idle = "1";
  } finally {
    C.inFlight = false;
    C.sent = null;  // the answer (or the state fetched after a refusal) is in S now
    sendChanges();
  }
}

// --- parameters from the schema ----------------------------------------------------------

const GROUPS = ["material", "skin", "layer", "wrinkles", "light", "camera", "view", "sss",
  "spectral", "texture", "mesh"];
const BLINN = ["material.melanin", "material.blood", "material.specular", "material.shininess"];

const BIOPHYSICAL = ["skin.melanin_fraction", "skin.eumelanin", "skin.haemoglobin",
  "skin.oxygenation", "skin.epidermis_mm", "skin.scattering"];

function relevant(key) {
  const model = S.values["material.model"];
  const spectral = model === "spectral" || model === "biophysical";
  const skin = model === "biophysical" ? "biophysical" : S.values["skin.model"];
  if (key === "name") return false;
  if (BLINN.includes(key)) return model === "blinn";
  if (key === "material.brdf") return model === "lafortune";
  if (BIOPHYSICAL.includes(key)) return spectral && skin === "biophysical";
  if (key === "skin.melanin" || key === "skin.subject") return spectral && skin !== "biophysical";
  if (key === "skin.model") return model === "spectral";
  if (/^(skin|spectral|sss)\./.test(key) || key === "mesh.unit_mm") return spectral;
  if (key === "camera.fov") return S.values["camera.projection"] === "perspective";
  return true;
}

function fmt(v) {
  return Math.abs(v) >= 100 ? v.toFixed(0) : Math.abs(v) >= 10 ? v.toFixed(1) : v.toFixed(3);
}

function control(key, spec, value) {
  const div = document.createElement("div");
  div.className = "param" + (key in S.changes ? " changed" : "");
  div.dataset.key = key;
  const short = key.split(".").pop();
  div.innerHTML = `<div class="head"><span class="name" title="${key}">${short}` +
    `${spec.param ? "" : "<small title='static: changes what is compiled (slower)'>static</small>"}` +
    `</span></div><div class="ctl"></div><div class="err"></div>`;
  const ctl = div.querySelector(".ctl");
  const name = div.querySelector(".name");
  name.onclick = () => { if (key in S.changes) change({[key]: null}, false); };
  if (spec.kind === "bool") {
    const c = document.createElement("input");
    c.type = "checkbox"; c.checked = value; c.name = key;
    c.onchange = () => change({[key]: c.checked}, false);
    ctl.append(c);
    div.update = (v) => { c.checked = v; };
  } else if (spec.choices) {
    const c = document.createElement("select");
    c.name = key;
    for (const o of spec.choices) c.add(new Option(o, o, false, o === value));
    c.onchange = () => change({[key]: spec.kind === "int" ? parseInt(c.value) : c.value}, false);
    ctl.append(c);
    div.update = (v) => { c.value = v; };
  } else if (spec.kind === "vec3" || spec.kind === "vec2") {
    const lim = key === "camera.rotate" ? 180 : key.startsWith("light") ? 1 :
      spec.hi !== null ? spec.hi : 2;
    const vec = document.createElement("div");
    vec.className = "vec";
    const inputs = [];
    ["x", "y", "z"].slice(0, spec.kind === "vec2" ? 2 : 3).forEach((axis, i) => {
      const r = document.createElement("input");
      r.type = "range"; r.min = -lim; r.max = lim; r.step = lim / 200; r.value = value[i];
      r.name = `${key}.${axis}`;
      const n = document.createElement("input");
      n.type = "number"; n.step = "any"; n.value = value[i];
      guardNumber(n, key, spec);
      const lab = document.createElement("span"); lab.textContent = axis;
      const read = () => inputs.map((p) => parseFloat(p[1].value));
      r.oninput = () => { n.value = r.value; change({[key]: read()}, true); };
      r.onchange = () => { n.value = r.value; change({[key]: read()}, false); };
      n.onchange = () => {
        if (!isFinite(parseFloat(n.value))) { n.value = r.value; notANumber(key, spec); return; }
        r.value = n.value; change({[key]: read()}, false);  // the box's value, unclamped
      };
      inputs.push([r, n]);
      vec.append(lab, r, n);
    });
    ctl.append(vec);
    div.update = (v) => inputs.forEach(([r, n], i) => {
      if (document.activeElement !== r && document.activeElement !== n) { r.value = v[i]; n.value = v[i]; }
    });
  } else if ((spec.kind === "float" || spec.kind === "int") && spec.lo !== null &&
             (spec.hi - spec.lo) <= 10000 && !/size|height/.test(key)) {
    // A wide range around a small usual value (a layer's thickness: 0 to 10 mm, usually
    // 0.01): the slider runs on the cube root, so its first half is the first 1/8th.
    const span = spec.hi - spec.lo;
    const wide = spec.kind === "float" && spec.lo >= 0 &&
      span >= 100 * Math.max(Math.abs(spec.default || 0), span / 1e4);
    const toPos = (v) => wide ? Math.cbrt((v - spec.lo) / span) : v;
    const fromPos = (p) => wide ? Number((spec.lo + span * p ** 3).toPrecision(3)) : p;
    const r = document.createElement("input");
    r.type = "range"; r.min = wide ? 0 : spec.lo; r.max = wide ? 1 : spec.hi; r.name = key;
    r.title = `${key}: ${spec.lo} to ${spec.hi}${wide ? " (finer near " + spec.lo + ")" : ""}`;
    r.step = spec.kind === "int" ? 1 : wide ? 0.001 : span / 1000;
    r.value = toPos(value);
    const n = document.createElement("input");
    n.type = "number"; n.step = "any"; n.value = value; n.min = spec.lo; n.max = spec.hi;
    guardNumber(n, key, spec);
    n.title = r.title;
    const num = (v) => spec.kind === "int" ? wholeNumber(v) : parseFloat(v);  // as typed
    const at = () => fromPos(spec.kind === "int" ? parseInt(r.value) : parseFloat(r.value));
    r.oninput = () => { n.value = at(); change({[key]: at()}, true); };
    r.onchange = () => change({[key]: at()}, false);
    n.onchange = () => {
      if (!isFinite(num(n.value))) { n.value = at(); notANumber(key, spec); return; }
      r.value = toPos(num(n.value)); change({[key]: num(n.value)}, false);
    };
    ctl.append(r, n);
    div.update = (v) => {
      if (document.activeElement !== r) r.value = toPos(v);
      if (document.activeElement !== n) n.value = v;
    };
  } else {
    const c = document.createElement("input");
    c.type = spec.kind === "str" ? "text" : "number"; c.value = value; c.name = key;
    if (spec.kind !== "str") guardNumber(c, key, spec);
    if (spec.lo !== null && spec.hi !== null) c.title = `${key}: ${spec.lo} to ${spec.hi}`;
    c.onchange = () => {
      const v = spec.kind === "str" ? c.value : spec.kind === "int" ? wholeNumber(c.value) :
        parseFloat(c.value);
      if (spec.kind !== "str" && !isFinite(v)) { c.value = S.values[key]; notANumber(key, spec); return; }
      change({[key]: v}, false);
    };
    ctl.append(c);
    div.update = (v) => { if (document.activeElement !== c) c.value = v; };
  }
  return div;
}

let paramsShown = "";

function buildParams() {
  const root = $("params");
  const shown = JSON.stringify(Object.keys(S.values).filter((k) => relevant(k)));
  if (shown === paramsShown) {  // the same controls: new values in place (a drag goes on)
    root.querySelectorAll(".param").forEach((div) => {
      const key = div.dataset.key;
      div.update(S.values[key]);
      div.classList.toggle("changed", key in S.changes);
      div.querySelector(".name").title = key in S.changes ?
        `${key}: changed; click to go back to the scene file's value` : key;
    });
    return;
  }
  paramsShown = shown;
  const open = new Set([...root.querySelectorAll("details[open]")].map((d) => d.dataset.group));
  const first = root.children.length === 0;
  root.innerHTML = "";
  const keys = S.schema.keys;
  const groups = {};
  for (const key of Object.keys(S.values)) {
    const spec = key.startsWith("layer.") ? S.schema.layer[key.split(".")[2]] : keys[key];
    if (!spec || !relevant(key)) continue;
    const g = key.startsWith("layer.") ? `layer ${key.split(".")[1]}` : key.split(".")[0];
    (groups[g] = groups[g] || []).push([key, spec]);
  }
  const order = (g) => { const i = GROUPS.indexOf(g.split(" ")[0]); return i < 0 ? 99 : i; };
  for (const g of Object.keys(groups).sort((a, b) => order(a) - order(b))) {
    const d = document.createElement("details");
    d.className = "box"; d.dataset.group = g;
    d.open = first ? ["material", "skin", "wrinkles", "light"].includes(g) : open.has(g);
    d.innerHTML = "<summary></summary>";
    d.firstChild.textContent = g.startsWith("layer ") ? `layer “${g.slice(6)}”` : g;
    if (g.startsWith("layer ")) d.firstChild.className = "layer";
    for (const [key, spec] of groups[g]) d.append(control(key, spec, S.values[key]));
    root.append(d);
  }
}

function showParamError(key, text) {
  if (!key) return;
  const el = document.querySelector(`.param[data-key="${CSS.escape(key)}"] .err`);
  if (el) el.textContent = text;
}

// A whole number as typed, or NaN: "300.7" is not 300 (parseInt once cut it silently).
function wholeNumber(text) {
  return /^\s*[+-]?\d+\s*$/.test(text) ? parseInt(text) : NaN;
}

// A number box left empty or holding letters (the browser then reports ""): say what it
// takes under the field, and show the value it keeps.
function notANumber(key, spec) {
  const range = spec.lo != null && spec.hi != null ? ` from ${spec.lo} to ${spec.hi}` : "";
  showParamError(key, `expected ${spec.kind === "int" ? "a whole number" : "a number"}${range}; ` +
    "kept the value before");
  message("");  // an older error in the footer is not this one
}

// The browser drops a letter typed into a number box without a word: say it.
function guardNumber(input, key, spec) {
  input.addEventListener("keydown", (ev) => {
    if (ev.key.length === 1 && !ev.ctrlKey && !ev.metaKey && !ev.altKey &&
        !/[0-9eE+\-.]/.test(ev.key)) notANumber(key, spec);
  });
}

function clearParamErrors() {
  document.querySelectorAll(".param .err").forEach((e) => { e.textContent = ""; });
}

// --- field edits -------------------------------------------------------------------------

function editsJson() {
  return S.edits.map((e) => {
    const o = {d1: e.d1, d2: e.d2, weight: e.weight};
    if (e.vertex !== null) o.vertex = e.vertex; else o.at = e.at;
    return o;
  });
}

function buildEdits() {
  const ol = $("edit-list");
  ol.innerHTML = "";
  S.edits.forEach((e, i) => {
    const li = document.createElement("li");
    const len = (d) => Math.hypot(...d).toFixed(2);
    const num = document.createElement("span");
    num.className = "num";
    num.textContent = `${i + 1}.`;
    const where = document.createElement("span");
    where.className = "where";
    where.textContent = e.vertex !== null ? `vertex ${e.vertex}` :
      `at (${e.at.map((v) => v.toFixed(2)).join(",")})`;
    const mags = document.createElement("span");
    mags.className = "mags";
    mags.textContent = `|d1| ${len(e.d1)} |d2| ${len(e.d2)} λ ${e.weight}`;
    li.append(num, where, mags);
    li.title = `${where.textContent}: d1 = [${e.d1.map(fmt)}], d2 = [${e.d2.map(fmt)}], ` +
      `λ ${e.weight}`;
    if (i === selected) li.className = "sel";
    li.onclick = () => { selected = i; buildEdits(); draw(); };
    ol.append(li);
    if (i === selected) requestAnimationFrame(() => li.scrollIntoView({block: "nearest"}));
  });
  const has = selected >= 0;
  $("edit-weight").disabled = $("edit-delete").disabled = !has;
  if (has) {
    $("edit-weight").value = S.edits[selected].weight;
    $("edit-weight-out").textContent = S.edits[selected].weight;
  } else $("edit-weight-out").textContent = "";
}

function setEdits(list) {
  change({"fields.edit": list}, "progressive");
}

async function loadArrows() {
  try {
    // an arrow every ~28 screen pixels, whatever the image's size (a 64-pixel arm shown
    // 1000 pixels wide had 3 arrows, each longer than a finger)
    const step = Math.round(Math.min(256, Math.max(4, 28 / screenScale())));
    arrows = await api("GET", `/api/fields?step=${step}`);
  } catch (e) { arrows = null; }
  draw();
}

// --- layers and painting -----------------------------------------------------------------

function buildLayers() {
  const spectral = ["spectral", "biophysical"].includes(S.values["material.model"]);
  const sel = $("paint-layer");
  const keep = sel.value;
  sel.innerHTML = "";
  for (const l of S.layers) sel.add(new Option(l.name + (l.painted ? " (painted)" : ""), l.name));
  const want = sel.dataset.want || keep;
  if (want && S.layers.some((l) => l.name === want)) sel.value = want;
  else if (S.layers.length) sel.value = S.layers[S.layers.length - 1].name;  // the top layer
  delete sel.dataset.want;
  const layer = S.layers.find((l) => l.name === sel.value);
  const mats = $("paint-material");
  if (files && mats.options.length !== files.materials.length) {
    mats.innerHTML = "";
    for (const m of files.materials) mats.add(new Option(m.split("/").pop(), m));
  }
  if (layer) mats.value = layer.material;
  $("paint-note").textContent = spectral ? (S.layers.length ? "Drag on the face to paint; " +
    "a painted layer is saved as a 16-bit map beside the scene." : "Add a layer to paint.") :
    "Painting needs the cosmetics model: set material → model to spectral or biophysical " +
    "(the face and makeup scenes have it).";
}

let files = null;  // the scenes and materials the server offers (refreshed on open and save)

async function loadFiles() {
  files = await api("GET", "/api/files").catch(() => null);
  if (!files) return;
  const list = $("open-list");
  list.innerHTML = "";
  for (const s of files.scenes) list.add(new Option(s.split("/").pop(), s));
  list.value = S ? S.source : files.scenes[0];
  $("paint-material").innerHTML = "";
  if (S) buildLayers();
}

let strokeSeq = 0;

const P = {queue: [], inFlight: false, stroke: null};

function paintPoints(points, final) {
  P.queue.push(...points);
  if (final) P.final = true;
  sendPaint();
}

async function sendPaint() {
  if (P.inFlight || (!P.queue.length && !P.final)) return;
  if (!P.queue.length) {  // the stroke ended with nothing left to send
    P.final = false;
    api("GET", "/api/state").then(adopt).catch(fail).finally(() => requestRender(false));
    return;
  }
  const points = P.queue.splice(0);
  const final = P.final; P.final = false;
  P.inFlight = true;
  const alt = drag && drag.alt;
  try {
    const res = await api("POST", "/api/paint", {
      stroke: P.stroke, layer: $("paint-layer").value, points,
      radius: parseFloat($("brush-radius").value), strength: parseFloat($("brush-strength").value),
      erase: $("brush-erase").checked || !!alt});
    if (res && res.radius_px) P.shownPx = res.radius_px;  // what a dab paints here, in image pixels
    if (final) adopt(await api("GET", "/api/state"));
    requestRender(!final);
  } catch (e) { fail(e); }
  finally {
    P.inFlight = false;
    if (P.queue.length || P.final) sendPaint();
  }
}

// --- the view: overlay, pointer ----------------------------------------------------------

function fitStage() {
  const vp = $("viewport"), img = $("view");
  const [w, h] = S ? S.image : [512, 512];
  // the image, centred, keeps clear of the hint line at the bottom (it covered the image)
  const hint = $("hint").offsetHeight || 0;
  const scale = Math.min((vp.clientWidth - 24) / w, (vp.clientHeight - 24 - 2 * hint) / h);
  img.style.width = `${w * scale}px`;
  img.style.height = `${h * scale}px`;
  placeStage();
  sizeOverlay();
}

function placeStage() {
  $("stage").style.transform = "";
}

function camera() {
  // camera.zoom and camera.center as they will be once the pending changes land
  const v = Object.assign({}, S.values, C.sent || {}, C.pending || {});
  return [v["camera.zoom"], v["camera.center"]];
}

// A camera.center coordinate kept in the frame (-0.5 to 0.5), rounded for the URL.
function inFrame(x) {
  return Math.round(Math.min(0.5, Math.max(-0.5, x)) * 1e4) / 1e4;
}

function zoomAt(ev, factor) {
  // camera.zoom about the pointer (a new render, sharp at any zoom): the point of the
  // mesh under the pointer stays put; camera.center is in fractions of the whole frame
  const [z, c] = camera();
  const r = $("view").getBoundingClientRect();
  const px = (ev.clientX - r.left) / r.width - 0.5, py = 0.5 - (ev.clientY - r.top) / r.height;
  const zn = Math.min(64, Math.max(1, z * factor));
  const cn = zn === 1 ? [0, 0] : [inFrame(c[0] + px / z - px / zn), inFrame(c[1] + py / z - py / zn)];
  change({"camera.zoom": Math.round(zn * 1e3) / 1e3, "camera.center": cn}, false);
}

function panBy(dx, dy) {
  // a drag of (dx, dy) screen pixels moves the zoomed frame with the pointer
  const [z, c] = camera();
  const r = $("view").getBoundingClientRect();
  change({"camera.center": [inFrame(c[0] - dx / r.width / z), inFrame(c[1] + dy / r.height / z)]},
         false);
}

function sizeOverlay() {
  const img = $("view"), c = $("overlay");
  const r = img.getBoundingClientRect();
  const dpr = window.devicePixelRatio || 1;
  c.width = Math.round(r.width * dpr);
  c.height = Math.round(r.height * dpr);
  draw();
}

function toImage(ev) {
  // pointer → image pixel coordinates (the render's own pixels)
  const r = $("view").getBoundingClientRect();
  return [(ev.clientX - r.left) / r.width * S.image[0], (ev.clientY - r.top) / r.height * S.image[1]];
}

function screenScale() {
  // screen pixels per image pixel
  return $("view").getBoundingClientRect().width / S.image[0] || 1;
}

function draw() {
  const c = $("overlay");
  const g = c.getContext("2d");
  g.setTransform(1, 0, 0, 1, 0, 0);
  g.clearRect(0, 0, c.width, c.height);
  if (!S) return;
  const k = c.width / S.image[0];
  g.setTransform(k, 0, 0, k, 0, 0);
  const lw = 1.2 / k * (window.devicePixelRatio || 1);
  if (tool === "fields" && $("show-arrows").checked && arrows) {
    const len = 16 / screenScale();  // |d| = 1: 16 screen pixels
    for (const [x, y, ax, ay, bx, by] of arrows.arrows) {
      arrow(g, x, y, ax * len, ay * len, "rgba(255,90,80,.85)", lw);
      arrow(g, x, y, bx * len, by * len, "rgba(90,230,120,.85)", lw);
    }
  }
  if (tool === "fields" && arrows) {
    for (const e of arrows.edits) {
      const [x, y] = e.screen;
      g.beginPath(); g.arc(x, y, 5 / k * 1.5, 0, 7);
      g.lineWidth = 2 * lw;
      g.strokeStyle = e.index === selected ? "#ffd34d" : "#5aa9ff";
      g.stroke();
    }
  }
  if (drag && drag.kind === "edit" && drag.to) {
    const [x0, y0] = drag.from, [x1, y1] = drag.to;
    arrow(g, x0, y0, x1 - x0, y1 - y0, drag.which === "d1" ? "#ff5a50" : "#5ae678", 2.5 * lw);
  }
  if (drag && drag.kind === "orbit" && drag.to) {
    g.fillStyle = "rgba(255,255,255,.8)";
    g.font = `${14 / k * 1.5}px system-ui`;
    const [rx, ry] = orbitAngles();
    g.fillText(`rotate x ${rx.toFixed(0)}°, y ${ry.toFixed(0)}°`, 8, 20 / k * 1.5);
  }
  if (tool === "paint" && cursor) {
    // the brush as large as it paints: at least a texel or so where the texels are larger
    // than the brush (the server's last dab, `P.shownPx`, until the brush or the view changes)
    const r = Math.max(parseFloat($("brush-radius").value), P.shownPx || 0);
    g.beginPath(); g.arc(cursor[0], cursor[1], r, 0, 7);
    g.lineWidth = lw; g.strokeStyle = "rgba(255,255,255,.9)"; g.stroke();
    g.beginPath(); g.arc(cursor[0], cursor[1], r * 0.5, 0, 7);
    g.strokeStyle = "rgba(255,255,255,.35)"; g.stroke();
  }
}

function arrow(g, x, y, dx, dy, colour, lw) {
  const L = Math.hypot(dx, dy);
  if (L < 0.5) return;
  g.strokeStyle = colour; g.lineWidth = lw;
  g.beginPath(); g.moveTo(x, y); g.lineTo(x + dx, y + dy);
  const ux = dx / L, uy = dy / L, h = Math.min(4 * lw, L * 0.4);  // the head: screen-sized
  g.moveTo(x + dx, y + dy); g.lineTo(x + dx - h * (ux - uy * 0.5), y + dy - h * (uy + ux * 0.5));
  g.moveTo(x + dx, y + dy); g.lineTo(x + dx - h * (ux + uy * 0.5), y + dy - h * (uy - ux * 0.5));
  g.stroke();
}

let cursor = null;

function orbitAngles() {
  const [rx, ry, rz] = S.values["camera.rotate"];
  const dx = drag.to[0] - drag.from[0], dy = drag.to[1] - drag.from[1];
  const wrap = (a) => ((a + 180) % 360 + 360) % 360 - 180;
  return [wrap(rx + dy * 0.5), wrap(ry + dx * 0.5), rz];
}

function nearestEdit(p) {
  if (!arrows) return -1;
  let best = -1, bestD = 10;
  for (const e of arrows.edits) {
    const d = Math.hypot(e.screen[0] - p[0], e.screen[1] - p[1]);
    if (d < bestD) { best = e.index; bestD = d; }
  }
  return best;
}

function pointerDown(ev) {
  if (!S || ev.button !== 0) return;
  const p = toImage(ev);
  $("overlay").setPointerCapture(ev.pointerId);
  if (tool === "orbit") {
    drag = {kind: "orbit", from: p, to: p};
  } else if (tool === "paint") {
    if (!S.layers.length) { message("no layer to paint: add one in the painting panel", "error"); return; }
    P.stroke = `${CLIENT}-${++strokeSeq}`;
    document.body.dataset.idle = "0";
    drag = {kind: "paint", last: p, alt: ev.altKey};
    paintPoints([p], false);
  } else {
    // The drag starts now; the vertex under the pointer arrives when the server answers
    // (moves and the release meanwhile are kept, not lost).
    const which = ev.shiftKey ? "d2" : document.querySelector("input[name=which]:checked").value;
    const near = nearestEdit(p);
    const at = near >= 0 ? arrows.edits.find((e) => e.index === near).screen : p;
    if (near >= 0) { selected = near; buildEdits(); }
    const d = {kind: "edit", index: near, from: at, down: p, to: p, which, pick: null};
    d.picked = api("POST", "/api/pick", {x: at[0], y: at[1]}).then((hit) => {
      if (!hit.hit) { message("no mesh there", ""); return null; }
      if (near < 0) d.from = hit.screen;
      d.pick = hit;
      draw();
      return hit;
    }).catch((e) => { fail(e); return null; });
    drag = d;
    draw();
  }
}

function pointerMove(ev) {
  if (!S) return;
  const p = toImage(ev);
  cursor = p;
  if (!drag) { if (tool === "paint") draw(); return; }
  drag.to = p;
  if (drag.kind === "paint") {
    paintPoints([p], false);
  }
  draw();
}

async function pointerUp(ev) {
  if (!drag) return;
  const d = drag;
  drag = null;
  if (d.kind === "edit") await d.picked;
  if (d.kind === "orbit") {
    if (Math.hypot(d.to[0] - d.from[0], d.to[1] - d.from[1]) > 2) {
      drag = d; const a = orbitAngles(); drag = null;
      change({"camera.rotate": a.map((v) => Math.round(v * 10) / 10)}, false);
    }
  } else if (d.kind === "paint") {
    paintPoints([], true);
  } else if (d.kind === "edit" && d.pick) {
    const list = editsJson();
    // the drag as the hand made it, from where the pointer went down (not from the vertex
    // it snapped to: a plain click 16 px off a vertex once set a short, arbitrary d1)
    const dx = d.to[0] - d.down[0], dy = d.to[1] - d.down[1];
    const moved = Math.hypot(dx, dy) > 3;
    const same = d.index >= 0 ? -1 :
      (arrows ? arrows.edits.findIndex((x) => x.vertex === d.pick.vertex) : -1);
    let e;
    if (d.index >= 0) e = list[d.index];
    else if (same >= 0) {  // that vertex has an edit already: take it, add no twin
      e = list[arrows.edits[same].index];
      selected = arrows.edits[same].index;
      buildEdits();
    } else {
      const r3 = (v) => v.map((x) => Math.round(x * 1000) / 1000);
      e = {vertex: d.pick.vertex, d1: r3(d.pick.d1), d2: r3(d.pick.d2), weight: 1.0};
      list.push(e);
      selected = list.length - 1;
    }
    if (moved) {
      const s = Math.min(Math.hypot(dx, dy) / PX_PER_UNIT, 2) / Math.hypot(dx, dy);
      const v = [0, 1, 2].map((i) => (d.pick.right[i] * dx + d.pick.down[i] * dy) * s);
      e[d.which] = v.map((x) => Math.round(x * 1000) / 1000);
    }
    if (moved || (d.index < 0 && same < 0)) setEdits(list);
  }
  draw();
}

// --- wiring ------------------------------------------------------------------------------

function setTool(t) {
  tool = t;
  localStorage.setItem("jaxskin.tool", t);
  document.querySelectorAll(".tool").forEach((b) => b.classList.toggle("active", b.dataset.tool === t));
  $("viewport").className = t;
  $("fields-panel").classList.toggle("hidden", t !== "fields");
  $("paint-panel").classList.toggle("hidden", t !== "paint");
  $("hint").textContent = {
    orbit: "drag: turn the mesh · wheel: zoom about the pointer (camera.zoom) · middle drag or Space+drag: pan (camera.center) · double-click: the whole mesh",
    fields: "click the mesh: add an edit at the nearest vertex · drag: its direction and magnitude · Shift: d2",
    paint: "drag: paint the layer's thickness · Alt: erase · [ ]: brush size",
  }[t];
  fitStage();  // the hint's height may have changed; this redraws the overlay too
  if (t === "fields" && S) loadArrows();
}

function wire() {
  document.querySelectorAll(".tool").forEach((b) => { b.onclick = () => setTool(b.dataset.tool); });
  const ov = $("overlay");
  ov.addEventListener("pointerdown", pointerDown);
  ov.addEventListener("pointermove", pointerMove);
  ov.addEventListener("pointerup", pointerUp);
  ov.addEventListener("pointerleave", () => { cursor = null; draw(); });
  $("viewport").addEventListener("wheel", (ev) => {
    ev.preventDefault();
    if (!S) return;
    zoomAt(ev, Math.exp(-ev.deltaY * 0.0015));
  }, {passive: false});
  $("viewport").addEventListener("dblclick", () => {
    if (S && tool === "orbit") change({"camera.zoom": 1, "camera.center": [0, 0]}, false);
  });
  // the middle button (or any button with Space held) pans the view (camera.center)
  let panning = null, space = false;
  const typing = (t) => t && (t.tagName === "TEXTAREA" || t.tagName === "SELECT" ||
    (t.tagName === "INPUT" && !["range", "checkbox", "radio", "button"].includes(t.type)));
  window.addEventListener("keydown", (ev) => {
    if (ev.code === "Space" && !typing(ev.target)) { space = true; ev.preventDefault(); }
  });
  window.addEventListener("keyup", (ev) => { if (ev.code === "Space") space = false; });
  $("viewport").addEventListener("pointerdown", (ev) => {
    if (ev.button === 1 || space) {
      panning = [ev.clientX, ev.clientY];
      ev.preventDefault(); ev.stopPropagation();
    }
  }, true);
  window.addEventListener("pointermove", (ev) => {
    if (panning) $("stage").style.transform =
      `translate(${ev.clientX - panning[0]}px, ${ev.clientY - panning[1]}px)`;
  });
  window.addEventListener("pointerup", (ev) => {
    if (!panning) return;
    const [x0, y0] = panning;
    panning = null;
    placeStage();
    if (S && (ev.clientX !== x0 || ev.clientY !== y0)) panBy(ev.clientX - x0, ev.clientY - y0);
  });
  $("show-arrows").onchange = () => (S && $("show-arrows").checked ? loadArrows() : draw());
  $("edit-weight").oninput = () => { $("edit-weight-out").textContent = $("edit-weight").value; };
  $("edit-weight").onchange = () => {
    const list = editsJson();
    list[selected].weight = parseFloat($("edit-weight").value);
    setEdits(list);
  };
  $("edit-delete").onclick = deleteEdit;
  for (const id of ["brush-radius", "brush-strength"]) {
    const f = () => { $(id + "-out").textContent = $(id).value; P.shownPx = 0; };
    $(id).addEventListener("input", f); f();
  }
  $("paint-layer").onchange = () => { $("paint-layer").dataset.want = $("paint-layer").value; buildLayers(); };
  $("paint-material").onchange = () => {
    const layer = $("paint-layer").value;
    if (layer) change({[`layer.${layer}.material`]: $("paint-material").value}, false);
  };
  $("add-layer").onclick = () => {
    const name = $("new-layer").value.trim();
    if (!name) { message("name the new layer first", "error"); return; }
    change({[`layer.${name}.material`]: $("paint-material").value || "blush_rose"}, false);
    $("paint-layer").dataset.want = name;
    $("new-layer").value = "";
  };
  $("undo-btn").onclick = () => step("undo");
  $("redo-btn").onclick = () => step("redo");
  $("save-btn").onclick = save;
  $("save-name").oninput = () => { $("save-name").dataset.auto = "0"; };
  $("open-btn").onclick = () => openScene($("open-list").value, []);
  $("upload").onchange = upload;
  window.addEventListener("resize", fitStage);
  window.addEventListener("keydown", (ev) => {
    if (ev.target.tagName === "INPUT" && ev.target.type !== "range") return;
    if ((ev.ctrlKey || ev.metaKey) && ev.key.toLowerCase() === "z") {
      ev.preventDefault(); step(ev.shiftKey ? "redo" : "undo");
    } else if (ev.key === "Delete" && tool === "fields") deleteEdit();
    else if (ev.ctrlKey || ev.metaKey || ev.altKey) return;
    else if (["1", "2", "3"].includes(ev.key)) setTool(["orbit", "fields", "paint"][ev.key - 1]);
    else if (ev.key === "[" || ev.key === "]") {  // brush size, as in paint programs
      const r = $("brush-radius");
      r.value = Math.max(2, Math.min(80, parseFloat(r.value) * (ev.key === "]" ? 1.25 : 0.8)));
      r.dispatchEvent(new Event("input"));
      draw();
    }
  });
}

function deleteEdit() {
  if (selected < 0) return;
  const list = editsJson();
  list.splice(selected, 1);
  selected = -1;
  setEdits(list);
}

async function step(which) {
  try { adopt(await api("POST", `/api/${which}`)); requestRender(false); } catch (e) { fail(e); }
}

async function save(overwrite) {
  const name = $("save-name").value.trim();
  try {
    const r = await api("POST", "/api/save", {name, overwrite: overwrite === true});
    adopt(r);
    loadFiles();
    message(`saved ${r.written.join(", ")}`, "ok");
    requestRender(false);
  } catch (e) {
    if (e.status === 409 && confirm(`${e.message}\n\nReplace it?`)) return save(true);
    fail(e);
  }
}

async function upload() {
  const file = $("upload").files[0];
  $("upload").value = "";
  if (!file) return;
  try {
    const r = await fetch(`/api/upload?name=${encodeURIComponent(file.name)}`, {method: "POST", body: file});
    const data = await r.json();
    if (!r.ok) throw Object.assign(new Error(data.error), {key: data.key, status: r.status});
    await loadFiles();
    if (file.name.endsWith(".toml")) await openScene(data.path, []);
    else {
      message(`uploaded ${data.path}: choose it as a layer's material`, "ok");
      const layer = $("paint-layer").value;
      if (layer) change({[`layer.${layer}.material`]: data.path}, false);
    }
  } catch (e) { fail(e); }
}

// the changes of a link that the server refused (and `extra` ones the page did), named
function refusedMessage(state, extra) {
  const refused = [...extra, ...(state.refused || [])];
  return refused.length ?
    "not applied: " + refused.map((r) => `${r.key}: ${r.error}`).join("; ") : null;
}

async function openScene(scene, query, extra = []) {
  try {
    const state = await api("POST", "/api/open", {scene, changes: query});
    selected = -1;
    adopt(state);
    loadFiles();
    const refused = refusedMessage(state, extra);
    if (refused) message(refused, "error");
    else message(`opened ${state.source}`);
    requestRender(false);
    return true;
  } catch (e) { fail(e); return false; }
}

// A link without scene=: its keys are changes to the scene the server has open now (its
// changes and paint kept, one undo step); each refused one is named, none dropped.
async function applyLink(current, query, extra) {
  let state;
  try {
    state = await api("POST", "/api/apply", {changes: query});
  } catch (e) {
    adopt(current); requestRender(false); loadFiles(); fail(e);
    return;
  }
  adopt(state); requestRender(false); loadFiles();
  const refused = refusedMessage(state, extra);
  if (refused) message(refused, "error");
  else message(`applied to ${state.source}: ${query.map(([k]) => k).join(", ")}`, "ok");
}

async function start() {
  wire();
  setTool(tool);
  let params = new URLSearchParams(location.search);
  const state = await api("GET", "/api/state");
  const last = new URLSearchParams(localStorage.getItem("jaxskin.last") || "");
  // the bare address: what this browser last showed, while the server has that scene (a
  // link's keys are never replaced by it)
  if (!location.search.replace("?", "") && last.get("scene") === state.source) params = last;
  const scenes = params.getAll("scene");
  const wanted = scenes[0];  // none, or "scene=": the scene the server has open
  const extra = scenes.slice(1).map((s) => ({key: "scene", error: `given twice; ${s} not opened`}));
  const query = [...params.entries()].filter(([k]) => k !== "scene");
  const same = wanted === state.source && !extra.length &&
    JSON.stringify(query) === JSON.stringify(state.query);
  if (!wanted && (query.length || extra.length)) await applyLink(state, query, extra);
  else if (!wanted || same) { adopt(state); requestRender(false); loadFiles(); }
  else if (!await openScene(wanted, query, extra)) {
    // a link to a scene that cannot be opened: the scene the server has, and the reason
    const text = $("message").textContent;
    adopt(state); requestRender(false); loadFiles();
    message(`not opened: ${text}`, "error");
  }
  if (tool === "fields") loadArrows();
}

start().catch((e) => message(`cannot start: ${e.message}`, "error"));
