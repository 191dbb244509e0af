// The console page: draws the frames the server streams, sends the operator's commands.
// No build step: plain JS and canvas. Followers are 1-based in messages and on screen.
"use strict";

const COLORS = ["#1e88e5", "#e53935", "#43a047", "#fb8c00", "#8e24aa", "#00897b", "#6d4c41", "#3949ab"];
const TRAIL_S = 5, PLOT_S = 10;
let info = null, last = null, ws = null;
let trails = [], hist = [];
let keys = { left: false, right: false, up: false, down: false };
let sentU0 = null, wantScale = null;
let frameWall = null;  // performance.now() of the last frame received
// what the page drew last (tests read it): the world view's slots and the plots' scales
window.__drawn = { frames: [], plots: {} };

const $ = (id) => document.getElementById(id);
const color = (i) => COLORS[i % COLORS.length];

function send(msg) { if (ws && ws.readyState === 1) ws.send(JSON.stringify(msg)); }

function connect() {
  ws = new WebSocket(`ws://${location.host}/ws`);
  ws.onopen = () => send({ type: "drive" });
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "state") { frameWall = performance.now(); $("stale").style.display = "none"; onState(msg); }
    else if (msg.type === "released") { releaseKeys(); logError("u0 back to 0: " + msg.reason); }
    else if (msg.type === "hello") onHello(msg);
    else if (msg.type === "error") logError(msg.message);
    else if (msg.type === "saved") onSaved(msg);
    else if (msg.type === "role") $("drive").disabled = true;
  };
  ws.onclose = () => { $("role").textContent = "disconnected"; };
}

function onSaved(msg) {
  const el = $("saved");
  if (msg.reason) {  // the record was written but the server refused to make it a replay
    el.className = "refused";
    el.textContent = `record ${msg.folder} (${msg.rows} rows) saved, replay refused: ${msg.reason}`;
  } else {
    el.className = "";
    el.textContent = `saved: ${msg.scenario} (${msg.rows} rows, replay with make sim SCENARIO=…)`;
  }
}

function logError(text) {
  const div = $("errors");
  div.textContent = (text + "\n" + div.textContent).slice(0, 2000);
}

function onHello(msg) {
  info = msg;
  $("title").textContent = msg.title || "console";
  $("inputs").textContent = msg.p === 1
    ? "This leader has one input: every arrow drives u0 (→ ↑ +, ← ↓ −), so it moves on a line; a gamepad's left stick x-axis sets it."
    : `This leader has ${msg.p} inputs: ← → drive u0[1], ↑ ↓ drive u0[2] (each up to ±${fmtNum(msg.u_max)}); a gamepad's left stick sets both.`;
  trails = Array.from({ length: msg.N }, () => []);
  buildTable();
}

function buildTable() {
  const tbl = $("followers");
  let html = "<tr><th>follower</th><th>health g</th><th>ĝ</th><th>|u|</th><th>peak |u|</th><th>bias</th><th>links</th><th>faults</th></tr>";
  for (let i = 0; i < info.N; i++) {
    const links = info.edges.filter((e) => e[0] === i + 1).map((e) =>
      `<button data-link="${i + 1},${e[1]}">${e[1] === 0 ? "leader" : e[1]}</button>`).join("");
    html += `<tr><td style="color:${color(i)}">${i + 1}</td>` +
      `<td><span class="bar" id="gbar${i}"></span> <span id="g${i}"></span></td>` +
      `<td id="ghat${i}"></td><td id="un${i}"></td><td id="pk${i}"></td><td id="b${i}"></td><td>${links}</td>` +
      `<td><button data-health="${i + 1}">g×0.6</button><button data-bias="${i + 1}">bias</button>` +
      `<button data-clear="${i + 1}">clear</button></td></tr>`;
  }
  tbl.innerHTML = html;
  tbl.querySelectorAll("button[data-health]").forEach((b) => b.onclick = () => {
    const i = +b.dataset.health;
    const g = Math.max(info.g_min, (last ? last.health[i - 1] : 1) * 0.6);
    send({ type: "health", follower: i, value: g });
  });
  tbl.querySelectorAll("button[data-bias]").forEach((b) => b.onclick = () => {
    const v = Math.min(info.bias_max, 5);
    send({ type: "bias", follower: +b.dataset.bias, value: Array(info.n).fill(v) });
  });
  tbl.querySelectorAll("button[data-clear]").forEach((b) => b.onclick = () =>
    send({ type: "clear", follower: +b.dataset.clear }));
  tbl.querySelectorAll("button[data-link]").forEach((b) => b.onclick = () => {
    const [i, j] = b.dataset.link.split(",").map(Number);
    const isCut = last && last.cut.some((c) => c[0] === i && c[1] === j);
    send({ type: "link", follower: i, neighbour: j, cut: !isCut });
  });
}

