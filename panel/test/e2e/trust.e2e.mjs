// End-to-end: the panel an operator can trust at 2 a.m. (issue 29), at 1400×900 and 1024×700
// at once: one browser, one page per size, both connected to the same `vs server --emulator`.
// Run by tests/panel/test_panel_trust_e2e.py, which owns the server process: this script
// prints "ASK <action>" and waits for "done <json>" on stdin once the test has done it.
//
// Per page, in turn: track Vega, measure every card and header item on every tab (nothing
// overflows); press STOP and measure the button before and after; slew to the Sun (refused)
// and read the reason the tab shows; the Log tab without and with routine events; log in
// as observer and press STOP again (refused), measuring the button. Then, both pages at
// once: the VSS killed (every value cell stale), restarted with its emulator's endpoint on
// another port (the Board's link follows the VSS there).
//
// env: PANEL_URL, ASTCOM_URL, MOUNT_PASSWORD, VSS_URL, OPERATOR_PASSWORD, OBSERVER_PASSWORD,
// ARTIFACTS, RESULT, CHROMIUM_PATH.
import { mkdirSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { createInterface } from 'node:readline';
import { launch, openAndConnect } from './browser.mjs';

const env = process.env;
const ARTIFACTS = env.ARTIFACTS || 'artifacts/panel/trust';
mkdirSync(ARTIFACTS, { recursive: true });
const SIZES = [{ width: 1400, height: 900 }, { width: 1024, height: 700 }];
const WAIT = { timeout: 60_000, polling: 100 };
const lines = createInterface({ input: process.stdin })[Symbol.asyncIterator]();

async function ask(action) {
  console.log(`ASK ${action}`);
  const answer = await lines.next();
  if (answer.done || !answer.value.startsWith('done')) throw new Error(`the test did not do ${action}: ${answer.value}`);
  const rest = answer.value.slice(4).trim();
  return rest ? JSON.parse(rest) : null;
}

const sizeName = (page) => `${page.viewportSize().width}x${page.viewportSize().height}`;
const shot = (page, name) => page.screenshot({ path: join(ARTIFACTS, `${name}-${sizeName(page)}.png`) });
const tab = async (page, name) => {
  await page.click(`button[data-tab=${name}]`);
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)))); // drawn
};
const box = (page) => page.locator('[data-testid=stop-all]').boundingBox();
const until = (page, fn, arg) => page.waitForFunction(fn, arg, WAIT);

/** Every visible card and every header item whose content is wider than its box. */
const overflows = (page) => page.evaluate(() => {
  const items = [document.querySelector('header'), ...document.querySelectorAll('header > *, header .links > *, header nav > button')];
  const cards = [...document.querySelectorAll('main .card')].filter((c) => c.offsetParent !== null);
  const name = (el) => el.dataset.testid || el.querySelector('h3')?.textContent || el.dataset.tab || el.className || el.tagName;
  return {
    checked: { header: items.length, cards: cards.length },
    over: [...items, ...cards].filter((el) => el.scrollWidth > el.clientWidth)
      .map((el) => ({ item: name(el), scrollWidth: el.scrollWidth, clientWidth: el.clientWidth })),
  };
});

async function connectVss(page, role, password) {
  await tab(page, 'Telescope');
  if (await page.locator('button.vss-disconnect').count()) await page.click('button.vss-disconnect');
  await page.fill('input[name=vss-url]', env.VSS_URL);
  await page.selectOption('select[name=vss-role]', role);
  await page.fill('input[name=vss-password]', password);
  await page.click('button.vss-connect');
  await until(page, (r) => window.panelTelescope.status === 'connected' && window.panelTelescope.grantedRole === r && window.panelTelescope.state, role);
}

async function connectBoard(page, role) {
  await tab(page, 'Board');
  if (await page.locator('button.disconnect').count()) await page.click('button.disconnect');
  await page.selectOption('select[name=role]', role);
  await page.fill('input[name=password]', env.MOUNT_PASSWORD);
  await page.click('button.connect');
  await until(page, (r) => window.panelProbe.session.status === 'connected' && window.panelProbe.session.grantedRole === r, role);
}

/** Press the header's STOP and wait for both answers; return what the message says. */
async function pressStop(page) {
  const presses = await page.evaluate(() => window.panelStop.presses);
  await page.click('[data-testid=stop-all]');
  await until(page, (n) => window.panelStop.presses === n + 1 && !window.panelStop.pending, presses);
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  return (await page.textContent('[data-testid=stop-outcome]')).trim();
}

/** The value cells of both boards: those without the stale look (colour and italics). */
const notStale = (page) => page.evaluate(() => {
  const cells = [...document.querySelectorAll(['[data-testid=telescope-board] [data-field]', '[data-testid=astcom-board] [data-field]',
    'table.watch td[data-field]', '#tab-Diagnostics .diag-cards td.num', '#tab-Parameters td[data-param-value]'].join(', '))];
  const name = (c) => c.dataset.field || (c.dataset.paramValue && `param:${c.dataset.paramValue}`) || `diagnostics:${c.closest('[data-group]')?.dataset.group}`;
  const stale = (el) => {
    const cs = getComputedStyle(el);
    return cs.color === 'rgb(138, 143, 153)' && cs.fontStyle === 'italic';
  };
  return { checked: cells.length, fields: cells.map(name), notStale: cells.filter((c) => !stale(c)).map((c) => `${name(c)}=${c.textContent.trim()}`) };
});

