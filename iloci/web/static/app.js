// iloci serve: the page. Plain JavaScript, no build step, nothing from the internet.
"use strict";

const pad = document.getElementById("pad");
const answerCanvas = document.getElementById("answer");
const padCtx = pad.getContext("2d");
const ansCtx = answerCanvas.getContext("2d");
const $ = (id) => document.getElementById(id);

let stroke = [];          // [x, y, t]: x right, y up (canvas pixels), t seconds
let drawing = false;
let pointer = null;       // the pointerId that started the stroke: the only one drawn
let pending = null;       // the guess waiting for yes / no
let busy = false;
// the most points the server takes in one stroke (iloci.web.schemas.MAX_POINTS)
const MAX_POINTS = 5000;
// a stroke spanning less than this share of the pad's shorter side is a dot, not a shape
const MIN_SPAN = 0.03;
let animation = null;
// the server's token (a new one each start): every write carries it
const TOKEN = document.querySelector('meta[name="iloci-token"]').content;
// this tab's id: its own turn; kept over a reload of the tab, not shared with others
const CLIENT = sessionStorage.getItem("iloci-client") ||
  (crypto.randomUUID ? crypto.randomUUID() : String(Math.random()).slice(2));
sessionStorage.setItem("iloci-client", CLIENT);

function mode() { return document.querySelector("input[name=mode]:checked").value; }

function showError(text) {
  const box = $("error");
  box.textContent = text || "";
  box.hidden = !text;
}

function say(text) { $("message").textContent = text || ""; }

