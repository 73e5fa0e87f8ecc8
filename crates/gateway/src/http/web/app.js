// cellbus cell overview: everything comes from the gateway's event stream
// (/api/events/stream); plots start from /api/history and grow with live values.
//
// A large cell is shown a line (or a search's matches) at a time: the page opens the
// stream for the shown devices only (`?line=` or `?device=`), so the gateway sends their
// snapshot and changes and nothing of the rest; at most PAGE_SIZE cards are on the page,
// and a plot loads its history when it scrolls into view. The view is in the address
// (`#line=NAME`, `&q=TEXT` for a search, `&page=N`), so a link opens the same view.
// `#view=trend&…` shows the trend view instead, `#view=production&device=ID` a device's
// production, `#view=alarms` the alarm list and journal (trend.js, production.js and
// alarms.js, loaded before this script); the header's alarm banner is on every view.
//
// DOM contract (for tests and other tools): each device is <section class="device"
// id="device-ID" data-status="up|down|connecting">; each point is an element with
// id="point-DEVICE.POINT" and data-quality="good|stale|bad|none", whose .value child
// shows the live value.
'use strict';

const PLOT_WINDOW_MS = 10 * 60 * 1000;
const MAX_EVENTS = 200;
/** A cell this small shows every device at once by default; a larger one its first line. */
const SMALL_CELL = 50;
/** Most device cards on the page at once: a longer line or search result is paged. */
const PAGE_SIZE = 50;
/** History queries in flight at once: the gateway runs 4 at a time and makes others wait. */
const HISTORY_AT_ONCE = 4;
/** The line selector's value for every line (no line is named so: names are a-z, 0-9, _, -). */
const ALL_LINES = '*';

const state = {
  writesEnabled: null, // unknown until the stream's snapshot says
  devices: new Map(), // id -> device shown (with points by id in .byId)
  series: new Map(),  // point id -> [[t_ms, value|null], ...]
  dirty: new Set(),   // point ids whose plot needs drawing
  visible: new Set(), // point ids whose plot is on screen
  lines: [],
  order: [],          // every device id, line by line in poll order
  view: null,         // { line, q, page } shown now
  shown: [],          // ids of the devices the view shows, in order
  streamQuery: null,  // the stream's query for them
  generation: 0,      // counts snapshots: answers for an older one are dropped
};

// ---- helpers -------------------------------------------------------------------------

function el(tag, className, text) {
  const node = document.createElement(tag);
  if (className) node.className = className;
  if (text !== undefined) node.textContent = text;
  return node;
}

function formatNumber(value) {
  if (typeof value !== 'number') return String(value);
  return value.toFixed(decimalsFor(value));
}

/** The decimals a number needs: none when whole, two below 10, else one. */
function decimalsFor(value) {
  if (Number.isInteger(value)) return 0;
  return Math.abs(value) < 10 ? 2 : 1;
}

/**
 * One number format per unit (a point without a unit has its own): as many decimals as
 * the most any value of that unit has needed so far, so "50 Hz" never stands beside
 * "50.0 Hz". Returns whether the unit's decimals grew (its shown values are then redone).
 */
const unitDecimals = new Map();

function formatKey(point) {
  return point.unit ? `unit:${point.unit}` : `point:${point.id}`;
}

function widenFormat(point) {
  if (typeof point.value !== 'number' || point.text) return false;
  const key = formatKey(point);
  const needed = decimalsFor(point.value);
  if (needed <= (unitDecimals.get(key) ?? 0)) return false;
  unitDecimals.set(key, needed);
  return true;
}

function formatReading(point) {
  return point.value.toFixed(unitDecimals.get(formatKey(point)) ?? 0);
}

function formatClock(ms) {
  const d = new Date(ms);
  return d.toLocaleTimeString([], { hour: '2-digit', minute: '2-digit', second: '2-digit', hour12: false });
}

/** Quality as shown: the gateway pushes every change of it (stale included). */
function judge(point) {
  return point.quality || 'none';
}

function shownValue(point) {
  if (point.value === null || point.value === undefined) return '—';
  if (point.text) return point.text;
  if (typeof point.value !== 'number') return String(point.value);
  return formatReading(point);
}

/**
 * Whether a point is one of the device's live readings, shown large: those of the poll
 * group its kind lists first (`live`), whatever the periods (a device polled every 2 s
 * throughout keeps its settings below, under "Settings and counters").
 */
function isLive(device, point) {
  const first = device.groups.length ? device.groups[0].name : undefined;
  return first === undefined || point.group === first;
}

// ---- devices -------------------------------------------------------------------------

