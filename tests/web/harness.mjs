// Shared pieces of the browser tests (tests/web/*.test.mjs): contourd on config/sim.yaml and
// contour-web as child processes, Debian's chromium driven by puppeteer-core, a direct JSON-lines
// client of contourd's socket (to see the daemon's state independently of the page), screenshots
// into the build tree. A test that cannot run here exits 77 with the reason (ctest: skipped).
import { spawn, execFileSync } from 'node:child_process';
import fs from 'node:fs';
import net from 'node:net';
import os from 'node:os';
import path from 'node:path';
import { createRequire } from 'node:module';

export const SRC = process.env.CONTOUR_SOURCE_DIR || path.resolve(path.dirname(new URL(import.meta.url).pathname), '../..');
export const BUILD = process.env.CONTOUR_BINARY_DIR || path.join(SRC, 'build/ci');
export const CONTOURD = process.env.CONTOURD || path.join(BUILD, 'daemon/contourd');
export const CONTOUR_WEB = process.env.CONTOUR_WEB || path.join(BUILD, 'tools/contour-web/contour-web');
export const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';
export const ARTIFACTS = process.env.CONTOUR_WEB_ARTIFACTS || path.join(BUILD, 'tests/web/artifacts');
export const TABLE2 = path.join(SRC, 'config/programs/table2.ngc');

export function skip(reason) {
  console.log(`SKIPPED: ${reason}`);
  process.exit(77);
}

// puppeteer-core from tests/web/node_modules (tools/deps.d/web.sh), or skip.
export function loadPuppeteer() {
  for (const [what, p] of [['chromium', CHROMIUM], ['contourd', CONTOURD], ['contour-web', CONTOUR_WEB]]) {
    if (!fs.existsSync(p)) skip(`${what} not found at ${p} (tools/deps.sh installs chromium; build contourd and contour-web)`);
  }
  const require = createRequire(path.join(SRC, 'tests/web/package.json'));
  try {
    return require('puppeteer-core');
  } catch {
    skip('puppeteer-core is not installed in tests/web/node_modules (run tools/deps.sh: tools/deps.d/web.sh)');
  }
  return null;
}

let failures = 0;
export function check(cond, what) {
  if (cond) {
    console.log(`ok   ${what}`);
  } else {
    failures++;
    console.log(`FAIL ${what}`);
  }
  return cond;
}
export function done() {
  console.log(failures === 0 ? 'web test: all checks passed' : `web test: ${failures} check(s) failed`);
  process.exit(failures === 0 ? 0 : 1);
}

export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

const children = [];
function cleanup() {
  for (const c of children) { try { c.kill('SIGKILL'); } catch { /* gone */ } }
}
process.on('exit', cleanup);
for (const sig of ['SIGINT', 'SIGTERM']) process.on(sig, () => { cleanup(); process.exit(1); });

async function waitFor(pred, timeoutMs, what) {
  const until = Date.now() + timeoutMs;
  for (;;) {
    const v = await pred();
    if (v) return v;
    if (Date.now() > until) throw new Error(`timed out after ${timeoutMs} ms waiting for ${what}`);
    await sleep(20);
  }
}
export { waitFor };

// contourd on config/sim.yaml (or `config`) with its socket in a fresh directory.
export async function startDaemon(tag, config = path.join(SRC, 'config/sim.yaml')) {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), `contour-web-${tag}-`));
  const sock = path.join(dir, 'contourd.sock');
  const log = fs.openSync(path.join(dir, 'contourd.log'), 'w');
  const p = spawn(CONTOURD, ['--config', config, '--socket', sock], { stdio: ['ignore', log, log], env: { ...process.env, XDG_RUNTIME_DIR: dir } });
  children.push(p);
  const d = { proc: p, dir, sock, log: () => fs.readFileSync(path.join(dir, 'contourd.log'), 'utf8') };
  await waitFor(async () => fs.existsSync(sock) && (await tryStatus(sock)), 20000, 'contourd to answer status');
  await waitFor(async () => (await tryStatus(sock))?.state === 'READY', 20000, 'contourd READY');
  return d;
}