function onState(s) {
  if (last && s.t < last.t) { trails = trails.map(() => []); hist = []; }
  last = s;
  if (wantScale !== null && Math.abs(s.scale - wantScale) < 1e-12) wantScale = null;
  if (!info) return;
  for (let i = 0; i < info.N; i++) {
    if (s.p && s.p[i]) trails[i].push([s.t, s.p[i][0], s.p[i][1]]);
    while (trails[i].length && trails[i][0][0] < s.t - TRAIL_S) trails[i].shift();
  }
  hist.push([s.t, s.et, s.est]);
  while (hist.length && hist[0][0] < s.t - PLOT_S) hist.shift();
  $("t").textContent = s.t.toFixed(2);
  $("ratio").textContent = s.ratio.toFixed(2);
  $("scale").textContent = s.scale;
  const health = $("health");
  health.textContent = s.failure ? "HELD" : (s.busy ? `BUSY ${s.busy.toFixed(1)} s (last state shown)` : (s.paused ? "paused" : "ok"));
  health.className = s.failure || s.busy ? "alarm" : "";
  const bound = info.peak_bound, worst = s.peak_u.some((v) => v === null) ? Infinity : Math.max(...s.peak_u);
  const over = s.peak_u.filter((v) => v === null || !(v <= bound)).length;
  $("peak").textContent = s.t < info.peak_from ? `— (from t = ${info.peak_from} s)` :
    `${isFinite(worst) ? fmt(worst) : "∞"} ${over ? `> ${bound}: ${over} follower${over > 1 ? "s" : ""} above the bound` : `≤ ${bound}: ok`}`;
  $("peak").className = over ? "alarm" : "";
  $("recoveries").textContent = s.recoveries ? `, ${s.recoveries} restart${s.recoveries > 1 ? "s" : ""} after a failure` : "";
  $("events").textContent = (s.events || []).map((e) => `t = ${e[0].toFixed(2)} s ${e[1]}: ${e[2]}`).join("\n");
  $("queued").textContent = s.slots_full ? " (waiting for a ramp to end)" : (s.queued ? " (lands within " + fmtNum(info.rise / 12) + " s)" : "");
  $("steps").textContent = s.steps;
  $("load").textContent = (100 * s.load).toFixed(0) + " %";
  $("u0").textContent = s.u0.map((v) => v.toFixed(2)).join(", ");
  $("role").textContent = `${s.role} (${s.pages} page${s.pages > 1 ? "s" : ""})`;
  const drive = $("drive");
  drive.style.display = s.role === "watcher" ? "inline" : "none";
  drive.disabled = s.driven;  // another page drives: it must close first
  drive.title = s.driven ? "another page drives" : "no page drives: take over";
  $("banner").style.display = s.failure ? "block" : "none";
  $("why").textContent = s.failure;
  $("pause").textContent = s.paused ? "resume" : "pause";
  for (let i = 0; i < info.N; i++) {
    $("g" + i).textContent = s.health[i].toFixed(2);
    $("gbar" + i).style.width = (60 * s.health[i]) + "px";
    $("gbar" + i).style.background = s.health[i] < info.nominal_health[i] ? "#e53935" : "#43a047";
    $("ghat" + i).textContent = s.ghat ? fmt(s.ghat[i]) : "";
    $("un" + i).textContent = s.unorm ? fmt(s.unorm[i]) : "";
    $("pk" + i).textContent = s.t < info.peak_from ? "—" : (s.peak_u[i] === null ? "∞" : fmt(s.peak_u[i]));
    $("pk" + i).className = s.peak_u[i] !== null && s.peak_u[i] <= info.peak_bound ? "" : "alarm";
    $("b" + i).textContent = s.bias[i].map((v) => v.toFixed(1)).join(", ");
  }
  document.querySelectorAll("button[data-link]").forEach((b) => {
    const [i, j] = b.dataset.link.split(",").map(Number);
    b.style.textDecoration = s.cut.some((c) => c[0] === i && c[1] === j) ? "line-through" : "none";
  });
  drawWorld(s);
  drawPlot($("plot_et"), 1);
  drawPlot($("plot_est"), 2);
}

