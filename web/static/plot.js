// Joint positions over a sliding time window, drawn on a 2D canvas (no library needed).
const COLORS = ["#f85149", "#d29922", "#3fb950", "#4493f8", "#a371f7", "#39c5cf"];

export class JointPlot {
  constructor(canvas, windowS = 10) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.windowS = windowS;
    this.samples = []; // [t_s, [deg...]]
    this.dirty = false;
    const tick = () => { if (this.dirty) this.draw(); requestAnimationFrame(tick); };
    requestAnimationFrame(tick);
  }

  push(stampNs, positionsRad) {
    const t = stampNs / 1e9;
    this.samples.push([t, positionsRad.map((q) => (q * 180) / Math.PI)]);
    const cutoff = t - this.windowS;
    while (this.samples.length && this.samples[0][0] < cutoff) this.samples.shift();
    this.dirty = true;
  }

  draw() {
    this.dirty = false;
    const { canvas, ctx } = this;
    const dpr = window.devicePixelRatio || 1;
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (canvas.width !== Math.round(w * dpr)) { canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr); }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, w, h);
    if (this.samples.length < 2) return;
    const tEnd = this.samples[this.samples.length - 1][0];
    const tStart = tEnd - this.windowS;
    let lo = Infinity, hi = -Infinity;
    for (const [, qs] of this.samples) for (const q of qs) { lo = Math.min(lo, q); hi = Math.max(hi, q); }
    if (hi - lo < 10) { const m = (hi + lo) / 2; lo = m - 5; hi = m + 5; }
    const pad = 18;
    const x = (t) => pad + ((t - tStart) / this.windowS) * (w - pad - 4);
    const y = (q) => h - 12 - ((q - lo) / (hi - lo)) * (h - 24);
    ctx.strokeStyle = "#2c3440"; ctx.lineWidth = 1;
    ctx.fillStyle = "#8b96a5"; ctx.font = "10px system-ui";
    for (const q of [lo, (lo + hi) / 2, hi]) {
      ctx.beginPath(); ctx.moveTo(pad, y(q)); ctx.lineTo(w, y(q)); ctx.stroke();
      ctx.fillText(q.toFixed(0), 0, y(q) + 3);
    }
    const n = this.samples[0][1].length;
    for (let j = 0; j < n; j++) {
      ctx.strokeStyle = COLORS[j % COLORS.length]; ctx.lineWidth = 1.5;
      ctx.beginPath();
      this.samples.forEach(([t, qs], i) => (i ? ctx.lineTo(x(t), y(qs[j])) : ctx.moveTo(x(t), y(qs[j]))));
      ctx.stroke();
    }
    ctx.fillText(`last ${this.windowS} s, degrees`, w - 110, 10);
  }
}

export { COLORS };
