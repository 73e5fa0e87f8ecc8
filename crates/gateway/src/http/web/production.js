// cellbus production view: one device's machine states over the shift under way and the
// last hour (coloured bars from /api/states), and for a device that counts production its
// OEE with availability, performance and quality, boards against the plan, the stops'
// Pareto, MTBF and MTTR (/api/production). Asked for again every 10 s, and soon after the
// device's machine state changes on the event stream.
//
// The view is in the address: `#view=production&device=ID` (without a device: the first
// that counts production, else the first with machine states).
//
// DOM contract (for tests): each bar (#shift-bar, #hour-bar) has data-from, data-to and
// data-answered (the answer's `to`), and a .segment per interval with data-start, data-end,
// data-state, data-category, data-code and data-reason; each figure is
// [data-figure="oee|availability|performance|quality|boards|mtbf|mttr"] with a .value;
// #production-numbers has data-answered; #stops holds an li.stop per stop shown.
//
// Loaded before app.js: only definitions here; app.js shows the view (showProduction).
'use strict';

/** The categories of SEMI E10 / IPC-CFX states, in the legend's order, in words. */
const CATEGORIES = [
  ['productive', 'Productive'],
  ['standby', 'Standby'],
  ['engineering', 'Engineering'],
  ['scheduled_down', 'Scheduled down'],
  ['unscheduled_down', 'Unscheduled down'],
  ['non_scheduled', 'Not scheduled'],
  ['unknown', 'No data'],
];
const CATEGORY_WORDS = new Map(CATEGORIES);
/** The view is asked for again this often. */
const PRODUCTION_REFRESH_MS = 10e3;

const production = {
  shown: false,
  device: null,   // the device shown
  timer: null,
  load: 0,        // counts loads: an older load's answers are dropped
  soon: null,     // a load asked for after a state change
  shift: null,    // the last shift bar drawn: { answer, from, to }
  hour: null,     // the last hour's bar drawn
};

// ---- which device -----------------------------------------------------------------------

/** Whether the cell view's snapshot shows the device with machine states (`production`: counting boards too). */
function reportsStates(device, counting = false) {
  return device.byId && device.byId.has(`${device.id}.${counting ? 'oee' : 'machine_state'}`);
}

/** The devices known to report machine states, in the cell's order. */
function devicesWithStates() {
  return state.order.map((id) => state.devices.get(id)).filter((d) => d && reportsStates(d));
}

/** The device a production view without one shows: the first counting production. */
function defaultProductionDevice() {
  const known = devicesWithStates();
  const counting = known.find((d) => reportsStates(d, true));
  return (counting || known[0] || {}).id || null;
}

function renderDeviceChoice() {
  const select = document.getElementById('production-device');
  const ids = devicesWithStates().map((d) => d.id);
  if (production.device && !ids.includes(production.device)) ids.unshift(production.device);
  const same = select.options.length === ids.length && ids.every((id, i) => select.options[i].value === id);
  if (!same) {
    select.replaceChildren(...ids.map((id) => {
      const device = state.devices.get(id);
      const option = el('option', '', device ? `${id} · ${device.name}` : id);
      option.value = id;
      return option;
    }));
  }
  if (production.device) select.value = production.device;
}

// ---- showing it ----------------------------------------------------------------------------

/** Shows the production view the address asks for (`params`), or hides it (`null`). */
function showProduction(params) {
  production.shown = Boolean(params);
  clearInterval(production.timer);
  production.timer = null;
  if (!params) return;
  const device = params.get('device') || defaultProductionDevice();
  if (device !== production.device) clearProduction();
  production.device = device;
  renderDeviceChoice();
  updateProductionLinks();
  if (!production.device) {
    document.getElementById('production-note').textContent = state.devices.size
      ? 'No device shown on the cell page reports machine states.'
      : 'Waiting for the gateway…';
    return;
  }
  production.timer = setInterval(() => {
    if (!document.hidden) loadProduction();
  }, PRODUCTION_REFRESH_MS);
  loadProduction();
}

/** The cell's snapshot arrived: the device choice, and a device for a view without one. */
function productionSnapshot() {
  if (!production.shown) return;
  if (production.device) renderDeviceChoice();
  else showProduction(pageFromAddress().params);
}

/** The device's machine state changed on the stream: ask again in a second. */
function productionNoticed(deviceId) {
  if (!production.shown || deviceId !== production.device || production.soon) return;
  production.soon = setTimeout(() => {
    production.soon = null;
    loadProduction();
  }, 1000);
}

