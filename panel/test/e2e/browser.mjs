// Launch Debian's chromium through playwright-core (never a downloaded browser build).
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { chromium } from 'playwright-core';

export const CHROMIUM = process.env.CHROMIUM_PATH || '/usr/bin/chromium';

// Without the background-networking flags chromium keeps trying to reach Google's servers.
const ARGS = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync',
  '--disable-dev-shm-usage'];

// How often page.waitForFunction evaluates its condition unless told otherwise. Playwright's
// default polls at every animation frame, which makes the browser render 60 frames a second
// for as long as a test waits; every condition the scripts wait for holds for seconds once
// true (a state reached, a count grown), so a tenth of a second loses nothing.
export const WAIT_POLL_MS = 100;

function pollingEvery(page, ms) {
  const waitForFunction = page.waitForFunction.bind(page);
  page.waitForFunction = (fn, arg, options = {}) => waitForFunction(fn, arg, { polling: ms, ...options });
  return page;
}

/** Return {context, close()}: a persistent context in a fresh, empty profile folder. */
export async function launch({ width = 1400, height = 900 } = {}) {
  const profile = mkdtempSync(join(tmpdir(), 'panel-chromium-'));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: CHROMIUM,
    headless: true,
    args: ARGS,
    viewport: { width, height },
    acceptDownloads: true,
  });
  const newPage = context.newPage.bind(context);
  context.newPage = async (...args) => pollingEvery(await newPage(...args), WAIT_POLL_MS);
  return {
    context,
    async close() {
      await context.close();
      rmSync(profile, { recursive: true, force: true });
    },
  };
}

/** Open the panel, connect to `endpoint` on the Board tab, wait for "connected". */
export async function openAndConnect(page, panelUrl, endpoint, password) {
  await page.goto(panelUrl);
  await page.fill('input[name=url]', endpoint);
  await page.fill('input[name=password]', password || '');
  await page.click('button.connect');
  await page.waitForFunction(() => window.panelProbe?.session.status === 'connected', null, { timeout: 60_000 });
}

/** Tick signals on the Signals tab and start streaming them at `rateHz`. */
export async function streamSignals(page, names, rateHz) {
  await page.click('button[data-tab=Signals]');
  for (const name of names) {
    await page.fill('input[name=signal-filter]', name);
    await page.locator(`input[data-signal="${name}"]`).check();
  }
  await page.fill('input[name=signal-filter]', '');
  await page.fill('input[name=rate]', String(rateHz));
  await page.click('button.start-stream');
  await page.waitForFunction(() => window.panelProbe.session.stream.samples > 0, null, { timeout: 60_000 });
}

/**
 * On the Compute tab, define the series `name` = `expr` (in `unit`) and wait until it has
 * been evaluated on `n` samples.
 */
export async function computeSeries(page, name, expr, { unit = '', n = 200, timeout = 15_000 } = {}) {
  await page.click('button[data-tab=Compute]');
  await page.fill('input[name=compute-name-0]', name);
  await page.fill('input[name=compute-expr-0]', expr);
  if (unit) await page.fill('input[name=compute-unit-0]', unit);
  await page.click('button.apply-computes');
  await page.waitForFunction(([nm, want]) => { // the expression has been evaluated on some packets
    const { series } = window.panelProbe;
    const c = series.series.get(nm);
    let count = 0;
    for (let i = 0; c && i < series.count; i++) if (!Number.isNaN(c[i])) count++;
    return count >= want;
  }, [name, n], { timeout });
}

/**
 * Check the computed series `name` sample by sample against `reference`, a JS expression
 * of the series `inputs` (and Math): return {n, worst} (the largest absolute difference).
 */
export async function checkComputed(page, name, inputs, reference) {
  return page.evaluate(([nm, ins, ref]) => {
    const { series } = window.panelProbe;
    const f = new Function(...ins.map((_, k) => `x${k}`), `return ${ref};`);
    const cols = ins.map((i) => series.series.get(i));
    const c = series.series.get(nm);
    let n = 0;
    let worst = 0;
    for (let i = 0; i < series.count; i++) {
      if (Number.isNaN(c[i])) continue;
      n++;
      worst = Math.max(worst, Math.abs(c[i] - f(...cols.map((col) => col[i]))));
    }
    return { n, worst };
  }, [name, inputs, reference]);
}

/** On the Parameters tab, set `name` to `value` and wait until the tab shows it; return it. */
export async function writeParameter(page, name, value) {
  await page.click('button[data-tab=Parameters]');
  await page.fill('input[name=param-filter]', name);
  await page.fill(`input[data-param="${name}"]`, value);
  await page.click(`button[data-set="${name}"]`);
  await page.waitForFunction(([n, v]) => document.querySelector(`[data-param-value="${n}"]`)?.textContent.trim() === v,
    [name, value], { timeout: 60_000 });
  return page.textContent(`[data-param-value="${name}"]`);
}

/**
 * Run `body(page, result)` in a fresh chromium page; write `result` (with ok, error and the
 * page's uncaught errors) as JSON to `resultPath`, keep a screenshot on failure, and exit
 * with 0 only when the body finished.
 */
export async function runPageScript(resultPath, failureShot, body) {
  const { writeFileSync } = await import('node:fs');
  const result = { steps: [] };
  const browser = await launch();
  const page = await browser.context.newPage();
  page.on('pageerror', (err) => {
    result.pageErrors = [...(result.pageErrors || []), err.message];
  });
  try {
    await body(page, result);
    result.ok = true;
  } catch (err) {
    result.ok = false;
    result.error = String(err.stack || err);
    await page.screenshot({ path: failureShot }).catch(() => {});
  } finally {
    writeFileSync(resultPath, JSON.stringify(result, null, 2));
    await browser.close();
  }
  process.exit(result.ok ? 0 : 1);
}
