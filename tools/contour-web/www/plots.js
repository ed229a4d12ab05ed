// Small canvas plots: the circle test's polar plot and the loop-lateness histogram.
export function drawPolar(canvas, samples, radius, info) {
  const ctx = canvas.getContext('2d');
  const w = canvas.width, h = canvas.height, R = Math.min(w, h) * 0.36, cx = w / 2, cy = h / 2;
  ctx.fillStyle = '#10151c'; ctx.fillRect(0, 0, w, h);
  ctx.strokeStyle = '#2c3846';
  for (const f of [0.6, 1.4]) { ctx.beginPath(); ctx.arc(cx, cy, R * f, 0, 2 * Math.PI); ctx.stroke(); }
  ctx.fillStyle = '#9aa7b5'; ctx.font = '12px sans-serif';
  if (!samples.length) { ctx.fillText('no circle run yet', 10, 20); return null; }
  let maxDev = 0, minDev = Infinity, maxD = -Infinity;
  const devs = samples.map(([x, y]) => {
    const d = (Math.hypot(x, y) - radius) * 1000;  // um
    maxDev = Math.max(maxDev, Math.abs(d)); minDev = Math.min(minDev, d); maxD = Math.max(maxD, d);
    return [Math.atan2(y, x), d];
  });
  const scaleUm = Math.max(1, maxDev);
  const gain = (R * 0.4) / scaleUm;  // the largest deviation shows as 40 % of the radius
  ctx.strokeStyle = '#55606e'; ctx.beginPath(); ctx.arc(cx, cy, R, 0, 2 * Math.PI); ctx.stroke();
  ctx.strokeStyle = '#ff5a5a'; ctx.lineWidth = 1.5; ctx.beginPath();
  devs.forEach(([t, d], i) => {
    const r = R + d * gain;
    const x = cx + r * Math.cos(t), y = cy - r * Math.sin(t);
    if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y);
  });
  ctx.stroke(); ctx.lineWidth = 1;
  ctx.fillStyle = '#d9e1ea';
  ctx.fillText(`R ${radius} mm, radial deviation scale ±${scaleUm.toFixed(1)} µm = 40 % of R`, 10, 18);
  ctx.fillText(`deviation ${minDev.toFixed(1)} … ${maxD.toFixed(1)} µm, roundness ${(maxD - minDev).toFixed(1)} µm`, 10, 34);
  if (info) ctx.fillText(info, 10, h - 10);
  return { min_um: minDev, max_um: maxD, roundness_um: maxD - minDev };
}

export function drawHistogram(canvas, hist, title) {
  const ctx = canvas.getContext('2d');
  const w = canvas.width, h = canvas.height, m = 34;
  ctx.fillStyle = '#10151c'; ctx.fillRect(0, 0, w, h);
  ctx.fillStyle = '#9aa7b5'; ctx.font = '12px sans-serif';
  if (!hist || !hist.bin_low_us || hist.bin_low_us.length === 0) { ctx.fillText('no lateness histogram in the status yet', 10, 20); return; }
  const lows = hist.bin_low_us, counts = hist.count;
  const maxX = Math.max(...lows) + 1, maxC = Math.max(...counts);
  const lx = (v) => m + (Math.log10(1 + v) / Math.log10(1 + maxX)) * (w - 2 * m);
  const ly = (c) => h - m - (Math.log10(1 + c) / Math.log10(1 + maxC)) * (h - 2 * m);
  ctx.fillStyle = '#4aa3ff';
  for (let i = 0; i < lows.length; i++) {
    const x0 = lx(lows[i]), x1 = Math.max(x0 + 1, lx(lows[i] + 1));
    ctx.fillRect(x0, ly(counts[i]), x1 - x0, h - m - ly(counts[i]));
  }
  ctx.strokeStyle = '#55606e'; ctx.beginPath(); ctx.moveTo(m, h - m); ctx.lineTo(w - m, h - m); ctx.stroke();
  ctx.fillStyle = '#9aa7b5';
  for (const t of [0, 10, 100, 1000, 10000]) if (t <= maxX) { ctx.fillText(`${t}`, lx(t) - 6, h - m + 14); }
  ctx.fillText('wake-up lateness (µs, log)', w / 2 - 70, h - 6);
  ctx.fillText(title || '', m, 16);
}
