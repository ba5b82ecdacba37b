// iloci serve: the page. Plain JavaScript, no build step, nothing from the internet.
"use strict";

const pad = document.getElementById("pad");
const answerCanvas = document.getElementById("answer");
const padCtx = pad.getContext("2d");
const ansCtx = answerCanvas.getContext("2d");
const $ = (id) => document.getElementById(id);

let stroke = [];          // [x, y, t]: x right, y up (pixels), t seconds
let drawing = false;
let pending = null;       // the guess waiting for yes / no
let busy = false;
let animation = null;

function mode() { return document.querySelector("input[name=mode]:checked").value; }

function showError(text) {
  const box = $("error");
  box.textContent = text || "";
  box.hidden = !text;
}

function say(text) { $("message").textContent = text || ""; }

async function api(path, body) {
  const options = body === undefined ? {} : {
    method: "POST", headers: {"Content-Type": "application/json"}, body: JSON.stringify(body)};
  let response;
  try {
    response = await fetch(path, options);
  } catch (err) {
    throw new Error("the server does not answer (is `iloci serve` still running?)");
  }
  let data = null;
  try { data = await response.json(); } catch (err) { data = null; }
  if (!response.ok) {
    throw new Error((data && data.error) || `the server answered ${response.status}`);
  }
  return data;
}

// -- drawing ------------------------------------------------------------------
function clearPad() {
  padCtx.clearRect(0, 0, pad.width, pad.height);
  stroke = [];
}

function clearAnswer() {
  if (animation) { cancelAnimationFrame(animation); animation = null; }
  ansCtx.clearRect(0, 0, answerCanvas.width, answerCanvas.height);
  $("guess").innerHTML = "&nbsp;";
  $("judge").hidden = true;
  $("arm").hidden = true;
}

function addPoint(e) {
  const r = pad.getBoundingClientRect();
  const x = (e.clientX - r.left) * pad.width / r.width;
  const y = (e.clientY - r.top) * pad.height / r.height;
  const t = e.timeStamp / 1000;
  const last = stroke[stroke.length - 1];
  if (last && t <= last[2]) return;           // same instant: keep the first
  stroke.push([x, pad.height - y, t]);
  if (stroke.length > 1) {
    const p = stroke[stroke.length - 2];
    padCtx.beginPath();
    padCtx.moveTo(p[0], pad.height - p[1]);
    padCtx.lineTo(x, y);
    padCtx.stroke();
  }
}

pad.addEventListener("pointerdown", (e) => {
  if (busy) return;
  e.preventDefault();
  pad.setPointerCapture(e.pointerId);
  clearPad();
  if (mode() === "teach") clearAnswer();
  showError("");
  padCtx.lineWidth = 3; padCtx.lineCap = "round"; padCtx.strokeStyle = "#222";
  drawing = true;
  addPoint(e);
});

pad.addEventListener("pointermove", (e) => {
  if (!drawing) return;
  const events = e.getCoalescedEvents ? e.getCoalescedEvents() : [e];
  for (const c of (events.length ? events : [e])) addPoint(c);
});

function penUp(e) {
  if (!drawing) return;
  drawing = false;
  addPoint(e);
  if (stroke.length < 3) { showError("Draw a longer stroke."); return; }
  if (mode() === "teach") observe(); else recognize();
}
pad.addEventListener("pointerup", penUp);
pad.addEventListener("pointercancel", () => { drawing = false; });

// -- the robot's answer ---------------------------------------------------------
// the answer canvas shows the pad's frame (pixels, y up); when the robot's
// drawing leaves it, the view zooms out around both, axes kept equal
function viewOf(points) {
  const all = stroke.map((p) => [p[0], p[1]]).concat(points);
  const xs = all.map((p) => p[0]), ys = all.map((p) => p[1]);
  const lo = [Math.min(...xs), Math.min(...ys)], hi = [Math.max(...xs), Math.max(...ys)];
  const W = answerCanvas.width, H = answerCanvas.height, m = 12;
  if (lo[0] >= m && lo[1] >= m && hi[0] <= W - m && hi[1] <= H - m) {
    return (p) => [p[0], H - p[1]];
  }
  const s = Math.min((W - 2 * m) / Math.max(hi[0] - lo[0], 1), (H - 2 * m) / Math.max(hi[1] - lo[1], 1));
  const cx = (lo[0] + hi[0]) / 2, cy = (lo[1] + hi[1]) / 2;
  return (p) => [W / 2 + (p[0] - cx) * s, H / 2 - (p[1] - cy) * s];
}