async function onePage(page, out) {
  const p = { size: sizeName(page) };
  out.pages.push(p);
  await openAndConnect(page, env.PANEL_URL, env.ASTCOM_URL, env.MOUNT_PASSWORD);
  await connectVss(page, 'operator', env.OPERATOR_PASSWORD);
  p.steps = ['connected'];

  // track Vega and look at every tab: nothing overflows its card or header cell
  await page.selectOption('select[name=target-kind]', 'star');
  await page.fill('input[name=target]', 'Vega');
  await page.click('button.vss-track');
  await until(page, () => /^\d/.test(document.querySelector('[data-field="rms-1s"]')?.textContent.trim() ?? ''));
  p.overflow = {};
  for (const name of ['Board', 'Telescope', 'Diagnostics', 'Signals', 'Plot', 'Compute', 'Parameters', 'Input', 'Log']) {
    await tab(page, name);
    p.overflow[name] = await overflows(page);
  }
  await tab(page, 'Telescope');
  await shot(page, 'telescope-tracking');
  await tab(page, 'Board');
  await shot(page, 'board');
  p.steps.push('overflow measured');

  // STOP: the button stays where it was, however the answers read
  await tab(page, 'Telescope');
  p.stopBox = { before: await box(page) };
  p.stopOutcome = await pressStop(page);
  p.stopBox.after = await box(page);
  await until(page, () => window.panelTelescope.state?.operation?.phase === 'aborted');
  p.afterStop = await page.evaluate(() => ({
    phase: document.querySelector('[data-field=phase]').textContent.trim(),
    phaseStyle: document.querySelector('[data-field=phase]').dataset.style,
    ended: document.querySelector('[data-field=ended]')?.textContent.trim(),
    errors: [...document.querySelectorAll('[data-testid=errors] [data-field=error]')].map((e) => e.textContent.trim()),
    errorsBad: document.querySelector('[data-testid=errors]').classList.contains('bad'),
    rms: document.querySelector('[data-field="rms-1s"]').textContent.trim(),
    trackingWhy: document.querySelector('[data-testid=tracking-why]')?.textContent.trim(),
  }));
  await shot(page, 'stop-outcome');
  p.stopTruth = await ask('truth-stop');
  p.steps.push('stopped');

  // a refused slew says why, on the tab that sent it
  await page.fill('input[name=target]', 'Sun');
  await page.click('button.vss-slew');
  await until(page, () => document.querySelector('[data-testid=command-outcome-text]')?.dataset.outcome === 'refused');
  p.refused = {
    what: (await page.textContent('[data-testid=command-outcome] b')).trim(),
    text: (await page.textContent('[data-testid=command-outcome-text]')).trim(),
    color: await page.$eval('[data-testid=command-outcome-text]', (el) => getComputedStyle(el).color),
  };
  await shot(page, 'refused-slew');
  p.refusedTruth = await ask('truth-refused');
  p.steps.push('refused slew shown');

  // the Log tab: clock syncs hidden until asked for
  await tab(page, 'Log');
  await until(page, () => window.panelEventLog.rows().some((e) => e.kind === 'clock_sync'));
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  const logView = () => page.evaluate(() => {
    const rows = [...document.querySelectorAll('[data-testid=log-table] tbody tr')];
    return {
      rows: rows.length,
      clockSyncRows: rows.filter((r) => r.dataset.kind === 'clock_sync').length,
      setUtcRows: rows.filter((r) => r.querySelector('[data-col=message]').textContent.startsWith('time.set_utc(')).length,
      held: window.panelEventLog.rows().length,
      heldClockSync: window.panelEventLog.rows().filter((e) => e.kind === 'clock_sync').length,
      hiddenNote: document.querySelector('[data-testid=log-routine-hidden]').textContent.trim(),
      fieldsLinesMax: Math.max(0, ...rows.map((r) => {
        const text = r.querySelector('.fields-text');
        return text.getBoundingClientRect().height / parseFloat(getComputedStyle(text).fontSize);
      })),
      rowHeightMax: Math.max(0, ...rows.map((r) => r.getBoundingClientRect().height)),
      tableWidth: document.querySelector('[data-testid=log-table]').getBoundingClientRect().width,
      pageWidth: document.documentElement.clientWidth,
      pageScrollWidth: document.documentElement.scrollWidth,
    };
  });
  p.logDefault = await logView();
  await shot(page, 'log-routine-hidden');
  await page.check('input[name=log-routine]');
  await until(page, () => [...document.querySelectorAll('[data-testid=log-table] tbody tr')].some((r) => r.dataset.kind === 'clock_sync'));
  p.logRoutine = await logView();
  await shot(page, 'log-routine-shown');
  await page.uncheck('input[name=log-routine]');
  p.steps.push('log routine hidden and shown');

  // as an observer: the buttons say why they are disabled, and a refused STOP moves nothing
  await connectBoard(page, 'observer');
  await connectVss(page, 'observer', env.OBSERVER_PASSWORD);
  p.observer = {
    disabled: await page.$$eval('[data-testid=telescope-controls] button', (bs) => bs.map((b) => ({ text: b.textContent.trim(), disabled: b.disabled, title: b.title }))),
    hint: (await page.textContent('[data-testid=controls-hint]')).trim(),
  };
  // the Board's link as observer: what would write or call is disabled, saying why
  await tab(page, 'Parameters');
  p.observerParameters = await page.$$eval('#tab-Parameters button[data-set], #tab-Parameters button.write-all', (bs) => bs.map((b) => ({ disabled: b.disabled, title: b.title })));
  await tab(page, 'Input');
  p.observerInput = await page.$$eval('#tab-Input button[class^=quick-], #tab-Input button.run-trajectory', (bs) => bs.map((b) => ({ disabled: b.disabled, title: b.title })));
  await tab(page, 'Telescope');
  p.stopBox.beforeRefused = await box(page);
  p.refusedStopOutcome = await pressStop(page);
  p.stopBox.afterRefused = await box(page);
  p.refusedStopFailed = await page.$eval('[data-testid=stop-outcome-box]', (el) => el.classList.contains('failed'));
  await shot(page, 'stop-refused');
  p.steps.push('refused stop');
}

