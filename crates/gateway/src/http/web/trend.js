// cellbus trend view: any numeric points of the cell on one time axis, one y axis per
// unit, drawn by uPlot (vendored in /vendor, MIT) from /api/history's buckets.
//
// The view is in the address: `#view=trend&points=A,B&range=1h` follows the last hour (a
// range ending now, asked again every 10 s), `…&from=TIME&to=TIME` is a fixed span (after
// a zoom or a move). Every zoom or move asks /api/history again for the visible span, in
// buckets about two pixels wide (whole minutes, from the per-minute rollups, from 5 h).
//
// DOM contract (for tests): #trend-chosen holds an <li data-point="ID"> per point;
// #trend-plot the chart; #trend-span the shown span as text, and data-from / data-to its
// ends in ms since the epoch.
//
// Loaded before app.js: only definitions here; app.js shows the view (showTrend).
'use strict';

/** The ranges offered, ending now. */
const TREND_RANGES = { '10m': 600e3, '1h': 3600e3, '8h': 8 * 3600e3, '24h': 86400e3, '7d': 7 * 86400e3, '30d': 30 * 86400e3 };
/** The range a trend opens with. */
const TREND_DEFAULT_RANGE = '1h';
/** Most points in one trend. */
const TREND_MAX_POINTS = 8;
/** The shortest and longest span a zoom or move may show. */
const TREND_MIN_SPAN = 10e3;
const TREND_MAX_SPAN = 30 * 86400e3;
/** A trend ending now is asked for again this often. */
const TREND_REFRESH_MS = 10e3;
/** Bucket widths offered to the gateway, in ms: the smallest that gives about a pixel. */
const TREND_STEPS = [
  100, 200, 500, 1e3, 2e3, 5e3, 10e3, 15e3, 30e3, 60e3, 120e3, 300e3, 600e3, 900e3,
  1800e3, 3600e3, 7200e3, 10800e3, 21600e3, 43200e3, 86400e3,
];
/** Series colours, distinct on the dark background. */
const TREND_COLOURS = ['#58a6ff', '#f0883e', '#3fb950', '#d2a8ff', '#ff7b72', '#e3b341', '#39c5cf', '#db61a2'];

const trend = {
  shown: false,
  points: [],          // point ids, in the order chosen
  range: TREND_DEFAULT_RANGE, // a range ending now ('1h'), or null for from..to
  base: TREND_DEFAULT_RANGE,  // the last range chosen: what "Reset zoom" goes back to
  from: null,          // ms: the span shown (a fixed one, or the last answer's)
  to: null,
  catalog: new Map(),  // point id -> { id, name, unit, kind, device }
  asked: new Set(),    // device ids whose points were asked for
  plot: null,          // the uPlot
  plotKey: '',         // the points and units the plot was built for
  data: null,          // [times, ...series] as drawn
  load: 0,             // counts loads: an older load's answers are dropped
  timer: null,
  moving: false,       // a move or pinch is under way (no refresh meanwhile)
};

// ---- the address ----------------------------------------------------------------------

/** The trend an address asks for (`params`: its hash's parameters). */
function trendFromAddress(params) {
  const points = (params.get('points') || '').split(',').map((p) => p.trim()).filter(Boolean);
  const from = Date.parse(params.get('from') || '');
  const to = Date.parse(params.get('to') || '');
  const fixed = Number.isFinite(from) && Number.isFinite(to) && from < to;
  const range = params.get('range');
  return {
    points: [...new Set(points)].slice(0, TREND_MAX_POINTS),
    range: fixed ? null : (range in TREND_RANGES ? range : TREND_DEFAULT_RANGE),
    from: fixed ? from : null,
    to: fixed ? to : null,
  };
}

/** The address of the trend shown. */
function trendAddress() {
  const params = new URLSearchParams({ view: 'trend' });
  if (trend.points.length) params.set('points', trend.points.join(','));
  if (trend.range) params.set('range', trend.range);
  else {
    params.set('from', new Date(trend.from).toISOString());
    params.set('to', new Date(trend.to).toISOString());
  }
  return `#${params.toString().replaceAll('%2C', ',').replaceAll('%3A', ':')}`;
}

