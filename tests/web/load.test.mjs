// Browser load test (issue 21): 8 browser clients on the 1 kHz scope during Table 2. contourd's
// telemetry ring drops nothing, and the run's figures are exactly those of the same run without
// browser clients (the sim bus is lockstep: figures do not depend on timing). Each client's share
// of the run's samples is printed (and must reach 95 %). The loop-lateness comparison with and
// without clients is a benchmark (tools/contour-web/bench-clients.sh), not asserted here.
import * as h from './harness.mjs';

const kClients = Number(process.env.CONTOUR_WEB_LOAD_CLIENTS || 8);
const puppeteer = h.loadPuppeteer();

async function table2(direct) {
  const load = await direct.ok({ cmd: 'load', path: h.TABLE2 });
  const run = await direct.ok({ cmd: 'run' });
  await h.waitFor(async () => {
    const st = await direct.ok({ cmd: 'status' });
    return st.finished_job === run.job && st.state === 'READY';
  }, 60000, 'Table 2 to finish');
  const res = await direct.ok({ cmd: 'result', job: run.job });
  return { ...res, motion_blocks: load.motion_blocks };
}

let browser = null;
let w = null;
try {
  // The same run on two fresh daemons (same start state): without, then with browser clients.
  const d0 = await h.startDaemon('load-quiet');
  const c0 = await h.DaemonClient.open(d0.sock);
  const quiet = await table2(c0);
  c0.close();
  d0.proc.kill('SIGTERM');
  h.check(quiet.completed, `Table 2 without browser clients: max ${quiet.max_contour_error_um} µm, RMS ${quiet.rms_contour_error_um} µm, ${quiet.samples} samples, telemetry dropped ${quiet.telemetry_dropped}`);

  const d = await h.startDaemon('load');
  w = await h.startWeb(d.sock);
  const direct = await h.DaemonClient.open(d.sock);
  browser = await h.launchBrowser(puppeteer, 'load');
  const pages = [];
  for (let i = 0; i < kClients; i++) {
    const p = await h.openPage(browser, w.url);
    await p.click('button[data-view=scope]');
    pages.push(p);
  }
  await Promise.all(pages.map((p) => p.waitForFunction(() => window.contourWeb.scope.stats.samples > 100, { timeout: 20000 })));
  const busy = await table2(direct);
  await h.sleep(500);  // the last batches on their way
  h.check(busy.completed, `Table 2 with ${kClients} browser clients: max ${busy.max_contour_error_um} µm, RMS ${busy.rms_contour_error_um} µm, ${busy.samples} samples, telemetry dropped ${busy.telemetry_dropped}`);
  h.check(busy.telemetry_dropped === 0 && quiet.telemetry_dropped === 0, 'contourd dropped no telemetry (ring) in either run');
  h.check(busy.max_contour_error_um === quiet.max_contour_error_um && busy.rms_contour_error_um === quiet.rms_contour_error_um &&
    busy.samples === quiet.samples && busy.duration_s === quiet.duration_s, 'the run\'s figures are unchanged by the clients (lockstep sim)');
  const expected = Math.round(busy.duration_s / 0.001);
  for (let i = 0; i < pages.length; i++) {
    const s = await pages[i].evaluate(() => window.contourWeb.scope.stats);
    const got = s.byJob[busy.job] || 0;
    h.check(got >= 0.95 * expected, `client ${i + 1}: ${got} of ${expected} run samples (${(100 * got / expected).toFixed(1)} %), dropped in contour-web ${s.dropped}, by contourd ${s.daemon_dropped}`);
  }
  const info = await pages[0].evaluate(() => window.contourWeb.rpc.call('web.info'));
  h.check(info.counters.daemon_dropped === 0, `contourd dropped none of contour-web's subscription (${info.counters.daemon_dropped}), gaps ${info.counters.sample_gaps}`);
  await h.screenshot(pages[0], 'load-scope');
} catch (e) {
  h.check(false, `exception: ${e.stack}`);
  if (w) console.log(w.log());
  direct.close();
} finally {
  if (browser) await browser.close();
}
h.done();