function renderDevices(devices) {
  const container = document.getElementById('devices');
  container.replaceChildren();
  state.devices.clear();
  state.generation += 1;
  state.series.clear();
  state.dirty.clear();
  state.visible.clear();
  historyLoads.queue = [];
  historyLoads.asked.clear();
  if (plotObserver) plotObserver.disconnect();
  if (devices.length === 0) {
    const view = state.view || {};
    const why = view.q
      ? `No device id contains “${view.q}”.`
      : state.order.length ? 'No devices on this line.' : 'No devices are configured.';
    container.append(el('p', 'placeholder', why));
    return;
  }
  // In the view's order (line by line), whatever order the gateway lists them in.
  const position = new Map(state.shown.map((id, i) => [id, i]));
  const ordered = [...devices].sort(
    (a, b) => (position.get(a.id) ?? Infinity) - (position.get(b.id) ?? Infinity),
  );
  for (const device of ordered) {
    device.byId = new Map(device.points.map((p) => [p.id, p]));
    state.devices.set(device.id, device);
    container.append(renderDevice(device));
    updateDeviceStatus(device);
    for (const point of device.points) updatePoint(point, false);
  }
  for (const canvas of container.querySelectorAll('canvas')) {
    if (plotObserver) plotObserver.observe(canvas);
    else seen(canvas.dataset.point);
  }
}

function renderDevice(device) {
  const template = document.getElementById('device-template');
  const card = template.content.firstElementChild.cloneNode(true);
  card.id = `device-${device.id}`;
  card.dataset.status = device.status;
  card.querySelector('.device-name').textContent = device.name;
  const address = device.address === null ? 'no address' : `address ${device.address}`;
  card.querySelector('.device-meta').textContent =
    `${device.id} · ${device.protocol.toUpperCase()} · line ${device.line} · ${address}`;
  const trendLink = card.querySelector('.trend-link');
  const trended = readingsToTrend(device);
  trendLink.hidden = trended.length === 0;
  trendLink.href = `#view=trend&points=${trended.join(',')}&range=1h`;
  trendLink.title = 'Its readings over the last hour';
  const productionLink = card.querySelector('.production-link');
  productionLink.hidden = !device.points.some((p) => p.id === `${device.id}.machine_state`);
  productionLink.href = `#view=production&device=${device.id}`;
  productionLink.title = 'Its machine states this shift, and its OEE when it counts boards';
  for (const point of device.points) {
    const primary = isLive(device, point);
    if (point.kind.type === 'numeric') {
      card.querySelector(primary ? '.tiles.primary' : '.tiles.secondary').append(renderTile(point));
    } else {
      card.querySelector(primary ? '.states:not(.secondary-states)' : '.secondary-states').append(renderState(point));
    }
  }
  if (state.writesEnabled && device.points.some((p) => p.writable)) {
    const write = card.querySelector('details.write');
    write.hidden = false;
    setUpWriteForm(device, write.querySelector('form'));
  }
  return card;
}

/** The points a device's "Trend" link opens: its live measurements, else its live states. */
function readingsToTrend(device) {
  const live = device.points.filter((p) => isLive(device, p));
  const numbers = live.filter((p) => p.kind.type === 'numeric');
  const chosen = numbers.length ? numbers : live.filter((p) => p.kind.type === 'enum');
  return chosen.slice(0, 4).map((p) => p.id);
}

function renderTile(point) {
  const tile = el('div', 'point');
  tile.id = `point-${point.id}`;
  tile.append(el('span', 'quality'), el('div', 'label', point.name));
  const reading = el('div', 'reading');
  reading.append(el('span', 'value', '—'), el('span', 'unit', point.unit || ''));
  const canvas = el('canvas');
  canvas.dataset.point = point.id;
  tile.append(reading, canvas);
  return tile;
}

function renderState(point) {
  const row = el('li', 'state point');
  row.id = `point-${point.id}`;
  row.append(el('span', 'label', point.name), el('span', 'text value', '—'));
  return row;
}

/** Applies a point's new view; `live` says it came from the stream (extends its plot). */
function updatePoint(view, live = true) {
  const deviceId = view.id.split('.')[0];
  const device = state.devices.get(deviceId);
  if (!device) return;
  const point = Object.assign(device.byId.get(view.id) || {}, view);
  device.byId.set(view.id, point);
  if (live && view.id === `${deviceId}.machine_state`) productionNoticed(deviceId);
  const node = document.getElementById(`point-${view.id}`);
  if (!node) return;
  node.dataset.quality = judge(point);
  node.dataset.alarm = String(Boolean(point.alarm));
  if (widenFormat(point)) reformat(formatKey(point));
  node.querySelector('.value').textContent = shownValue(point);
  const when = point.t ? formatClock(Date.parse(point.t)) : 'never';
  node.title = point.error ? `${point.error} (${when})` : `${point.name}: read ${when}`;
  if (live && point.kind && point.kind.type === 'numeric') {
    const series = state.series.get(view.id) || [];
    const t = point.t ? Date.parse(point.t) : Date.now();
    series.push([t, point.quality === 'good' && typeof point.value === 'number' ? point.value : null]);
    state.series.set(view.id, withinWindow(series, Date.now()));
    state.dirty.add(view.id);
  }
}