/** The Production tab and the view's trend link, for the device shown (`counting` boards). */
function updateProductionLinks(counting = false) {
  const id = production.device;
  document.getElementById('tab-production').href = id ? `#view=production&device=${id}` : '#view=production';
  const trendLink = document.getElementById('production-trend');
  trendLink.hidden = !id;
  if (!id) return;
  const points = counting
    ? ['oee', 'oee_availability', 'oee_performance', 'oee_quality'].map((p) => `${id}.${p}`)
    : [`${id}.machine_state_code`];
  trendLink.href = `#view=trend&points=${points.join(',')}&range=8h`;
  trendLink.textContent = counting ? 'Trend of its OEE' : 'Trend of its state';
}

function chooseDevice(id) {
  window.history.pushState(null, '', `#view=production&device=${encodeURIComponent(id)}`);
  showProduction(pageFromAddress().params);
}

function clearProduction() {
  production.load += 1;
  production.shift = null;
  production.hour = null;
  for (const id of ['shift-bar', 'hour-bar', 'shift-axis', 'hour-axis', 'stops', 'state-times']) {
    document.getElementById(id).replaceChildren();
  }
  document.getElementById('production-numbers').hidden = true;
  document.getElementById('production-stops').hidden = true;
  for (const id of ['production-shift', 'production-now', 'state-detail', 'production-note']) {
    document.getElementById(id).textContent = '';
  }
}

// ---- the answers ---------------------------------------------------------------------------

async function getJson(url) {
  const response = await api(url);
  const body = await response.json();
  if (!response.ok) throw new Error(body.error || `the gateway answered ${response.status}`);
  return body;
}

/** Asks for the shift's production and states and the last hour's states, then draws. */
async function loadProduction() {
  const id = production.device;
  if (!id) return;
  production.load += 1;
  const load = production.load;
  const device = encodeURIComponent(id);
  let answers;
  try {
    answers = await Promise.all([
      getJson(`/api/production?device=${device}`),
      getJson(`/api/states?device=${device}`),
      getJson(`/api/states?device=${device}&from=-1h&to=now`),
    ]);
  } catch (e) {
    if (load === production.load) document.getElementById('production-note').textContent = String(e.message || e);
    return;
  }
  if (load !== production.load || !production.shown || id !== production.device) return;
  const [report, shift, hour] = answers;
  document.getElementById('production-note').textContent = '';
  renderShiftWords(report);
  const whole = report.shift
    ? { from: Date.parse(report.shift.start), to: Date.parse(report.shift.end) }
    : { from: Date.parse(shift.from), to: Date.parse(shift.to) };
  production.shift = { answer: shift, ...whole };
  production.hour = { answer: hour, from: Date.parse(hour.from), to: Date.parse(hour.to) };
  renderBar('shift', production.shift);
  renderBar('hour', production.hour);
  renderNow(shift);
  renderNumbers(report);
  renderStops(report);
  renderStateTimes(report);
}

// ---- the state bars ------------------------------------------------------------------------

function renderShiftWords(report) {
  const words = document.getElementById('production-shift');
  if (report.shift) {
    const start = Date.parse(report.shift.start);
    const end = Date.parse(report.shift.end);
    const sameDay = new Date(start).toDateString() === new Date(end - 1).toDateString();
    const midnight = formatHour(end) === '00:00' ? '24:00' : formatHour(end);
    const until = sameDay ? midnight : `${formatDay(end)} ${formatHour(end)}`;
    const unobserved = report.unobserved_s ? `, ${formatDuration(report.unobserved_s)} without data` : '';
    words.textContent = `Shift ${report.shift.name}: ${formatDay(start)} ${formatHour(start)} – ${until}`
      + ` · ${formatDuration(report.planned_s)} planned so far${unobserved}`;
  } else {
    words.textContent = 'Outside every shift: the last 24 hours';
  }
}

function formatDay(ms) {
  return new Date(ms).toLocaleDateString([], { weekday: 'short', day: 'numeric', month: 'short' });
}

function formatHour(ms) {
  return new Date(ms).toLocaleTimeString([], { hour: '2-digit', minute: '2-digit', hour12: false });
}

/** A duration in seconds as words: 42 s, 12 min 5 s, 3 h 20 min. */
function formatDuration(seconds) {
  if (seconds === null || seconds === undefined) return '—';
  const s = Math.round(seconds);
  if (s < 60) return `${s} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min${s % 60 ? ` ${s % 60} s` : ''}`;
  const minutes = Math.round(s / 60);
  return `${Math.floor(minutes / 60)} h${minutes % 60 ? ` ${minutes % 60} min` : ''}`;
}

function describeInterval(interval) {
  const start = Date.parse(interval.start);
  const end = Date.parse(interval.end);
  const long = end - start > 86400e3;
  const when = (ms) => (long ? `${formatDay(ms)} ${formatClock(ms)}` : formatClock(ms));
  const category = CATEGORY_WORDS.get(interval.category) || interval.category;
  const code = interval.code ? `, ${interval.code}` : '';
  const reason = interval.reason ? ` · ${interval.reason}` : '';
  return `${when(start)} – ${when(end)} (${formatDuration((end - start) / 1000)}) · ${interval.state}`
    + ` · ${category}${code}${reason}`;
}

