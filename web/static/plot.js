// Plots on 2D canvases (no library): joint positions over time, the cycle-time trend of recent picks,
// and the stage times of recent picks as stacked bars. Every plot has a labelled time axis.
const COLORS = ["#f85149", "#d29922", "#3fb950", "#4493f8", "#a371f7", "#39c5cf"];
const STAGE_COLORS = {
  DETECT: "#4493f8", PLAN: "#a371f7", APPROACH: "#39c5cf", GRASP: "#d29922", LIFT: "#3fb950",
  REORIENT: "#db61a2", TRANSPORT: "#8957e5", PLACE: "#f0883e", RELEASE: "#8b96a5", RETRY: "#f85149",
};
const AXIS = "#2c3440", LABEL = "#8b96a5";

function prepare(canvas) {
  const ctx = canvas.getContext("2d");
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
  }
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  ctx.font = "11px system-ui";
  return { ctx, w, h };
}

const clock = (ms) => new Date(ms).toLocaleTimeString([], { hour12: false });

export class JointPlot {
  constructor(canvas, windowS = 10) {
    this.canvas = canvas;
    this.windowS = windowS;
    this.samples = []; // [t_s (controller clock), [deg...]]
    this.wallAtEnd = Date.now();
    this.dirty = false;
    const tick = () => { if (this.dirty) this.draw(); requestAnimationFrame(tick); };
    requestAnimationFrame(tick);
  }

  push(stampNs, positionsRad) {
    const t = stampNs / 1e9;
    this.samples.push([t, positionsRad.map((q) => (q * 180) / Math.PI)]);
    this.wallAtEnd = Date.now();
    const cutoff = t - this.windowS;
    while (this.samples.length && this.samples[0][0] < cutoff) this.samples.shift();
    this.dirty = true;
  }

  draw() {
    this.dirty = false;
    const { ctx, w, h } = prepare(this.canvas);
    if (this.samples.length < 2) return;
    const tEnd = this.samples[this.samples.length - 1][0];
    const tStart = tEnd - this.windowS;
    let lo = Infinity, hi = -Infinity;
    for (const [, qs] of this.samples) for (const q of qs) { lo = Math.min(lo, q); hi = Math.max(hi, q); }
    if (hi - lo < 10) { const m = (hi + lo) / 2; lo = m - 5; hi = m + 5; }
    const left = 34, bottom = 18;
    const x = (t) => left + ((t - tStart) / this.windowS) * (w - left - 6);
    const y = (q) => h - bottom - ((q - lo) / (hi - lo)) * (h - bottom - 8);
    ctx.strokeStyle = AXIS; ctx.fillStyle = LABEL; ctx.lineWidth = 1;
    for (const q of [lo, (lo + hi) / 2, hi]) {
      ctx.beginPath(); ctx.moveTo(left, y(q)); ctx.lineTo(w, y(q)); ctx.stroke();
      ctx.fillText(`${q.toFixed(0)}°`, 2, y(q) + 4);
    }
    for (let s = 0; s <= this.windowS; s += 2) { // time axis: seconds before the newest state
      const t = tEnd - s;
      ctx.beginPath(); ctx.moveTo(x(t), 8); ctx.lineTo(x(t), h - bottom); ctx.stroke();
      ctx.fillText(s === 0 ? clock(this.wallAtEnd) : `−${s} s`, Math.min(x(t) - 12, w - 52), h - 4);
    }
    const n = this.samples[0][1].length;
    for (let j = 0; j < n; j++) {
      ctx.strokeStyle = COLORS[j % COLORS.length]; ctx.lineWidth = 1.5;
      ctx.beginPath();
      this.samples.forEach(([t, qs], i) => (i ? ctx.lineTo(x(t), y(qs[j])) : ctx.moveTo(x(t), y(qs[j]))));
      ctx.stroke();
    }
  }
}