/** Shows again every value of a unit whose format widened. */
function reformat(key) {
  for (const device of state.devices.values()) {
    for (const point of device.byId.values()) {
      if (formatKey(point) !== key) continue;
      const node = document.getElementById(`point-${point.id}`);
      if (node) node.querySelector('.value').textContent = shownValue(point);
    }
  }
}

function updateDeviceStatus(summary) {
  const device = state.devices.get(summary.id);
  if (device) Object.assign(device, summary);
  const card = document.getElementById(`device-${summary.id}`);
  if (!card) return;
  card.dataset.status = summary.status;
  card.querySelector('.status-pill').textContent = summary.status;
  card.querySelector('.status-detail').textContent = statusDetail(device || summary);
}

function statusDetail(device) {
  if (device.status === 'down') {
    const reason = device.error ? device.error.message : 'not answering';
    if (device.next_try_at) {
      const seconds = Math.max(0, Math.round((Date.parse(device.next_try_at) - Date.now()) / 1000));
      return `${reason} · next try in ${seconds} s`;
    }
    return reason;
  }
  if (device.status === 'up' && device.since) return `up since ${formatClock(Date.parse(device.since))}`;
  return 'waiting for the first answer';
}

// ---- plots ---------------------------------------------------------------------------

// A plot's history is asked for when it comes into view, at most HISTORY_AT_ONCE at once.
const historyLoads = { queue: [], running: 0, asked: new Set() };

const plotObserver = 'IntersectionObserver' in window
  ? new IntersectionObserver((entries) => {
    for (const entry of entries) {
      if (entry.isIntersecting) seen(entry.target.dataset.point);
      else state.visible.delete(entry.target.dataset.point);
    }
  }, { rootMargin: '200px' })
  : null;

function seen(pointId) {
  state.visible.add(pointId);
  state.dirty.add(pointId);
  if (historyLoads.asked.has(pointId)) return;
  historyLoads.asked.add(pointId);
  historyLoads.queue.push({ pointId, generation: state.generation });
  pumpHistory();
}

function pumpHistory() {
  while (historyLoads.running < HISTORY_AT_ONCE && historyLoads.queue.length) {
    const job = historyLoads.queue.shift();
    if (job.generation !== state.generation) continue;
    historyLoads.running += 1;
    loadHistory(job.pointId, job.generation).finally(() => {
      historyLoads.running -= 1;
      pumpHistory();
    });
  }
}

async function loadHistory(pointId, generation) {
  try {
    const response = await api(`/api/history?point=${encodeURIComponent(pointId)}&from=-10m`);
    // The body is read to its end whatever happens next: until it is, the request is still
    // open, and its turn would be given to the next while it holds a connection.
    const answer = response.ok ? await response.json() : (await response.text(), null);
    if (!answer || generation !== state.generation) return;
    const samples = (answer.before ? [answer.before] : []).concat(answer.samples || []);
    const loaded = samples.map((s) => [
      Date.parse(s.t),
      s.quality === 'good' && typeof s.value === 'number' ? s.value : null,
    ]);
    const live = state.series.get(pointId) || [];
    const start = loaded.length ? loaded[loaded.length - 1][0] : -Infinity;
    state.series.set(pointId, loaded.concat(live.filter(([t]) => t > start)));
    state.dirty.add(pointId);
  } catch (e) {
    console.warn('history', pointId, e);
  }
}

/** `series` without what scrolled out of the plot, keeping the value held at its start. */
function withinWindow(series, now) {
  if (series.length < 2 || series[1][0] >= now - PLOT_WINDOW_MS) return series;
  const firstInside = series.findIndex(([t]) => t >= now - PLOT_WINDOW_MS);
  return firstInside === -1 ? series.slice(-1) : series.slice(Math.max(0, firstInside - 1));
}