/** Draws a bar (`which`: shift or hour) of `drawn.answer`'s intervals over drawn.from..to. */
function renderBar(which, drawn) {
  const bar = document.getElementById(`${which}-bar`);
  const span = Math.max(1, drawn.to - drawn.from);
  const at = (ms) => `${((Math.min(Math.max(ms, drawn.from), drawn.to) - drawn.from) / span) * 100}%`;
  bar.dataset.from = String(drawn.from);
  bar.dataset.to = String(drawn.to);
  bar.dataset.answered = drawn.answer.to;
  const segments = drawn.answer.intervals.map((interval) => {
    const segment = el('div', `segment cat-${interval.category}`);
    const start = Date.parse(interval.start);
    const end = Date.parse(interval.end);
    segment.style.left = at(start);
    segment.style.width = `calc(${at(end)} - ${at(start)})`;
    Object.assign(segment.dataset, {
      start: interval.start, end: interval.end, state: interval.state,
      category: interval.category, code: String(interval.code), reason: interval.reason || '',
    });
    segment.title = describeInterval(interval);
    return segment;
  });
  const answeredTo = Date.parse(drawn.answer.to);
  if (answeredTo < drawn.to) {
    const now = el('div', 'now-mark');
    now.style.left = at(answeredTo);
    now.title = `now: ${formatClock(answeredTo)}`;
    segments.push(now);
  }
  bar.replaceChildren(...segments);
  bar.setAttribute('aria-label', `${which === 'shift' ? 'The shift' : 'The last hour'}: `
    + drawn.answer.intervals.map((i) => i.state).join(', '));
  const axis = document.getElementById(`${which}-axis`);
  axis.replaceChildren(...[0, 0.25, 0.5, 0.75, 1].map((f) => {
    const tick = el('span', '', formatHour(drawn.from + f * span));
    tick.style.left = `${f * 100}%`;
    return tick;
  }));
}

/** The interval of a bar under the pointer at `clientX`, if any. */
function intervalAt(which, clientX) {
  const drawn = production[which];
  if (!drawn) return null;
  const box = document.getElementById(`${which}-bar`).getBoundingClientRect();
  const t = drawn.from + ((clientX - box.left) / Math.max(1, box.width)) * (drawn.to - drawn.from);
  return drawn.answer.intervals.find((i) => Date.parse(i.start) <= t && t < Date.parse(i.end)) || null;
}

function showIntervalAt(which, clientX) {
  const interval = intervalAt(which, clientX);
  const detail = document.getElementById('state-detail');
  for (const bar of ['shift-bar', 'hour-bar']) {
    for (const segment of document.getElementById(bar).querySelectorAll('.segment.picked')) {
      segment.classList.remove('picked');
    }
  }
  if (!interval) {
    detail.textContent = '';
    return;
  }
  const bar = document.getElementById(`${which}-bar`);
  for (const segment of bar.querySelectorAll('.segment')) {
    if (segment.dataset.start === interval.start) segment.classList.add('picked');
  }
  detail.textContent = describeInterval(interval);
  detail.dataset.start = interval.start;
}

function renderNow(shift) {
  const last = shift.intervals[shift.intervals.length - 1];
  const now = document.getElementById('production-now');
  now.replaceChildren();
  if (!last) return;
  const pill = el('span', `state-pill cat-${last.category}`, last.state);
  const since = el('span', 'since', ` since ${formatClock(Date.parse(last.start))}`);
  now.append(pill, since);
  if (last.reason) now.append(el('span', 'reason', ` · ${last.reason}`));
}

function renderLegend() {
  const legend = document.getElementById('state-legend');
  legend.replaceChildren(...CATEGORIES.map(([category, words]) => {
    const item = el('li');
    item.dataset.category = category;
    item.append(el('span', `swatch cat-${category}`), el('span', '', words));
    return item;
  }));
}

// ---- the numbers ---------------------------------------------------------------------------

/** A ratio 0..1 as the page shows it: a percentage with one decimal, or — (not computable). */
function formatRatio(ratio) {
  return typeof ratio === 'number' ? `${(ratio * 100).toFixed(1)} %` : '—';
}

function setFigure(name, text, title) {
  const figure = document.querySelector(`[data-figure="${name}"]`);
  figure.querySelector('.value').textContent = text;
  figure.title = title || '';
}

