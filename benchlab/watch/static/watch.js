"use strict";
// benchlab watch: every second, ask /api/update for what is new (buckets from the last one held on, events
// after the last one held) and draw each channel's min/max per bucket (about one bucket per pixel) on <canvas>.

const POLL_MS = 1000;
const GROUPS = [["degC", "Temperatures"], ["rpm", "Speeds"], ["N*m", "Torques"], ["W", "Friction power"],
  ["1", "Clutch state"]];
const COLORS = ["#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#7f7f7f", "#bcbd22"];
const ALARM = /^(interlock|run_aborted|timeout|slip_time_limit|cycle_skipped|controller_(silent|fault|estop|alive_error)|\w+_error)$/;
const MARGIN = { left: 62, right: 12, top: 8, bottom: 22 };

const view = { span: 0, level: null, first: 0, count: 0, min: [], max: [], generation: null, events: [],
  status: null, updates: 0, plots: null, busy: false, again: false, timer: null };

const $ = (id) => document.getElementById(id);
const esc = (text) => String(text).replace(/&/g, "&amp;").replace(/</g, "&lt;").replace(/>/g, "&gt;").replace(/"/g, "&quot;");

function fmtTime(s) {
  if (s === null || !isFinite(s)) return "–";
  const sign = s < 0 ? "-" : "";
  s = Math.abs(s);
  const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60), sec = Math.floor(s % 60);
  const mm = String(m).padStart(h ? 2 : 1, "0"), ss = String(sec).padStart(2, "0");
  return sign + (h ? `${h}:${mm}:${ss}` : `${mm}:${ss}`);
}

function fmtValue(v) {
  if (v === null || v === undefined || !isFinite(v)) return "–";
  const a = Math.abs(v);
  return a >= 1000 ? v.toFixed(0) : a >= 100 ? v.toFixed(1) : a >= 1 ? v.toFixed(2) : v.toPrecision(3);
}

function decode(b64) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return Array.from(new Float32Array(bytes.buffer));
}

function plotWidth() {
  const canvas = document.querySelector(".plot canvas");
  const css = canvas ? canvas.clientWidth : document.body.clientWidth - 40;
  return Math.max(50, Math.round(css - MARGIN.left - MARGIN.right));
}

async function poll() {
  if (view.busy) { view.again = true; return; }
  view.busy = true;
  clearTimeout(view.timer);
  let soon = false;
  try {
    const q = new URLSearchParams({ width: plotWidth(), span: view.span, events: view.events.length });
    if (view.level !== null) { q.set("level", view.level); q.set("have", view.first + view.count); }
    const reply = await fetch("api/update?" + q.toString(), { cache: "no-store" });
    const answer = await reply.json();
    if (!reply.ok) throw new Error(answer.error || reply.statusText);
    if (apply(answer)) render();
    else soon = true;  // another run under the same name: ask again from scratch
  } catch (err) {
    offline(String(err.message || err));
  }
  view.busy = false;
  soon = soon || view.again;
  view.again = false;
  view.timer = setTimeout(poll, soon ? 0 : POLL_MS);
}

function apply(answer) {
  const s = answer.status;
  if (s.generation !== view.generation) {
    const first = view.generation === null;
    Object.assign(view, { generation: s.generation, level: null, first: 0, count: 0, min: [], max: [], events: [],
      plots: null });
    $("plots").innerHTML = "";
    if (!first) return false;
  }
  const ser = answer.series;
  const n = s.channels.length;
  const fresh = ser.level !== view.level || ser.first < view.first || ser.first > view.first + view.count;
  if (fresh) {
    view.level = ser.level; view.first = ser.first; view.count = 0;
    view.min = Array.from({ length: n }, () => []); view.max = Array.from({ length: n }, () => []);
  }
  const at = ser.first - view.first;
  for (let c = 0; c < n; c++) {
    view.min[c].length = at; view.max[c].length = at;
    view.min[c].push(...decode(ser.min[c])); view.max[c].push(...decode(ser.max[c]));
  }
  view.count = at + ser.count;
  const drop = ser.span_first - view.first;
  if (drop > 0) {
    for (let c = 0; c < n; c++) { view.min[c].splice(0, drop); view.max[c].splice(0, drop); }
    view.first += drop; view.count -= drop;
  }
  if (answer.events && answer.events.first === view.events.length) view.events.push(...answer.events.items);
  view.status = s;
  view.updates += 1;
  return true;
}

function offline(why) {
  const badge = $("badge");
  badge.className = "badge offline";
  badge.textContent = "server not answering";
  $("problem").style.display = "block";
  $("problem").textContent = `No answer from the watch server (${why}); the run command may have ended. ` +
    "Last data shown; asking again every second.";
}