/** Values hold until the next change: a step line from the window's start to now. */
function drawPlot(pointId) {
  const tile = document.getElementById(`point-${pointId}`);
  const canvas = tile && tile.querySelector('canvas');
  if (!canvas) return;
  const ratio = window.devicePixelRatio || 1;
  const width = Math.max(1, Math.round(canvas.clientWidth * ratio));
  const height = Math.max(1, Math.round(canvas.clientHeight * ratio));
  if (canvas.width !== width) canvas.width = width;
  if (canvas.height !== height) canvas.height = height;
  const ctx = canvas.getContext('2d');
  ctx.clearRect(0, 0, width, height);
  const now = Date.now();
  const start = now - PLOT_WINDOW_MS;
  const series = withinWindow(state.series.get(pointId) || [], now);
  state.series.set(pointId, series);
  const values = series.map(([, v]) => v).filter((v) => v !== null);
  if (values.length === 0) return;
  let low = Math.min(...values);
  let high = Math.max(...values);
  if (high - low < 1e-9) { low -= 1; high += 1; }
  const pad = (high - low) * 0.1;
  low -= pad; high += pad;
  const x = (t) => ((Math.max(t, start) - start) / PLOT_WINDOW_MS) * width;
  const y = (v) => height - ((v - low) / (high - low)) * height;
  ctx.strokeStyle = getComputedStyle(document.documentElement).getPropertyValue('--accent') || '#58a6ff';
  ctx.lineWidth = 1.5 * ratio;
  ctx.beginPath();
  let drawing = false;
  series.forEach(([t, v], i) => {
    const next = i + 1 < series.length ? series[i + 1][0] : now;
    if (v === null) { drawing = false; return; }
    if (!drawing) ctx.moveTo(x(t), y(v)); else ctx.lineTo(x(t), y(v));
    ctx.lineTo(x(next), y(v));
    drawing = true;
  });
  ctx.stroke();
}

/** Draws the plots on screen that changed; one scrolling into view is drawn then. */
function drawDirtyPlots() {
  for (const id of state.dirty) {
    if (state.visible.has(id)) drawPlot(id);
  }
  state.dirty.clear();
}

function scrollAllPlots() {
  for (const id of state.visible) state.dirty.add(id);
}

// ---- lines and events ----------------------------------------------------------------

/** The line health cards: every line of a small cell, else the lines of the shown devices. */
function renderLines(lines) {
  state.lines = lines;
  state.order = lines.flatMap((line) => line.devices);
  renderLineChoice();
  const container = document.getElementById('lines');
  container.replaceChildren();
  const small = state.order.length <= SMALL_CELL;
  const shownLines = new Set(linesShown(lines));
  for (const line of lines) {
    if (!small && !shownLines.has(line.name)) continue;
    const card = el('div', 'line');
    card.id = `line-${line.name}`;
    card.dataset.open = String(line.open);
    card.append(el('div', 'line-name', `Line ${line.name}${line.open ? '' : ' — not open'}`));
    card.append(el('div', 'line-endpoint', line.endpoint));
    const stats = el('div', 'line-stats');
    stats.append(
      el('span', '', `${formatNumber(Math.round(line.utilisation * 100))} % busy`),
      el('span', '', `${line.polls_per_second.toFixed(1)} polls/s`),
      el('span', '', `${line.errors_per_second.toFixed(2)} errors/s`),
    );
    card.append(stats);
    const meter = el('div', 'meter');
    const fill = el('div');
    fill.style.width = `${Math.min(100, line.utilisation * 100)}%`;
    meter.append(fill);
    card.append(meter);
    if (line.backed_off.length) card.append(el('div', 'backed-off', backedOff(line.backed_off)));
    if (!line.open && line.error) card.append(el('div', 'backed-off', line.error));
    container.append(card);
  }
}

/** The names of the lines with a device on the page. */
function linesShown(lines) {
  return lines.filter((line) => line.devices.some((id) => state.devices.has(id))).map((l) => l.name);
}

/** "backed off: a, b", shortened when a long line has many. */
function backedOff(ids) {
  const named = ids.slice(0, 12).join(', ');
  return `backed off: ${named}${ids.length > 12 ? ` and ${ids.length - 12} more` : ''}`;
}

/** The line selector: every line with its size and trouble, kept in step with the view. */
function renderLineChoice() {
  const select = document.getElementById('line-select');
  const options = [[ALL_LINES, `All lines (${state.order.length} devices)`]].concat(
    state.lines.map((line) => {
      const trouble = !line.open ? ', not open'
        : line.backed_off.length ? `, ${line.backed_off.length} backed off` : '';
      return [line.name, `${line.name} (${line.devices.length}${trouble})`];
    }),
  );
  const same = select.options.length === options.length
    && options.every(([value], i) => select.options[i].value === value);
  if (same) {
    // Only the words change: an open list stays open.
    options.forEach(([, text], i) => {
      if (select.options[i].textContent !== text) select.options[i].textContent = text;
    });
  } else {
    select.replaceChildren(...options.map(([value, text]) => {
      const option = el('option', '', text);
      option.value = value;
      return option;
    }));
  }
  if (state.view) select.value = state.view.line;
}

