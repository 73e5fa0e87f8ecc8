// What big.mjs and page.mjs share: the browser they drive and the pages they open in it.
import { chromium } from 'playwright-core';

/** Headless Chromium: CHROMIUM, else Debian's /usr/bin/chromium. */
export function launch() {
  return chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: [
      '--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
    ],
  });
}

/** A new 1600 × 1000 page of `browser`; what it throws is added to `errors`. */
export async function openPage(browser, errors) {
  const page = await browser.newPage({ viewport: { width: 1600, height: 1000 } });
  page.on('pageerror', (e) => errors.push(String(e)));
  return page;
}