function render() {
  const s = view.status;
  $("file").textContent = s.file;
  const badge = $("badge");
  let state = s.status, text = s.status;
  if (s.held) { state = "held"; text = "held by an interlock"; }
  else if (s.status === "running" && s.quiet_s > 10) { state = "quiet"; text = `running · no new data for ${fmtTime(s.quiet_s)}`; }
  badge.className = "badge " + state;
  badge.textContent = text;
  $("problem").style.display = s.problem ? "block" : "none";
  $("problem").textContent = s.problem || "";
  $("t-data").textContent = "t = " + fmtTime(s.t_data);
  $("rows").textContent = String(s.rows);
  document.body.dataset.rows = String(s.rows);
  $("protocol").textContent = s.protocol + (s.seed !== null ? ` (seed ${s.seed})` : "");
  const left = s.step ? s.step.run_left_s : null;
  $("left").textContent = left !== null ? `~${fmtTime(left)} left` : "";
  const done = s.t_data - s.t0, whole = left !== null ? done + left : s.planned_s;
  $("progress").style.width = whole > 0 ? Math.min(100, 100 * done / whole).toFixed(1) + "%" : "0";
  $("seen").innerHTML = `updated ${new Date().toLocaleTimeString()} · update <span id="updates">${view.updates}</span>`;
  renderStep(s.step);
  renderInterlocks(s);
  renderLatest(s);
  renderPlots(s);
  renderEvents();
}

function renderStep(step) {
  if (!step) { $("step").textContent = "–"; $("step-detail").textContent = "no schedule in this file"; return; }
  if (step.done) { $("step").textContent = `all ${step.steps} steps done`; $("step-detail").textContent = ""; return; }
  $("step").textContent = `cycle ${step.cycle + 1}/${step.cycles} · step ${step.index + 1}/${step.steps} · ` +
    step.phase + (step.label ? ` (${step.label})` : "");
  const set = `engine ${fmtValue(step.engine_speed_rpm)} rpm, clutch ${fmtValue(step.clutch_torque_nm)} N·m, ` +
    `load ${fmtValue(step.load_torque_nm)} N·m`;
  const left = !step.started ? "starting" : step.until
    ? `until ${step.until}: time-out in ${fmtTime(step.left_s)} (expected ${fmtTime(step.expected_left_s)})`
    : `${fmtTime(step.left_s)} left of this step`;
  $("step-detail").textContent = `${set} · ${left}`;
}

function renderInterlocks(s) {
  const names = Object.keys(s.interlocks);
  const el = $("interlocks");
  if (s.held || names.length) {
    el.className = "big alarm";
    el.textContent = (s.held ? "HELD: " : "tripped: ") + (names.join(", ") || "interlock");
    $("interlock-detail").textContent = Object.values(s.interlocks).join("; ");
  } else {
    el.className = "big ok";
    el.textContent = "none active";
    const last = [...view.events].reverse().find((e) => e.kind === "interlock_cleared");
    $("interlock-detail").textContent = last ? `last cleared at ${fmtTime(last.time)}: ${last.detail}` : "";
  }
}

function renderLatest(s) {
  const rows = s.channels.map((ch) => {
    const v = s.latest[ch.name];
    return `<tr><td>${esc(ch.name)}</td><td class="num">${fmtValue(v ? v.value : null)}</td><td>${esc(ch.unit)}</td></tr>`;
  });
  $("latest").innerHTML = rows.join("");
}

function buildPlots(s) {
  const groups = new Map();
  s.channels.forEach((ch, i) => {
    if (!groups.has(ch.unit)) groups.set(ch.unit, []);
    groups.get(ch.unit).push(i);
  });
  const units = GROUPS.map(([unit]) => unit);
  const rank = (unit) => (units.indexOf(unit) + 1) || units.length + 1;
  const order = [...groups.keys()].sort((a, b) => rank(a) - rank(b));
  const box = $("plots");
  box.innerHTML = "";
  view.plots = order.map((unit) => {
    const div = document.createElement("div");
    div.className = "plot";
    const legend = document.createElement("div");
    legend.style.padding = ".3em .6em";
    const title = (GROUPS.find(([u]) => u === unit) || [unit, unit])[1];
    legend.innerHTML = `<b>${esc(title)}</b> (${esc(unit)}) ` + groups.get(unit).map((i) =>
      `<span style="margin-left:.8em"><span class="swatch" style="background:${COLORS[i % COLORS.length]}"></span>` +
      `${esc(s.channels[i].name)}</span>`).join("");
    const canvas = document.createElement("canvas");
    canvas.dataset.unit = unit;
    if (unit === "1") canvas.style.height = "90px";  // a state (0/1) needs less room
    div.append(legend, canvas);
    box.append(div);
    return { unit, channels: groups.get(unit), canvas };
  });
}

function niceStep(range, target) {
  const raw = range / Math.max(1, target), mag = Math.pow(10, Math.floor(Math.log10(raw)));
  return [1, 2, 2.5, 5, 10].map((f) => f * mag).find((x) => x >= raw) || 10 * mag;
}

function tickDecimals(step) {
  const exponent = Math.floor(Math.log10(step) + 1e-9), mantissa = step / Math.pow(10, exponent);
  return Math.max(0, -exponent + (Math.abs(mantissa - 2.5) < 1e-6 ? 1 : 0));
}

function timeStep(range, target) {
  const steps = [1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600, 7200, 10800, 21600, 43200, 86400];
  return steps.find((x) => range / x <= target) || 86400 * Math.ceil(range / target / 86400);
}