function showStrokeFaint(ctx, view) {
  if (stroke.length < 2) return;
  ctx.save();
  ctx.strokeStyle = "#bbb"; ctx.lineWidth = 2; ctx.setLineDash([4, 4]);
  ctx.beginPath();
  stroke.forEach((p, i) => {
    const [x, y] = view(p);
    if (i === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
  });
  ctx.stroke();
  ctx.restore();
}

function animateAnswer(answer) {
  // the drawing is in the frame of what was drawn: pad pixels, y up
  clearAnswer();
  const pts = answer.drawing;
  const view = viewOf(pts);
  const total = Math.min(6, Math.max(0.8, answer.dt * (pts.length - 1)));   // seconds
  const start = performance.now();
  const frame = (now) => {
    const k = Math.max(1, Math.min(pts.length, 1 + Math.floor((now - start) / 1000 / total * (pts.length - 1))));
    ansCtx.clearRect(0, 0, answerCanvas.width, answerCanvas.height);
    showStrokeFaint(ansCtx, view);
    ansCtx.strokeStyle = "#1f5fbf"; ansCtx.lineWidth = 3; ansCtx.lineCap = "round";
    ansCtx.beginPath();
    for (let i = 0; i < k; i++) {
      const [x, y] = view(pts[i]);
      if (i === 0) ansCtx.moveTo(x, y); else ansCtx.lineTo(x, y);
    }
    ansCtx.stroke();
    const [hx, hy] = view(pts[k - 1]);
    ansCtx.fillStyle = "#1f5fbf";
    ansCtx.beginPath(); ansCtx.arc(hx, hy, 5, 0, 2 * Math.PI); ansCtx.fill();
    animation = k < pts.length ? requestAnimationFrame(frame) : null;
  };
  animation = requestAnimationFrame(frame);
}

function showAnswer(answer) {
  pending = answer;
  animateAnswer(answer);
  // the novelty answer: nothing the robot knows is like the drawing, it
  // drew it back as it saw it and asks whether it is a new concept
  $("guess").textContent = answer.novel ?
    `Something new? The robot knows nothing like it and drew it back as it saw it: ` +
    `is it a new concept ("${answer.concept}")? (attempt ${answer.attempt})` :
    `Is it "${answer.concept}"? (confidence ${answer.confidence.toFixed(2)}, ` +
    `attempt ${answer.attempt})`;
  $("judge").hidden = false;
  if (answer.arm) { $("arm").src = answer.arm; $("arm").hidden = false; }
}

function describe(outcome) {
  const what = {
    strengthen: `an example of "${outcome.concept}" it knew well (strengthened)`,
    new_exemplar: `a new example of "${outcome.concept}"`,
    new_concept: `a new concept, "${outcome.concept}"`,
  }[outcome.action] || outcome.action;
  const secs = outcome.rehearsal_seconds ? ` (rehearsal ${outcome.rehearsal_seconds.toFixed(1)} s)` : "";
  return `Learned: ${what}${secs}. Draw the next one.`;
}

async function withProgress(promise) {
  busy = true;
  $("progress").hidden = false;
  $("bar").value = 0; $("ptext").textContent = "";
  const timer = setInterval(async () => {
    try {
      const p = (await api("/api/progress")).progress;
      if (p) {
        $("bar").value = p.fraction;
        $("ptext").textContent = `rehearsing (${p.phase}), ${p.elapsed.toFixed(1)} s`;
      }
    } catch (err) { /* shown when the main request fails */ }
  }, 250);
  try { return await promise; } finally {
    clearInterval(timer);
    $("progress").hidden = true;
    busy = false;
  }
}

async function observe() {
  say("The robot is thinking...");
  try {
    const data = await withProgress(api("/api/observe", {points: stroke}));
    if (data.answer) { say(""); showAnswer(data.answer); }
    else { pending = null; say(describe(data.outcome)); renderMemory(data.memory); }
  } catch (err) { say(""); showError(err.message); }
}

async function judge(value) {
  if (!pending || busy) return;
  $("judge").hidden = true;
  say(value > 0 ? "Yes: learning..." : "No: thinking again...");
  try {
    const data = await withProgress(api("/api/feedback", {answer: pending.id, value}));
    if (data.answer) { say(""); showAnswer(data.answer); }
    else { pending = null; say(describe(data.outcome)); renderMemory(data.memory); }
  } catch (err) {
    say(""); showError(err.message);
    if (pending) $("judge").hidden = false;
  }
}

async function recognize() {
  say("Recognizing...");
  try {
    const r = await api("/api/recognize", {points: stroke});
    clearAnswer();
    say("");
    $("guess").textContent = r.unknown ?
      `Unknown: like nothing it was taught (nearest "${r.concept}", familiarity ` +
      `${r.familiarity.toFixed(2)}); nothing learned.` :
      `Recognized: "${r.concept}" (confidence ${r.confidence.toFixed(2)}); nothing learned.`;
  } catch (err) { say(""); showError(err.message); }
}

$("yes").addEventListener("click", () => judge(1));
$("no").addEventListener("click", () => judge(-1));
$("clear").addEventListener("click", () => { clearPad(); showError(""); });
document.addEventListener("keydown", (e) => {
  if (e.target.tagName === "INPUT") return;
  if (e.key === "y") judge(1);
  else if (e.key === "n") judge(-1);
  else if (e.key === "c") { clearPad(); showError(""); }
});
document.querySelectorAll("input[name=mode]").forEach((r) => r.addEventListener("change", () => {
  clearAnswer(); clearPad(); pending = null; say(mode() === "recognize" ?
    "Recognize: draw, and the robot names the concept (it learns nothing)." : "");
}));

// -- the memory -------------------------------------------------------------------
function thumbnail(points, prototype) {
  const c = document.createElement("canvas");
  c.width = 72; c.height = 72;
  const ctx = c.getContext("2d");
  if (points.length > 1) {
    const xs = points.map((p) => p[0]), ys = points.map((p) => p[1]);
    const lo = [Math.min(...xs), Math.min(...ys)], hi = [Math.max(...xs), Math.max(...ys)];
    const s = 60 / Math.max(hi[0] - lo[0], hi[1] - lo[1], 1e-9);
    const ox = 36 - (lo[0] + hi[0]) / 2 * s, oy = 36 + (lo[1] + hi[1]) / 2 * s;
    ctx.strokeStyle = prototype ? "#2d3e50" : "#1f5fbf"; ctx.lineWidth = 2;
    ctx.beginPath();
    points.forEach((p, i) => {
      const x = ox + p[0] * s, y = oy - p[1] * s;
      if (i === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
    });
    ctx.stroke();
  }
  return c;
}

function renderMemory(memory) {
  if (!memory) return;
  $("memsummary").textContent = `${memory.concepts.length} concept(s), ${memory.entries} entries, ` +
    `${memory.demonstrations_seen} drawing(s) learned; saved in ${memory.file}`;
  const box = $("concepts");
  box.textContent = "";
  if (!memory.concepts.length) {
    box.textContent = "Empty: draw a first shape to teach the robot.";
  }
  for (const concept of memory.concepts) {
    const div = document.createElement("div");
    div.className = "concept";
    div.dataset.concept = concept.name;
    const name = document.createElement("div");
    name.className = "name";
    name.textContent = `${concept.name} (${concept.num_samples} drawing${concept.num_samples === 1 ? "" : "s"})`;
    div.appendChild(name);
    const form = document.createElement("form");
    const input = document.createElement("input");
    input.placeholder = "new name"; input.maxLength = 40; input.setAttribute("aria-label", `rename ${concept.name}`);
    const button = document.createElement("button");
    button.type = "submit"; button.textContent = "Rename";
    form.append(input, button);
    form.addEventListener("submit", async (e) => {
      e.preventDefault();
      showError("");
      try {
        const data = await api("/api/rename", {concept: concept.name, name: input.value});
        renderMemory(data.memory);
        say(`Renamed "${concept.name}" to "${input.value.trim()}".`);
        if (pending) { pending = null; clearAnswer(); }
      } catch (err) { showError(err.message); }
    });
    div.appendChild(form);
    const thumbs = document.createElement("div");
    thumbs.className = "thumbs";
    for (const entry of concept.entries) {
      const t = document.createElement("div");
      t.className = "thumb" + (entry.prototype ? " prototype" : "");
      t.title = `${entry.prototype ? "prototype" : "exemplar"} of ${entry.num_samples} drawing(s): ` +
        entry.sources.join(", ");
      t.appendChild(thumbnail(entry.drawing, entry.prototype));
      const label = document.createElement("span");
      label.textContent = `${entry.prototype ? "prototype" : "exemplar"} x${entry.num_samples}`;
      t.appendChild(label);
      thumbs.appendChild(t);
    }
    div.appendChild(thumbs);
    box.appendChild(div);
  }
}

async function start() {
  try {
    const state = await api("/api/state");
    renderMemory(state.memory);
    if (state.pending) showAnswer(state.pending);
  } catch (err) { showError(err.message); }
}
start();