// Cycle time of each recent pick against its time; failures in red.
export function drawCycleTrend(canvas, picks) {
  const { ctx, w, h } = prepare(canvas);
  const pts = picks.filter((p) => p.cycle_time != null)
    .map((p) => ({ t: new Date(p.timestamp).getTime(), c: p.cycle_time, ok: p.success }))
    .sort((a, b) => a.t - b.t);
  ctx.fillStyle = LABEL;
  if (!pts.length) { ctx.fillText("no picks yet", 10, h / 2); return 0; }
  const left = 34, bottom = 18;
  let t0 = pts[0].t, t1 = pts[pts.length - 1].t;
  if (t1 - t0 < 60000) { t0 = t1 - 60000; }
  const cmax = Math.max(5, ...pts.map((p) => p.c)) * 1.15;
  const x = (t) => left + ((t - t0) / (t1 - t0 || 1)) * (w - left - 10);
  const y = (c) => h - bottom - (c / cmax) * (h - bottom - 8);
  ctx.strokeStyle = AXIS; ctx.lineWidth = 1;
  for (const c of [0, cmax / 2, cmax]) {
    ctx.beginPath(); ctx.moveTo(left, y(c)); ctx.lineTo(w, y(c)); ctx.stroke();
    ctx.fillText(`${c.toFixed(0)} s`, 2, y(c) + 4);
  }
  for (let k = 0; k <= 3; k++) { // time axis: wall-clock times of the picks
    const t = t0 + (k / 3) * (t1 - t0);
    ctx.fillText(clock(t), Math.min(Math.max(x(t) - 24, left), w - 52), h - 4);
  }
  ctx.strokeStyle = "#4493f8"; ctx.lineWidth = 1.5; ctx.beginPath();
  pts.forEach((p, i) => (i ? ctx.lineTo(x(p.t), y(p.c)) : ctx.moveTo(x(p.t), y(p.c))));
  ctx.stroke();
  for (const p of pts) {
    ctx.fillStyle = p.ok ? "#3fb950" : "#f85149";
    ctx.beginPath(); ctx.arc(x(p.t), y(p.c), 3.5, 0, 2 * Math.PI); ctx.fill();
  }
  return pts.length;
}

// One horizontal bar per pick (newest on top), one segment per stage, seconds on the x axis.
export function drawStageBars(canvas, details) {
  const { ctx, w, h } = prepare(canvas);
  ctx.fillStyle = LABEL;
  const rows = details.filter((d) => d.stage_durations && Object.keys(d.stage_durations).length);
  if (!rows.length) { ctx.fillText("no stage times yet", 10, h / 2); return 0; }
  const left = 48, bottom = 18;
  // the legend first: the stages in the order they come, wrapped to as many lines as the width needs
  const stages = [...new Set(rows.flatMap((d) => Object.keys(d.stage_durations)))];
  const keys = [];
  let lx = left, ly = 12;
  for (const stage of stages) {
    const wd = ctx.measureText(stage.toLowerCase()).width + 24;
    if (lx + wd > w && lx > left) { lx = left; ly += 14; }
    keys.push([stage, lx, ly]);
    lx += wd;
  }
  const legend = ly + 4;
  const total = (d) => Object.values(d.stage_durations).reduce((a, b) => a + b, 0);
  const tmax = Math.max(...rows.map(total)) * 1.05;
  const bh = Math.max(2, Math.min(18, (h - bottom - legend - 4) / rows.length - 3));
  const x = (s) => left + (s / tmax) * (w - left - 8);
  ctx.strokeStyle = AXIS;
  for (let k = 0; k <= 4; k++) {
    const s = (k / 4) * tmax;
    ctx.beginPath(); ctx.moveTo(x(s), legend); ctx.lineTo(x(s), h - bottom); ctx.stroke();
    ctx.textAlign = k === 4 ? "right" : "center";
    ctx.fillText(`${s.toFixed(1)} s`, k === 4 ? w - 2 : x(s), h - 4);
  }
  ctx.textAlign = "left";
  rows.forEach((d, i) => {
    const top = legend + 4 + i * (bh + 3);
    ctx.fillStyle = LABEL; ctx.fillText(`#${d.id}`, 2, top + bh - 4);
    let s = 0;
    for (const [stage, dt] of Object.entries(d.stage_durations)) {
      ctx.fillStyle = STAGE_COLORS[stage] || "#6e7681";
      ctx.fillRect(x(s), top, Math.max(1, x(s + dt) - x(s)), bh);
      s += dt;
    }
  });
  for (const [stage, kx, ky] of keys) {
    ctx.fillStyle = STAGE_COLORS[stage] || "#6e7681"; ctx.fillRect(kx, ky - 9, 9, 9);
    ctx.fillStyle = LABEL; ctx.fillText(stage.toLowerCase(), kx + 12, ky);
  }
  return rows.length;
}

export { COLORS };
