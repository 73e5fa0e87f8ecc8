// cellbus alarm view: the alarm list of /api/alarms (every alarm active, waiting for an
// acknowledgement or shelved; most urgent, then newest, first), 50 at a time, with
// Acknowledge, Shelve and Unshelve for each (POST /api/alarms/{id}/ack|shelve|unshelve with
// the write token, the operator's name and a comment, asked in a dialog that is the
// confirmation), and below it the journal of the last 24 hours (/api/alarms/journal).
// The header's banner counts the alarms by priority on every view. The stream carries
// every alarm change as an event (alarm_raised, alarm_cleared, alarm_changed, a shelving
// that ran out included) whatever devices it follows: the banner, and the view when it is
// shown, are asked for again half a second after one, and with each snapshot (a stream
// opened again); the view also every 10 s, so its "now" moves on.
//
// The view is in the address: `#view=alarms` (`&page=N` past the first 50).
//
// DOM contract (for tests): #alarm-banner holds a .alarm-count per priority with
// data-priority, data-active and data-unacknowledged; #alarm-list holds a tr.alarm per
// alarm with data-id, data-priority, data-state, data-acknowledged and data-shelved-until, and its
// buttons [data-action="ack|shelve|unshelve"]; the action's dialog is #alarm-dialog
// (#alarm-operator, #alarm-comment, #alarm-duration, #alarm-token, #alarm-confirm,
// #alarm-result); #alarm-journal holds a tr per entry with data-alarm, data-changes
// (space-separated) and data-by.
//
// Loaded before app.js: only definitions here; app.js shows the view (showAlarms).
'use strict';

/** Alarms on a page of the list. */
const ALARMS_PAGE = 50;
/** The view (list, journal and banner) is asked for again this often while shown. */
const ALARMS_REFRESH_MS = 10e3;
const PRIORITY_WORDS = [['urgent', 'Urgent'], ['high', 'High'], ['medium', 'Medium'], ['low', 'Low']];
const ALARM_STATE_WORDS = {
  normal: 'normal',
  unacknowledged: 'active, unacknowledged',
  acknowledged: 'active, acknowledged',
  returned_unacknowledged: 'cleared, unacknowledged',
};
const CHANGE_WORDS = {
  activated: 'raised',
  cleared: 'cleared',
  acknowledged: 'acknowledged',
  shelved: 'shelved',
  shelved_for_chattering: 'shelved for chattering',
  unshelved: 'unshelved',
  shelve_expired: 'shelving ran out',
  removed_from_service: 'taken out of service',
  returned_to_service: 'back in service',
};
const ACTION_WORDS = { ack: 'Acknowledge', shelve: 'Shelve', unshelve: 'Unshelve' };
/** Where the operator's name is kept (the write token is the write form's, per tab). */
const OPERATOR_KEY = 'cellbus-operator';
const WRITE_TOKEN_KEY = 'cellbus-token';

const alarms = {
  shown: false,
  page: 1,
  timer: null,
  soon: null,
  load: 0,       // counts loads: an older load's answers are dropped
  acting: null,  // { alarm, action } the dialog is open for
};

// ---- the banner ------------------------------------------------------------------------------

/** The header's counts: per priority, the alarms active and those waiting for an acknowledgement. */
function renderAlarmBanner(counts) {
  const by = new Map(counts.map((c) => [c.priority, c]));
  const said = [];
  for (const [priority, word] of PRIORITY_WORDS) {
    const c = by.get(priority) || { active: 0, unacknowledged: 0, shelved: 0 };
    const chip = document.querySelector(`#alarm-banner .alarm-count[data-priority="${priority}"]`);
    chip.dataset.active = String(c.active);
    chip.dataset.unacknowledged = String(c.unacknowledged);
    chip.textContent = c.active || c.unacknowledged
      ? `${word} ${c.active} active · ${c.unacknowledged} unack.` : `${word} 0`;
    said.push(`${word}: ${c.active} active, ${c.unacknowledged} waiting for an acknowledgement`
      + (c.shelved ? `, ${c.shelved} shelved` : ''));
  }
  const banner = document.getElementById('alarm-banner');
  banner.title = `${said.join('\n')}\nOpen the alarm list`;
}