let linesRefreshed = 0;

/**
 * Every 5 s: the health of the lines on the page; every line's (for the selector) on every
 * 6th turn, or every turn in a small cell.
 */
async function refreshLines() {
  linesRefreshed += 1;
  const shown = linesShown(state.lines);
  const some = state.order.length > SMALL_CELL && linesRefreshed % 6 !== 0
    && shown.length > 0 && shown.length < state.lines.length;
  try {
    const url = some ? `/api/lines?${new URLSearchParams({ line: shown.join(',') })}` : '/api/lines';
    const response = await api(url);
    if (!response.ok) return;
    const { lines } = await response.json();
    if (!some) {
      renderLines(lines);
      return;
    }
    const fresh = new Map(lines.map((line) => [line.name, line]));
    renderLines(state.lines.map((line) => fresh.get(line.name) || line));
  } catch (e) {
    console.warn('lines', e);
  }
}

// ---- the pages: the cell, a trend, production, alarms -------------------------------------

const PAGE_TITLES = { cell: 'cell overview', trend: 'trend', production: 'production', alarms: 'alarms' };

/** The page the address asks for: `#view=trend…`, `#view=production…`, `#view=alarms…`, else the cell. */
function pageFromAddress() {
  const params = new URLSearchParams(window.location.hash.slice(1));
  const view = params.get('view');
  return { page: view in PAGE_TITLES ? view : 'cell', params };
}

/** Shows the page the address asks for (only which is visible, with `load` false). */
function showPage(load = true) {
  const { page, params } = pageFromAddress();
  document.getElementById('cell-view').hidden = page !== 'cell';
  document.getElementById('trend-view').hidden = page !== 'trend';
  document.getElementById('production-view').hidden = page !== 'production';
  document.getElementById('alarms-view').hidden = page !== 'alarms';
  for (const tab of document.querySelectorAll('.pages a')) {
    if (tab.dataset.page === page) tab.setAttribute('aria-current', 'page');
    else tab.removeAttribute('aria-current');
  }
  document.querySelector('.subtitle').textContent = PAGE_TITLES[page];
  document.title = `cellbus · ${PAGE_TITLES[page]}`;
  if (!load) return;
  showTrend(page === 'trend' ? params : null);
  showProduction(page === 'production' ? params : null);
  showAlarms(page === 'alarms' ? params : null);
}

// ---- the view: which devices are shown ------------------------------------------------

function viewFromAddress() {
  const params = new URLSearchParams(window.location.hash.slice(1));
  return {
    line: params.get('line'),
    q: (params.get('q') || '').trim(),
    page: Math.max(1, Number.parseInt(params.get('page'), 10) || 1),
  };
}

/** The view's address: the line unless it is the default "all" of a small cell. */
function addressOf(view) {
  const params = new URLSearchParams();
  const small = state.order.length <= SMALL_CELL;
  if (!(small && view.line === ALL_LINES)) params.set('line', view.line);
  if (view.q) params.set('q', view.q);
  if (view.page > 1) params.set('page', String(view.page));
  const text = params.toString();
  return text ? `#${text}` : window.location.pathname + window.location.search;
}

/** The devices a view matches, in order: a search looks through every line. */
function matching(view) {
  if (view.q) {
    const q = view.q.toLowerCase();
    return state.order.filter((id) => id.toLowerCase().includes(q));
  }
  if (view.line === ALL_LINES) return state.order;
  const line = state.lines.find((l) => l.name === view.line);
  return line ? line.devices : [];
}

/**
 * Shows `wanted` (a view, perhaps from an address: an unknown line becomes the default,
 * the page is clamped) and records it in the address: `how` is 'push' (a new history
 * entry), 'replace' or null (the address is already it). Opens the stream for the shown
 * devices when they changed.
 */
