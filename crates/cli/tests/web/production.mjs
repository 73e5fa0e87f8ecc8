// The production view in headless Chromium, on the demo cell, as a supervisor opens it:
// the cell page, then the Production tab, which shows the placement machine. Once the
// machine has finished a board (its OEE is then a number) and run out of parts (a stop
// with its feeder), records what the page shows (the state bars' segments with their
// place and colour, the legend, the figures, the stops) and every /api/states and
// /api/production answer the page got, so the Rust test can hold each to the answer it was
// drawn from; points at the widest segment of the last hour's bar and records what the
// page then says; waits for the page to ask again by itself; looks at the view on a 360 px
// phone.
// Usage: node production.mjs http://127.0.0.1:PORT screenshot.png
// Prints one JSON line with what it saw; exits non-zero with a reason otherwise.
import { launch, openPage, onAPhone } from './browser.mjs';

const [base, screenshot] = process.argv.slice(2);

const browser = await launch();
try {
  const errors = [];
  const page = await openPage(browser, errors);

  // Every answer of the production API the page got: its address and body.
  const answers = [];
  page.on('response', (r) => {
    const url = new URL(r.url());
    if (url.pathname !== '/api/states' && url.pathname !== '/api/production') return;
    answers.push(r.json().then((body) => ({ path: url.pathname, query: url.search, body })));
  });

  await page.goto(`${base}/`);
  await page.click('#tab-production');
  // The placement machine's first known state (the gateway has just started).
  await page.waitForSelector('#shift-bar .segment:not(.cat-unknown)', { timeout: 30000 });
  await page.waitForSelector('#hour-bar .segment:not(.cat-unknown)', { timeout: 30000 });
  await page.waitForSelector('#production-numbers:not([hidden])', { timeout: 30000 });
  // The OEE is a number once the machine has finished a board, and the demo's machine runs
  // out of parts within its first minute or so: wait for both.
  await page.waitForFunction(
    () => document.querySelector('[data-figure="oee"] .value').textContent !== '—'
      && [...document.querySelectorAll('#stops li.stop')].some((li) => li.dataset.reason.startsWith('parts exhausted')),
    null,
    { timeout: 150000, polling: 100 },
  );

  const shown = () => page.evaluate(() => {
    const bar = (id) => {
      const node = document.getElementById(id);
      const box = node.getBoundingClientRect();
      return {
        from: Number(node.dataset.from),
        to: Number(node.dataset.to),
        answered: node.dataset.answered,
        width: box.width,
        segments: [...node.querySelectorAll('.segment')].map((s) => {
          const r = s.getBoundingClientRect();
          const style = getComputedStyle(s);
          return {
            ...s.dataset,
            left: r.left - box.left,
            width: r.width,
            x: r.left + r.width / 2,
            y: r.top + r.height / 2,
            colour: `${style.backgroundColor} ${style.backgroundImage}`,
          };
        }),
      };
    };
    const figure = (name) => document.querySelector(`[data-figure="${name}"]`);
    return {
      address: window.location.hash,
      device: document.getElementById('production-device').value,
      now: document.getElementById('production-now').textContent,
      shift: bar('shift-bar'),
      hour: bar('hour-bar'),
      legend: Object.fromEntries([...document.querySelectorAll('#state-legend li')].map((li) => {
        const style = getComputedStyle(li.querySelector('.swatch'));
        return [li.dataset.category, `${style.backgroundColor} ${style.backgroundImage}`];
      })),
      answered: document.getElementById('production-numbers').dataset.answered,
      figures: Object.fromEntries(['oee', 'availability', 'performance', 'quality', 'boards', 'mtbf', 'mttr']
        .map((name) => [name, figure(name).querySelector('.value').textContent])),
      boards_label: figure('boards').querySelector('.label').textContent,
      stops: [...document.querySelectorAll('#stops li.stop')].map((li) => ({
        ...li.dataset, text: li.querySelector('.stop-time').textContent,
      })),
    };
  });
  const first = await shown();

  // Point at the widest known segment of the last hour's bar.
  const widest = first.hour.segments.filter((s) => s.category !== 'unknown')
    .sort((a, b) => b.width - a.width)[0];
  await page.mouse.move(widest.x, widest.y);
  const pointed = await page.evaluate(() => {
    const detail = document.getElementById('state-detail');
    return { start: detail.dataset.start, text: detail.textContent };
  });
  if (screenshot) await page.screenshot({ path: screenshot, fullPage: true });

  // Asked for again by itself (every 10 s, or when the machine's state changes).
  await page.waitForFunction(
    (before) => document.getElementById('production-numbers').dataset.answered !== before,
    first.answered,
    { timeout: 30000, polling: 100 },
  );
  const later = await shown();

  // On a phone: nothing wider than the screen.
  const phone = await onAPhone(page, screenshot);
  if (errors.length) throw new Error(`the page threw: ${errors.join('; ')}`);
  console.log(JSON.stringify({
    first, pointed: { ...pointed, segment: widest }, later, phone, answers: await Promise.all(answers),
  }));
} finally {
  await browser.close();
}