/** Records the trend in the address: a new history entry (`push`) or in place. */
function recordTrend(push) {
  const address = trendAddress();
  if (address === window.location.hash) return;
  window.history[push ? 'pushState' : 'replaceState'](null, '', address);
  trendTab();
}

/** The Trend tab goes back to the last trend shown. */
function trendTab() {
  if (trend.points.length) document.getElementById('tab-trend').href = trendAddress();
}

// ---- showing it -------------------------------------------------------------------------

/** Shows the trend the address asks for (`params`), or hides it (`null`). */
function showTrend(params) {
  trend.shown = Boolean(params);
  clearInterval(trend.timer);
  trend.timer = null;
  if (!params) return;
  const wanted = trendFromAddress(params);
  const same = wanted.points.join() === trend.points.join() && wanted.range === trend.range
    && (wanted.range || (wanted.from === trend.from && wanted.to === trend.to));
  Object.assign(trend, wanted);
  if (wanted.range) trend.base = wanted.range;
  trend.timer = setInterval(refreshTrend, TREND_REFRESH_MS);
  trendTab();
  renderTrendControls();
  // Back to a fixed span already drawn: nothing to ask (a range ending now has moved on).
  if (same && trend.plot && !trend.range) {
    resizeTrend();
    return;
  }
  describePoints(trend.points).then(() => {
    renderChosen();
    loadTrend();
  });
}

function refreshTrend() {
  if (trend.shown && trend.range && !trend.moving && !document.hidden) loadTrend();
}

/** Makes the trend `points` over `range` (or from..to), recorded in the address. */
function setTrend(changes, push = true) {
  Object.assign(trend, changes);
  if (changes.range) trend.base = changes.range;
  recordTrend(push);
  renderTrendControls();
  renderChosen();
  loadTrend();
}

function renderTrendControls() {
  for (const button of document.querySelectorAll('#trend-view [data-range]')) {
    button.setAttribute('aria-pressed', String(button.dataset.range === trend.range));
  }
  document.getElementById('trend-reset').disabled = trend.range === trend.base;
  const none = trend.points.length === 0;
  for (const id of ['trend-earlier', 'trend-later', 'trend-out', 'trend-csv']) {
    document.getElementById(id).disabled = none;
  }
}

// ---- the points -------------------------------------------------------------------------

/** Whether a point can be plotted: a number (a measurement, or an enumeration's value). */
function plottable(point) {
  return point.kind && (point.kind.type === 'numeric' || point.kind.type === 'enum');
}

function addToCatalog(device) {
  for (const point of device.points || []) {
    if (!plottable(point)) continue;
    trend.catalog.set(point.id, {
      id: point.id, name: point.name, unit: point.unit || '', kind: point.kind,
      device: device.id, deviceName: device.name,
    });
  }
}

/** Learns the names and units of the devices' points (those on the cell view are known). */
async function describeDevices(ids) {
  for (const device of state.devices.values()) {
    if (!trend.asked.has(device.id)) {
      trend.asked.add(device.id);
      addToCatalog(device);
    }
  }
  const missing = [...new Set(ids)].filter((id) => !trend.asked.has(id) && state.order.includes(id));
  if (!missing.length) return;
  missing.forEach((id) => trend.asked.add(id));
  try {
    const query = new URLSearchParams({ device: missing.join(','), fields: 'id,name,points' });
    const response = await api(`/api/devices?${query}`);
    if (!response.ok) return;
    for (const device of (await response.json()).devices) addToCatalog(device);
  } catch (e) {
    console.warn('devices', e);
    missing.forEach((id) => trend.asked.delete(id));
  }
}

function describePoints(ids) {
  return describeDevices(ids.map((id) => id.split('.')[0]));
}

function pointLabel(id) {
  const point = trend.catalog.get(id);
  if (!point) return id;
  return `${point.device} · ${point.name}${point.unit ? ` (${point.unit})` : ''}`;
}