async function tryStatus(sock) {
  try {
    const c = await DaemonClient.open(sock);
    const r = await c.call({ cmd: 'status' });
    c.close();
    return r.ok ? r.result : null;
  } catch { return null; }
}

// contour-web on a free port; resolves with {url, port, proc, log()}.
export async function startWeb(sock, extraArgs = [], { config } = {}) {
  const args = ['--socket', sock, '--listen', '127.0.0.1:0', ...extraArgs];
  if (config) args.push('--config', config);
  const p = spawn(CONTOUR_WEB, args, { stdio: ['ignore', 'pipe', 'pipe'] });
  children.push(p);
  let out = '';
  p.stdout.on('data', (b) => { out += b; });
  p.stderr.on('data', (b) => { out += b; });
  const m = await waitFor(() => out.match(/serving http:\/\/127\.0\.0\.1:(\d+)\//), 15000, 'contour-web to listen')
    .catch((e) => { throw new Error(`${e.message}; its output:\n${out}`); });
  const port = Number(m[1]);
  return { proc: p, port, url: `http://127.0.0.1:${port}/`, log: () => out };
}

export async function launchBrowser(puppeteer, tag) {
  const userDir = fs.mkdtempSync(path.join(os.tmpdir(), `contour-web-chromium-${tag}-`));
  return puppeteer.launch({
    executablePath: CHROMIUM,
    headless: true,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
      '--disable-component-update', '--disable-sync', '--no-first-run', '--disable-quic',
      `--user-data-dir=${userDir}`, '--window-size=1400,1000'],
    defaultViewport: { width: 1400, height: 1000 },
    protocolTimeout: 120000,
  });
}

export async function screenshot(page, name) {
  fs.mkdirSync(ARTIFACTS, { recursive: true });
  const file = path.join(ARTIFACTS, `${name}.png`);
  await page.screenshot({ path: file });
  console.log(`screenshot ${file}`);
  return file;
}

// The page, connected, with the daemon's state shown.
export async function openPage(browser, url, hash = '') {
  const page = await browser.newPage();
  page.on('pageerror', (e) => console.log(`page error: ${e.message}`));
  await page.goto(url + hash, { waitUntil: 'load' });
  await page.waitForFunction(() => document.querySelector('#conn')?.classList.contains('up'), { timeout: 20000 });
  return page;
}

export async function pageState(page) {
  return page.$eval('#state', (e) => e.textContent);
}

// A direct JSON-lines client of contourd's socket.
export class DaemonClient {
  static open(sock) {
    return new Promise((resolve, reject) => {
      const s = net.createConnection(sock);
      s.once('connect', () => resolve(new DaemonClient(s)));
      s.once('error', reject);
    });
  }
  constructor(s) {
    this.s = s; this.buf = ''; this.id = 1; this.pending = new Map();
    s.on('data', (b) => {
      this.buf += b;
      let i;
      while ((i = this.buf.indexOf('\n')) >= 0) {
        const line = this.buf.slice(0, i); this.buf = this.buf.slice(i + 1);
        let j; try { j = JSON.parse(line); } catch { continue; }
        if (j.id !== undefined && this.pending.has(j.id)) { this.pending.get(j.id)(j); this.pending.delete(j.id); }
      }
    });
    s.on('error', () => {});
  }
  call(req) {
    const id = this.id++;
    return new Promise((resolve) => { this.pending.set(id, resolve); this.s.write(JSON.stringify({ ...req, id }) + '\n'); });
  }
  async ok(req) {
    const r = await this.call(req);
    if (!r.ok) throw new Error(`${req.cmd}: ${r.error}`);
    return r.result;
  }
  close() { this.s.destroy(); }
}

// Polls contourd's state every ~2 ms from its own connection; resolves with the ms from `t0` to
// the first status in `want` (or null after timeoutMs).
export async function timeToState(client, want, t0, timeoutMs = 3000) {
  const until = t0 + timeoutMs;
  while (Date.now() < until) {
    const st = await client.ok({ cmd: 'status' });
    if (want.includes(st.state)) return Date.now() - t0;
    await sleep(2);
  }
  return null;
}

export function gitVersionOf(p) {
  try { return execFileSync(p, ['--version']).toString().trim(); } catch { return '?'; }
}