function showView(wanted, how) {
  const known = state.lines.some((l) => l.name === wanted.line) || wanted.line === ALL_LINES;
  const fallback = state.order.length <= SMALL_CELL || state.lines.length === 0
    ? ALL_LINES : state.lines[0].name;
  const view = { line: known ? wanted.line : fallback, q: wanted.q || '', page: wanted.page || 1 };
  const all = matching(view);
  const pages = Math.max(1, Math.ceil(all.length / PAGE_SIZE));
  view.page = Math.min(view.page, pages);
  const from = (view.page - 1) * PAGE_SIZE;
  state.view = view;
  state.shown = all.slice(from, from + PAGE_SIZE);
  const address = addressOf(view);
  const current = window.location.hash || window.location.pathname + window.location.search;
  if (how && address !== current) window.history[`${how}State`](null, '', address);
  document.getElementById('tab-cell').href = address.startsWith('#') ? address : '#';

  document.getElementById('line-select').value = view.line;
  const search = document.getElementById('search');
  if (search.value.trim() !== view.q && document.activeElement !== search) search.value = view.q;
  document.getElementById('shown').textContent = describeView(view, all.length, from);
  document.getElementById('pager').hidden = pages === 1;
  document.getElementById('previous').disabled = view.page === 1;
  document.getElementById('next').disabled = view.page === pages;

  let query;
  if (state.shown.length === state.order.length && !view.q) query = '';
  else if (!view.q && view.line !== ALL_LINES && state.shown.length === all.length) {
    query = new URLSearchParams({ line: view.line }).toString();
  } else query = new URLSearchParams({ device: state.shown.join(',') }).toString();
  if (query !== state.streamQuery) connect(query);
}

function describeView(view, count, from) {
  const where = view.q ? ` whose id contains “${view.q}”`
    : view.line === ALL_LINES ? '' : ` on line ${view.line}`;
  if (count === 0) return view.q ? `No device id contains “${view.q}”` : `No devices${where}`;
  if (count <= PAGE_SIZE) return `${count} device${count === 1 ? '' : 's'}${where}`;
  const to = Math.min(count, from + PAGE_SIZE);
  return `${from + 1}–${to} of ${count} devices${where}`;
}

let searchTimer = null;

function setUpToolbar() {
  document.getElementById('line-select').addEventListener('change', (e) => {
    document.getElementById('search').value = '';
    showView({ line: e.target.value, q: '', page: 1 }, 'push');
  });
  const search = document.getElementById('search');
  const find = () => {
    clearTimeout(searchTimer);
    if (!state.view) return;
    const q = search.value.trim();
    // Starting a search is a new history entry (Back returns to the line); typing on is not.
    showView({ ...state.view, q, page: 1 }, state.view.q || !q ? 'replace' : 'push');
  };
  search.addEventListener('input', () => {
    clearTimeout(searchTimer);
    searchTimer = setTimeout(find, 250);
  });
  search.addEventListener('keydown', (e) => {
    if (e.key === 'Enter') find();
  });
  const turn = (by) => {
    if (state.view) showView({ ...state.view, page: state.view.page + by }, 'push');
    window.scrollTo(0, 0);
  };
  document.getElementById('previous').addEventListener('click', () => turn(-1));
  document.getElementById('next').addEventListener('click', () => turn(1));
  // Back, forward, or an address typed or pasted.
  const follow = () => {
    if (!state.view) return;
    if (pageFromAddress().page === 'cell') showView(viewFromAddress(), null);
    showPage();
  };
  window.addEventListener('popstate', follow);
  window.addEventListener('hashchange', follow);
}

// The cell's summary, the MQTT and IPC-CFX links and the OPC UA server as /healthz says
// them (the interfaces hidden when the gateway does not serve them).
async function refreshHealth() {
  try {
    const response = await api('/healthz');
    // 503 is a failing gateway's health, still to be read.
    if (!response.ok && response.status !== 503) return;
    const health = await response.json();
    showCellSummary(health);
    const link = health.mqtt;
    const badge = document.getElementById('mqtt');
    badge.hidden = !link;
    if (link) {
      const connected = link === 'connected';
      badge.dataset.state = connected ? 'live' : 'lost';
      badge.textContent = connected ? 'MQTT' : 'MQTT down';
      badge.title = `MQTT ${link}`;
    }
    // IPC-CFX: "connected to URL" or "disconnected: why", then "; N messages wait".
    const cfx = health.cfx;
    const endpoint = document.getElementById('cfx');
    endpoint.hidden = !cfx;
    if (cfx) {
      const connected = cfx.startsWith('connected');
      const waiting = /; (\d+) messages? waits?$/.exec(cfx);
      endpoint.dataset.state = connected ? 'live' : 'lost';
      endpoint.textContent = (connected ? 'CFX' : 'CFX down') +
        (waiting ? ` · ${waiting[1]} waiting` : '');
      endpoint.title = `IPC-CFX ${cfx}`;
    }
    const opcua = health.opcua;
    const served = document.getElementById('opcua');
    served.hidden = !opcua;
    if (opcua) {
      served.dataset.state = 'live';
      const sessions = opcua.sessions === 1 ? '1 session' : `${opcua.sessions} sessions`;
      served.textContent = `OPC UA · ${sessions}`;
      served.title = `OPC UA on ${opcua.endpoint}: ${sessions}, ` +
        `${opcua.subscriptions} subscriptions, ${opcua.monitored_items} monitored items`;
    }
  } catch (e) {
    console.warn('healthz', e);
  }
}

