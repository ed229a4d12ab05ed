// Live scope (uPlot): every sample of the scope channel, a rolling window, pause, drag-zoom,
// cursor readout (the legend), export of the visible window as CSV or PNG.
const CAP = 120000;  // 2 min at 1 kHz
export const SCOPE_SERIES = [
  { name: 'true_error_um', label: 'contour error, true (µm)', scale: 'um', color: '#ff5a5a', on: true },
  { name: 'model_error_um', label: 'contour error, model (µm)', scale: 'um', color: '#ffb13b', on: true },
  { name: 'ferr_x_um', label: 'following error X (µm)', scale: 'um', color: '#4aa3ff', on: false },
  { name: 'ferr_y_um', label: 'following error Y (µm)', scale: 'um', color: '#43d18a', on: false },
  { name: 'ferr_z_um', label: 'following error Z (µm)', scale: 'um', color: '#c97dff', on: false },
  { name: 'path_velocity_mm_min', label: 'path velocity (mm/min)', scale: 'mm/min', color: '#d9e1ea', on: true },
  { name: 'force_n', label: 'cutting force (N)', scale: 'N', color: '#8fe3e0', on: false },
  { name: 'lateness_us', label: 'loop lateness (µs)', scale: 'us', color: '#f27ad6', on: false },
];

export class Scope {
  constructor(el, legendOpts = {}) {
    this.el = el;
    this.windowS = 5;
    this.paused = false;
    this.len = 0;
    this.head = 0;
    this.x = new Float64Array(CAP);
    this.cols = SCOPE_SERIES.map(() => new Float64Array(CAP));
    // byJob: samples of each job while it ran (in_program), what the browser tests count.
    this.stats = { samples: 0, batches: 0, dropped: 0, daemon_dropped: 0, gaps: 0, byJob: {} };
    this.dirty = false;
    const series = [{ label: 't (s)', value: (u, v) => (v == null ? '—' : v.toFixed(3)) }];
    for (const s of SCOPE_SERIES) {
      series.push({ label: s.label, scale: s.scale, stroke: s.color, width: 1, show: s.on,
        value: (u, v) => (v == null ? '—' : v.toFixed(s.scale === 'mm/min' ? 0 : 2)) });
    }
    const rect = el.getBoundingClientRect();
    this.u = new uPlot({
      width: Math.max(400, rect.width || 900), height: 380,
      series,
      scales: { x: { time: false } },
      axes: [
        { stroke: '#9aa7b5', grid: { stroke: '#1f2a36' }, label: 't (s)' },
        { scale: 'um', stroke: '#9aa7b5', grid: { stroke: '#1f2a36' }, label: 'µm' },
        { scale: 'mm/min', side: 1, stroke: '#9aa7b5', grid: { show: false }, label: 'mm/min' },
      ],
      cursor: { drag: { x: true, y: false }, sync: { key: 'scope' } },
      hooks: { setSelect: [() => { this.setPaused(true); }] },
      legend: { live: true, ...legendOpts },
    }, this.data(), el);
    setInterval(() => this.redraw(), 100);
    window.addEventListener('resize', () => this.u.setSize({ width: Math.max(400, el.getBoundingClientRect().width), height: 380 }));
  }

  push(p) {
    const n = p.cycle.length;
    this.stats.batches++;
    this.stats.samples += n;
    this.stats.dropped = p.dropped;
    this.stats.daemon_dropped = p.daemon_dropped;
    this.stats.gaps = p.gaps;
    for (let i = 0; i < n; i++) {
      const j = p.job[i];
      const running = p.signals.in_program ? p.signals.in_program[i] === 1 : true;
      if (j && running) this.stats.byJob[j] = (this.stats.byJob[j] || 0) + 1;
      const k = this.head;
      this.x[k] = p.cycle[i] / 1000;
      SCOPE_SERIES.forEach((s, si) => {
        const col = p.signals[s.name];
        const v = col ? col[i] : null;
        this.cols[si][k] = v === null || v === undefined ? NaN : v;
      });
      this.head = (k + 1) % CAP;
      this.len = Math.min(CAP, this.len + 1);
    }
    this.dirty = true;
  }

  // The last windowS seconds, in order (NaN -> null for gaps).
  data(fromS, toS) {
    const out = [[]];
    SCOPE_SERIES.forEach(() => out.push([]));
    if (this.len === 0) return out;
    const last = this.x[(this.head - 1 + CAP) % CAP];
    const lo = fromS ?? last - this.windowS, hi = toS ?? last;
    for (let i = 0; i < this.len; i++) {
      const k = (this.head - this.len + i + CAP) % CAP;
      const t = this.x[k];
      if (t < lo || t > hi) continue;
      out[0].push(t);
      for (let s = 0; s < SCOPE_SERIES.length; s++) {
        const v = this.cols[s][k];
        out[s + 1].push(Number.isFinite(v) ? v : null);
      }
    }
    return out;
  }

  redraw() {
    if (this.paused || !this.dirty || document.hidden) return;
    this.dirty = false;
    this.u.setData(this.data());
  }

  setPaused(p) {
    this.paused = p;
    if (!p) { this.dirty = true; this.redraw(); }
    if (this.onPause) this.onPause(p);
  }

  show(name, on) {
    const i = SCOPE_SERIES.findIndex((s) => s.name === name);
    if (i >= 0) this.u.setSeries(i + 1, { show: on });
  }

  visibleCsv() {
    const lo = this.u.scales.x.min, hi = this.u.scales.x.max;
    const d = this.data(lo, hi);
    const rows = [['t_s', ...SCOPE_SERIES.map((s) => s.name)].join(',')];
    for (let i = 0; i < d[0].length; i++) {
      rows.push(d.map((col) => (col[i] === null ? '' : col[i])).join(','));
    }
    return rows.join('\n') + '\n';
  }

  visiblePng() { return this.u.ctx.canvas.toDataURL('image/png'); }
}
