// Opens the gateway's page in headless Chromium and checks what a person would see:
// a card for every device the API lists, and a value on the page that changes by itself.
// Usage: node page.mjs http://127.0.0.1:PORT screenshot.png
// With READ_TOKEN set, the gateway needs it: the page must ask for it (a prompt, answered
// here) before it shows anything.
// With MQTT set, the gateway publishes to a broker: the page must show the MQTT link up.
// Prints one JSON line with what it saw; exits non-zero with a reason otherwise.
import { launch, openPage, onAPhone } from './browser.mjs';

const [base, screenshot] = process.argv.slice(2);

const readToken = process.env.READ_TOKEN || '';
const headers = readToken ? { Authorization: `Bearer ${readToken}` } : {};
const api = await (await fetch(`${base}/api/devices`, { headers })).json();
const ids = api.devices.map((d) => d.id);

const browser = await launch();
try {
  const errors = [];
  const page = await openPage(browser, errors);
  let asked = 0;
  page.on('dialog', async (dialog) => {
    asked += 1;
    await dialog.accept(readToken);
  });
  await page.goto(`${base}/`);
  for (const id of ids) {
    await page.waitForSelector(`[id="device-${id}"]`, { timeout: 20000 });
  }
  const values = () =>
    [...document.querySelectorAll('[id^="point-"]')].map((el) => [
      el.id,
      el.querySelector('.value')?.textContent ?? '',
    ]);
  const before = await page.evaluate(values);
  const changed = await page.waitForFunction(
    (before) => {
      const then = new Map(before);
      for (const el of document.querySelectorAll('[id^="point-"]')) {
        const text = el.querySelector('.value')?.textContent ?? '';
        if (then.has(el.id) && text !== '' && text !== then.get(el.id)) {
          return { id: el.id, before: then.get(el.id), after: text };
        }
      }
      return false;
    },
    before,
    { timeout: 20000, polling: 100 },
  );
  const change = await changed.jsonValue();
  if (process.env.MQTT) {
    await page.waitForFunction(
      () => document.getElementById('mqtt').textContent === 'MQTT',
      null,
      { timeout: 30000, polling: 100 },
    );
  }
  const mqtt = await page.evaluate(() => {
    const badge = document.getElementById('mqtt');
    return badge.hidden ? null : badge.textContent;
  });
  const cfx = await page.evaluate(() => {
    const badge = document.getElementById('cfx');
    return badge.hidden ? null : badge.textContent;
  });
  if (screenshot) await page.screenshot({ path: screenshot, fullPage: true });
  // The header's word on the cell (from /healthz, which needs no token).
  await page.waitForFunction(
    () => /^\d+ of \d+ devices up/.test(document.getElementById('cell-summary').textContent),
    null,
    { timeout: 20000, polling: 100 },
  );
  const summary = await page.evaluate(() => document.getElementById('cell-summary').textContent);
  // One number format per unit: every shown number of a unit has as many decimals.
  const formats = await page.evaluate(() => {
    const byUnit = {};
    for (const tile of document.querySelectorAll('.point')) {
      const unit = tile.querySelector('.unit')?.textContent;
      const value = tile.querySelector('.value')?.textContent ?? '';
      if (!unit || !/^-?\d+(\.\d+)?$/.test(value)) continue;
      const decimals = value.includes('.') ? value.split('.')[1].length : 0;
      (byUnit[unit] ||= new Set()).add(decimals);
    }
    return Object.fromEntries(Object.entries(byUnit).map(([u, d]) => [u, [...d]]));
  });
  // On a phone: nothing wider than the screen.
  const phone = await onAPhone(page, screenshot);
  if (errors.length) throw new Error(`the page threw: ${errors.join('; ')}`);
  console.log(JSON.stringify({ devices: ids, points: before.length, change, asked, mqtt, cfx, summary, formats, phone }));
} finally {
  await browser.close();
}
