// cellbus cell overview: everything comes from the gateway's event stream
// (/api/events/stream); plots start from /api/history and grow with live values.
//
// DOM contract (for tests and other tools): each device is <section class="device"
// id="device-ID" data-status="up|down|connecting">; each point is an element with
// id="point-DEVICE.POINT" and data-quality="good|stale|bad|none", whose .value child
// shows the live value.
'use strict';

const PLOT_WINDOW_MS = 10 * 60 * 1000;
const MAX_EVENTS = 200;

const state = {
  writesEnabled: false,
  devices: new Map(), // id -> device (with points by id in .byId)
  series: new Map(),  // point id -> [[t_ms, value|null], ...]
  dirty: new Set(),   // point ids whose plot needs drawing
  lines: [],
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
  if (Number.isInteger(value)) return String(value);
  return value.toFixed(Math.abs(value) < 10 ? 2 : 1);
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
  return formatNumber(point.value);
}

function fastestPeriod(device) {
  return Math.min(...device.groups.map((g) => g.period_ms));
}

// ---- devices -------------------------------------------------------------------------

function renderDevices(devices) {
  const container = document.getElementById('devices');
  container.replaceChildren();
  state.devices.clear();
  if (devices.length === 0) {
    container.append(el('p', 'placeholder', 'No devices are configured.'));
    return;
  }
  for (const device of devices) {
    device.byId = new Map(device.points.map((p) => [p.id, p]));
    state.devices.set(device.id, device);
    container.append(renderDevice(device));
    updateDeviceStatus(device);
    for (const point of device.points) updatePoint(point, false);
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
  const fastest = fastestPeriod(device);
  for (const point of device.points) {
    const primary = point.period_ms === fastest;
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

function renderTile(point) {
  const tile = el('div', 'point');
  tile.id = `point-${point.id}`;
  tile.append(el('span', 'quality'), el('div', 'label', point.name));
  const reading = el('div', 'reading');
  reading.append(el('span', 'value', '—'), el('span', 'unit', point.unit || ''));
  tile.append(reading, el('canvas'));
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
  const node = document.getElementById(`point-${view.id}`);
  if (!node) return;
  node.dataset.quality = judge(point);
  node.dataset.alarm = String(Boolean(point.alarm));
  node.querySelector('.value').textContent = shownValue(point);
  const when = point.t ? formatClock(Date.parse(point.t)) : 'never';
  node.title = point.error ? `${point.error} (${when})` : `${point.name}: read ${when}`;
  if (live && point.kind && point.kind.type === 'numeric') {
    const series = state.series.get(view.id) || [];
    const t = point.t ? Date.parse(point.t) : Date.now();
    series.push([t, point.quality === 'good' && typeof point.value === 'number' ? point.value : null]);
    state.series.set(view.id, series);
    state.dirty.add(view.id);
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

async function loadHistory(pointId) {
  try {
    const response = await api(`/api/history?point=${encodeURIComponent(pointId)}&from=-10m`);
    if (!response.ok) return;
    const history = await response.json();
    const samples = (history.before ? [history.before] : []).concat(history.samples || []);
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
  let series = state.series.get(pointId) || [];
  // Drop what scrolled out, keeping the one value held at the window's start.
  const firstInside = series.findIndex(([t]) => t >= start);
  if (firstInside > 1) series = series.slice(firstInside - 1);
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

function drawDirtyPlots() {
  for (const id of state.dirty) drawPlot(id);
  state.dirty.clear();
}

function scrollAllPlots() {
  for (const id of state.series.keys()) state.dirty.add(id);
}

// ---- lines and events ----------------------------------------------------------------

function renderLines(lines) {
  state.lines = lines;
  const container = document.getElementById('lines');
  container.replaceChildren();
  for (const line of lines) {
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
    if (line.backed_off.length) card.append(el('div', 'backed-off', `backed off: ${line.backed_off.join(', ')}`));
    if (!line.open && line.error) card.append(el('div', 'backed-off', line.error));
    container.append(card);
  }
}

async function refreshLines() {
  try {
    const response = await api('/api/lines');
    if (response.ok) renderLines((await response.json()).lines);
  } catch (e) {
    console.warn('lines', e);
  }
}

// The MQTT link and the OPC UA server as /healthz says them (each hidden when the
// gateway does not serve it).
async function refreshMqtt() {
  try {
    const response = await api('/healthz');
    if (!response.ok) return;
    const health = await response.json();
    const link = health.mqtt;
    const badge = document.getElementById('mqtt');
    badge.hidden = !link;
    if (link) {
      const connected = link === 'connected';
      badge.dataset.state = connected ? 'live' : 'lost';
      badge.textContent = connected ? 'MQTT' : 'MQTT down';
      badge.title = `MQTT ${link}`;
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

function addEvent(event, atTop = true) {
  if (atTop && event.kind && event.kind.startsWith('mqtt_')) refreshMqtt();
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

let source = null;

function connect() {
  const connection = document.getElementById('connection');
  const read = readToken();
  source = new EventSource(
    read ? `/api/events/stream?token=${encodeURIComponent(read)}` : '/api/events/stream',
  );
  source.onopen = () => {
    connection.dataset.state = 'live';
    connection.textContent = 'live';
  };
  source.onerror = () => {
    connection.dataset.state = 'lost';
    connection.textContent = 'reconnecting…';
    // Refused for good (a read token is needed): ask for it once, then start again.
    if (source.readyState === EventSource.CLOSED) {
      api('/api/lines').then((response) => {
        if (response.ok) connect();
      }, () => {});
    }
  };
  source.addEventListener('snapshot', (e) => {
    const snapshot = JSON.parse(e.data);
    state.writesEnabled = snapshot.writes_enabled;
    document.getElementById('writes-badge').hidden = !snapshot.writes_enabled;
    renderDevices(snapshot.devices);
    renderLines(snapshot.lines);
    loadEvents();
    for (const device of snapshot.devices) {
      for (const point of device.points) {
        if (point.kind.type === 'numeric') loadHistory(point.id);
      }
    }
  });
  source.addEventListener('value', (e) => updatePoint(JSON.parse(e.data)));
  source.addEventListener('device', (e) => updateDeviceStatus(JSON.parse(e.data)));
  source.addEventListener('event', (e) => addEvent(JSON.parse(e.data)));
  source.addEventListener('lagged', () => {
    // We missed changes: start over with a fresh snapshot.
    source.close();
    connect();
  });
}

function tick() {
  document.getElementById('clock').textContent = formatClock(Date.now());
  for (const device of state.devices.values()) {
    const card = document.getElementById(`device-${device.id}`);
    if (card) card.querySelector('.status-detail').textContent = statusDetail(device);
  }
}

connect();
tick();
setInterval(tick, 1000);
setInterval(refreshLines, 5000);
refreshMqtt();
setInterval(refreshMqtt, 10000);
setInterval(scrollAllPlots, 2000);
(function frame() {
  drawDirtyPlots();
  requestAnimationFrame(frame);
})();