async function refreshAlarmBanner() {
  try {
    renderAlarmBanner((await getJson('/api/alarms?limit=1')).counts);
  } catch (e) {
    console.warn('alarms', e);
  }
}

// ---- showing the view ------------------------------------------------------------------------

/** Shows the alarm view the address asks for (`params`), or hides it (`null`). */
function showAlarms(params) {
  alarms.shown = Boolean(params);
  clearInterval(alarms.timer);
  alarms.timer = null;
  if (!params) return;
  alarms.page = Math.max(1, Number.parseInt(params.get('page'), 10) || 1);
  alarms.timer = setInterval(() => {
    if (!document.hidden) loadAlarms();
  }, ALARMS_REFRESH_MS);
  loadAlarms();
}

/** An alarm event on the stream: the banner (and the view) again in half a second. */
function alarmsNoticed() {
  if (alarms.soon) return;
  alarms.soon = setTimeout(() => {
    alarms.soon = null;
    refreshAlarms();
  }, 500);
}

function refreshAlarms() {
  if (alarms.shown) loadAlarms();
  else refreshAlarmBanner();
}

function turnAlarmPage(by) {
  const page = Math.max(1, alarms.page + by);
  window.history.pushState(null, '', page > 1 ? `#view=alarms&page=${page}` : '#view=alarms');
  showAlarms(pageFromAddress().params);
}

/** Asks for the page of the list and the journal, then shows both and the banner. */
async function loadAlarms() {
  alarms.load += 1;
  const load = alarms.load;
  const offset = (alarms.page - 1) * ALARMS_PAGE;
  const note = document.getElementById('alarms-note');
  let answers;
  try {
    answers = await Promise.all([
      getJson(`/api/alarms?limit=${ALARMS_PAGE}&offset=${offset}`),
      getJson('/api/alarms/journal?from=-24h&limit=100'),
    ]);
  } catch (e) {
    if (load === alarms.load) note.textContent = `The alarms could not be read: ${e.message || e}`;
    return;
  }
  if (load !== alarms.load) return;
  const [list, journal] = answers;
  renderAlarmBanner(list.counts);
  if (!alarms.shown) return;
  const pages = Math.max(1, Math.ceil(list.total / ALARMS_PAGE));
  if (alarms.page > pages) {
    // Alarms went back to normal: the last page there is.
    alarms.page = pages;
    window.history.replaceState(null, '', pages > 1 ? `#view=alarms&page=${pages}` : '#view=alarms');
    loadAlarms();
    return;
  }
  note.textContent = state.writesEnabled !== false ? ''
    : 'Writes are off on this gateway (start it with --allow-writes): alarms can be read here, not acknowledged or shelved.';
  renderAlarmList(list, pages);
  renderJournal(journal.entries);
}

// ---- the list --------------------------------------------------------------------------------

/** An RFC 3339 time as the view shows it: the time of day, with the day unless today. */
function alarmTime(text) {
  if (!text) return '—';
  const ms = Date.parse(text);
  const today = new Date(ms).toDateString() === new Date().toDateString();
  return today ? formatClock(ms) : `${formatDay(ms)} ${formatClock(ms)}`;
}

/** An alarm's value in words: a device state's label from the cell view, a number with its unit. */
function alarmValue(alarm) {
  const v = alarm.value;
  if (v === null || v === undefined) return '—';
  const device = state.devices.get(alarm.device);
  const point = device && alarm.point ? device.byId.get(alarm.point) : null;
  const states = point && point.kind && point.kind.states;
  const named = states && states.find((s) => s.value === v);
  let words = named ? named.label
    : typeof v === 'number' ? `${formatNumber(v)}${point && point.unit ? ` ${point.unit}` : ''}` : String(v);
  if (alarm.limit !== undefined) words += ` (${alarm.level || 'limit'} ${formatNumber(alarm.limit)})`;
  return words;
}

/** A table cell with its column's name, which a phone shows beside it. */
function labelled(label, text, className) {
  const td = el('td', className, text);
  td.dataset.label = label;
  return td;
}