function fmt(v) { return v === null ? "—" : (Math.abs(v) >= 1000 ? v.toExponential(1) : v.toFixed(2)); }
function fmtNum(v) { return String(+v.toPrecision(6)); }

function drawWorld(s) {
  const cv = $("world"), g = cv.getContext("2d");
  g.clearRect(0, 0, cv.width, cv.height);
  if (!s.y0 || s.y0.length < 2) return;
  const [cx, cy] = s.y0;
  let half = 8;
  for (const pt of [...(s.p || []), ...(s.slots || [])]) {
    if (pt[0] === null || pt[1] === null) continue;
    half = Math.max(half, 1.15 * Math.abs(pt[0] - cx), 1.15 * Math.abs(pt[1] - cy));
  }
  const k = Math.min(cv.width, cv.height) / (2 * half);
  const X = (x) => cv.width / 2 + k * (x - cx), Y = (y) => cv.height / 2 - k * (y - cy);
  g.strokeStyle = "#eee";
  for (let v = Math.ceil((cx - half) / 5) * 5; v < cx + half * cv.width / cv.height; v += 5) {
    g.beginPath(); g.moveTo(X(v), 0); g.lineTo(X(v), cv.height); g.stroke();
  }
  for (let v = Math.ceil((cy - half) / 5) * 5; v < cy + half; v += 5) {
    g.beginPath(); g.moveTo(0, Y(v)); g.lineTo(cv.width, Y(v)); g.stroke();
  }
  for (let i = 0; i < info.N; i++) {
    g.strokeStyle = color(i); g.globalAlpha = 0.5; g.beginPath();
    trails[i].forEach((q, n) => n ? g.lineTo(X(q[1]), Y(q[2])) : g.moveTo(X(q[1]), Y(q[2])));
    g.stroke(); g.globalAlpha = 1;
    const sl = s.slots[i], p = s.p[i];
    g.strokeRect(X(sl[0]) - 6, Y(sl[1]) - 6, 12, 12);
    g.fillStyle = color(i); g.beginPath(); g.arc(X(p[0]), Y(p[1]), 6, 0, 2 * Math.PI); g.fill();
    g.fillStyle = "#000"; g.fillText(String(i + 1), X(p[0]) + 8, Y(p[1]) - 8);
  }
  g.fillStyle = "#000"; g.beginPath(); g.arc(X(cx), Y(cy), 8, 0, 2 * Math.PI); g.fill();
  g.fillText("leader y0", X(cx) + 10, Y(cy) + 14);
  g.fillText("● follower p_i   □ slot y0 + b_i (the offset each controller tracks)", 8, cv.height - 8);
  const fr = window.__drawn.frames;
  fr.push({ t: s.t, y0: s.y0, slots: s.slots, p: s.p, et: s.et, est: s.est, unorm: s.unorm, u0: s.u0_now || s.u0 });
  if (fr.length > 600) fr.shift();
}

