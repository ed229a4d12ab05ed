// Toolpath view on a canvas: the loaded program's path (gcode.js), the executed path on top
// coloured by the true contour error (scope samples), the current position, and the blend
// corners' largest errors on hover. Views: XY, XZ, YZ and a 3-D orthographic view (drag to turn,
// wheel to zoom).
const MAX_POINTS = 400000;

export function errorColor(f) {
  // 0 -> blue, 0.5 -> green/yellow, 1 -> red
  const x = Math.max(0, Math.min(1, f));
  const r = Math.round(255 * Math.min(1, Math.max(0, 1.8 * x - 0.4)));
  const g = Math.round(255 * (x < 0.5 ? 0.3 + 1.2 * x : 1.6 - 1.6 * x + 0.3));
  const b = Math.round(255 * Math.max(0, 1 - 2.2 * x));
  return `rgb(${r},${Math.min(255, g)},${b})`;
}

export class Toolpath {
  constructor(canvas, tooltip, legend) {
    this.c = canvas; this.tip = tooltip; this.legend = legend;
    this.plan = null;
    this.view = 'xy';
    this.az = -0.6; this.el = 0.6; this.zoom = 1;
    this.n = 0;
    this.x = new Float32Array(MAX_POINTS); this.y = new Float32Array(MAX_POINTS);
    this.z = new Float32Array(MAX_POINTS); this.e = new Float32Array(MAX_POINTS);
    this.maxErr = 1;
    this.pos = null;
    this.pending = false;
    this.lastJob = 0;
    let drag = null;
    canvas.addEventListener('pointerdown', (ev) => { if (this.view === '3d') drag = [ev.clientX, ev.clientY, this.az, this.el]; });
    window.addEventListener('pointerup', () => { drag = null; });
    canvas.addEventListener('pointermove', (ev) => {
      if (drag) {
        this.az = drag[2] + (ev.clientX - drag[0]) * 0.01;
        this.el = Math.max(-1.5, Math.min(1.5, drag[3] + (ev.clientY - drag[1]) * 0.01));
        this.request();
      }
      this.hover(ev);
    });
    canvas.addEventListener('mouseleave', () => { this.tip.hidden = true; });
    canvas.addEventListener('wheel', (ev) => { ev.preventDefault(); this.zoom *= ev.deltaY < 0 ? 1.15 : 1 / 1.15; this.request(); }, { passive: false });
  }

  setView(v) { this.view = v; this.request(); }
  setPlan(p) { this.plan = p; this.request(); }
  clearExecuted() {
    this.n = 0; this.maxErr = 1;
    if (this.plan) for (const c of this.plan.corners) c.max_um = 0;
    this.request();
  }
  setPosition(p) { this.pos = p; this.request(); }

  // Scope columns of one notify_scope batch.
  addSamples(job, xs, ys, zs, errs, inProgram) {
    for (let i = 0; i < xs.length; i++) {
      if (!inProgram[i]) continue;
      if (job[i] !== this.lastJob) { this.lastJob = job[i]; this.clearExecuted(); }
      if (this.n >= MAX_POINTS) break;
      const e = errs[i] === null ? NaN : errs[i];
      this.x[this.n] = xs[i]; this.y[this.n] = ys[i]; this.z[this.n] = zs[i]; this.e[this.n] = e;
      this.n++;
      if (Number.isFinite(e)) {
        if (e > this.maxErr) this.maxErr = e;
        if (this.plan) {
          for (const c of this.plan.corners) {
            const d = Math.hypot(xs[i] - c.p[0], ys[i] - c.p[1], zs[i] - c.p[2]);
            if (d < 2.0 && e > c.max_um) c.max_um = e;
          }
        }
      }
    }
    this.request();
  }

  request() {
    if (this.pending) return;
    this.pending = true;
    requestAnimationFrame(() => { this.pending = false; this.draw(); });
  }

  project(p) {
    switch (this.view) {
      case 'xz': return [p[0], p[2]];
      case 'yz': return [p[1], p[2]];
      case '3d': {
        const ca = Math.cos(this.az), sa = Math.sin(this.az), ce = Math.cos(this.el), se = Math.sin(this.el);
        const x1 = ca * p[0] - sa * p[1], y1 = sa * p[0] + ca * p[1];
        return [x1, ce * p[2] + se * y1];
      }
      default: return [p[0], p[1]];
    }
  }

  fit() {
    let minx = Infinity, miny = Infinity, maxx = -Infinity, maxy = -Infinity;
    const take = (p) => { const q = this.project(p); minx = Math.min(minx, q[0]); maxx = Math.max(maxx, q[0]); miny = Math.min(miny, q[1]); maxy = Math.max(maxy, q[1]); };
    if (this.plan) for (const m of this.plan.moves) for (const p of m.pts) take(p);
    const step = Math.max(1, Math.floor(this.n / 2000));
    for (let i = 0; i < this.n; i += step) take([this.x[i], this.y[i], this.z[i]]);
    if (this.pos) take(this.pos);
    if (!Number.isFinite(minx)) { minx = -10; maxx = 10; miny = -10; maxy = 10; }
    const w = this.c.width, h = this.c.height, m = 30;
    const sx = (w - 2 * m) / Math.max(1e-6, maxx - minx), sy = (h - 2 * m) / Math.max(1e-6, maxy - miny);
    const s = Math.min(sx, sy) * this.zoom;
    const cx = (minx + maxx) / 2, cy = (miny + maxy) / 2;
    this.tf = (p) => { const q = this.project(p); return [w / 2 + (q[0] - cx) * s, h / 2 - (q[1] - cy) * s]; };
  }

