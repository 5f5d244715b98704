// Smoke test of the panel against a controller that is not our emulator: the C example
// device (astcom_device) behind `astcom relay`, whose names differ (extra.sNN, wave.*,
// time.now_us). Run by tests/panel/test_panel_c_device_e2e.py, which starts the device and
// the Relay, then checks with the Python client what this script did through the page.
//
// env: PANEL_URL, ASTCOM_URL, ASTCOM_PASSWORD, ARTIFACTS, RESULT, PARAM_NAME, PARAM_VALUE.
import { mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { checkComputed, computeSeries, openAndConnect, runPageScript, streamSignals, writeParameter } from './browser.mjs';

const env = process.env;
const ARTIFACTS = join(env.ARTIFACTS || 'artifacts/panel', 'c-device');
mkdirSync(ARTIFACTS, { recursive: true });
const tab = (page, name) => page.click(`button[data-tab=${name}]`);

await runPageScript(env.RESULT, join(ARTIFACTS, 'failure.png'), async (page, result) => {
  // The Board connects through the Relay like to any endpoint; LIST comes whole.
  await openAndConnect(page, env.PANEL_URL, env.ASTCOM_URL, env.ASTCOM_PASSWORD);
  result.entries = await page.evaluate(() => window.panelProbe.session.entries.length);
  result.steps.push('connected');

  // Input: a function call returns its value.
  await tab(page, 'Input');
  await page.fill('input[name=call-name]', 'time.now_us');
  await page.click('button.call');
  await page.waitForFunction(() => document.querySelector('.call-result').textContent.trim() !== '');
  result.nowUs = Number(await page.textContent('.call-result'));
  result.hostUs = Date.now() * 1000;
  result.steps.push('function called');

  // Signals and Plot: two signals at every tick, drawn.
  await streamSignals(page, ['extra.s00', 'counter'], 1000);
  await tab(page, 'Plot');
  const before = await page.evaluate(() => window.panelProbe.probe.plotUpdates);
  await page.waitForFunction((b) => window.panelProbe.probe.plotUpdates > b + 5 && window.panelProbe.probe.plotPoints > 50,
    before, { timeout: 15_000 });
  await page.screenshot({ path: join(ARTIFACTS, 'plot.png') });
  result.steps.push('plot');

  // Compute: an expression over the streamed signals, checked sample by sample in the page.
  await computeSeries(page, 'twice', '2 * extra.s00 + counter');
  result.computeCheck = await checkComputed(page, 'twice', ['extra.s00', 'counter'], '2 * x0 + x1');
  result.steps.push('compute');

  // Parameters: write one, see it shown.
  result.paramShown = await writeParameter(page, env.PARAM_NAME, env.PARAM_VALUE);
  await page.screenshot({ path: join(ARTIFACTS, 'parameters.png') });
  result.steps.push('parameter written');

  // Board: STATS polled (the device's clients, through the Relay).
  await tab(page, 'Board');
  await page.waitForFunction(() => document.querySelector('#tab-Board [data-field=clients]')?.textContent.trim() > '0',
    null, { timeout: 10_000 });
  result.stream = await page.evaluate(() => ({ samples: window.panelProbe.session.stream.samples,
    lost: window.panelProbe.session.stream.lost }));
  await page.screenshot({ path: join(ARTIFACTS, 'board.png') });
  result.steps.push('board');
});