// robust scale of a plot: the 98th percentile of the window (× 1.25), never a lone spike
function robustTop(values) {
  const v = values.filter((x) => x !== null && isFinite(x)).sort((a, b) => a - b);
  if (!v.length) return { top: 1e-9, max: 0, clipped: false };
  const q = v[Math.min(v.length - 1, Math.floor(0.98 * v.length))];
  const max = v[v.length - 1];
  const top = Math.max(1.25 * q, 1e-9);
  return max > top ? { top, max, clipped: true } : { top: Math.max(max, 1e-9), max, clipped: false };
}

function drawPlot(cv, col) {
  const g = cv.getContext("2d");
  g.clearRect(0, 0, cv.width, cv.height);
  if (!hist.length || !hist[hist.length - 1][col]) return;
  const t1 = hist[hist.length - 1][0], t0 = t1 - PLOT_S;
  const L = 42, B = 26, T = 6;  // margins: value labels left, time axis and its label below
  const sc = robustTop(hist.flatMap((h) => h[col]));
  const X = (t) => L + (cv.width - L - 5) * (t - t0) / PLOT_S;
  const Y = (v) => cv.height - B - (cv.height - B - T) * Math.min(v, sc.top) / sc.top;
  g.strokeStyle = "#999"; g.fillStyle = "#555";
  g.beginPath(); g.moveTo(L, T); g.lineTo(L, cv.height - B); g.lineTo(cv.width - 5, cv.height - B); g.stroke();
  g.fillText(sc.top.toPrecision(2), 2, T + 8); g.fillText("0", 2, cv.height - B);
  const ticks = [];
  for (let k = Math.ceil(Math.max(t0, 0)); k <= t1; k += 1) {  // a tick every simulated second
    const x = X(k);
    g.beginPath(); g.moveTo(x, cv.height - B); g.lineTo(x, cv.height - B + 3); g.stroke();
    if (k % 2 === 0) g.fillText(String(k), x - 3, cv.height - B + 12);
    ticks.push(k);
  }
  g.fillText("simulated time t (s)", cv.width / 2 - 45, cv.height - 2);
  for (let i = 0; i < info.N; i++) {
    g.strokeStyle = color(i); g.beginPath();
    hist.forEach((h, n) => { const v = h[col][i] ?? 0; n ? g.lineTo(X(h[0]), Y(v)) : g.moveTo(X(h[0]), Y(v)); });
    g.stroke();
  }
  if (sc.clipped) {  // values above the scale are drawn at its top, and the page says so
    g.fillStyle = "#c62828";
    g.fillRect(L, T - 2, cv.width - L - 5, 2);
    g.fillText(`clipped: max ${sc.max.toPrecision(3)}`, cv.width - 130, T + 10);
  }
  window.__drawn.plots[cv.id] = { top: sc.top, max: sc.max, clipped: sc.clipped, ticks, t0, t1, xlabel: "simulated time t (s)" };
}

// ---- operator input: keyboard and the Gamepad API
function commandFromKeys() {
  // one input: every arrow drives it (→ ↑ +, ← ↓ −); two or more: ← → u0[1], ↑ ↓ u0[2]
  const u = Array(info.p).fill(0), a = info.u_max;
  const plus = (b) => (b ? 1 : 0);
  if (info.p === 1) {
    u[0] = a * Math.sign(plus(keys.right || keys.up) - plus(keys.left || keys.down));
  } else {
    u[0] = a * (plus(keys.right) - plus(keys.left));
    u[1] = a * (plus(keys.up) - plus(keys.down));
  }
  return u;
}

function pushU0(u) {
  const key = JSON.stringify(u);
  if (key !== sentU0) { sentU0 = key; send({ type: "u0", value: u }); }
}