/** /healthz again within half a second: many devices going down at once ask once. */
let healthDue = null;

function healthSoon() {
  if (healthDue) return;
  healthDue = setTimeout(() => {
    healthDue = null;
    refreshHealth();
  }, 500);
}

/** The header's word on the whole cell: devices up, the lines not open, the health. */
function showCellSummary(health) {
  const summary = document.getElementById('cell-summary');
  if (!summary || typeof health.devices !== 'number') return;
  let words = `${health.devices_up} of ${health.devices} devices up`;
  const reasons = health.reasons || [];
  const closed = reasons
    .filter((r) => r.startsWith('line '))
    .map((r) => r.split(' ')[1]);
  if (closed.length) words += ` · line${closed.length > 1 ? 's' : ''} ${closed.join(', ')} down`;
  summary.textContent = words;
  summary.dataset.state = health.status || 'ok';
  summary.title = reasons.length ? reasons.join('\n') : 'All devices answer; the history is written.';
}

function addEvent(event, atTop = true) {
  if (atTop && event.kind && /^(interface_|device_|line_|history_|config_)/.test(event.kind)) healthSoon();
  // The configuration was reloaded: devices and lines may have come and gone.
  if (atTop && event.kind === 'config_reloaded' && source) connect(state.streamQuery);
  if (atTop && event.kind && event.kind.startsWith('alarm_')) alarmsNoticed();
  const list = document.getElementById('events');
  const item = el('li');
  item.dataset.kind = event.kind;
  const time = el('time', '', formatClock(Date.parse(event.t)));
  time.dateTime = event.t;
  item.append(time, el('span', '', event.message));
  if (atTop) list.prepend(item); else list.append(item);
  while (list.children.length > MAX_EVENTS) list.lastElementChild.remove();
}

async function loadEvents() {
  try {
    const response = await api('/api/events?limit=50');
    if (!response.ok) return;
    const list = document.getElementById('events');
    list.replaceChildren();
    for (const event of (await response.json()).events) addEvent(event, false);
  } catch (e) {
    console.warn('events', e);
  }
}

// ---- writes --------------------------------------------------------------------------

function setUpWriteForm(device, form) {
  const select = form.querySelector('select[name=point]');
  const holder = form.querySelector('.value-input');
  const result = form.querySelector('output');
  const token = form.querySelector('input[name=token]');
  token.value = sessionStorage.getItem('cellbus-token') || '';
  const writable = device.points.filter((p) => p.writable);
  for (const point of writable) {
    const range = point.kind.type === 'enum' ? '' : ` (${point.writable.min} to ${point.writable.max}${point.unit ? ' ' + point.unit : ''})`;
    const option = el('option', '', `${point.name}${range}`);
    option.value = point.id;
    select.append(option);
  }
  const showInput = () => {
    const point = writable.find((p) => p.id === select.value);
    holder.replaceChildren();
    if (!point) return;
    let input;
    if (point.kind.type === 'enum') {
      input = el('select');
      for (const s of point.kind.states) {
        if (s.value < point.writable.min || s.value > point.writable.max) continue;
        const option = el('option', '', s.label);
        option.value = String(s.value);
        input.append(option);
      }
    } else {
      input = el('input');
      input.type = 'number';
      input.min = point.writable.min;
      input.max = point.writable.max;
      input.step = point.writable.integer ? '1' : (point.writable.step ? String(point.writable.step) : 'any');
      input.required = true;
      const current = device.byId.get(point.id);
      if (current && typeof current.value === 'number') input.value = current.value;
    }
    input.name = 'value';
    holder.append(input);
  };
  select.addEventListener('change', showInput);
  showInput();
  form.addEventListener('submit', async (e) => {
    e.preventDefault();
    sessionStorage.setItem('cellbus-token', token.value);
    const value = Number(form.querySelector('[name=value]').value);
    result.textContent = 'writing…';
    result.dataset.ok = '';
    try {
      const response = await fetch(`/api/devices/${encodeURIComponent(device.id)}/write`, {
        method: 'POST',
        headers: { 'Content-Type': 'application/json', Authorization: `Bearer ${token.value}` },
        body: JSON.stringify({ point: select.value, value }),
      });
      const body = await response.json();
      result.dataset.ok = String(response.ok);
      result.textContent = response.ok ? body.detail : body.error;
    } catch (err) {
      result.dataset.ok = 'false';
      result.textContent = `the gateway did not answer: ${err}`;
    }
  });
}

