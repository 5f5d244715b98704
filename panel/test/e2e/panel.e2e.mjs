// End-to-end: the built panel in headless chromium against a live mount emulator.
// Run by tests/panel/test_panel_e2e.py, which starts the emulator and `vs panel`'s server,
// then checks with the Python client what this script did through the page.
//
// env: PANEL_URL, ASTCOM_URL, ASTCOM_PASSWORD, ARTIFACTS (screenshot folder), RESULT (JSON
// path), PARAM_NAME, PARAM_VALUE, AZ_FORMULA, EL_FORMULA, TRAJ_DURATION_S, TRAJ_STEP_S.
import assert from 'node:assert/strict';
import { mkdirSync, readFileSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { checkComputed, computeSeries, launch, openAndConnect, streamSignals, writeParameter } from './browser.mjs';

const env = process.env;
const ARTIFACTS = env.ARTIFACTS || 'artifacts/panel';
mkdirSync(ARTIFACTS, { recursive: true });
const result = { steps: [] };
const step = (name) => {
  result.steps.push(name);
  console.log(`e2e: ${name}`);
};
const shot = (page, tab) => page.screenshot({ path: join(ARTIFACTS, `${tab.toLowerCase()}.png`), fullPage: false });
const tab = (page, name) => page.click(`button[data-tab=${name}]`);

const browser = await launch();
const page = await browser.context.newPage();
page.on('pageerror', (err) => {
  result.pageErrors = [...(result.pageErrors || []), err.message];
});
try {
  // A wrong password is refused and said so in the Board's log; the page stays usable.
  await page.goto(env.PANEL_URL);
  await page.fill('input[name=url]', env.ASTCOM_URL);
  await page.fill('input[name=password]', 'not-the-password');
  await page.click('button.connect');
  await page.waitForFunction(() => /wrong password/.test(document.querySelector('[data-testid=log]').textContent));
  result.wrongPasswordLog = await page.textContent('[data-testid=log] .error');
  await openAndConnect(page, env.PANEL_URL, env.ASTCOM_URL, env.ASTCOM_PASSWORD);
  step('connected');
  result.entries = await page.evaluate(() => window.panelProbe.session.entries.length);
  // The plot asks for animation frames only when it has something new to draw: none on an
  // idle page (a frame loop there costs the browser CPU for nothing)
  const plotFrames = () => page.evaluate(() => window.panelProbe.probe.plotFrames);
  const idleFrames = await plotFrames();
  await page.waitForTimeout(1000);
  result.idlePlotFrames = (await plotFrames()) - idleFrames;

  // Input: power the mount on (Start), then check a function call returns a value.
  await tab(page, 'Input');
  await page.waitForFunction(() => document.querySelector('input[name=quick-start]').value !== '');
  result.quickStart = await page.inputValue('input[name=quick-start]');
  await page.click('button.quick-start');
  await page.fill('input[name=call-name]', 'time.now_us');
  await page.click('button.call');
  await page.waitForFunction(() => document.querySelector('.call-result').textContent.trim() !== '');
  result.nowUs = Number(await page.textContent('.call-result'));
  step('function called');

  // Signals: stream two signals at 1 kHz on the stream channel.
  await streamSignals(page, ['axis.az.error', 'axis.az.position_deg'], 1000);
  step('streaming');
  // nor while the samples stream in but the Plot tab is not shown
  const hiddenFrames = await plotFrames();
  const hiddenSamples = await page.evaluate(() => window.panelProbe.session.stream.samples);
  await page.waitForTimeout(500);
  result.hiddenPlot = { frames: (await plotFrames()) - hiddenFrames,
    samples: (await page.evaluate(() => window.panelProbe.session.stream.samples)) - hiddenSamples };

  // Compute: an expression over a streamed signal, checked sample by sample in the page.
  await computeSeries(page, 'az_err_arcsec', 'axis.az.error * 3600 * 180 / pi', { unit: 'arcsec', timeout: 10_000 });
  result.computeCheck = await checkComputed(page, 'az_err_arcsec', ['axis.az.error'], 'x0 * 3600 * 180 / Math.PI');
  assert.ok(result.computeCheck.n > 0, 'the computed series received no sample');
  // Save the Compute tab's state, clear it, load the file back.
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#tab-Compute button.save-state')]);
  const savedPath = join(ARTIFACTS, 'panel-compute.json');
  await download.saveAs(savedPath);
  result.savedCompute = JSON.parse(readFileSync(savedPath, 'utf8'));
  await page.fill('input[name=compute-expr-0]', '');
  await page.setInputFiles('#tab-Compute input.state-input', savedPath);
  await page.waitForFunction(() => document.querySelector('input[name=compute-expr-0]').value !== '');
  result.reloadedExpr = await page.inputValue('input[name=compute-expr-0]');
  await shot(page, 'Compute');
  step('compute');

  // Plot: the plot receives data (decimated points drawn, several redraws).
  await tab(page, 'Plot');
  const before = await page.evaluate(() => window.panelProbe.probe.plotUpdates);
  await page.waitForFunction((b) => window.panelProbe.probe.plotUpdates > b + 5 && window.panelProbe.probe.plotPoints > 50,
    before, { timeout: 10_000 });
  result.plot = await page.evaluate(() => ({ ...window.panelProbe.probe, samples: window.panelProbe.session.stream.samples, lost: window.panelProbe.session.stream.lost }));
  step('plot');
  // Axes: the units and tick labels of one plot per signal, then of all in one plot.
  const redrawn = async () => {
    const n = await page.evaluate(() => window.panelProbe.probe.plotUpdates);
    await page.waitForFunction((b) => window.panelProbe.probe.plotUpdates > b + 2, n, { timeout: 10_000 });
  };
  await redrawn();
  result.stackedAxes = await page.evaluate(() => ({ ...window.panelProbe.probe.yAxes }));
  await page.uncheck('input[name=stacked]');
  await redrawn();
  result.allInOneAxes = await page.evaluate(() => ({ ...window.panelProbe.probe.yAxes }));
  await page.screenshot({ path: join(ARTIFACTS, 'plot-all-in-one.png') });
  await page.check('input[name=stacked]');
  // an angle shown in another unit: the axis says it, the samples drawn are converted
  await page.selectOption('select[name="unit:axis.az.error"]', 'arcsec');
  await redrawn();
  result.unitChosen = await page.evaluate(() => ({ axes: Object.keys(window.panelProbe.probe.yAxes), drawn: window.panelProbe.probe.drawn }));
  await page.screenshot({ path: join(ARTIFACTS, 'plot-arcsec.png') });
  await page.selectOption('select[name="unit:axis.az.error"]', 'rad');
  await redrawn();
  // Export the visible window as CSV: every sample, with units in the header.
  await page.click('button.pause');
  const [csvFile] = await Promise.all([page.waitForEvent('download'), page.click('button.export-csv')]);
  const csvPath = join(ARTIFACTS, 'plot-export.csv');
  await csvFile.saveAs(csvPath);
  result.csvPath = csvPath;
  result.csvWindowS = Number(await page.inputValue('input[name=window]'));
  await page.click('button.pause');
  step('plot axes and CSV');

  // Input: run a trajectory from formulas; meanwhile change a parameter online.
  await tab(page, 'Input');
  await page.fill('input[name="traj-expr-az_rad"]', env.AZ_FORMULA);
  await page.fill('input[name="traj-expr-el_rad"]', env.EL_FORMULA);
  await page.fill('input[name=traj-duration]', env.TRAJ_DURATION_S);
  await page.fill('input[name=traj-step]', env.TRAJ_STEP_S);
  await page.fill('input[name=traj-lead]', env.TRAJ_LEAD_S);
  await page.fill('input[name=traj-ramp]', env.TRAJ_RAMP_S);
  await page.click('button.preview-trajectory');
  await page.waitForSelector('[data-testid=traj-preview] canvas');
  result.previewStatus = await page.textContent('.traj-status');
  await page.click('button.run-trajectory');
  await page.waitForFunction(() => window.panelTrajectory.lastRun !== null);
  step('trajectory started');

  result.paramShown = await writeParameter(page, env.PARAM_NAME, env.PARAM_VALUE);
  await page.fill('input[name=param-filter]', 'axis.az');
  await shot(page, 'Parameters');
  step('parameter written');

  await tab(page, 'Input');
  await page.waitForFunction(() => window.panelTrajectory.lastRun?.done && !window.panelTrajectory.running, null, { timeout: 20_000 });
  result.trajectory = await page.evaluate(() => JSON.parse(JSON.stringify({ ...window.panelTrajectory.lastRun, status: window.panelTrajectory.status })));
  result.progress = await page.textContent('.traj-progress');
  result.logAfterTrajectory = await page.textContent('[data-testid=log]');
  await shot(page, 'Input');
  step('trajectory pushed');
  // The plot while the mount follows the formulas (1.5 s into the run).
  await tab(page, 'Plot');
  await page.waitForFunction((t0) => window.panelProbe.series.lastTUs > t0 + 1.5e6, result.trajectory.t0_us, { timeout: 10_000 });
  await shot(page, 'Plot');

  await tab(page, 'Diagnostics');
  await page.waitForFunction(() => [...document.querySelectorAll('#tab-Diagnostics td.num')].some((td) => td.textContent.trim() !== '—'));
  await shot(page, 'Diagnostics');
  await tab(page, 'Signals');
  await shot(page, 'Signals');
  await tab(page, 'Board');
  // one poll of the watch list and STATS
  await page.waitForFunction(() => document.querySelector('#tab-Board [data-field=clients]')
    && document.querySelector('#tab-Board [data-field^="watch:"]')?.textContent.trim() !== '—', null, { timeout: 10_000 });
  await shot(page, 'Board');
  step('screenshots');

  // Every tab saves its state to a JSON file and loads it back.
  result.states = {};
  for (const name of ['Board', 'Telescope', 'Diagnostics', 'Signals', 'Plot', 'Compute', 'Parameters', 'Input', 'Log']) {
    await tab(page, name);
    const [file] = await Promise.all([page.waitForEvent('download'), page.click(`#tab-${name} button.save-state`)]);
    const path = join(ARTIFACTS, `state-${name.toLowerCase()}.json`);
    await file.saveAs(path);
    await page.setInputFiles(`#tab-${name} input.state-input`, path);
    await page.waitForFunction((n) => /^loaded /.test(document.querySelector(`#tab-${n} .statefile .muted`).textContent), name);
    result.states[name] = JSON.parse(readFileSync(path, 'utf8'));
  }
  // A file of another tab is refused with a message.
  await tab(page, 'Plot');
  await page.setInputFiles('#tab-Plot input.state-input', join(ARTIFACTS, 'state-input.json'));
  await page.waitForFunction(() => /holds the Input tab's state/.test(document.querySelector('#tab-Plot .statefile .muted').textContent));
  step('states saved and loaded');

  // Errors at a glance: once the trajectory is over, inject an encoder fault through the
  // Parameters tab; the Diagnostics card and the Board's watch list turn red.
  const endUs = result.trajectory.t0_us + (Number(env.TRAJ_DURATION_S) + 0.5) * 1e6;
  await page.waitForFunction((t) => window.panelProbe.series.lastTUs > t, endUs, { timeout: 15_000 });
  await tab(page, 'Parameters');
  await page.fill('input[name=param-filter]', 'axis.el.inject_encoder_fault');
  await page.fill('input[data-param="axis.el.inject_encoder_fault"]', '1');
  await page.click('button[data-set="axis.el.inject_encoder_fault"]');
  await tab(page, 'Diagnostics');
  await page.waitForSelector('#tab-Diagnostics .card.bad[data-group="axis.el"]', { timeout: 10_000 });
  result.faultCards = await page.$$eval('#tab-Diagnostics .card.bad', (cards) => cards.map((c) => c.dataset.group));
  await page.screenshot({ path: join(ARTIFACTS, 'diagnostics-fault.png') });
  await tab(page, 'Board');
  await page.waitForFunction(() => [...document.querySelectorAll('table.watch tr.bad td:first-child')].some((td) => td.textContent === 'axis.el.fault_text'));
  result.faultRows = await page.$$eval('table.watch tr.bad td:first-child', (tds) => tds.map((td) => td.textContent));
  step('fault shown');
  result.ok = true;
} catch (err) {
  result.ok = false;
  result.error = String(err.stack || err);
  await page.screenshot({ path: join(ARTIFACTS, 'failure.png') }).catch(() => {});
} finally {
  writeFileSync(env.RESULT || join(ARTIFACTS, 'e2e-result.json'), JSON.stringify(result, null, 2));
  await browser.close();
}
process.exit(result.ok ? 0 : 1);