function renderChosen() {
  const list = document.getElementById('trend-chosen');
  list.replaceChildren(...trend.points.map((id, i) => {
    const item = el('li', 'chip');
    item.dataset.point = id;
    item.title = id;
    const swatch = el('span', 'swatch');
    swatch.style.background = TREND_COLOURS[i % TREND_COLOURS.length];
    const remove = el('button', 'remove', '×');
    remove.type = 'button';
    remove.setAttribute('aria-label', `Remove ${pointLabel(id)}`);
    remove.addEventListener('click', () => {
      setTrend({ points: trend.points.filter((p) => p !== id) });
    });
    item.append(swatch, el('span', '', pointLabel(id)), remove);
    return item;
  }));
  const find = document.getElementById('trend-find');
  find.disabled = trend.points.length >= TREND_MAX_POINTS;
  find.placeholder = find.disabled ? `At most ${TREND_MAX_POINTS} points in one trend`
    : 'Add a point: device id or point name…';
}

/** The points whose id, name or unit contain every word of `text`, at most `most`. */
function findPoints(text, most) {
  const words = text.toLowerCase().split(/\s+/).filter(Boolean);
  const found = [];
  for (const point of trend.catalog.values()) {
    if (trend.points.includes(point.id)) continue;
    const haystack = `${point.id} ${point.name} ${point.unit} ${point.deviceName}`.toLowerCase();
    if (words.every((w) => haystack.includes(w))) found.push(point);
    if (found.length >= most) break;
  }
  return found;
}

let findTimer = null;

async function showMatches() {
  const find = document.getElementById('trend-find');
  const list = document.getElementById('trend-matches');
  const text = find.value.trim();
  if (!text) {
    list.hidden = true;
    return;
  }
  // The devices whose id the first word is part of (the cell view knows some already).
  const first = text.toLowerCase().split(/[\s.]+/)[0];
  await describeDevices(state.order.filter((id) => id.toLowerCase().includes(first)).slice(0, 20));
  if (find.value.trim() !== text) return;
  const found = findPoints(text, 30);
  list.replaceChildren(...found.map((point) => {
    const item = el('li');
    const button = el('button', '', pointLabel(point.id));
    button.type = 'button';
    button.dataset.point = point.id;
    button.addEventListener('click', () => {
      find.value = '';
      list.hidden = true;
      if (trend.points.length < TREND_MAX_POINTS) setTrend({ points: [...trend.points, point.id] });
      find.focus();
    });
    item.append(button);
    return item;
  }));
  if (!found.length) list.append(el('li', 'placeholder', `No point matches “${text}”.`));
  list.hidden = false;
}

// ---- the history --------------------------------------------------------------------------

/** The plot area's width in CSS pixels (the page's, before the plot exists). */
function plotWidth() {
  if (trend.plot) return trend.plot.bbox.width / (window.devicePixelRatio || 1);
  return Math.max(200, document.getElementById('trend-plot').clientWidth - 120);
}

/** The bucket width for `span` ms over the plot: the first step that gives ≤ 1 per 2 pixels. */
function stepFor(span) {
  const wanted = span / Math.max(50, plotWidth() / 2);
  return TREND_STEPS.find((s) => s >= wanted) || TREND_STEPS[TREND_STEPS.length - 1];
}

function stepText(ms) {
  if (ms < 1e3) return `${ms}ms`;
  return `${ms / 1e3}s`;
}

/** Asks /api/history for every point over the span shown, then draws. */
async function loadTrend() {
  trend.load += 1;
  const load = trend.load;
  const note = document.getElementById('trend-note');
  if (!trend.points.length) {
    drawTrend(null);
    note.textContent = 'Choose the points to plot: type a device id or a point name above.';
    return;
  }
  const span = trend.range ? TREND_RANGES[trend.range] : trend.to - trend.from;
  const step = stepFor(span);
  const times = trend.range
    ? { from: `-${trend.range}`, to: 'now' }
    : { from: new Date(trend.from).toISOString(), to: new Date(trend.to).toISOString() };
  const answers = await Promise.all(trend.points.map(async (point) => {
    const query = new URLSearchParams({ point, ...times, step: stepText(step) });
    try {
      const response = await api(`/api/history?${query}`);
      const body = await response.json();
      return response.ok ? body : { point, error: body.error || `answered ${response.status}` };
    } catch (e) {
      return { point, error: `the gateway did not answer (${e})` };
    }
  }));
  if (load !== trend.load || !trend.shown) return;
  const good = answers.filter((a) => !a.error);
  const errors = answers.filter((a) => a.error).map((a) => `${a.point}: ${a.error}`);
  if (good.length) {
    trend.from = Math.min(...good.map((a) => Date.parse(a.from)));
    trend.to = Math.max(...good.map((a) => Date.parse(a.to)));
  }
  note.textContent = errors.join(' · ');
  drawTrend(good.length ? align(answers, trend.from, trend.to) : null, step);
}

