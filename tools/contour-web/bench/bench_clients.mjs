// Benchmark (issue 21): contourd's loop wake-up lateness while Table 2 runs, without and with N
// browser clients on the 1 kHz scope (default 8). The histogram is contourd's own
// (status.timing.lateness_histogram, cumulative): each phase takes the difference of two
// snapshots, so both phases are measured in one run on one machine. Ratios are reported, never
// asserted: the VM's steal time dominates absolute figures.
//   node tools/contour-web/bench/bench_clients.mjs [--runs 3] [--clients 8] [--json FILE]
import fs from 'node:fs';
import * as h from '../../../tests/web/harness.mjs';

const arg = (k, d) => { const i = process.argv.indexOf(k); return i > 0 ? process.argv[i + 1] : d; };
const runs = Number(arg('--runs', 3));
const clients = Number(arg('--clients', 8));
const jsonOut = arg('--json', '');

function hist(st) {
  const m = new Map();
  const hh = st.timing.lateness_histogram;
  hh.bin_low_us.forEach((b, i) => m.set(b, hh.count[i]));
  return m;
}
function delta(a, b) {
  const d = [];
  for (const [k, v] of b) { const x = v - (a.get(k) || 0); if (x > 0) d.push([k, x]); }
  return d.sort((p, q) => p[0] - q[0]);
}
function summary(d) {
  const n = d.reduce((s, [, c]) => s + c, 0);
  const q = (f) => { let acc = 0; for (const [k, c] of d) { acc += c; if (acc >= f * n) return k; } return NaN; };
  const mean = d.reduce((s, [k, c]) => s + (k + 0.5) * c, 0) / Math.max(1, n);
  return { cycles: n, mean_us: mean, p50_us: q(0.5), p99_us: q(0.99), p999_us: q(0.999), max_us: d.length ? d[d.length - 1][0] : NaN };
}
function cpuSeconds(pid) {
  try {
    const f = fs.readFileSync(`/proc/${pid}/stat`, 'utf8').split(') ')[1].split(' ');
    return (Number(f[11]) + Number(f[12])) / 100;  // utime + stime, clock ticks of 10 ms
  } catch { return NaN; }
}

async function phase(direct, label, d, w) {
  const st0 = await direct.ok({ cmd: 'status' });
  const cpu0 = cpuSeconds(d.proc.pid), web0 = w ? cpuSeconds(w.proc.pid) : NaN;
  for (let i = 0; i < runs; i++) {
    await direct.ok({ cmd: 'load', path: h.TABLE2 });
    const run = await direct.ok({ cmd: 'run' });
    await h.waitFor(async () => { const st = await direct.ok({ cmd: 'status' }); return st.finished_job === run.job && st.state === 'READY'; }, 60000, 'Table 2');
    await direct.ok({ cmd: 'stop' }).catch(() => {});
    // Back to the start (the figures are not compared here: only the loop's timing).
    await direct.ok({ cmd: 'set-position', axis: 'X', position_mm: 0 });
    await direct.ok({ cmd: 'set-position', axis: 'Y', position_mm: 0 });
    await direct.ok({ cmd: 'set-position', axis: 'Z', position_mm: 0 });
  }
  const st1 = await direct.ok({ cmd: 'status' });
  const s = summary(delta(hist(st0), hist(st1)));
  s.overruns = st1.timing.overruns - st0.timing.overruns;
  s.contourd_cpu_s = cpuSeconds(d.proc.pid) - cpu0;
  s.contour_web_cpu_s = w ? cpuSeconds(w.proc.pid) - web0 : NaN;
  s.telemetry_dropped = st1.telemetry_dropped;
  console.log(`${label}: ${JSON.stringify(s)}`);
  return s;
}

const puppeteer = h.loadPuppeteer();
const d = await h.startDaemon('bench');
const w = await h.startWeb(d.sock);
const direct = await h.DaemonClient.open(d.sock);
const without = await phase(direct, `Table 2 x${runs}, no browser clients`, d, w);
const browser = await h.launchBrowser(puppeteer, 'bench');
const pages = [];
for (let i = 0; i < clients; i++) {
  const p = await h.openPage(browser, w.url);
  await p.click('button[data-view=scope]');
  pages.push(p);
}
const withc = await phase(direct, `Table 2 x${runs}, ${clients} browser clients on the scope`, d, w);
let received = 0;
for (const p of pages) received += await p.evaluate(() => window.contourWeb.scope.stats.samples);
await browser.close();
direct.close();
const ratio = {};
for (const k of ['mean_us', 'p50_us', 'p99_us', 'p999_us', 'max_us']) ratio[k] = withc[k] / Math.max(1e-9, without[k]);
console.log(`lateness ratio with/without ${clients} clients: ${JSON.stringify(Object.fromEntries(Object.entries(ratio).map(([k, v]) => [k, Number(v.toFixed(2))])))}`);
console.log(`scope samples received by the ${clients} clients: ${received}`);
if (jsonOut) fs.writeFileSync(jsonOut, JSON.stringify({ runs, clients, without, with: withc, ratio, received }, null, 2));
process.exit(0);