// dead-man's handle: a held command is sent again every info.keepalive s (the server sets
// u0 to 0 when none comes for info.deadman s); leaving the page releases every key
setInterval(() => {
  const held = sentU0 !== null && JSON.parse(sentU0).some((v) => v !== 0);
  if (info && held && last && last.role === "driver") send({ type: "u0", value: JSON.parse(sentU0) });
}, 200);

function releaseKeys() {
  keys = { left: false, right: false, up: false, down: false };
  if (info && last && last.role === "driver") pushU0(Array(info.p).fill(0));
}
window.addEventListener("blur", releaseKeys);
window.addEventListener("pagehide", releaseKeys);
document.addEventListener("visibilitychange", () => { if (document.hidden) releaseKeys(); });

// frames stop: say so (the server sends one at least every frame period while it runs)
setInterval(() => {
  if (frameWall === null) return;
  const gap = (performance.now() - frameWall) / 1000;
  const el = $("stale");
  el.textContent = gap > 1 ? `NO FRAMES for ${gap.toFixed(1)} s: the server does not answer (the view is stale)` : "";
  el.style.display = gap > 1 ? "block" : "none";
  if (gap > 1) { $("health").textContent = "NO FRAMES"; $("health").className = "alarm"; }
}, 250);

function askReset() {
  if (window.confirm("Reset: back to t = 0, the run so far is dropped (save it first). Reset?")) send({ type: "reset" });
}

const KEYMAP = { ArrowLeft: "left", ArrowRight: "right", ArrowUp: "up", ArrowDown: "down" };
window.addEventListener("keydown", (e) => {
  if (!info) return;
  if (KEYMAP[e.key]) { keys[KEYMAP[e.key]] = true; pushU0(commandFromKeys()); e.preventDefault(); }
  else if (e.key === " ") { send({ type: last && last.paused ? "resume" : "pause" }); e.preventDefault(); }
  else if (e.key === "r") askReset();
  else if (e.key === "+" || e.key === "=") scaleBy(2);
  else if (e.key === "-") scaleBy(0.5);
});
window.addEventListener("keyup", (e) => {
  if (info && KEYMAP[e.key]) { keys[KEYMAP[e.key]] = false; pushU0(commandFromKeys()); }
});

function scaleBy(f) {
  // the next of info.scales up (f > 1) or down from the scale asked for last, not the last
  // frame's: quick presses each count; 1 is one of the steps
  const base = wantScale !== null ? wantScale : (last ? last.scale : 1);
  const ladder = info.scales;
  const up = ladder.filter((v) => v > base * (1 + 1e-9)), down = ladder.filter((v) => v < base * (1 - 1e-9));
  const s = f > 1 ? (up.length ? up[0] : ladder[ladder.length - 1]) : (down.length ? down[down.length - 1] : ladder[0]);
  wantScale = s;
  send({ type: "scale", value: s });
}

function pollGamepad() {
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  const pad = Array.from(pads).find((p) => p);
  if (pad && info) {
    $("pads").textContent = "gamepad: " + pad.id;
    const dead = (v) => (Math.abs(v) < 0.1 ? 0 : v);
    const u = Array(info.p).fill(0);
    const clip = (v) => Math.max(-info.u_max, Math.min(info.u_max, v));
    u[0] = clip(+(info.u_max * dead(pad.axes[0] || 0)).toFixed(3));
    if (info.p > 1) u[1] = clip(+(-info.u_max * dead(pad.axes[1] || 0)).toFixed(3));  // stick up = +
    if (!Object.values(keys).some((k) => k) && document.hasFocus()) pushU0(u);
  }
  requestAnimationFrame(pollGamepad);
}

$("pause").onclick = () => send({ type: last && last.paused ? "resume" : "pause" });
$("reset").onclick = $("reset2").onclick = askReset;
$("retry").onclick = () => send({ type: "resume" });
$("drive").onclick = () => send({ type: "drive" });
$("slower").onclick = () => scaleBy(0.5);
$("faster").onclick = () => scaleBy(2);
$("save").onclick = () => send({ type: "save" });
connect();
requestAnimationFrame(pollGamepad);