function renderAlarmList(list, pages) {
  const from = list.offset;
  const count = list.alarms.length;
  document.getElementById('alarms-shown').textContent = list.total === 0 ? 'No alarms'
    : list.total <= ALARMS_PAGE ? `${list.total} alarm${list.total === 1 ? '' : 's'}`
      : `${from + 1}–${from + count} of ${list.total} alarms`;
  document.getElementById('alarms-pager').hidden = pages === 1;
  document.getElementById('alarms-previous').disabled = alarms.page === 1;
  document.getElementById('alarms-next').disabled = alarms.page >= pages;
  const body = document.getElementById('alarm-list');
  if (count === 0) {
    emptyTable(body, 10, 'No alarm is active, waiting for an acknowledgement or shelved.');
    return;
  }
  body.replaceChildren(...list.alarms.map((alarm) => {
    const row = el('tr', 'alarm');
    Object.assign(row.dataset, {
      id: alarm.id, priority: alarm.priority, state: alarm.state,
      acknowledged: String(alarm.acknowledged), shelvedUntil: alarm.shelved_until || '',
    });
    const device = state.devices.get(alarm.device);
    const deviceCell = labelled('Device', alarm.device);
    if (device) deviceCell.title = device.name;
    const message = labelled('Message', alarm.message, 'alarm-message');
    message.title = alarm.id;
    const shelved = alarm.shelved_until ? alarmTime(alarm.shelved_until)
      : alarm.out_of_service ? 'out of service' : '—';
    row.append(
      labelled('Priority', alarm.priority, 'priority'),
      deviceCell,
      message,
      labelled('State', ALARM_STATE_WORDS[alarm.state] || alarm.state, 'alarm-state'),
      labelled('Value', alarmValue(alarm)),
      labelled('First active', alarmTime(alarm.first_active), 'when'),
      labelled('Last active', alarmTime(alarm.last_active), 'when'),
      labelled('Count', String(alarm.count), 'number'),
      labelled('Shelved until', shelved, 'when'),
    );
    const actions = labelled('', '', 'actions');
    const offer = (action, words) => {
      const button = el('button', '', words);
      button.type = 'button';
      button.dataset.action = action;
      button.addEventListener('click', () => openAlarmDialog(alarm, action));
      actions.append(button);
    };
    if (!alarm.acknowledged && !alarm.out_of_service) offer('ack', 'Acknowledge');
    if (alarm.shelved_until) offer('unshelve', 'Unshelve…');
    else if (!alarm.out_of_service) offer('shelve', 'Shelve…');
    row.append(actions);
    return row;
  }));
}

// ---- the journal -----------------------------------------------------------------------------

// A table body that has nothing to show: one row across its `columns` saying so.
function emptyTable(body, columns, words) {
  const empty = el('td', 'placeholder', words);
  empty.colSpan = columns;
  const row = el('tr');
  row.append(empty);
  body.replaceChildren(row);
}

function renderJournal(entries) {
  const body = document.getElementById('alarm-journal');
  if (!entries.length) {
    emptyTable(body, 6, 'Nothing happened to an alarm in the last 24 hours.');
    return;
  }
  body.replaceChildren(...entries.map((entry) => {
    const row = el('tr');
    const changes = entry.changes || [];
    Object.assign(row.dataset, { alarm: entry.alarm || '', changes: changes.join(' '), by: entry.by || '' });
    const words = changes.map((c) => {
      if (c === 'shelved' && entry.shelved_until) return `shelved until ${alarmTime(entry.shelved_until)}`;
      return CHANGE_WORDS[c] || c;
    });
    const time = labelled('Time', alarmTime(entry.t), 'when');
    time.title = entry.t;
    row.append(
      time,
      labelled('Alarm', entry.alarm || '—', 'alarm-id'),
      labelled('What happened', words.join(', ')),
      labelled('By', entry.by || '—'),
      labelled('Comment', entry.comment || '—'),
      labelled('Message', entry.message, 'alarm-message'),
    );
    return row;
  }));
}

// ---- acting on an alarm ----------------------------------------------------------------------

