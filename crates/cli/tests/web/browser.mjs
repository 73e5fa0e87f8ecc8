// What the page scripts share: the browser they drive and the pages they open in it.
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

/**
 * The page at a phone's width (360 px): how far it overflows and the first elements wider
 * than the screen; a screenshot beside `screenshot` (`-phone.png`) when one is asked for.
 */
export async function onAPhone(page, screenshot, ready) {
  await page.setViewportSize({ width: 360, height: 780 });
  if (ready) await ready();
  const phone = await page.evaluate(() => ({
    overflow: document.documentElement.scrollWidth - window.innerWidth,
    widest: [...document.querySelectorAll('body *')]
      .filter((el) => el.getBoundingClientRect().right > window.innerWidth + 1)
      .slice(0, 5)
      .map((el) => `${el.tagName.toLowerCase()}.${el.className}#${el.id}`),
  }));
  if (screenshot) await page.screenshot({ path: screenshot.replace(/\.png$/, '-phone.png'), fullPage: true });
  return phone;
}
