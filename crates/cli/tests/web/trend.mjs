// The trend view in headless Chromium, on the demo cell: a person picks two points by
// typing, then zooms, moves and downloads what is shown; the script records what the page
// asked /api/history for at each step, so the Rust test can check that every zoom and
// move asks for the span then visible, and the answers the zoom got, to check the CSV by.
// - picks `sealer0 temp` and `load power` in the point finder (°C and kVA: two y axes);
// - once the points have some history, shows the last 10 minutes and zooms by dragging
//   across the newest tenth of the chart, then downloads the CSV of what is shown;
// - moves earlier with the ◀ button, later by shift-dragging, and earlier with one finger;
// - reloads the address and records what the page then shows and asks for;
// - looks at the view on a 360 px phone.
// Usage: node trend.mjs http://127.0.0.1:PORT screenshot.png
// Prints one JSON line with what it saw; exits non-zero with a reason otherwise.
import { readFile } from 'node:fs/promises';
import { launch, openPage, onAPhone } from './browser.mjs';

const [base, screenshot] = process.argv.slice(2);

const browser = await launch();
try {
  const errors = [];
  const page = await openPage(browser, errors);

  // Every history query the page makes, in order: its point, from, to and step; and the
  // answers it got, by address.
  const asked = [];
  const answers = new Map();
  page.on('request', (r) => {
    const url = new URL(r.url());
    if (url.pathname !== '/api/history') return;
    const query = Object.fromEntries(url.searchParams);
    asked.push({ ...query, from_ms: Date.parse(query.from), to_ms: Date.parse(query.to), url: r.url() });
  });
  page.on('response', (r) => {
    if (new URL(r.url()).pathname === '/api/history') answers.set(r.url(), r.json().catch((e) => String(e)));
  });
  /** The queries asked since `mark` (a length of `asked`), once there is one per point. */
  async function askedSince(mark, points = 2) {
    const deadline = Date.now() + 20000;
    while (asked.length < mark + points) {
      if (Date.now() > deadline) throw new Error(`no history asked for after ${JSON.stringify(asked.slice(mark))}`);
      await page.waitForTimeout(50);
    }
    return asked.slice(mark, mark + points);
  }
  /** The span the page says it shows (ms), once it is not `old`. */
  async function shownSpan(old) {
    const handle = await page.waitForFunction((old) => {
      const span = document.getElementById('trend-span');
      const from = Number(span.dataset.from);
      const to = Number(span.dataset.to);
      const shown = { from, to, text: span.textContent };
      if (!shown.from || (old && shown.from === old.from && shown.to === old.to)) return false;
      return shown;
    }, old, { timeout: 20000, polling: 50 }).catch(async (e) => {
      const now = await page.evaluate(() => document.getElementById('trend-span').dataset);
      throw new Error(`the span shown stayed ${JSON.stringify(now)} (${e}); asked ${JSON.stringify(asked.slice(-6))}`);
    });
    return handle.jsonValue();
  }

  await page.goto(`${base}/#view=trend&range=10m`);
  for (const [typed, wanted] of [['sealer0 temp', 'sealer0.temperature'], ['load power', 'cross1.load_power']]) {
    await page.fill('#trend-find', typed);
    await page.click(`#trend-matches button[data-point="${wanted}"]`, { timeout: 20000 });
    await page.waitForSelector(`#trend-chosen li[data-point="${wanted}"]`, { timeout: 20000 });
  }
  const chosen = await page.evaluate(() =>
    [...document.querySelectorAll('#trend-chosen li')].map((li) => li.dataset.point));
  const picked = { address: await page.evaluate(() => window.location.hash), chosen };
  await page.waitForSelector('#trend-plot .u-over', { timeout: 20000 });
  // Both series drawn: uPlot's legend names them.
  const legend = await page.evaluate(() =>
    [...document.querySelectorAll('#trend-plot .u-legend .u-series th')].map((th) => th.textContent));

  // The demo gateway has just started: wait until both points have a few seconds of
  // history, then show the last 10 minutes again (the newest seconds are at the right).
  const deadline = Date.now() + 30000;
  for (const point of chosen) {
    for (;;) {
      const answer = await (await fetch(`${base}/api/history?point=${point}&from=-10m&step=1s`)).json();
      if ((answer.buckets || []).length >= 3) break;
      if (Date.now() > deadline) throw new Error(`${point} has no history: ${JSON.stringify(answer)}`);
      await page.waitForTimeout(200);
    }
  }
  const before = await shownSpan(null);
  let mark = asked.length;
  await page.click('#trend-view [data-range="10m"]');
  const firstAsked = await askedSince(mark);
  const first = await shownSpan(before);

  // Zoom: drag across the newest tenth of the chart.
  const over = await page.locator('#trend-plot .u-over').boundingBox();
  const y = over.y + over.height / 2;
  mark = asked.length;
  await page.mouse.move(over.x + over.width * 0.9, y);
  await page.mouse.down();
  await page.mouse.move(over.x + over.width * 0.95, y, { steps: 5 });
  await page.mouse.move(over.x + over.width - 1, y, { steps: 5 });
  await page.mouse.up();
  const zoomAsked = await askedSince(mark);
  const zoomed = await shownSpan(first);
  const zoomAddress = await page.evaluate(() => window.location.hash);
  const zoomAnswers = await Promise.all(zoomAsked.map((a) => answers.get(a.url)));

  // The CSV of what is shown.
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#trend-csv')]);
  const csv = {
    name: download.suggestedFilename(),
    text: await readFile(await download.path(), 'utf8'),
  };
  if (screenshot) await page.screenshot({ path: screenshot, fullPage: true });

  // Earlier by half the span (the button).
  mark = asked.length;
  await page.click('#trend-earlier');
  const earlierAsked = await askedSince(mark);
  const earlier = await shownSpan(zoomed);

  // Later by shift-dragging a quarter of the chart's width to the left.
  mark = asked.length;
  await page.keyboard.down('Shift');
  await page.mouse.move(over.x + over.width * 0.6, y);
  await page.mouse.down();
  await page.mouse.move(over.x + over.width * 0.45, y, { steps: 5 });
  await page.mouse.move(over.x + over.width * 0.35, y, { steps: 5 });
  await page.mouse.up();
  await page.keyboard.up('Shift');
  const draggedAsked = await askedSince(mark);
  const dragged = await shownSpan(earlier);

  // Earlier again with one finger moving right by a fifth of the width (touch events).
  mark = asked.length;
  await page.evaluate(({ x, y, width }) => {
    const target = document.querySelector('#trend-plot .u-over');
    const touch = (clientX) => new Touch({ identifier: 1, target, clientX, clientY: y });
    const send = (type, touches) => target.dispatchEvent(new TouchEvent(type, {
      bubbles: true, cancelable: true, touches, targetTouches: touches, changedTouches: [touch(x)],
    }));
    send('touchstart', [touch(x)]);
    send('touchmove', [touch(x + width * 0.1)]);
    send('touchmove', [touch(x + width * 0.2)]);
    send('touchend', []);
  }, { x: over.x + over.width * 0.3, y, width: over.width });
  const touchedAsked = await askedSince(mark);
  const touched = await shownSpan(dragged);

  const address = await page.evaluate(() => window.location.hash);

  // The address keeps the view: a reload shows the same points over the same span.
  mark = asked.length;
  await page.reload();
  const reloadAsked = await askedSince(mark);
  await page.waitForSelector('#trend-plot .u-over', { timeout: 20000 });
  const reloaded = {
    address: await page.evaluate(() => window.location.hash),
    chosen: await page.evaluate(() =>
      [...document.querySelectorAll('#trend-chosen li')].map((li) => li.dataset.point)),
    span: await shownSpan(null),
  };

  // On a phone: nothing wider than the screen.
  const phone = await onAPhone(page, screenshot, async () => {
    await page.waitForFunction(() => {
      const plot = document.querySelector('#trend-plot .uplot');
      return plot && plot.getBoundingClientRect().width <= window.innerWidth;
    }, null, { timeout: 20000, polling: 50 });
  });
  if (errors.length) throw new Error(`the page threw: ${errors.join('; ')}`);
  console.log(JSON.stringify({
    picked, legend, first: { asked: firstAsked, shown: first },
    zoom: { asked: zoomAsked, answers: zoomAnswers, shown: zoomed, address: zoomAddress },
    earlier: { asked: earlierAsked, shown: earlier },
    dragged: { asked: draggedAsked, shown: dragged },
    touched: { asked: touchedAsked, shown: touched },
    csv, address, reloaded: { ...reloaded, asked: reloadAsked }, phone,
  }));
} finally {
  await browser.close();
}