// ---- the read token ------------------------------------------------------------------

// A gateway started with a read token answers 401 to the API without it: the page asks
// for it once and keeps it for the browser tab.
const READ_TOKEN_KEY = 'cellbus-read-token';

function readToken() {
  return sessionStorage.getItem(READ_TOKEN_KEY) || '';
}

async function api(url, options = {}) {
  const send = () => {
    const headers = { ...(options.headers || {}) };
    const read = readToken();
    if (read && !headers.Authorization) headers.Authorization = `Bearer ${read}`;
    return fetch(url, { ...options, headers });
  };
  let response = await send();
  if (response.status === 401 && askReadToken()) response = await send();
  return response;
}

let asked = false;

function askReadToken() {
  if (asked) return false;
  asked = true;
  const given = window.prompt('This gateway needs its read token:');
  if (!given) return false;
  sessionStorage.setItem(READ_TOKEN_KEY, given.trim());
  return true;
}

// ---- the stream ----------------------------------------------------------------------

/** The event stream's path. */
const STREAM = '/api/events/stream';

let source = null;

/** Follows the stream for the devices `query` selects ('' for all); closes the last one. */
function connect(query) {
  if (source) source.close();
  state.streamQuery = query;
  const connection = document.getElementById('connection');
  const params = new URLSearchParams(query);
  const read = readToken();
  if (read) params.set('token', read);
  const rest = params.toString();
  const opened = new EventSource(rest ? `${STREAM}?${rest}` : STREAM);
  source = opened;
  opened.onopen = () => {
    connection.dataset.state = 'live';
    connection.textContent = 'live';
  };
  opened.onerror = () => {
    if (source !== opened) return;
    connection.dataset.state = 'lost';
    connection.textContent = 'reconnecting…';
    // Refused for good (a read token is needed): ask for it once, then start again.
    if (opened.readyState === EventSource.CLOSED) {
      api('/api/lines').then((response) => {
        if (response.ok && source === opened) connect(query);
      }, () => {});
    }
  };
  opened.addEventListener('snapshot', (e) => {
    const snapshot = JSON.parse(e.data);
    state.writesEnabled = snapshot.writes_enabled;
    document.getElementById('writes-badge').hidden = !snapshot.writes_enabled;
    state.lines = snapshot.lines;
    state.order = snapshot.lines.flatMap((line) => line.devices);
    renderLineChoice();
    renderDevices(snapshot.devices);
    renderLines(snapshot.lines);
    loadEvents();
    productionSnapshot();
    refreshAlarms();
  });
  opened.addEventListener('value', (e) => updatePoint(JSON.parse(e.data)));
  opened.addEventListener('device', (e) => updateDeviceStatus(JSON.parse(e.data)));
  opened.addEventListener('event', (e) => addEvent(JSON.parse(e.data)));
  opened.addEventListener('lagged', () => {
    // We missed changes: start over with a fresh snapshot.
    if (source === opened) connect(query);
  });
}

function tick() {
  document.getElementById('clock').textContent = formatClock(Date.now());
  for (const device of state.devices.values()) {
    const card = document.getElementById(`device-${device.id}`);
    if (card) card.querySelector('.status-detail').textContent = statusDetail(device);
  }
}

/** Learns the cell's lines (asking for the read token if needed), then shows the view. */
async function start() {
  let why;
  try {
    const response = await api('/api/lines');
    if (response.ok) {
      const { lines } = await response.json();
      state.lines = lines;
      state.order = lines.flatMap((line) => line.devices);
      renderLineChoice();
      // The cell's view is recorded in the address only when it is the page shown.
      showView(viewFromAddress(), pageFromAddress().page === 'cell' ? 'replace' : null);
      showPage();
      return;
    }
    why = response.status === 401 ? 'This gateway needs its read token: reload the page to give it.'
      : `The gateway answered ${response.status}; trying again…`;
  } catch (e) {
    why = `The gateway does not answer (${e}); trying again…`;
  }
  document.getElementById('devices').replaceChildren(el('p', 'placeholder', why));
  setTimeout(start, 3000);
}

setUpToolbar();
setUpTrend();
setUpProduction();
setUpAlarms();
showPage(false);
start();
tick();
setInterval(tick, 1000);
setInterval(refreshLines, 5000);
refreshHealth();
setInterval(refreshHealth, 10000);
setInterval(scrollAllPlots, 2000);
(function frame() {
  drawDirtyPlots();
  requestAnimationFrame(frame);
})();
