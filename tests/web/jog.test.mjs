// Browser test (issue 21): the jog pad's dead-man. A long jog (100 mm at 600 mm/min, ~10 s) held
// from the page stops (a) when the button is released, (b) when the browser is killed mid-jog,
// (c) when a connected client goes silent for web.jog_deadman_ms. The daemon's own status says
// when the jog ended (polled over a separate socket connection); times are printed, not asserted
// tightly (the axis must stop well before the jog's own end).
import * as h from './harness.mjs';

const puppeteer = h.loadPuppeteer();
const d = await h.startDaemon('jog');
const w = await h.startWeb(d.sock);
const direct = await h.DaemonClient.open(d.sock);
const kJogS = 10;  // the jog's own duration: 100 mm at 600 mm/min

async function jogging() {
  const st = await direct.ok({ cmd: 'status' });
  return { jogging: st.jogging, x: st.act_mm[0], state: st.state };
}
async function waitJogging(want, ms) {
  return h.waitFor(async () => ((await jogging()).jogging === want ? true : null), ms, `jogging ${want}`);
}
async function hold(page, selector) {
  const b = await page.$(selector);
  const box = await b.boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
}

let browser = null;
try {
  // (a) release
  browser = await h.launchBrowser(puppeteer, 'jog-a');
  let page = await h.openPage(browser, w.url);
  await page.waitForFunction(() => document.querySelector('#state').textContent === 'READY', { timeout: 15000 });
  await hold(page, 'button.jog[data-axis=X][data-dir="1"]');
  await waitJogging(true, 5000);
  await h.sleep(400);
  const x0 = (await jogging()).x;
  let t0 = Date.now();
  await page.mouse.up();
  await waitJogging(false, 5000).catch(() => {});
  let j = await jogging();
  h.check(!j.jogging && j.x > x0 && j.x < 20, `release stops the jog: ${Date.now() - t0} ms, X ${j.x.toFixed(3)} mm`);
  await h.screenshot(page, 'jog');

  // (b) the browser killed mid-jog
  await hold(page, 'button.jog[data-axis=X][data-dir="-1"]');
  await waitJogging(true, 5000);
  await h.sleep(400);
  t0 = Date.now();
  browser.process().kill('SIGKILL');
  browser = null;
  await waitJogging(false, kJogS * 1000).catch(() => {});
  const killMs = Date.now() - t0;
  j = await jogging();
  h.check(!j.jogging && killMs < kJogS * 1000 / 2,
    `killing the browser mid-jog stops the jog: ${killMs} ms after the kill (the jog alone would last ${kJogS} s), X ${j.x.toFixed(3)} mm`);
  h.check(/dead-man: client \d+ .* its connection closed/.test(w.log()), 'contour-web logs why it stopped the jog');

  // (c) a connected client that goes silent (no dead-man keepalive)
  browser = await h.launchBrowser(puppeteer, 'jog-c');
  page = await h.openPage(browser, w.url);
  await page.waitForFunction(() => document.querySelector('#state').textContent === 'READY', { timeout: 15000 });
  const r = await page.evaluate(() => window.contourWeb.rpc.call('jog', { axis: 'Y', velocity_mm_min: 600, distance_mm: 100 })
    .then((x) => JSON.stringify(x), (e) => e.message));
  h.check(/target_mm/.test(r), `a jog without keepalive starts (${r})`);
  t0 = Date.now();
  await waitJogging(false, kJogS * 1000).catch(() => {});
  const silentMs = Date.now() - t0;
  j = await jogging();
  h.check(!j.jogging && silentMs < kJogS * 1000 / 2, `a silent client's jog is stopped by the dead-man after ${silentMs} ms (web.jog_deadman_ms 500)`);
  h.check(await page.$eval('#conn', (e) => e.classList.contains('up')), 'the silent client itself stays connected');
} catch (e) {
  h.check(false, `exception: ${e.stack}`);
  console.log(w.log());
} finally {
  direct.close();
  if (browser) await browser.close();
}
h.done();
