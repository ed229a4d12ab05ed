// contour-web page: DRO, controls, live scope, toolpath, tuning, events. Everything goes through
// the JSON-RPC WebSocket (rpc.js); status fields the daemon does not send (yet) show as "—".
import { Rpc } from './rpc.js';
import { parseGcode } from './gcode.js';
import { Toolpath } from './toolpath.js';
import { Scope, SCOPE_SERIES } from './scope.js';
import { drawPolar, drawHistogram } from './plots.js';

const $ = (s) => document.querySelector(s);
const $$ = (s) => Array.from(document.querySelectorAll(s));
const fmt = (v, d = 3) => (typeof v === 'number' && Number.isFinite(v) ? v.toFixed(d) : '—');

const state = { status: {}, info: null, role: '', program: null, seenJob: 0, seenFinished: null,
  circle: null, jog: null, events: 0 };
const wsUrl = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`;
const rpc = new Rpc(wsUrl);
const toolpath = new Toolpath($('#toolpath'), $('#tp-tip'), $('#tp-legend'));
const scope = new Scope($('#scope'));
window.contourWeb = { rpc, state, scope, toolpath };  // read by the browser tests

// --- views ----------------------------------------------------------------------------------
for (const b of $$('.tab')) {
  b.addEventListener('click', () => {
    $$('.tab').forEach((x) => x.classList.toggle('active', x === b));
    $$('.view').forEach((v) => v.classList.toggle('active', v.id === `view-${b.dataset.view}`));
    if (b.dataset.view === 'scope') scope.u.setSize({ width: Math.max(400, $('#scope').getBoundingClientRect().width), height: 380 });
    if (b.dataset.view === 'operate') toolpath.request();
    if (b.dataset.view === 'tuning') { renderTiming(); loadGains(); }
  });
}
for (const b of $$('.tpv')) {
  b.addEventListener('click', () => {
    $$('.tpv').forEach((x) => x.classList.toggle('active', x === b));
    toolpath.setView(b.dataset.tp);
  });
}

// --- connection, login, subscriptions --------------------------------------------------------
function tokenFromHash() {
  const m = location.hash.match(/token=([^&]+)/);
  if (!m) return '';
  history.replaceState(null, '', location.pathname);  // keep it out of the address bar
  return decodeURIComponent(m[1]);
}

rpc.onOpen = async () => {
  state.info = await rpc.call('web.info');
  state.role = state.info.role;
  const token = tokenFromHash() || sessionStorage.getItem('contour-token') || '';
  if (token) {
    try {
      const r = await rpc.call('web.login', { token });
      sessionStorage.setItem('contour-token', token);
      state.role = r.role;
    } catch (e) {
      sessionStorage.removeItem('contour-token');
      showLogin(`login: ${e.message}`);
      return;
    }
  }
  if (state.role === 'none') { showLogin(''); return; }
  $('#login').hidden = true;
  await subscribeAll();
};

rpc.onState = (up) => {
  $('#conn').textContent = up ? 'connected' : (rpc.closedByServer ? `disconnected: ${rpc.closedByServer}` : 'disconnected');
  $('#conn').className = `conn ${up ? 'up' : 'down'}`;
  $('#role').textContent = up && state.role ? `(${state.role})` : '';
  if (!up) stopJog('connection lost');
};

function showLogin(msg) {
  $('#login').hidden = false;
  $('#login-msg').textContent = msg;
  $('#login-msg').className = 'msg err';
}

$('#btn-login').addEventListener('click', async () => {
  const token = $('#login-token').value.trim();
  try {
    const r = await rpc.call('web.login', { token });
    sessionStorage.setItem('contour-token', token);
    state.role = r.role;
    $('#login').hidden = true;
    $('#role').textContent = `(${r.role})`;
    await subscribeAll();
  } catch (e) { showLogin(e.message); }
});

async function subscribeAll() {
  const st = await rpc.call('subscribe', { topic: 'status' });
  state.status = {};
  applyStatus(st.status);
  await rpc.call('subscribe', { topic: 'telemetry' });
  const ev = await rpc.call('subscribe', { topic: 'events' });
  $('#events').innerHTML = '';
  for (const e of ev.events) addEvent(e);
  $('#role').textContent = `(${state.role})`;
  loadGains();
}

rpc.on('notify_status_update', (p) => applyStatus(p[0]));
rpc.on('notify_event', (e) => addEvent(e));
rpc.on('notify_scope', (p) => {
  scope.push(p);
  const s = p.signals;
  if (s.act_x_mm && s.true_error_um && s.in_program) {
    toolpath.addSamples(p.job, s.act_x_mm, s.act_y_mm, s.act_z_mm, s.true_error_um, s.in_program);
  }
  if (state.circle && state.circle.job && s.act_x_mm && s.progress_mm) {
    // The arc only: reference progress past the approach move (the interpolator's FIR blends the
    // two, so line numbers alone would let approach samples in).
    const c = state.circle;
    for (let i = 0; i < p.cycle.length; i++) {
      const prog = s.progress_mm[i];
      if (p.job[i] === c.job && prog >= c.approach_mm && prog <= c.approach_mm + 2 * Math.PI * c.R) {
        c.samples.push([s.act_x_mm[i], s.act_y_mm[i]]);
      }
    }
  }
  scopeStats();
});

// --- status ------------------------------------------------------------------------------------
function axisNames(st) {
  if (Array.isArray(st.axes)) return st.axes.map((a) => (typeof a === 'string' ? a : a.name));
  if (st.homed && typeof st.homed === 'object' && !Array.isArray(st.homed)) return Object.keys(st.homed);
  return ['X', 'Y', 'Z'].slice(0, (st.act_mm || [0, 0, 0]).length);
}

function applyStatus(diff) {
  Object.assign(state.status, diff);
  const st = state.status;
  const s = st.state || '—';
  $('#state').textContent = s;
  $('#state').className = `state s-${s}`;
  const fault = st.fault ? `${st.fault.cause}${st.fault.axis >= 0 ? ` axis ${st.fault.axis}` : ''}` +
    (st.fault.value ? ` (${fmt(st.fault.value)} > ${fmt(st.fault.limit)})` : '') : '';
  // The cause matters while it holds the machine (FAULT/ESTOP); status keeps the last one after.
  const stopped = s === 'FAULT' || s === 'ESTOP';
  const cause = st.daemon_error || (stopped ? fault || (st.cause && st.cause !== 'none' ? st.cause : '') : '');
  $('#cause').textContent = cause;
  $('#btn-reset').title = cause ? `reset: cause ${cause}` : 'reset (FAULT/ESTOP only)';
  renderDro(st);
  if (Array.isArray(st.act_mm)) toolpath.setPosition(st.act_mm);
  if (st.feed_override !== undefined && document.activeElement !== $('#override')) {
    $('#override').value = Math.round(st.feed_override * 100);
    $('#override-val').textContent = `${Math.round(st.feed_override * 100)} %`;
  }
  // Program start / end in the event log with the run's figures.
  if (st.job && st.job !== state.seenJob) {
    state.seenJob = st.job;
    addEvent({ event: 'program', text: `program started: job ${st.job}${st.program ? ` (${st.program.name})` : ''}` });
  }
  if (state.seenFinished === null) state.seenFinished = st.finished_job || 0;
  if (st.finished_job && st.finished_job !== state.seenFinished) {
    state.seenFinished = st.finished_job;
    programEnded(st.finished_job);
  }
  if ($('#view-tuning').classList.contains('active')) renderTiming();
}

async function programEnded(job) {
  try {
    const r = await rpc.call('result', { job });
    addEvent({ event: 'program', text: `program job ${job} ${r.completed ? 'completed' : `ended (${r.state})`}: ` +
      `${fmt(r.duration_s, 3)} s, max contour error ${fmt(r.max_contour_error_um, 2)} µm, ` +
      `RMS ${fmt(r.max_contour_error_um === undefined ? NaN : r.rms_contour_error_um, 2)} µm, ` +
      `max following error ${fmt(r.max_following_error_um, 1)} µm, overruns ${r.overruns}` +
      (r.faults && r.faults.length ? `, faults: ${r.faults.join('; ')}` : '') });
    state.lastResult = r;
    if (state.circle && state.circle.job === job) finishCircle(r);
  } catch (e) { addEvent({ event: 'web', text: `result of job ${job}: ${e.message}` }); }
}

function renderDro(st) {
  const names = axisNames(st);
  const act = st.act_mm || [], ref = st.ref_mm || [];
  const work = Array.isArray(st.work_mm) ? st.work_mm : null;
  const rows = names.map((n, i) => {
    const homed = st.homed && typeof st.homed === 'object' ? (Array.isArray(st.homed) ? st.homed[i] : st.homed[n]) : undefined;
    const fe = typeof ref[i] === 'number' && typeof act[i] === 'number' ? (ref[i] - act[i]) * 1000 : NaN;
    return `<tr><td>${n}</td><td>${fmt(work ? work[i] : act[i])}</td><td>${fmt(act[i])}</td><td>${fmt(ref[i])}</td>` +
      `<td>${fmt(fe, 1)} µm</td><td>${homed === undefined ? '—' : homed ? '✓' : '✗'}</td></tr>`;
  });
  $('#dro tbody').innerHTML = rows.join('');
  const sp = st.spindle || {};
  const force = st.force || {};
  const prog = st.program || {};
  const pct = (v) => (typeof v === 'number' ? `${Math.round(v * 100)} %` : '—');
  const kv = [
    ['tool', st.tool ?? st.tool_number ?? '—'],
    ['work offset', st.work_offset ?? st.offset ?? '—'],
    ['feed override', pct(st.feed_override)],
    ['rapid override', st.rapid_override !== undefined ? pct(st.rapid_override) : '—'],
    ['spindle override', st.spindle_override !== undefined ? pct(st.spindle_override) : '—'],
    ['spindle', sp.present ? `${fmt(sp.actual_rpm ?? sp.command_rpm, 0)} rpm (cmd ${fmt(sp.command_rpm, 0)})` : `${fmt(st.spindle_rpm_cmd, 0)} rpm`],
    ['force', force.available ? `${fmt(force.force_n, 1)} N` : '—'],
    ['contour error', `${fmt(st.contour_error_um, 2)} µm`],
    ['program', prog.name ? `${prog.name} (${fmt(prog.progress_pct, 0)} %, line ${st.line ?? '—'}, max ${fmt(prog.max_contour_error_um, 2)} µm, RMS ${fmt(prog.rms_contour_error_um, 2)} µm)` : '—'],
    ['jogging', st.jogging ? 'yes' : 'no'],
    ['loop', st.timing ? `lateness p99 ${fmt(st.timing.lateness_p99_us, 0)} µs, overruns ${st.timing.overruns}` : '—'],
  ];
  $('#dro-extra').innerHTML = kv.map(([k, v]) => `<span>${k}</span><span>${escapeHtml(String(v))}</span>`).join('');
}

function escapeHtml(s) {
  return s.replace(/[&<>"']/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;' }[c]));
}

// --- commands -----------------------------------------------------------------------------------
async function command(method, params, msgEl = '#cmd-msg') {
  const el = $(msgEl);
  state.sentAt = { ...(state.sentAt || {}), [method]: Date.now() };  // the tests time from here too
  try {
    const r = await rpc.call(method, params);
    if (el) { el.textContent = `${method}: ok`; el.className = 'msg ok'; }
    return r;
  } catch (e) {
    if (el) { el.textContent = `${method}: ${e.message}`; el.className = 'msg err'; }
    addEvent({ event: 'web', text: `${method} refused: ${e.message}` });
    throw e;
  }
}
const quiet = (p) => p.catch(() => {});

$('#estop').addEventListener('click', () => quiet(command('estop')));
$('#btn-hold').addEventListener('click', () => quiet(command('hold')));
$('#btn-resume').addEventListener('click', () => quiet(command('resume')));
$('#btn-stop').addEventListener('click', () => quiet(command('stop')));
$('#btn-reset').addEventListener('click', () => quiet(command('reset')));
$('#btn-run').addEventListener('click', () => quiet(command('run')));
$('#override').addEventListener('input', () => { $('#override-val').textContent = `${$('#override').value} %`; });
$('#override').addEventListener('change', () => quiet(command('override', { percent: Number($('#override').value) })));

$('#btn-upload').addEventListener('click', async () => {
  const f = $('#file').files[0];
  if (!f) { $('#cmd-msg').textContent = 'choose a program file first'; $('#cmd-msg').className = 'msg err'; return; }
  const text = await f.text();
  try {
    const r = await uploadProgram(f.name, text);
    state.program = { name: f.name, text, job: r.job };
    $('#program-info').textContent = `${f.name}: job ${r.job}, ${r.lines} lines, ${r.motion_blocks} motion blocks, ${fmt(r.length_mm, 1)} mm`;
    preview(text);
  } catch (e) { /* shown by command() */ }
});

// The daemon's `upload`: chunks of one socket line each, offsets in bytes, the last one loads it.
async function uploadProgram(name, text) {
  const enc = new TextEncoder();
  const chunk = 16 * 1024;
  let offset = 0, r = null;
  for (let i = 0; i < text.length || i === 0; i += chunk) {
    const data = text.slice(i, i + chunk);
    const final = i + chunk >= text.length;
    r = await command('upload', { name, offset, data, final });
    offset += enc.encode(data).length;
    if (final) break;
  }
  return r;
}

function preview(text) {
  const start = Array.isArray(state.status.act_mm) ? state.status.act_mm.slice(0, 3) : [0, 0, 0];
  const p = parseGcode(text, start);
  toolpath.setPlan(p);
  toolpath.clearExecuted();
  const e = p.extents;
  $('#preview-info').textContent = Number.isFinite(e.min[0])
    ? `preview: ${p.blocks} motion blocks, ${fmt(p.length_mm, 1)} mm of feed moves, ${p.corners.length} corners; ` +
      `X ${fmt(e.min[0], 2)}…${fmt(e.max[0], 2)}, Y ${fmt(e.min[1], 2)}…${fmt(e.max[1], 2)}, Z ${fmt(e.min[2], 2)}…${fmt(e.max[2], 2)} mm`
    : 'preview: no motion';
}

$('#file').addEventListener('change', async () => {
  const f = $('#file').files[0];
  if (f) preview(await f.text());
});

// Jog: hold to jog (a long jog stopped on release, with the dead-man keepalive meanwhile) or a step.
function stopJog(why) {
  if (!state.jog) return;
  clearInterval(state.jog.timer);
  state.jog.btn.classList.remove('held');
  state.jog = null;
  if (rpc.up) quiet(command('stop'));
  if (why) addEvent({ event: 'web', text: `jog stopped: ${why}` });
}
for (const b of $$('.jog')) {
  b.addEventListener('pointerdown', (ev) => {
    ev.preventDefault();
    const dir = Number(b.dataset.dir), v = Number($('#jog-speed').value);
    const mode = $('#jog-step').value;
    if (mode !== 'hold') {
      quiet(command('jog', { axis: b.dataset.axis, velocity_mm_min: v, distance_mm: dir * Number(mode) }));
      return;
    }
    b.setPointerCapture(ev.pointerId);
    b.classList.add('held');
    state.jog = { btn: b, timer: setInterval(() => rpc.notify('web.deadman'), 150) };
    quiet(command('jog', { axis: b.dataset.axis, velocity_mm_min: v, distance_mm: dir * Number($('#jog-travel').value) }));
  });
  for (const evName of ['pointerup', 'pointercancel', 'lostpointercapture']) {
    b.addEventListener(evName, () => { if (state.jog && state.jog.btn === b) stopJog(''); });
  }
}
window.addEventListener('blur', () => stopJog('window lost focus'));
document.addEventListener('visibilitychange', () => { if (document.hidden) stopJog('page hidden'); });

// MDI: the daemon's `mdi` command where it has one, else a one-block program (`run {program}`).
$('#btn-mdi').addEventListener('click', async () => {
  const text = $('#mdi-input').value.trim();
  if (!text) return;
  try {
    await rpc.call('mdi', { program: text });
    $('#cmd-msg').textContent = `MDI: ${text}`; $('#cmd-msg').className = 'msg ok';
  } catch (e) {
    if (/unknown command/.test(e.message)) quiet(command('run', { program: `${text}\n`, name: 'MDI' }));
    else { $('#cmd-msg').textContent = `mdi: ${e.message}`; $('#cmd-msg').className = 'msg err'; }
  }
});
$('#mdi-input').addEventListener('keydown', (ev) => { if (ev.key === 'Enter') $('#btn-mdi').click(); });

// --- gains ----------------------------------------------------------------------------------------
async function loadGains() {
  try {
    const g = await rpc.call('gains');
    // A refresh never takes the value an operator is typing out of the field.
    if (document.activeElement && document.activeElement.closest('#gains-table')) return;
    renderGains(g);
  } catch (e) { $('#gains-msg').textContent = `gains: ${e.message}`; }
}
function renderGains(g) {
  const rows = [];
  for (const [k, v] of Object.entries(g)) {
    if (typeof v === 'object' && !Array.isArray(v)) continue;
    const editable = !/generation|cycle/.test(k);
    const val = Array.isArray(v) ? v.join(', ') : v;
    rows.push(`<tr><td>${k}</td><td>${editable ? `<input data-gain="${k}" value="${escapeHtml(String(val))}">` : escapeHtml(String(val))}</td></tr>`);
  }
  $('#gains-table tbody').innerHTML = rows.join('');
  for (const inp of $$('#gains-table input')) {
    inp.addEventListener('keydown', async (ev) => {
      if (ev.key !== 'Enter') return;
      const k = inp.dataset.gain;
      const raw = inp.value.trim();
      let val = raw.includes(',') ? raw.split(',').map((x) => Number(x.trim())) : (raw === 'true' || raw === 'false' ? raw === 'true' : Number(raw));
      if (typeof val === 'number' && !Number.isFinite(val)) val = raw;
      try {
        const r = await rpc.call('gains', { set: { [k]: val } });
        $('#gains-msg').textContent = `${k} set (generation ${r.generation ?? '?'})`;
        $('#gains-msg').className = 'msg ok';
        renderGains(r);
      } catch (e) {
        // The daemon's own reason, as it gave it.
        $('#gains-msg').textContent = `refused: ${e.message}`;
        $('#gains-msg').className = 'msg err';
      }
    });
  }
}

// --- circle test, timing ---------------------------------------------------------------------------
$('#btn-circle').addEventListener('click', async () => {
  const R = Number($('#circle-r').value), F = Number($('#circle-f').value);
  const prog = `(circle test)\nG21 G90 G17\nG1 X${R} Y0 F3000\nG2 X${R} Y0 I${-R} J0 F${F}\nM2\n`;
  const at = state.status.act_mm || [0, 0, 0];
  state.circle = { R, F, job: 0, samples: [], approach_mm: Math.hypot(R - at[0], at[1]) };
  try {
    const r = await command('run', { program: prog, name: 'circle-test.ngc' }, '#circle-msg');
    state.circle.job = r.job;
    $('#circle-msg').textContent = `circle test running (job ${r.job})`;
  } catch (e) { state.circle = null; }
});
function finishCircle(r) {
  const c = state.circle;
  const res = drawPolar($('#circle-canvas'), c.samples, c.R, `job ${c.job}: max contour error ${fmt(r.max_contour_error_um, 2)} µm`);
  $('#circle-msg').textContent = res ? `roundness ${fmt(res.roundness_um, 1)} µm over ${c.samples.length} samples` : 'no samples';
  $('#circle-msg').className = 'msg ok';
  c.done = res;
}
drawPolar($('#circle-canvas'), [], 10);

let lastTiming = 0;
function renderTiming() {
  const now = performance.now();
  if (now - lastTiming < 1000) return;
  lastTiming = now;
  const t = state.status.timing;
  if (!t) return;
  drawHistogram($('#latency-canvas'), t.lateness_histogram, `${t.cycles} cycles, ${t.realtime ? 'SCHED_FIFO' : 'not real-time'}`);
  $('#timing-info').textContent = `lateness mean ${fmt(t.lateness_mean_us, 1)} µs, p99 ${fmt(t.lateness_p99_us, 0)} µs, ` +
    `p99.9 ${fmt(t.lateness_p999_us, 0)} µs, max ${fmt(t.lateness_max_us, 0)} µs; overruns ${t.overruns}`;
}

// --- scope controls --------------------------------------------------------------------------------
for (const s of SCOPE_SERIES) {
  const l = document.createElement('label');
  l.innerHTML = `<input type="checkbox" data-signal="${s.name}" ${s.on ? 'checked' : ''}> <span style="color:${s.color}">${s.label}</span>`;
  l.querySelector('input').addEventListener('change', (ev) => scope.show(s.name, ev.target.checked));
  $('#scope-signals').appendChild(l);
}
scope.onPause = (p) => { $('#scope-pause').textContent = p ? 'Resume scope' : 'Pause'; };
$('#scope-pause').addEventListener('click', () => scope.setPaused(!scope.paused));
$('#scope-window').addEventListener('change', () => { scope.windowS = Number($('#scope-window').value); scope.dirty = true; });
$('#scope').addEventListener('dblclick', () => scope.setPaused(false));
function download(name, href) {
  const a = document.createElement('a');
  a.href = href; a.download = name; document.body.appendChild(a); a.click(); a.remove();
}
$('#scope-csv').addEventListener('click', () => {
  download('contour-scope.csv', URL.createObjectURL(new Blob([scope.visibleCsv()], { type: 'text/csv' })));
});
$('#scope-png').addEventListener('click', () => download('contour-scope.png', scope.visiblePng()));
let lastStats = 0;
function scopeStats() {
  const now = performance.now();
  if (now - lastStats < 500) return;
  lastStats = now;
  const s = scope.stats;
  $('#scope-stats').textContent = `${s.samples} samples received; dropped here ${s.dropped}, by contourd ${s.daemon_dropped}, gaps ${s.gaps}`;
}

// --- events -----------------------------------------------------------------------------------------
function addEvent(e) {
  const li = document.createElement('li');
  const text = e.text || JSON.stringify(e);
  const kind = e.event === 'web' ? 'web' : e.event === 'program' ? 'program'
    : /fault|EMCY|E-STOP|estop|lost/i.test(text) ? 'fault' : '';
  li.className = kind;
  li.textContent = `${new Date().toLocaleTimeString()}  ${text}`;
  const ul = $('#events');
  ul.insertBefore(li, ul.firstChild);
  while (ul.children.length > 500) ul.removeChild(ul.lastChild);
  state.events++;
}