/** A bucket's or sample's number, or null (no good numeric value). */
function heldValue(sample) {
  if (!sample) return null;
  if ('avg' in sample) return sample.avg;
  return sample.quality === 'good' && typeof sample.value === 'number' ? sample.value : null;
}

/**
 * One table from the answers: the times of every bucket (and the span's ends), each
 * series' value at each (a value holds until the next bucket: buckets without a change are
 * left out). A point whose answer failed is a series of nulls.
 */
function align(answers, from, to) {
  const times = new Set([from, to]);
  for (const answer of answers) {
    for (const b of answer.buckets || []) times.add(Date.parse(b.t));
  }
  const xs = [...times].filter((t) => t >= from && t <= to).sort((a, b) => a - b);
  const columns = answers.map((answer) => {
    const buckets = (answer.buckets || []).map((b) => [Date.parse(b.t), b.avg]);
    let next = 0;
    let held = heldValue(answer.before);
    return xs.map((t) => {
      while (next < buckets.length && buckets[next][0] <= t) {
        held = buckets[next][1];
        next += 1;
      }
      return held;
    });
  });
  return [xs, ...columns];
}

// ---- the chart ----------------------------------------------------------------------------

/** The scale a point's values are drawn on: its unit's (an enumeration has its own). */
function scaleOf(id) {
  const point = trend.catalog.get(id);
  if (point && point.kind.type === 'enum') return `enum:${id}`;
  return `unit:${point ? point.unit : ''}`;
}

function cssVar(name, fallback) {
  return getComputedStyle(document.documentElement).getPropertyValue(name).trim() || fallback;
}

function formatTrendValue(id, value) {
  if (value === null || value === undefined) return '—';
  const point = trend.catalog.get(id);
  if (point && point.kind.type === 'enum') {
    const named = (point.kind.states || []).find((s) => s.value === value);
    if (named) return named.label;
  }
  return `${formatNumber(Math.round(value * 1000) / 1000)}${point && point.unit ? ` ${point.unit}` : ''}`;
}

function plotHeight() {
  return window.innerWidth < 600 ? 260 : 380;
}