function renderPlots(s) {
  if (!view.plots) buildPlots(s);
  const size = 2 ** view.level;
  const tEnd = s.t0 + s.rows * s.dt;
  const tStart = view.span > 0 ? Math.max(s.t0, tEnd - view.span) : s.t0;
  for (const plot of view.plots) drawPlot(plot, s, size, tStart, Math.max(tEnd, tStart + s.dt));
}

function drawPlot(plot, s, size, tStart, tEnd) {
  const canvas = plot.canvas, dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
  const ctx = canvas.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  const pw = w - MARGIN.left - MARGIN.right, ph = h - MARGIN.top - MARGIN.bottom;
  let lo = Infinity, hi = -Infinity;
  for (const c of plot.channels) {
    for (let i = 0; i < view.count; i++) {
      const a = view.min[c][i], b = view.max[c][i];
      if (isFinite(a)) lo = Math.min(lo, a);
      if (isFinite(b)) hi = Math.max(hi, b);
    }
  }
  if (!isFinite(lo)) { lo = 0; hi = 1; }
  if (hi - lo < 1e-9) { lo -= 1; hi += 1; }
  const pad = 0.05 * (hi - lo);
  lo -= pad; hi += pad;
  const X = (t) => MARGIN.left + (t - tStart) / (tEnd - tStart) * pw;
  const Y = (v) => MARGIN.top + (hi - v) / (hi - lo) * ph;
  ctx.font = "11px system-ui, sans-serif";
  ctx.strokeStyle = "#e6e9ee"; ctx.fillStyle = "#5a6372"; ctx.lineWidth = 1;
  const ys = niceStep(hi - lo, Math.max(2, Math.min(5, Math.floor(ph / 30))));
  ctx.textAlign = "right"; ctx.textBaseline = "middle";
  for (let v = Math.ceil(lo / ys) * ys; v <= hi; v += ys) {
    ctx.beginPath(); ctx.moveTo(MARGIN.left, Y(v)); ctx.lineTo(w - MARGIN.right, Y(v)); ctx.stroke();
    ctx.fillText((Math.abs(v) < ys / 1e6 ? 0 : v).toFixed(tickDecimals(ys)), MARGIN.left - 6, Y(v));
  }
  const xs = timeStep(tEnd - tStart, Math.max(2, pw / 110));
  ctx.textAlign = "center"; ctx.textBaseline = "top";
  for (let t = Math.ceil(tStart / xs) * xs; t <= tEnd; t += xs) {
    ctx.beginPath(); ctx.moveTo(X(t), MARGIN.top); ctx.lineTo(X(t), MARGIN.top + ph); ctx.stroke();
    ctx.fillText(fmtTime(t), X(t), MARGIN.top + ph + 4);
  }
  ctx.strokeStyle = "#c62828";
  for (const e of view.events) {
    if (e.kind !== "interlock" && e.kind !== "run_aborted") continue;
    if (e.time < tStart || e.time > tEnd) continue;
    ctx.beginPath(); ctx.moveTo(X(e.time), MARGIN.top); ctx.lineTo(X(e.time), MARGIN.top + ph); ctx.stroke();
  }
  ctx.save();
  ctx.beginPath(); ctx.rect(MARGIN.left, MARGIN.top, pw, ph); ctx.clip();
  const step = size * s.dt;
  for (const c of plot.channels) {
    ctx.strokeStyle = COLORS[c % COLORS.length]; ctx.lineWidth = 1.2;
    ctx.beginPath();
    let open = false;
    for (let i = 0; i < view.count; i++) {
      const a = view.min[c][i], b = view.max[c][i];
      if (!isFinite(a) || !isFinite(b)) { open = false; continue; }
      const x = X(s.t0 + (view.first + i) * step + step / 2);
      if (open) ctx.lineTo(x, Y(b)); else ctx.moveTo(x, Y(b));
      ctx.lineTo(x, Y(a));
      open = true;
    }
    ctx.stroke();
  }
  ctx.restore();
}

function renderEvents() {
  $("event-count").textContent = String(view.events.length);
  const last = view.events.slice(-60).reverse();
  $("events").innerHTML = last.map((e) => {
    const cls = ALARM.test(e.kind) ? "alarm" : e.kind === "interlock_cleared" ? "ok" : "";
    return `<tr class="${cls}"><td>${fmtTime(e.time)}</td><td>${e.cycle >= 0 ? e.cycle + 1 : ""}</td>` +
      `<td>${e.step >= 0 ? e.step + 1 : ""}</td><td>${esc(e.kind)}</td><td>${esc(e.detail)}</td></tr>`;
  }).join("");
}

document.querySelectorAll("#spans button").forEach((button) => button.addEventListener("click", () => {
  document.querySelectorAll("#spans button").forEach((b) => b.classList.toggle("on", b === button));
  view.span = Number(button.dataset.span);
  view.level = null;
  poll();
}));
window.addEventListener("resize", () => { if (view.status) renderPlots(view.status); });
poll();
