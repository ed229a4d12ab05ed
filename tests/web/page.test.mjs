// Browser test (issue 21): the page loads, connects and shows READY; an invalid gain shows the
// daemon's refusal word for word; a viewer token cannot command; a cross-origin WebSocket (and a
// DNS-rebinding Host) is refused; screenshots of each view go to the build tree.
import fs from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import * as h from './harness.mjs';

const puppeteer = h.loadPuppeteer();
const d = await h.startDaemon('page');
const w = await h.startWeb(d.sock);
const browser = await h.launchBrowser(puppeteer, 'page');
const direct = await h.DaemonClient.open(d.sock);

try {
  // --- loads, connects, READY ---------------------------------------------------------------------
  const page = await h.openPage(browser, w.url);
  await page.waitForFunction(() => document.querySelector('#state').textContent === 'READY', { timeout: 15000 })
    .catch(() => {});
  h.check((await h.pageState(page)) === 'READY', 'page shows READY');
  h.check(await page.$eval('#conn', (e) => e.textContent === 'connected'), 'page says connected');
  h.check(await page.$eval('#estop', (e) => !e.disabled && e.getBoundingClientRect().top < 80),
    'E-stop button enabled, at the top of the page');
  const dro = await page.$$eval('#dro tbody tr', (rows) => rows.length);
  h.check(dro === 3, `DRO shows 3 axes (${dro})`);
  await h.screenshot(page, 'view-operate');

  // --- an invalid gain: the daemon's refusal, word for word ----------------------------------------
  const theirs = await direct.call({ cmd: 'gains', set: { kp: [-1, 0.6, 0.6] } });
  h.check(theirs.ok === false && theirs.error, `contourd refuses kp -1 (${theirs.error})`);
  await page.click('button[data-view=tuning]');
  await page.waitForSelector('#gains-table input[data-gain=kp]', { timeout: 10000 });
  // Typed and entered in one step: the view's own gains refresh may replace the table between two
  // puppeteer calls (seen under load: the fresh input's 0.6 was entered, "kp set").
  await page.$eval('#gains-table input[data-gain=kp]', (e) => {
    e.focus();
    e.value = '-1, 0.6, 0.6';
    e.dispatchEvent(new KeyboardEvent('keydown', { key: 'Enter', bubbles: true }));
  });
  await page.waitForFunction(() => document.querySelector('#gains-msg').textContent.startsWith('refused'), { timeout: 10000 })
    .catch(() => {});
  const shown = await page.$eval('#gains-msg', (e) => e.textContent);
  h.check(shown === `refused: ${theirs.error}`, `page shows the daemon's refusal: "${shown}"`);
  const after = await direct.ok({ cmd: 'gains' });
  h.check(Array.isArray(after.kp) && after.kp[0] > 0, `gains unchanged (kp ${JSON.stringify(after.kp)})`);
  await h.sleep(1200);  // the latency histogram redraws once a second
  await h.screenshot(page, 'view-tuning');
  await page.click('button[data-view=scope]');
  await h.sleep(800);
  await h.screenshot(page, 'view-scope');
  await page.click('button[data-view=events]');
  await h.sleep(300);
  await h.screenshot(page, 'view-events');

  // --- cross-origin and DNS rebinding ------------------------------------------------------------
  const upgrade = (headers) => new Promise((resolve) => {
    const req = http.request({ host: '127.0.0.1', port: w.port, path: '/ws', headers: {
      Connection: 'Upgrade', Upgrade: 'websocket', 'Sec-WebSocket-Version': '13',
      'Sec-WebSocket-Key': 'dGhlIHNhbXBsZSBub25jZQ==', ...headers } });
    req.on('upgrade', (res, sock) => { sock.destroy(); resolve(101); });
    req.on('response', (res) => { res.resume(); resolve(res.statusCode); });
    req.on('error', () => resolve(-1));
    req.end();
  });
  const host = `127.0.0.1:${w.port}`;
  h.check(await upgrade({ Host: host, Origin: `http://${host}` }) === 101, 'same-origin WebSocket accepted');
  h.check(await upgrade({ Host: host, Origin: 'http://evil.example' }) === 403, 'cross-origin WebSocket refused (403)');
  h.check(await upgrade({ Host: `evil.example:${w.port}`, Origin: `http://evil.example:${w.port}` }) === 421,
    'DNS-rebinding Host refused (421)');
  // From a real page: the page at 127.0.0.1 opening a socket to localhost is cross-origin.
  const fromPage = await page.evaluate((port) => new Promise((resolve) => {
    const ws = new WebSocket(`ws://localhost:${port}/ws`);
    ws.onopen = () => { ws.close(); resolve('open'); };
    ws.onerror = () => resolve('refused');
  }), w.port);
  h.check(fromPage === 'refused', `a browser's cross-origin WebSocket is refused (${fromPage})`);
  await page.close();

  // --- tokens and roles ------------------------------------------------------------------------------
  const cfgDir = fs.mkdtempSync(path.join(os.tmpdir(), 'contour-web-tokens-'));
  const cfg = path.join(cfgDir, 'web.yaml');
  // sim.yaml's machine logic names its programs relative to config/: made absolute for the copy.
  const simYaml = fs.readFileSync(path.join(h.SRC, 'config/sim.yaml'), 'utf8')
    .replaceAll('{file: plc/', `{file: ${path.join(h.SRC, 'config/plc')}/`);
  fs.writeFileSync(cfg, `${simYaml}
web:
  tokens:
    - {name: shop, role: operator, token: operator-token-0123456789}
    - {name: office, role: viewer, token: viewer-token-0123456789}
`);
  const wt = await h.startWeb(d.sock, [], { config: cfg });
  h.check(!wt.log().includes('viewer-token-0123456789') && !wt.log().includes('operator-token-0123456789'),
    'tokens never appear in contour-web\'s log');
  const anon = await browser.newPage();
  await anon.goto(wt.url, { waitUntil: 'load' });
  await anon.waitForFunction(() => !document.querySelector('#login').hidden, { timeout: 10000 }).catch(() => {});
  h.check(await anon.$eval('#login', (e) => !e.hidden), 'without a token the page asks for one');
  await anon.type('#login-token', 'not-the-token-at-all');
  await anon.click('#btn-login');
  await anon.waitForFunction(() => /invalid token/.test(document.querySelector('#login-msg').textContent), { timeout: 5000 }).catch(() => {});
  h.check(/invalid token/.test(await anon.$eval('#login-msg', (e) => e.textContent)), 'a wrong token is refused');
  await h.screenshot(anon, 'view-login');
  await anon.close();

  const viewer = await h.openPage(browser, wt.url, '#token=viewer-token-0123456789');
  await viewer.waitForFunction(() => window.contourWeb.state.role === 'viewer', { timeout: 10000 }).catch(() => {});
  h.check(await viewer.evaluate(() => window.contourWeb.state.role) === 'viewer', 'viewer token: role viewer');
  await viewer.waitForFunction(() => document.querySelector('#state').textContent === 'READY', { timeout: 10000 }).catch(() => {});
  h.check((await h.pageState(viewer)) === 'READY', 'viewer sees the status');
  const cycles0 = (await direct.ok({ cmd: 'status' })).timing.cycles;
  for (const [method, params] of [['jog', { axis: 'X', velocity_mm_min: 500, distance_mm: 5 }],
    ['run', { program: 'G1 X1 F100\n' }], ['estop', {}], ['override', { percent: 50 }], ['gains', { set: { cp: 10 } }]]) {
    const r = await viewer.evaluate((m, p) => window.contourWeb.rpc.call(m, p).then(() => 'accepted', (e) => `${e.code} ${e.message}`), method, params);
    h.check(/^-32003 forbidden/.test(r), `viewer cannot ${method}: ${r}`);
  }
  const q = await viewer.evaluate(() => window.contourWeb.rpc.call('gains').then((g) => typeof g.kp, (e) => e.message));
  h.check(q === 'object', `viewer may read the gains (${q})`);
  const st = await direct.ok({ cmd: 'status' });
  h.check(st.state === 'READY' && !st.jogging && st.feed_override === 1 && st.act_mm[0] === 0,
    `the daemon did nothing for the viewer (state ${st.state}, jogging ${st.jogging}, override ${st.feed_override}, cycles advanced ${st.timing.cycles - cycles0})`);
  await viewer.close();
  const op = await h.openPage(browser, wt.url, '#token=operator-token-0123456789');
  await op.waitForFunction(() => window.contourWeb.state.role === 'operator', { timeout: 10000 }).catch(() => {});
  const r = await op.evaluate(() => window.contourWeb.rpc.call('override', { percent: 90 }).then((x) => JSON.stringify(x), (e) => e.message));
  h.check(/feed_override_percent/.test(r), `operator token may command (${r})`);
  await op.close();
} catch (e) {
  h.check(false, `exception: ${e.stack}`);
  console.log(w.log());
} finally {
  direct.close();
  await browser.close();
}
h.done();