/** The chart's options for the points shown: a y axis per scale, left then right. */
function plotOptions() {
  const muted = cssVar('--muted', '#8b98a5');
  const grid = cssVar('--line', '#2a3440');
  const scales = { x: { time: true, auto: false } };
  const axes = [{
    stroke: muted, grid: { stroke: grid, width: 1 }, ticks: { stroke: grid, width: 1 },
    values: timeTicks, size: 46, space: 80,
  }];
  const series = [{ label: 'Time', value: (u, t) => (t === null ? '—' : formatWhen(t, true)) }];
  const stepped = uPlot.paths.stepped({ align: 1 });
  trend.points.forEach((id, i) => {
    const scale = scaleOf(id);
    if (!scales[scale]) {
      scales[scale] = { auto: true };
      const point = trend.catalog.get(id);
      const enumeration = point && point.kind.type === 'enum';
      const axis = {
        scale,
        side: Object.keys(scales).length % 2 === 0 ? 3 : 1,
        stroke: muted,
        grid: { show: Object.keys(scales).length === 2, stroke: grid, width: 1 },
        ticks: { stroke: grid, width: 1 },
        label: enumeration ? point.name : (point && point.unit) || 'no unit',
        labelSize: 20,
        size: 56,
      };
      if (enumeration) {
        const labels = (point.kind.states || []).map((s) => s.label);
        axis.values = (u, splits) => splits.map((v) => formatTrendValue(id, v));
        axis.size = Math.min(170, 20 + 7 * Math.max(4, ...labels.map((l) => l.length)));
        axis.splits = (u, index, min, max) => enumSplits(u, scale, point.kind.states || [], min, max);
        scales[scale].range = (u, low, high) => [Math.min(low, 0) - 0.5, Math.max(high, 1) + 0.5];
      }
      axes.push(axis);
    }
    series.push({
      label: pointLabel(id),
      scale,
      stroke: TREND_COLOURS[i % TREND_COLOURS.length],
      width: 1.5,
      paths: stepped,
      points: { show: false },
      value: (u, v) => formatTrendValue(id, v),
    });
  });
  return {
    width: Math.max(200, document.getElementById('trend-plot').clientWidth),
    height: plotHeight(),
    ms: 1,
    scales,
    axes,
    series,
    legend: { live: true },
    cursor: {
      drag: { x: true, y: false, setScale: false },
      // A plain drag zooms (uPlot's selection); shift or the middle button moves instead.
      bind: {
        mousedown: (u, target, handler) => (e) => {
          if (e.button === 0 && !e.shiftKey && e.target === target) handler(e);
        },
      },
    },
    hooks: {
      setSelect: [(u) => {
        if (u.select.width < 4) return;
        const from = u.posToVal(u.select.left, 'x');
        const to = u.posToVal(u.select.left + u.select.width, 'x');
        u.setSelect({ left: 0, top: 0, width: 0, height: 0 }, false);
        zoomTrend(from, to);
      }],
    },
  };
}

/** An enumeration's values within min..max, at least 16 px apart on its axis. */
function enumSplits(u, scale, states, min, max) {
  const kept = [];
  let last = null;
  for (const value of states.map((s) => s.value).filter((v) => v >= min && v <= max).sort((a, b) => a - b)) {
    const at = u.valToPos(value, scale);
    if (last === null || Math.abs(at - last) >= 16) {
      kept.push(value);
      last = at;
    }
  }
  return kept;
}

/** Draws `data` (null: nothing to draw), building the chart when its points changed. */
function drawTrend(data, step) {
  trend.data = data;
  const holder = document.getElementById('trend-plot');
  const key = trend.points.map((id) => `${id}:${scaleOf(id)}`).join();
  if (!data) {
    if (trend.plot) trend.plot.destroy();
    trend.plot = null;
    trend.plotKey = '';
    holder.replaceChildren();
    describeSpan(step);
    return;
  }
  if (!trend.plot || trend.plotKey !== key) {
    if (trend.plot) trend.plot.destroy();
    holder.replaceChildren();
    trend.plot = new uPlot(plotOptions(), data, holder);
    trend.plotKey = key;
    attachGestures(trend.plot);
  } else {
    trend.plot.setData(data);
  }
  trend.plot.setScale('x', { min: trend.from, max: trend.to });
  describeSpan(step);
}

function resizeTrend() {
  if (!trend.plot) return;
  const width = Math.max(200, document.getElementById('trend-plot').clientWidth);
  if (width !== trend.plot.width || plotHeight() !== trend.plot.height) {
    trend.plot.setSize({ width, height: plotHeight() });
  }
}

/**
 * The time axis's labels, 24-hour: seconds when ticks are less than a minute apart, the
 * date alone when they are days apart, and the date under the first tick of each day.
 */
function timeTicks(u, splits, axis, space, increment) {
  let day = null;
  return splits.map((t) => {
    const d = new Date(t);
    const date = d.toLocaleDateString([], { day: 'numeric', month: 'short' });
    if (increment >= 86400e3) return date;
    const time = d.toLocaleTimeString([], {
      hour: '2-digit', minute: '2-digit', hour12: false,
      ...(increment < 60e3 ? { second: '2-digit' } : {}),
    });
    const newDay = date !== day;
    day = date;
    return newDay ? `${time}\n${date}` : time;
  });
}

/** A time as the trend's words show it: with the date when the span is long. */
function formatWhen(ms, withDate) {
  const d = new Date(ms);
  const time = d.toLocaleTimeString([], { hour: '2-digit', minute: '2-digit', second: '2-digit', hour12: false });
  if (!withDate) return time;
  return `${d.toLocaleDateString([], { day: 'numeric', month: 'short' })} ${time}`;
}