async function api(path, body, raw) {
  const options = body === undefined ? {} : {
    method: "POST",
    headers: {"Content-Type": raw ? "application/octet-stream" : "application/json",
              "X-Iloci-Token": TOKEN},
    body: raw ? body : JSON.stringify(body)};
  let response;
  try {
    response = await fetch(path, options);
  } catch (err) {
    throw new Error("the server does not answer (is `iloci serve` still running?)");
  }
  let data = null;
  try { data = await response.json(); } catch (err) { data = null; }
  if (!response.ok) {
    // a failed save: the page shows what the file still holds
    if (data && data.memory) renderMemory(data.memory);
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

// high-DPI: the backing store has the screen's pixels, the page's size stays
function fitCanvas(canvas) {
  const r = canvas.getBoundingClientRect();
  const ratio = window.devicePixelRatio || 1;
  const w = Math.max(1, Math.round(r.width * ratio)), h = Math.max(1, Math.round(r.height * ratio));
  if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
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

// the stroke belongs to the pointer that started it: a second finger or the
// palm is ignored; a cancelled pointer (the browser took it over) or lost
// capture ends the stroke without sending it
pad.addEventListener("pointerdown", (e) => {
  e.preventDefault();
  if (drawing) return;                       // another pointer is drawing: ignored
  if (busy) {   // kept on screen until the next stroke: the robot's answer does not hide it
    showError("Wait a moment: the robot is still busy with your last drawing or answer " +
              "(the bar shows how far). This stroke was not taken: draw it again when it has answered.");
    return;
  }
  if (e.pointerType === "mouse" && e.button !== 0) return;
  pointer = e.pointerId;
  try { pad.setPointerCapture(e.pointerId); } catch (err) { /* not capturable */ }
  fitCanvas(pad);
  clearPad();
  if (mode() === "teach") clearAnswer();
  showError("");
  padCtx.lineWidth = 3 * (window.devicePixelRatio || 1);
  padCtx.lineCap = "round"; padCtx.lineJoin = "round"; padCtx.strokeStyle = "#222";
  drawing = true;
  addPoint(e);
});

pad.addEventListener("pointermove", (e) => {
  if (!drawing || e.pointerId !== pointer) return;
  const events = e.getCoalescedEvents ? e.getCoalescedEvents() : [];
  for (const c of (events.length ? events : [e])) addPoint(c);
});

function penUp(e) {
  if (!drawing || e.pointerId !== pointer) return;
  drawing = false; pointer = null;
  addPoint(e);
  if (stroke.length < 5) { showError("The stroke is too short: draw a shape in one stroke (press, draw, lift)."); return; }
  // a dot or a tap with a tremor is no shape: the robot would learn it as one
  const xs = stroke.map((p) => p[0]), ys = stroke.map((p) => p[1]);
  const span = Math.max(Math.max(...xs) - Math.min(...xs), Math.max(...ys) - Math.min(...ys));
  if (span < MIN_SPAN * Math.min(pad.width, pad.height)) {
    showError("The stroke is too small to be a shape (a dot?): draw it larger, across the pad.");
    return;
  }
  // a long slow stroke has more points than the server takes: keep evenly spaced ones
  // (first and last included, times kept) rather than lose the drawing
  stroke = thinned(stroke, MAX_POINTS);
  if (mode() === "teach") observe(); else recognize();
}
// at most `most` of `points`, evenly spaced by index, the first and the last kept
function thinned(points, most) {
  const n = points.length;
  if (n <= most) return points;
  return Array.from({length: most}, (_, i) => points[Math.round(i * (n - 1) / (most - 1))]);
}
function abandon(e) {
  if (!drawing || e.pointerId !== pointer) return;
  drawing = false; pointer = null;
  clearPad();
  say("The stroke was interrupted (the browser took the pointer); draw it again.");
}
pad.addEventListener("pointerup", penUp);
pad.addEventListener("pointercancel", abandon);
pad.addEventListener("lostpointercapture", (e) => { if (drawing && e.pointerId === pointer) penUp(e); });

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
  fitCanvas(answerCanvas);
  const pts = answer.drawing;
  const view = viewOf(pts);
  const total = Math.min(6, Math.max(0.8, answer.dt * (pts.length - 1)));   // seconds
  const start = performance.now();
  const frame = (now) => {
    const k = Math.max(1, Math.min(pts.length, 1 + Math.floor((now - start) / 1000 / total * (pts.length - 1))));
    ansCtx.clearRect(0, 0, answerCanvas.width, answerCanvas.height);
    showStrokeFaint(ansCtx, view);
    ansCtx.strokeStyle = "#1f5fbf"; ansCtx.lineWidth = 3 * (window.devicePixelRatio || 1);
    ansCtx.lineCap = "round";
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
  if (answer.notice) say(answer.notice);
  animateAnswer(answer);
  // the novelty answer: nothing the robot knows is like the drawing, it
  // drew it back as it saw it and asks whether it is a new concept
  $("guess").textContent = answer.novel ?
    `Something new? The robot knows nothing like it and drew it back as it saw it: ` +
    `is it a new concept ("${answer.concept}")? (attempt ${answer.attempt})` :
    answer.last_guess ?
    `Is it "${answer.concept}"? It is the only concept left to guess, so this is no ` +
    `certainty (attempt ${answer.attempt})` :
    answer.unsure ?
    `Is it "${answer.concept}"? Unsure: the drawing is like nothing it was taught ` +
    `(familiarity ${answer.familiarity.toFixed(2)}); if it is new, say Something new ` +
    `(attempt ${answer.attempt})` :
    `Is it "${answer.concept}"? (confidence ${answer.confidence === null ? "n/a" : answer.confidence.toFixed(2)}, ` +
    `attempt ${answer.attempt})`;
  $("judge").hidden = false;
  $("new").hidden = !!answer.novel;
  if (answer.arm) { $("arm").src = answer.arm; $("arm").hidden = false; }
}

function describe(outcome) {
  const what = {
    strengthen: `an example of "${outcome.concept}" it knew well (strengthened)`,
    new_exemplar: `a new example of "${outcome.concept}"`,
    new_concept: `a new concept, "${outcome.concept}"`,
    already_learned: `nothing new: this very drawing is already in "${outcome.concept}"`,
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

function learned(data) {
  // the turn is over: no guess stays on screen
  pending = null;
  clearAnswer();
  say((data.notice ? data.notice + " " : "") + describe(data.outcome));
  renderMemory(data.memory);
}

async function observe() {
  say("The robot is thinking...");
  try {
    const data = await withProgress(api("/api/observe", {points: stroke, client: CLIENT}));
    if (data.answer) { say(""); showAnswer(data.answer); }
    else learned(data);
  } catch (err) { say(""); showError(err.message); }
}

async function judge(value) {
  if (!pending || busy) return;
  $("judge").hidden = true;
  say(value === "new" ? "Something new: learning..." :
      value > 0 ? "Yes: learning..." : "No: thinking again...");
  try {
    const data = await withProgress(api("/api/feedback", {turn: pending.turn, answer: pending.id, value,
                                                    client: CLIENT}));
    if (data.answer) { say(""); showAnswer(data.answer); }
    else learned(data);
  } catch (err) {
    say(""); showError(err.message);
    if (/no such guess|answered already/.test(err.message)) { pending = null; clearAnswer(); }
    else if (pending) $("judge").hidden = false;
  }
}

async function recognize() {
  say("Recognizing...");
  try {
    const r = await api("/api/recognize", {points: stroke});
    clearAnswer();
    say("");
    if (r.drawing && r.drawing.length > 1) animateAnswer({drawing: r.drawing, dt: 0.02});
    $("guess").textContent = r.unknown ?
      `Unknown: like nothing it was taught (nearest "${r.concept}"); nothing learned.` :
      `Recognized: "${r.concept}" (confidence ${r.confidence.toFixed(2)}); nothing learned.`;
  } catch (err) { say(""); showError(err.message); }
}

$("yes").addEventListener("click", () => judge(1));
$("no").addEventListener("click", () => judge(-1));
$("new").addEventListener("click", () => judge("new"));
$("clear").addEventListener("click", () => { clearPad(); showError(""); });
document.addEventListener("keydown", (e) => {
  // typing a name, or a browser shortcut (Ctrl+S saves the page, Alt+N ...), is no answer
  if (e.ctrlKey || e.metaKey || e.altKey || e.repeat) return;
  const t = e.target;
  if (t && (t.tagName === "INPUT" || t.tagName === "TEXTAREA" || t.tagName === "SELECT" ||
            t.isContentEditable)) return;
  if (e.key === "y") judge(1);
  else if (e.key === "n") judge(-1);
  else if (e.key === "s" && pending && !pending.novel) judge("new");
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

async function control(path, body, done) {
  if (busy) return;
  showError("");
  try {
    // the memory this page shows: the server refuses the control if another tab changed it
    const data = await api(path, {...body, version: memoryVersion});
    renderMemory(data.memory);
    say(done(data));
  } catch (err) { say(""); showError(err.message); }
}

let saved = false;       // whether the memory file exists (Export has something to give)
let memoryVersion = null;  // the server's version of the memory this page shows
function renderMemory(memory) {
  if (!memory) return;
  saved = !!memory.saved;
  memoryVersion = memory.version;
  $("memsummary").textContent = `${memory.concepts.length} concept(s), ${memory.entries} entries, ` +
    `${memory.demonstrations_seen} drawing(s) learned; saved in ${memory.file}`;
  $("undo").disabled = !memory.undo;
  $("undo").title = memory.undo ? `undo: ${memory.undo}` : "nothing to undo";
  if (memory.save_error) showError(memory.save_error);
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
        const data = await api("/api/rename", {concept: concept.name, name: input.value,
                                               version: memoryVersion});
        renderMemory(data.memory);
        say(`Renamed "${concept.name}" to "${input.value.trim()}".`);
      } catch (err) { say(""); showError(err.message); }
    });
    div.appendChild(form);
    const forget = document.createElement("button");
    forget.type = "button"; forget.className = "forget"; forget.textContent = "Forget";
    forget.title = `forget the concept ${concept.name} (undo brings it back)`;
    forget.addEventListener("click", () => control("/api/forget", {concept: concept.name},
      () => `Forgot "${concept.name}". (Undo brings it back.)`));
    name.appendChild(forget);
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
      if (concept.entries.length > 1) {
        const x = document.createElement("button");
        x.type = "button"; x.className = "forget-entry"; x.textContent = "\u00d7";
        x.title = "forget this entry";
        x.setAttribute("aria-label", `forget this entry of ${concept.name}`);
        x.addEventListener("click", () => control("/api/forget", {entry: entry.index},
          () => `Forgot an entry of "${concept.name}". (Undo brings it back.)`));
        t.appendChild(x);
      }
      thumbs.appendChild(t);
    }
    div.appendChild(thumbs);
    box.appendChild(div);
  }
}

$("undo").addEventListener("click", () => control("/api/undo", {},
  (d) => `Undone: ${d.undone}. The memory and the network are as before it.`));
$("reset").addEventListener("click", () => {
  if (!confirm("Start over with an empty memory? (Undo brings it back.)")) return;
  control("/api/reset", {}, () => "Started over: the memory is empty. Draw a first shape.");
});
$("export").addEventListener("click", (e) => {
  if (saved) return;                         // the browser downloads the file
  e.preventDefault();
  showError("Nothing is saved yet: teach a first drawing, then export.");
});
$("import").addEventListener("change", async () => {
  const file = $("import").files[0];
  if (!file) return;
  showError("");
  try {
    const data = await api("/api/import", await file.arrayBuffer(), true);
    renderMemory(data.memory);
    say(`Imported ${file.name}. (Undo brings the previous memory back.)`);
  } catch (err) { say(""); showError(err.message.replace("the file", file.name)); }
  $("import").value = "";
});

window.addEventListener("resize", () => { if (!drawing && !stroke.length) fitCanvas(pad); });

async function start() {
  fitCanvas(pad); fitCanvas(answerCanvas);
  try {
    const state = await api(`/api/state?client=${encodeURIComponent(CLIENT)}`);
    renderMemory(state.memory);
    if (state.pending) {
      // a reload: the drawing and the guess it is waiting on
      fitCanvas(pad);
      stroke = state.pending.points;
      padCtx.lineWidth = 3 * (window.devicePixelRatio || 1); padCtx.lineCap = "round";
      padCtx.strokeStyle = "#222";
      padCtx.beginPath();
      stroke.forEach((p, i) => {
        if (i === 0) padCtx.moveTo(p[0], pad.height - p[1]); else padCtx.lineTo(p[0], pad.height - p[1]);
      });
      padCtx.stroke();
      showAnswer(state.pending);
    }
    // a reload while the robot learns: say so, and show the memory once it has learned
    if (state.progress) await stillLearning();
    // a reload while this tab's drawing or answer is still being handled (the reload
    // cancelled the page's request, not the server's work): wait for it, then show it
    else if (state.working && !state.pending) await stillWorking();
  } catch (err) { showError(err.message); }
}

async function stillWorking() {
  say("The robot is still working on your last drawing or answer...");
  await withProgress((async () => {
    for (;;) {
      await new Promise((r) => setTimeout(r, 300));
      const s = await api(`/api/state?client=${encodeURIComponent(CLIENT)}`);
      if (!s.working) return;
    }
  })());
  say("");
  await start();
  if (!pending) say("The robot has finished with your last drawing or answer. Draw the next one.");
}

async function stillLearning() {
  say("The robot is still learning your last answer...");
  await withProgress((async () => {
    for (;;) {
      await new Promise((r) => setTimeout(r, 500));
      const p = (await api("/api/progress")).progress;
      if (!p) return;
    }
  })());
  const state = await api(`/api/state?client=${encodeURIComponent(CLIENT)}`);
  renderMemory(state.memory);
  say("The robot has learned your last answer. Draw the next one.");
}
start();
