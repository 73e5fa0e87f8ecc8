// Opens the page of a large cell (crates/cli/tests/web.rs: 1,000 JBC stations, 20 on each
// of 50 lines) in headless Chromium and checks that it shows a line at a time and takes
// from the gateway only what it shows:
// - the first line's cards, and no others, in the DOM; the stream opened for that line;
// - switching line (the selector), a search (`jbc987`), a search with more matches than a
//   page (paged), and an address (`#line=…`) opened in a new tab each show just their devices;
// - every `value` and `device` message the stream carries is for a shown device (Chromium's
//   own record of the stream's messages, through the DevTools protocol);
// - at most 4 history queries in flight at once (the gateway runs 4 and makes others wait).
// Measures (printed, not asserted): time to the first line's cards, bytes and messages per
// second of the stream while a line is shown against the whole cell's stream, the other
// requests' bytes per refresh.
// Usage: TOKEN=WRITE_TOKEN node big.mjs http://127.0.0.1:PORT screenshot.png
// Prints one JSON line with what it saw and measured; exits non-zero with a reason otherwise.
import { launch, openPage } from './browser.mjs';

const [base, screenshot] = process.argv.slice(2);
const WINDOW_MS = 10000;

const lines = (await (await fetch(`${base}/api/lines`)).json()).lines;
const lineOf = new Map(lines.flatMap((line) => line.devices.map((id) => [id, line.name])));

function check(condition, message) {
  if (!condition) throw new Error(message);
}

/** Bytes and messages of the whole cell's stream over `ms` (what an unfiltered page gets). */
async function wholeStream(ms) {
  const abort = new AbortController();
  const started = Date.now();
  let bytes = 0;
  let head = Buffer.alloc(0);
  let snapshot = 0;
  let messages = 0;
  const timer = setTimeout(() => abort.abort(), ms);
  try {
    const response = await fetch(`${base}/api/events/stream`, { signal: abort.signal });
    const decoder = new TextDecoder();
    for await (const chunk of response.body) {
      bytes += chunk.length;
      messages += decoder.decode(chunk, { stream: true }).split('\n\n').length - 1;
      if (snapshot === 0) {
        // The snapshot is the first message: its bytes up to the first blank line.
        head = Buffer.concat([head, chunk]);
        const end = head.indexOf('\n\n');
        if (end !== -1) snapshot = end + 2;
      }
    }
  } catch (e) {
    if (e.name !== 'AbortError') throw e;
  } finally {
    clearTimeout(timer);
  }
  return { bytes, snapshot_bytes: snapshot, messages, seconds: (Date.now() - started) / 1000 };
}