function renderNumbers(report) {
  const numbers = document.getElementById('production-numbers');
  const counting = 'oee' in report;
  numbers.hidden = !counting;
  document.getElementById('production-stops').hidden = !counting;
  updateProductionLinks(counting);
  if (!counting) {
    document.getElementById('production-note').textContent =
      'This device counts no boards: the page shows its machine states only.';
    return;
  }
  numbers.dataset.answered = report.to;
  const notComputable = 'not computable over this range';
  setFigure('oee', formatRatio(report.oee), report.oee === null ? notComputable : 'availability × performance × quality');
  setFigure('availability', formatRatio(report.availability), report.availability === null ? notComputable : 'run time / planned time');
  setFigure('performance', formatRatio(report.performance), report.basis?.performance || '');
  setFigure('quality', formatRatio(report.quality), report.basis?.quality || '');
  const boards = report.boards ?? null;
  const planned = report.boards_planned;
  const boardsText = boards === null ? '—' : formatNumber(boards);
  setFigure('boards', planned ? `${boardsText} of ${formatNumber(planned)}` : boardsText,
    report.basis?.boards_planned || '');
  document.querySelector('[data-figure="boards"] .label').textContent =
    planned ? 'Boards of the plan' : 'Boards (no plan set)';
  const meter = document.getElementById('boards-meter');
  meter.hidden = !planned;
  if (planned) meter.firstElementChild.style.width = `${Math.min(100, (100 * (boards || 0)) / planned)}%`;
  setFigure('mtbf', formatDuration(report.mtbf_s), 'mean time between failures: productive time per unscheduled stop');
  setFigure('mttr', formatDuration(report.mttr_s), 'mean time to repair: unscheduled down time per unscheduled stop');
  const basis = document.getElementById('production-basis');
  const said = [['Performance', report.basis?.performance], ['Quality', report.basis?.quality],
    ['Plan', report.basis?.boards_planned]].filter(([, words]) => words);
  basis.replaceChildren(...said.flatMap(([what, words]) => [el('dt', '', what), el('dd', '', words)]));
}

/** The stops' Pareto: minutes (seconds under one) per reason, longest first; the time without data below it. */
function renderStops(report) {
  const list = document.getElementById('stops');
  const stops = [...(report.stops || [])].sort((a, b) => b.seconds - a.seconds);
  const most = Math.max(1, ...stops.map((s) => s.seconds));
  list.replaceChildren(...stops.map((stop) => {
    const item = el('li', 'stop');
    item.dataset.reason = stop.reason;
    item.dataset.seconds = String(stop.seconds);
    item.dataset.count = String(stop.count);
    const bar = el('div', 'stop-bar');
    const fill = el('div', `cat-${stop.category || 'unscheduled_down'}`);
    fill.style.width = `${(stop.seconds / most) * 100}%`;
    bar.append(fill);
    const long = stop.seconds < 60 ? `${Math.round(stop.seconds)} s` : `${(stop.seconds / 60).toFixed(1)} min`;
    const times = `${stop.count} ${stop.count === 1 ? 'time' : 'times'}`;
    item.append(el('span', 'stop-reason', stop.reason), bar, el('span', 'stop-time', `${long} · ${times}`));
    return item;
  }));
  if (!stops.length) list.append(el('li', 'placeholder', 'No stops in this shift so far.'));
  const unobserved = report.unobserved_s || 0;
  document.getElementById('stops-unobserved').textContent = unobserved
    ? `Without data for ${formatDuration(unobserved)} of the shift (the gateway was not running,`
      + ' or had not polled the machine yet): that time is not planned time, nor a stop.'
    : '';
}

/** Time in each state over the shift so far, longest first, with its share of that time. */
function renderStateTimes(report) {
  const table = document.getElementById('state-times');
  const rows = [...(report.states || [])].sort((a, b) => b.seconds - a.seconds);
  const whole = rows.reduce((sum, row) => sum + row.seconds, 0);
  table.replaceChildren(...rows.map((row) => {
    const tr = el('tr');
    const name = el('td');
    name.append(el('span', `swatch cat-${row.category}`), el('span', '', row.state));
    const share = whole ? `${((100 * row.seconds) / whole).toFixed(1)} %` : '';
    tr.append(name, el('td', 'muted', CATEGORY_WORDS.get(row.category) || row.category),
      el('td', 'number', formatDuration(row.seconds)), el('td', 'number', share));
    return tr;
  }));
}

// ---- controls ------------------------------------------------------------------------------

function setUpProduction() {
  renderLegend();
  document.getElementById('production-device').addEventListener('change', (e) => chooseDevice(e.target.value));
  for (const which of ['shift', 'hour']) {
    const bar = document.getElementById(`${which}-bar`);
    bar.addEventListener('pointermove', (e) => showIntervalAt(which, e.clientX));
    bar.addEventListener('pointerdown', (e) => showIntervalAt(which, e.clientX));
  }
}
