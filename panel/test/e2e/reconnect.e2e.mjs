// End-to-end: the panel finds the mount's endpoint and the VirtualStar Server again after
// each is killed and restarted, and marks what it shows stale meanwhile. Run by
// tests/panel/test_panel_reconnect_e2e.py, which owns the processes: this script prints
// "ASK <action>" and waits for a line on stdin once the test has done it.
//
// env: PANEL_URL, ASTCOM_URL, ASTCOM_PASSWORD, VSS_URL, VSS_PASSWORD, ARTIFACTS, RESULT.
import { mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { createInterface } from 'node:readline';
import { openAndConnect, runPageScript, streamSignals } from './browser.mjs';

const env = process.env;
const ARTIFACTS = env.ARTIFACTS || 'artifacts/panel';
mkdirSync(ARTIFACTS, { recursive: true });
const lines = createInterface({ input: process.stdin })[Symbol.asyncIterator]();
async function ask(action) {
  console.log(`ASK ${action}`);
  const answer = await lines.next();
  if (answer.done || answer.value.trim() !== 'done') throw new Error(`the test did not do ${action}: ${answer.value}`);
}

/** What the page shows of both links: states, stale marks, freshness. */
const look = (page) => page.evaluate(() => {
  const q = (sel) => document.querySelector(sel);
  const { session } = window.panelProbe;
  const t = window.panelTelescope;
  return {
    astcom: session.status,
    astcomStaleClass: q('[data-testid=astcom-board]').classList.contains('stale'),
    astcomStaleNote: q('[data-testid=astcom-stale]')?.textContent.trim() ?? '',
    headerAstcom: q('[data-testid=status]').textContent.trim(),
    streamActive: session.stream.active,
    samples: session.stream.samples,
    vss: t.status,
    vssStaleClass: q('[data-testid=telescope-board]').classList.contains('stale'),
    vssStaleNote: q('[data-testid=vss-stale]').textContent.trim(),
    headerVss: q('[data-testid=vss-status]').textContent.trim(),
    vssUpdatedMs: t.updatedMs,
    mountLink: q('#tab-Telescope [data-field="mount-link"]').textContent.trim(),
    encoderAz: q('#tab-Telescope [data-field="encoder-az"]').textContent.trim(),
    encoderAzKept: q('#tab-Telescope [data-field="encoder-az"]').classList.contains('kept'),
    encoderAzColor: getComputedStyle(q('#tab-Telescope [data-field="encoder-az"]')).color,
    placeKept: q('[data-testid=place-kept]')?.textContent.trim() ?? '',
    log: q('[data-testid=log]').textContent,
  };
});
const until = (page, fn, arg, timeout = 60_000) => page.waitForFunction(fn, arg, { timeout, polling: 200 });

await runPageScript(env.RESULT || join(ARTIFACTS, 'reconnect-result.json'), join(ARTIFACTS, 'reconnect-failure.png'), async (page, result) => {
  await openAndConnect(page, env.PANEL_URL, env.ASTCOM_URL, env.ASTCOM_PASSWORD);
  await streamSignals(page, ['axis.az.position_deg'], 100);
  await page.click('button[data-tab=Telescope]');
  await page.fill('input[name=vss-url]', env.VSS_URL);
  await page.fill('input[name=vss-password]', env.VSS_PASSWORD);
  await page.click('button.vss-connect');
  await until(page, () => window.panelTelescope.state?.connected === true);
  await page.click('button[data-tab=Log]'); // the Log tab follows both logs from now on
  await until(page, () => ['emulator', 'vss'].every((s) => window.panelEventLog.rows().some((e) => e.source === s)));
  result.fresh = await look(page);

  await ask('kill-mount');
  await until(page, () => window.panelProbe.session.status === 'reconnecting');
  await until(page, () => window.panelTelescope.state?.connected === false);
  await page.click('button[data-tab=Board]');
  result.mountKilled = await look(page);
  await page.screenshot({ path: join(ARTIFACTS, 'reconnect-stale.png') });
  result.steps.push('mount killed');

  await ask('restart-mount');
  await until(page, () => window.panelProbe.session.status === 'connected' && window.panelProbe.session.stream.active);
  const samples = await page.evaluate(() => window.panelProbe.session.stream.samples);
  await until(page, (n) => window.panelProbe.session.stream.samples > n + 20, samples);
  await until(page, () => window.panelTelescope.state?.connected === true);
  result.mountBack = await look(page);
  result.steps.push('mount back');

  await ask('kill-vss');
  await until(page, () => window.panelTelescope.status === 'reconnecting');
  await page.click('button[data-tab=Telescope]');
  result.vssKilled = await look(page);
  await page.screenshot({ path: join(ARTIFACTS, 'reconnect-vss-stale.png') });
  result.steps.push('vss killed');

  await ask('restart-vss');
  const before = Date.now();
  await until(page, (t0) => window.panelTelescope.status === 'connected' && window.panelTelescope.updatedMs > t0, before);
  result.vssBack = await look(page);
  result.steps.push('vss back');

  // the Log tab read each restarted process's log from its first event (numbered from 1 again)
  await until(page, () => ['emulator', 'vss'].every(
    (s) => window.panelEventLog.rows().filter((e) => e.source === s && e.seq === 1).length === 2));
  result.logRows = await page.evaluate(() => JSON.parse(JSON.stringify(window.panelEventLog.rows())));
  result.steps.push('log read again from each restart');
});