  draw() {
    const ctx = this.c.getContext('2d');
    const rect = this.c.getBoundingClientRect();
    if (rect.width > 0 && (this.c.width !== Math.round(rect.width) || this.c.height !== Math.round(rect.height))) {
      this.c.width = Math.round(rect.width); this.c.height = Math.round(rect.height);
    }
    ctx.fillStyle = '#10151c'; ctx.fillRect(0, 0, this.c.width, this.c.height);
    this.fit();
    this.axes(ctx);
    if (this.plan) {
      for (const m of this.plan.moves) {
        ctx.beginPath();
        ctx.strokeStyle = m.kind === 'rapid' ? '#55606e' : '#9aa7b5';
        ctx.setLineDash(m.kind === 'rapid' ? [4, 4] : []);
        m.pts.forEach((p, i) => { const q = this.tf(p); if (i) ctx.lineTo(q[0], q[1]); else ctx.moveTo(q[0], q[1]); });
        ctx.stroke();
      }
      ctx.setLineDash([]);
    }
    // Executed path: runs of one colour bucket drawn as one path.
    ctx.lineWidth = 2;
    let bucket = -1, started = false;
    const buckets = 16;
    for (let i = 0; i < this.n; i++) {
      const e = this.e[i];
      const b = Number.isFinite(e) ? Math.min(buckets - 1, Math.floor((e / this.maxErr) * buckets)) : -2;
      const q = this.tf([this.x[i], this.y[i], this.z[i]]);
      if (b !== bucket) {
        if (started) { ctx.lineTo(q[0], q[1]); ctx.stroke(); }
        ctx.beginPath();
        ctx.strokeStyle = b === -2 ? '#888' : errorColor((b + 0.5) / buckets);
        ctx.moveTo(q[0], q[1]);
        bucket = b; started = true;
      } else {
        ctx.lineTo(q[0], q[1]);
      }
    }
    if (started) ctx.stroke();
    ctx.lineWidth = 1;
    if (this.plan) {
      for (const c of this.plan.corners) {
        const q = this.tf(c.p);
        ctx.fillStyle = c.max_um > 0 ? errorColor(c.max_um / this.maxErr) : '#ccc';
        ctx.fillRect(q[0] - 2.5, q[1] - 2.5, 5, 5);
      }
    }
    if (this.pos) {
      const q = this.tf(this.pos);
      ctx.strokeStyle = '#ffd24a'; ctx.beginPath();
      ctx.arc(q[0], q[1], 6, 0, 2 * Math.PI); ctx.moveTo(q[0] - 10, q[1]); ctx.lineTo(q[0] + 10, q[1]);
      ctx.moveTo(q[0], q[1] - 10); ctx.lineTo(q[0], q[1] + 10); ctx.stroke();
    }
    if (this.legend) this.legend.textContent = `contour error 0 … ${this.maxErr.toFixed(1)} µm (${this.n} samples)`;
  }

  axes(ctx) {
    const o = this.tf([0, 0, 0]);
    const names = this.view === 'xz' ? ['X', 'Z'] : this.view === 'yz' ? ['Y', 'Z'] : ['X', 'Y'];
    ctx.strokeStyle = '#2c3846'; ctx.fillStyle = '#6c7a89'; ctx.font = '11px sans-serif';
    if (this.view === '3d') {
      [[10, 0, 0, 'X'], [0, 10, 0, 'Y'], [0, 0, 10, 'Z']].forEach(([x, y, z, n]) => {
        const q = this.tf([x, y, z]);
        ctx.beginPath(); ctx.moveTo(o[0], o[1]); ctx.lineTo(q[0], q[1]); ctx.stroke(); ctx.fillText(n, q[0] + 3, q[1]);
      });
    } else {
      ctx.beginPath(); ctx.moveTo(0, o[1]); ctx.lineTo(this.c.width, o[1]); ctx.moveTo(o[0], 0); ctx.lineTo(o[0], this.c.height); ctx.stroke();
      ctx.fillText(names[0], this.c.width - 14, o[1] - 4); ctx.fillText(names[1], o[0] + 4, 12);
    }
  }

  hover(ev) {
    if (!this.plan || !this.tf) return;
    const r = this.c.getBoundingClientRect();
    const mx = (ev.clientX - r.left) * (this.c.width / r.width), my = (ev.clientY - r.top) * (this.c.height / r.height);
    let best = null, bd = 12;
    for (const c of this.plan.corners) {
      const q = this.tf(c.p);
      const d = Math.hypot(q[0] - mx, q[1] - my);
      if (d < bd) { bd = d; best = c; }
    }
    if (!best) { this.tip.hidden = true; return; }
    this.tip.hidden = false;
    this.tip.style.left = `${ev.clientX - r.left + 14}px`; this.tip.style.top = `${ev.clientY - r.top + 8}px`;
    this.tip.textContent = `corner at line ${best.line} (${best.angle_deg.toFixed(0)}°): ` +
      (best.max_um > 0 ? `max contour error ${best.max_um.toFixed(2)} µm` : 'not run yet') +
      ` — X${best.p[0].toFixed(3)} Y${best.p[1].toFixed(3)} Z${best.p[2].toFixed(3)}`;
  }
}
