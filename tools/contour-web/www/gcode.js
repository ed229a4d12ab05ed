// A small RS274 reader for the page's preview: G0/G1/G2/G3 (XY, XZ, YZ planes via G17/18/19,
// I/J/K centres or R), G20/G21, G90/G91, F. It draws what the program asks for; contourd's
// planner (blend corners, look-ahead) is the authority and checks the program on `load`.
// Returns {moves: [{kind: 'rapid'|'feed', line, pts: [[x,y,z], ...]}], corners, extents, length_mm, blocks}.
export function parseGcode(text, start = [0, 0, 0]) {
  const pos = start.slice();
  let absolute = true, inch = false, plane = 17, motion = 0;
  const moves = [];
  let blocks = 0, length = 0;
  const lines = text.split(/\r?\n/);
  for (let li = 0; li < lines.length; li++) {
    let l = lines[li].replace(/\(.*?\)/g, '').replace(/;.*$/, '').toUpperCase();
    if (!l.trim()) continue;
    const words = {};
    const gs = [];
    for (const m of l.matchAll(/([A-Z])\s*([-+]?\d*\.?\d+)/g)) {
      const k = m[1], v = parseFloat(m[2]);
      if (k === 'G') gs.push(v); else words[k] = v;
    }
    for (const g of gs) {
      if (g === 20) inch = true; else if (g === 21) inch = false;
      else if (g === 90) absolute = true; else if (g === 91) absolute = false;
      else if (g === 17 || g === 18 || g === 19) plane = g;
      else if (g === 0 || g === 1 || g === 2 || g === 3) motion = g;
    }
    const s = inch ? 25.4 : 1;
    const has = 'X' in words || 'Y' in words || 'Z' in words;
    if (!has) continue;
    const tgt = pos.slice();
    ['X', 'Y', 'Z'].forEach((a, i) => {
      if (a in words) tgt[i] = absolute ? words[a] * s : pos[i] + words[a] * s;
    });
    blocks++;
    const line = li + 1;
    if (motion === 2 || motion === 3) {
      const pts = arc(pos, tgt, words, s, plane, motion === 2);
      for (let i = 1; i < pts.length; i++) length += dist(pts[i - 1], pts[i]);
      moves.push({ kind: 'feed', line, pts });
    } else {
      length += motion === 0 ? 0 : dist(pos, tgt);
      moves.push({ kind: motion === 0 ? 'rapid' : 'feed', line, pts: [pos.slice(), tgt.slice()] });
    }
    pos[0] = tgt[0]; pos[1] = tgt[1]; pos[2] = tgt[2];
  }
  // Blend corners: joins of consecutive feed moves that change direction by more than 1 degree.
  const corners = [];
  for (let i = 1; i < moves.length; i++) {
    const a = moves[i - 1], b = moves[i];
    if (a.kind !== 'feed' || b.kind !== 'feed') continue;
    const p0 = a.pts[a.pts.length - 2], p1 = a.pts[a.pts.length - 1], p2 = b.pts[1];
    const u = sub(p1, p0), v = sub(p2, p1);
    const nu = norm(u), nv = norm(v);
    if (nu < 1e-9 || nv < 1e-9) continue;
    const c = (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]) / (nu * nv);
    if (c < Math.cos(Math.PI / 180)) corners.push({ p: p1.slice(), line: b.line, angle_deg: Math.acos(Math.max(-1, Math.min(1, c))) * 180 / Math.PI, max_um: 0 });
  }
  const ext = { min: [Infinity, Infinity, Infinity], max: [-Infinity, -Infinity, -Infinity] };
  for (const m of moves) for (const p of m.pts) for (let i = 0; i < 3; i++) {
    ext.min[i] = Math.min(ext.min[i], p[i]); ext.max[i] = Math.max(ext.max[i], p[i]);
  }
  return { moves, corners, extents: ext, length_mm: length, blocks };
}

function arc(p0, p1, w, s, plane, cw) {
  const [a, b, c] = plane === 17 ? [0, 1, 2] : plane === 18 ? [2, 0, 1] : [1, 2, 0];
  const off = plane === 17 ? ['I', 'J'] : plane === 18 ? ['K', 'I'] : ['J', 'K'];
  let ca, cb;
  if ('R' in w) {
    const r = w.R * s;
    const dx = p1[a] - p0[a], dy = p1[b] - p0[b];
    const d = Math.hypot(dx, dy);
    const h = Math.sqrt(Math.max(0, r * r - d * d / 4)) * ((cw ? -1 : 1) * (r < 0 ? -1 : 1));
    ca = p0[a] + dx / 2 - h * dy / d; cb = p0[b] + dy / 2 + h * dx / d;
  } else {
    ca = p0[a] + (w[off[0]] || 0) * s; cb = p0[b] + (w[off[1]] || 0) * s;
  }
  const r = Math.hypot(p0[a] - ca, p0[b] - cb);
  let t0 = Math.atan2(p0[b] - cb, p0[a] - ca), t1 = Math.atan2(p1[b] - cb, p1[a] - ca);
  let sweep = t1 - t0;
  if (cw && sweep >= -1e-9) sweep -= 2 * Math.PI;
  if (!cw && sweep <= 1e-9) sweep += 2 * Math.PI;
  const n = Math.max(8, Math.ceil(Math.abs(sweep) * r / 0.5));
  const pts = [];
  for (let i = 0; i <= Math.min(n, 2000); i++) {
    const f = i / Math.min(n, 2000), t = t0 + sweep * f;
    const p = [0, 0, 0];
    p[a] = ca + r * Math.cos(t); p[b] = cb + r * Math.sin(t); p[c] = p0[c] + (p1[c] - p0[c]) * f;
    pts.push(p);
  }
  return pts;
}
const sub = (p, q) => [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
const norm = (v) => Math.hypot(v[0], v[1], v[2]);
const dist = (p, q) => norm(sub(p, q));