/** Opens the dialog that asks who, why (and for how long) and is the confirmation. */
function openAlarmDialog(alarm, action) {
  alarms.acting = { alarm, action };
  const dialog = document.getElementById('alarm-dialog');
  const shelving = action === 'shelve';
  document.getElementById('alarm-dialog-title').textContent = `${ACTION_WORDS[action]} ${alarm.id}?`;
  const priority = new Map(PRIORITY_WORDS).get(alarm.priority) || alarm.priority;
  document.getElementById('alarm-dialog-what').textContent = `${priority} priority · ${alarm.message}`
    + ` · ${ALARM_STATE_WORDS[alarm.state] || alarm.state}`
    + (shelving ? '. While shelved, its changes are not announced; the shelving ends by itself.' : '');
  document.getElementById('alarm-duration-label').hidden = !shelving;
  const comment = document.getElementById('alarm-comment');
  comment.required = shelving;
  comment.placeholder = shelving ? 'why it is shelved (needed)' : 'optional';
  comment.value = '';
  const operator = document.getElementById('alarm-operator');
  operator.value = localStorage.getItem(OPERATOR_KEY) || operator.value;
  document.getElementById('alarm-token').value = sessionStorage.getItem(WRITE_TOKEN_KEY) || '';
  const result = document.getElementById('alarm-result');
  result.textContent = '';
  result.dataset.ok = '';
  confirmWords();
  dialog.showModal();
  (operator.value ? comment : operator).focus();
}

/** The confirming button says what it does: "Shelve for 1 hour". */
function confirmWords() {
  if (!alarms.acting) return;
  const { action } = alarms.acting;
  const duration = document.getElementById('alarm-duration');
  document.getElementById('alarm-confirm').textContent = action === 'shelve'
    ? `Shelve for ${duration.options[duration.selectedIndex].textContent}` : ACTION_WORDS[action];
}

async function actOnAlarm(e) {
  e.preventDefault();
  if (!alarms.acting) return;
  const { alarm, action } = alarms.acting;
  const by = document.getElementById('alarm-operator').value.trim();
  const comment = document.getElementById('alarm-comment').value.trim();
  const token = document.getElementById('alarm-token').value;
  localStorage.setItem(OPERATOR_KEY, by);
  sessionStorage.setItem(WRITE_TOKEN_KEY, token);
  const body = { by, comment };
  if (action === 'shelve') body.duration = document.getElementById('alarm-duration').value;
  const result = document.getElementById('alarm-result');
  const confirm = document.getElementById('alarm-confirm');
  result.dataset.ok = '';
  result.textContent = 'sending…';
  confirm.disabled = true;
  // The write token; without one the read token, as every other request sends it.
  const bearer = token || readToken();
  try {
    const response = await fetch(`/api/alarms/${encodeURIComponent(alarm.id)}/${action}`, {
      method: 'POST',
      headers: { 'Content-Type': 'application/json', ...(bearer ? { Authorization: `Bearer ${bearer}` } : {}) },
      body: JSON.stringify(body),
    });
    const answer = await response.json().catch(() => ({}));
    if (!response.ok) {
      result.dataset.ok = 'false';
      result.textContent = `${answer.error || 'refused'} (${response.status})`;
      return;
    }
    alarms.acting = null;
    document.getElementById('alarm-dialog').close();
    const done = { ack: 'acknowledged', shelve: `shelved until ${alarmTime(answer.alarm?.shelved_until)}`, unshelve: 'unshelved' };
    document.getElementById('alarms-done').textContent = `${alarm.id} ${done[action]} by ${by || 'you'}.`;
    refreshAlarms();
  } catch (err) {
    result.dataset.ok = 'false';
    result.textContent = `the gateway did not answer: ${err}`;
  } finally {
    confirm.disabled = false;
  }
}

// ---- controls --------------------------------------------------------------------------------

function setUpAlarms() {
  document.getElementById('alarms-previous').addEventListener('click', () => turnAlarmPage(-1));
  document.getElementById('alarms-next').addEventListener('click', () => turnAlarmPage(1));
  document.getElementById('alarm-form').addEventListener('submit', actOnAlarm);
  document.getElementById('alarm-duration').addEventListener('change', confirmWords);
  document.getElementById('alarm-cancel').addEventListener('click', () => {
    alarms.acting = null;
    document.getElementById('alarm-dialog').close();
  });
  document.getElementById('alarm-dialog').addEventListener('close', () => {
    alarms.acting = null;
  });
}