function describeSpan(step) {
  const span = document.getElementById('trend-span');
  if (trend.from === null || !trend.points.length) {
    span.textContent = '';
    return;
  }
  span.dataset.from = String(trend.from);
  span.dataset.to = String(trend.to);
  const long = trend.to - trend.from > 86400e3 || new Date(trend.from).getDate() !== new Date(trend.to).getDate();
  const words = `${formatWhen(trend.from, long)} – ${formatWhen(trend.to, long)}`;
  const each = step ? ` · a value per ${humanStep(step)}` : '';
  span.textContent = trend.range ? `last ${humanRange(trend.range)}: ${words}${each}` : `${words}${each}`;
}

function humanStep(ms) {
  if (ms < 1e3) return `${ms} ms`;
  if (ms < 60e3) return `${ms / 1e3} s`;
  if (ms < 3600e3) return `${ms / 60e3} min`;
  if (ms < 86400e3) return `${ms / 3600e3} h`;
  return `${ms / 86400e3} d`;
}

function humanRange(range) {
  return document.querySelector(`#trend-view [data-range="${range}"]`)?.textContent || range;
}

// ---- zoom and move ------------------------------------------------------------------------

/** The latest time a span may end at: now, as the gateway last said it. */
function trendNow() {
  return Math.max(Date.now(), trend.range ? trend.to : 0);
}

/** Shows from..to (ms), fixed, kept within the spans allowed and not past now. */
function zoomTrend(from, to) {
  if (!Number.isFinite(from) || !Number.isFinite(to)) return;
  let span = Math.min(TREND_MAX_SPAN, Math.max(TREND_MIN_SPAN, to - from));
  const middle = (from + to) / 2;
  let start = middle - span / 2;
  const now = trendNow();
  if (start + span > now) start = now - span;
  span = Math.round(span);
  start = Math.round(start);
  setTrend({ range: null, from: start, to: start + span });
}

/** Moves the span by `fraction` of itself (negative: earlier). */
function moveTrend(fraction) {
  const span = trend.to - trend.from;
  zoomTrend(trend.from + span * fraction, trend.to + span * fraction);
}

/**
 * Moving and pinching on the chart: shift-drag or the middle button with a mouse, one
 * finger on a touch screen move the span; two fingers zoom around their middle. The chart
 * follows at once; the history is asked for when the gesture ends.
 */
function attachGestures(u) {
  const over = u.over;
  let gesture = null;
  // uPlot applies a new scale a moment later: the gesture keeps the span it shows.
  const begin = (points) => {
    const min = gesture ? gesture.shown.min : u.scales.x.min;
    const max = gesture ? gesture.shown.max : u.scales.x.max;
    const anchorAt = (clientX) => min + ((clientX - over.getBoundingClientRect().left) / (over.clientWidth || 1)) * (max - min);
    if (points.length === 1) {
      gesture = { min, max, x: points[0].clientX, moved: false, shown: { min, max } };
    } else {
      const [a, b] = points;
      gesture = {
        min, max, moved: false, pinch: true, shown: { min, max },
        distance: Math.max(10, Math.abs(a.clientX - b.clientX)),
        anchor: anchorAt((a.clientX + b.clientX) / 2),
      };
    }
    trend.moving = true;
  };
  const follow = (points) => {
    if (!gesture) return;
    const width = over.clientWidth || 1;
    const span = gesture.max - gesture.min;
    let min;
    let max;
    if (gesture.pinch && points.length > 1) {
      const [a, b] = points;
      const wider = Math.min(TREND_MAX_SPAN, Math.max(TREND_MIN_SPAN,
        span * gesture.distance / Math.max(10, Math.abs(a.clientX - b.clientX))));
      const at = ((a.clientX + b.clientX) / 2 - over.getBoundingClientRect().left) / width;
      min = gesture.anchor - at * wider;
      max = min + wider;
    } else if (!gesture.pinch) {
      const shift = -((points[0].clientX - gesture.x) / width) * span;
      min = gesture.min + shift;
      max = gesture.max + shift;
    } else return;
    gesture.moved = true;
    gesture.shown = { min, max };
    u.setScale('x', { min, max });
  };
  const end = () => {
    if (!gesture) return;
    const { moved, shown } = gesture;
    gesture = null;
    trend.moving = false;
    if (moved) zoomTrend(shown.min, shown.max);
  };
  over.addEventListener('mousedown', (e) => {
    if (!(e.shiftKey || e.button === 1)) return;
    e.preventDefault();
    begin([e]);
    const move = (m) => follow([m]);
    const up = () => {
      window.removeEventListener('mousemove', move);
      window.removeEventListener('mouseup', up);
      end();
    };
    window.addEventListener('mousemove', move);
    window.addEventListener('mouseup', up);
  });
  over.addEventListener('touchstart', (e) => {
    e.preventDefault();
    begin([...e.touches]);
  }, { passive: false });
  over.addEventListener('touchmove', (e) => {
    e.preventDefault();
    // A second finger turns a move into a pinch, from where the chart is now.
    if (gesture && !gesture.pinch && e.touches.length > 1) begin([...e.touches]);
    follow([...e.touches]);
  }, { passive: false });
  over.addEventListener('touchend', (e) => {
    if (e.touches.length === 0) end();
  });
  over.addEventListener('touchcancel', end);
}