const browser = await launch();
try {
  const errors = [];
  const page = await openPage(browser, errors);

  // Every request the page makes, and the history queries in flight.
  const requests = [];
  let historyInFlight = 0;
  let historyMost = 0;
  page.on('request', (r) => {
    const url = new URL(r.url());
    requests.push(url.pathname + url.search);
    if (url.pathname === '/api/history') historyMost = Math.max(historyMost, ++historyInFlight);
  });
  const historyDone = (r) => {
    if (new URL(r.url()).pathname === '/api/history') historyInFlight -= 1;
  };
  page.on('requestfinished', historyDone);
  page.on('requestfailed', historyDone);

  // Chromium's own record of the bytes received and of each stream message.
  const cdp = await page.context().newCDPSession(page);
  await cdp.send('Network.enable');
  const urls = new Map();
  const received = { stream: 0, other: 0, otherRequests: 0 };
  const messages = [];
  cdp.on('Network.requestWillBeSent', (e) => urls.set(e.requestId, new URL(e.request.url)));
  cdp.on('Network.dataReceived', (e) => {
    const url = urls.get(e.requestId);
    if (url && url.pathname === '/api/events/stream') received.stream += e.dataLength;
    else received.other += e.dataLength;
  });
  cdp.on('Network.responseReceived', (e) => {
    const url = urls.get(e.requestId);
    if (url && url.pathname !== '/api/events/stream') received.otherRequests += 1;
  });
  cdp.on('Network.eventSourceMessageReceived', (e) => {
    messages.push({ url: urls.get(e.requestId), name: e.eventName, data: e.data });
  });

  const cards = () => page.evaluate(() => [...document.querySelectorAll('.device')].map((c) => c.id.slice(7)));
  const waitForCards = async (expected) => {
    await page.waitForFunction(
      (expected) => {
        const ids = [...document.querySelectorAll('.device')].map((c) => c.id.slice(7));
        return ids.length === expected.length && expected.every((id, i) => ids[i] === id);
      },
      expected,
      { timeout: 30000, polling: 50 },
    );
  };
  const streams = () => requests.filter((r) => r.startsWith('/api/events/stream'));
  /** Every value and device message of the stream opened with `query` is for `shown`. */
  const onlyShown = (query, shown) => {
    const wanted = new Set(shown);
    let checked = 0;
    for (const m of messages) {
      if (!m.url || m.url.search !== query || !['value', 'device'].includes(m.name)) continue;
      const id = JSON.parse(m.data).id.split('.')[0];
      check(wanted.has(id), `the stream ${query} carried ${m.name} of ${id}, not shown`);
      checked += 1;
    }
    return checked;
  };

  // 1. The first line: its 20 cards and nothing else.
  const first = lines[0];
  const started = Date.now();
  await page.goto(`${base}/`);
  await page.waitForSelector(`[id="device-${first.devices[0]}"]`, { timeout: 30000 });
  const firstCard = Date.now() - started;
  await waitForCards(first.devices);
  const firstLine = Date.now() - started;
  check(page.url().endsWith(`#line=${first.name}`), `the address names the line: ${page.url()}`);
  check(!requests.some((r) => r.startsWith('/api/devices')), 'the page never lists every device');
  check(
    streams().length === 1 && streams()[0] === `/api/events/stream?line=${first.name}`,
    `one stream, for the line: ${streams()}`,
  );
  const dom = await page.evaluate(() => ({
    cards: document.querySelectorAll('.device').length,
    points: document.querySelectorAll('[id^="point-"]').length,
    elements: document.getElementsByTagName('*').length,
    lineCards: document.querySelectorAll('.line').length,
    options: document.querySelectorAll('#line-select option').length,
  }));
  check(dom.lineCards === 1, `the health of the shown line only: ${dom.lineCards} line cards`);
  check(dom.options === lines.length + 1, `every line (and all) in the selector: ${dom.options}`);

  // A live value of the line's answering station changes on the page. An idle station's
  // readings stay put, so the change is made: a new air temperature setpoint, written
  // through the API (the gateway reads a write back at once).
  const station = first.devices[0];
  const setpoint = (await (await fetch(`${base}/api/devices/${station}`)).json()).points
    .find((p) => p.id.endsWith('.air_temperature_setpoint'));
  check(setpoint, `${station} has an air temperature setpoint`);
  const value = setpoint.value === 400 ? 410 : 400;
  const write = await fetch(`${base}/api/devices/${station}/write`, {
    method: 'POST',
    headers: { authorization: `Bearer ${process.env.TOKEN}`, 'content-type': 'application/json' },
    body: JSON.stringify({ point: setpoint.id, value }),
  });
  check(write.ok, `the setpoint write is taken: ${write.status} ${await write.text()}`);
  await page.waitForFunction(
    ([id, value]) => document.getElementById(`point-${id}`)?.querySelector('.value')
      .textContent.startsWith(`${value}`),
    [setpoint.id, value],
    { timeout: 30000, polling: 100 },
  );

  // 2. A refresh window with the line shown, beside the whole cell's stream.
  const before = { ...received, requests: requests.length, messages: messages.length };
  const [whole] = await Promise.all([wholeStream(WINDOW_MS), page.waitForTimeout(WINDOW_MS)]);
  const refresh = {
    seconds: WINDOW_MS / 1000,
    stream_messages: messages.slice(before.messages).filter((m) => m.url?.search === `?line=${first.name}`).length,
    stream_bytes: received.stream - before.stream,
    other_bytes: received.other - before.other,
    other_requests: received.otherRequests - before.otherRequests,
    paths: requests.slice(before.requests),
  };
  check(
    refresh.paths.every((p) => [`/api/lines?line=${first.name}`, '/api/lines', '/healthz', '/api/alarms?limit=1'].includes(p)
      || p.startsWith('/api/history')),
    `a refresh asks only for the line's health and the gateway's, and the alarm banner's counts after an alarm event (plots: history): ${refresh.paths}`,
  );
  check(
    refresh.paths.includes(`/api/lines?line=${first.name}`),
    `the shown line's health is refreshed by itself: ${refresh.paths}`,
  );
  const firstChecked = onlyShown(`?line=${first.name}`, first.devices);
  check(firstChecked > 0, 'the stream carried values of the shown line');

  // 3. Another line, chosen in the selector.
  const second = lines[1];
  await page.selectOption('#line-select', second.name);
  await waitForCards(second.devices);
  check(page.url().endsWith(`#line=${second.name}`), `the address follows: ${page.url()}`);
  check(streams().at(-1) === `/api/events/stream?line=${second.name}`, `stream: ${streams().at(-1)}`);

  // 4. A search through every line.
  const switched = Date.now();
  await page.fill('#search', 'jbc987');
  await waitForCards(['jbc987']);
  const searchMs = Date.now() - switched;
  check(page.url().includes('q=jbc987'), `the address keeps the search: ${page.url()}`);
  check(streams().at(-1) === '/api/events/stream?device=jbc987', `stream: ${streams().at(-1)}`);
  const found = await page.evaluate(() => document.querySelector('.device-meta').textContent);
  check(found.includes(`line ${lineOf.get('jbc987')}`), `jbc987's card names its line: ${found}`);

  // 5. A search with more matches than a page: paged, 50 cards at most.
  const nines = [...lineOf.keys()].filter((id) => id.includes('jbc9'));
  await page.fill('#search', 'jbc9');
  await waitForCards(nines.slice(0, 50));
  const pageOne = await page.evaluate(() => document.getElementById('shown').textContent);
  check(pageOne.startsWith(`1–50 of ${nines.length}`), `the count of matches: ${pageOne}`);
  await page.click('#next');
  await waitForCards(nines.slice(50, 100));
  check(page.url().includes('page=2'), `the address keeps the page: ${page.url()}`);
  const paged = streams().at(-1);
  check(paged.length < 2000, `a page's stream address stays short: ${paged.length} characters`);
  onlyShown(new URL(paged, base).search, nines.slice(50, 100));

  // The streams the page closed are closed at the gateway too: one open, far from its 64.
  const closing = Date.now();
  const openStreams = async () => {
    const text = await (await fetch(`${base}/metrics`)).text();
    return Number(/^cellbus_sse_clients (\d+)/m.exec(text)?.[1]);
  };
  let open = await openStreams();
  while (open !== 1) {
    check(Date.now() - closing < 30000, `${open} streams still open 30 s after switching`);
    await new Promise((resolve) => setTimeout(resolve, 100));
    open = await openStreams();
  }
  const closedMs = Date.now() - closing;

  // 6. An address opens the same view, in a new tab.
  const seventh = lines[6];
  const other = await openPage(browser, errors);
  await other.goto(`${base}/#line=${seventh.name}`);
  await other.waitForFunction(
    (expected) => {
      const ids = [...document.querySelectorAll('.device')].map((c) => c.id.slice(7));
      return ids.length === expected.length && expected.every((id, i) => ids[i] === id);
    },
    seventh.devices,
    { timeout: 30000, polling: 50 },
  );
  // Back to the line in the first tab.
  await page.goBack();
  await page.goBack();
  await waitForCards(second.devices);
  await other.close();

  if (screenshot) await page.screenshot({ path: screenshot, fullPage: true });
  check(historyMost <= 4, `at most 4 history queries at once, saw ${historyMost}`);
  if (errors.length) throw new Error(`the page threw: ${errors.join('; ')}`);
  const snapshot = messages.find((m) => m.name === 'snapshot' && m.url?.search === `?line=${first.name}`);
  console.log(JSON.stringify({
    devices: lineOf.size,
    lines: lines.length,
    first_card_ms: firstCard,
    first_line_ms: firstLine,
    search_ms: searchMs,
    dom,
    cards_after: (await cards()).length,
    refresh,
    line_snapshot_bytes: snapshot ? Buffer.byteLength(snapshot.data) : null,
    whole_cell_stream: whole,
    streams_opened: streams().length,
    streams_closed_after_ms: closedMs,
    history_most_at_once: historyMost,
    requests: requests.length,
  }));
} finally {
  await browser.close();
}