const result = { pages: [] };
const browser = await launch();
const pages = [];
try {
  for (const size of SIZES) {
    const page = await browser.context.newPage();
    page.on('pageerror', (err) => { result.pageErrors = [...(result.pageErrors || []), err.message]; });
    page.on('console', (msg) => { if (msg.type() === 'error') result.consoleErrors = [...(result.consoleErrors || []), msg.text()]; });
    await page.setViewportSize(size);
    pages.push(page);
    await onePage(page, result);
  }

  // both pages at once: the VSS (and the emulator inside it) killed
  await ask('kill-vss');
  for (const page of pages) {
    await until(page, () => window.panelTelescope.status === 'reconnecting' && window.panelProbe.session.status === 'reconnecting');
  }
  result.killed = [];
  for (const page of pages) {
    const k = { size: sizeName(page), ...(await notStale(page)) };
    k.header = await page.evaluate(() => ({
      astcom: document.querySelector('[data-testid=status]').textContent.trim(),
      astcomColor: getComputedStyle(document.querySelector('[data-testid=status] b')).color,
      astcomStyle: getComputedStyle(document.querySelector('[data-testid=status] b')).fontStyle,
      vss: document.querySelector('[data-testid=vss-status]').textContent.trim(),
    }));
    k.notes = await page.evaluate(() => ({
      vss: document.querySelector('[data-testid=vss-stale]').textContent.trim(),
      astcom: document.querySelector('[data-testid=astcom-stale]')?.textContent.trim(),
    }));
    await tab(page, 'Telescope');
    await shot(page, 'stale-telescope');
    await tab(page, 'Board');
    await shot(page, 'stale-board');
    result.killed.push(k);
  }

  // restarted, its emulator's endpoint elsewhere: the Board's link follows the VSS's word
  const restarted = await ask('restart-vss');
  result.restarted = [];
  for (const page of pages) {
    await until(page, (u) => window.panelTelescope.status === 'connected' && window.panelProbe.session.status === 'connected'
      && window.panelProbe.session.url === u, restarted.endpoint);
    const tick = Number(await page.textContent('[data-field=tick]'));
    await until(page, (t) => Number(document.querySelector('[data-field=tick]').textContent) > t, tick);
    result.restarted.push({
      size: sizeName(page),
      url: await page.evaluate(() => window.panelProbe.session.url),
      boardUrl: await page.inputValue('input[name=url]'),
      mountEndpoint: await page.evaluate(() => window.panelTelescope.mountEndpoint),
      log: await page.textContent('[data-testid=log]'),
      boardsStale: await page.evaluate(() => ({
        telescope: document.querySelector('[data-testid=telescope-board]').classList.contains('stale'),
        astcom: document.querySelector('[data-testid=astcom-board]').classList.contains('stale'),
      })),
    });
    await shot(page, 'restarted-board');
  }
  result.ok = true;
} catch (err) {
  result.ok = false;
  result.error = String(err.stack || err);
  for (const page of pages) await page.screenshot({ path: join(ARTIFACTS, `failure-${sizeName(page)}.png`) }).catch(() => {});
} finally {
  writeFileSync(env.RESULT || join(ARTIFACTS, 'trust-result.json'), JSON.stringify(result, null, 2));
  await browser.close();
}
process.exit(result.ok ? 0 : 1);