// ---- the CSV ------------------------------------------------------------------------------

/** The shown series as CSV: a time column (UTC, ISO 8601), one column per point. */
function trendCsv() {
  const data = trend.data;
  if (!data) return '';
  const quote = (text) => (/[",\n]/.test(text) ? `"${text.replaceAll('"', '""')}"` : text);
  const head = ['time', ...trend.points.map((id) => {
    const point = trend.catalog.get(id);
    return quote(point && point.unit ? `${id} (${point.unit})` : id);
  })];
  const rows = data[0].map((t, i) => [
    new Date(t).toISOString(),
    ...data.slice(1).map((column) => (column[i] === null || column[i] === undefined ? '' : String(column[i]))),
  ].join(','));
  return `${[head.join(','), ...rows].join('\n')}\n`;
}

function downloadCsv() {
  const text = trendCsv();
  if (!text) return;
  const stamp = (ms) => new Date(ms).toISOString().slice(0, 16).replace(':', '');
  const link = el('a');
  link.href = URL.createObjectURL(new Blob([text], { type: 'text/csv' }));
  link.download = `cellbus-trend-${stamp(trend.from)}-${stamp(trend.to)}.csv`;
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(link.href), 10e3);
}

// ---- controls -----------------------------------------------------------------------------

function setUpTrend() {
  for (const button of document.querySelectorAll('#trend-view [data-range]')) {
    button.addEventListener('click', () => setTrend({ range: button.dataset.range, from: null, to: null }));
  }
  document.getElementById('trend-earlier').addEventListener('click', () => moveTrend(-0.5));
  document.getElementById('trend-later').addEventListener('click', () => moveTrend(0.5));
  document.getElementById('trend-out').addEventListener('click', () => {
    const span = trend.to - trend.from;
    zoomTrend(trend.from - span / 2, trend.to + span / 2);
  });
  document.getElementById('trend-reset').addEventListener('click', () => {
    setTrend({ range: trend.base, from: null, to: null });
  });
  document.getElementById('trend-csv').addEventListener('click', downloadCsv);
  const find = document.getElementById('trend-find');
  find.addEventListener('input', () => {
    clearTimeout(findTimer);
    findTimer = setTimeout(showMatches, 150);
  });
  find.addEventListener('keydown', (e) => {
    if (e.key === 'Enter') {
      e.preventDefault();
      document.querySelector('#trend-matches button')?.click();
    } else if (e.key === 'Escape') {
      find.value = '';
      document.getElementById('trend-matches').hidden = true;
    }
  });
  if ('ResizeObserver' in window) {
    new ResizeObserver(() => resizeTrend()).observe(document.getElementById('trend-plot'));
  } else {
    window.addEventListener('resize', resizeTrend);
  }
}
