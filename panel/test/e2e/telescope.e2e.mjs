// End-to-end: the Telescope tab and the header's STOP against `vs server --emulator`.
// Run by tests/panel/test_panel_telescope_e2e.py (one scenario per run), which checks what
// the page did with its own clients of the VSS and of the mount's ASTCom endpoint.
//
// env: PANEL_URL, ASTCOM_URL, ASTCOM_PASSWORD, VSS_URL, VSS_PASSWORD, ARTIFACTS, RESULT,
// SCENARIO: 'track-stop' (wrong password, track Vega, read the board, header STOP) or
// 'park' (park from the board, read the board at rest) or 'program' (a running plan shown,
// then ended by the header's STOP).
import { mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { openAndConnect, runPageScript } from './browser.mjs';

const env = process.env;
const ARTIFACTS = env.ARTIFACTS || 'artifacts/panel';
mkdirSync(ARTIFACTS, { recursive: true });
const step = (result, name) => {
  result.steps.push(name);
  console.log(`telescope e2e: ${name}`);
};
const field = (page, name) => page.textContent(`#tab-Telescope [data-field="${name}"]`).then((t) => t.trim());
const BOARD_FIELDS = ['target', 'kind', 'phase', 'mode', 'mount-state', 'encoder-az', 'encoder-el', 'observed-az',
  'observed-el', 'ra', 'dec', 'mount-time', 'rms-1s', 'on-sky-rms-1s', 'on-target-rms-1s', 'planned-1s',
  'pointing-model', 'clock-offset', 'mount-link'];
const readBoard = async (page) => Object.fromEntries(await Promise.all(BOARD_FIELDS.map(async (f) => [f, await field(page, f)])));
/** Wait until the board has drawn a status polled after this moment. */
async function nextPoll(page) {
  const now = await page.evaluate(() => Date.now());
  await page.waitForFunction((t) => window.panelTelescope.updatedMs > t, now, { timeout: 30_000 });
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
}
const waitField = (page, name, pattern, timeout = 60_000) => page.waitForFunction(
  ([n, p]) => new RegExp(p).test(document.querySelector(`#tab-Telescope [data-field="${n}"]`)?.textContent.trim() ?? ''),
  [name, pattern], { timeout });

async function connectVss(page, password) {
  await page.click('button[data-tab=Telescope]');
  await page.fill('input[name=vss-password]', password);
  await page.click('button.vss-connect');
}

await runPageScript(env.RESULT || join(ARTIFACTS, 'telescope-result.json'), join(ARTIFACTS, `telescope-failure-${env.SCENARIO}.png`), async (page, result) => {
  await openAndConnect(page, env.PANEL_URL, env.ASTCOM_URL, env.ASTCOM_PASSWORD);
  await page.click('button[data-tab=Telescope]');
  await page.waitForFunction((u) => document.querySelector('input[name=vss-url]').value === u, env.VSS_URL);
  result.proposedVss = await page.inputValue('input[name=vss-url]'); // from vs panel --vss via config.json
  if (env.SCENARIO === 'track-stop') {
    await connectVss(page, 'not-the-password');
    await page.waitForFunction(() => /wrong password/.test(document.querySelector('[data-testid=log]')?.textContent ?? ''), null, { timeout: 15_000 });
    result.wrongPasswordState = await page.textContent('[data-testid=vss-state]');
    step(result, 'wrong password refused');
  }
  await connectVss(page, env.VSS_PASSWORD);
  await page.waitForFunction(() => window.panelTelescope.status === 'connected' && window.panelTelescope.state, null, { timeout: 15_000 });
  result.role = await page.evaluate(() => window.panelTelescope.grantedRole);
  step(result, 'connected to the VSS');

  if (env.SCENARIO === 'track-stop') {
    await page.selectOption('select[name=target-kind]', 'star');
    await page.fill('input[name=target]', 'Vega');
    await page.click('button.vss-track');
    await waitField(page, 'phase', '^tracking$');
    // a full 1 s window of tracking error behind the board's figures
    await page.waitForFunction(() => {
      const s = window.panelTelescope.state;
      return s?.operation?.phase === 'tracking' && s.tracking_error?.['1s']?.n > 500
        && s.mount_time_us > s.operation.info.tracking_from_us + 2e6;
    }, null, { timeout: 60_000 });
    await nextPoll(page);
    result.tracking = await readBoard(page);
    result.trackingOperation = await page.evaluate(() => JSON.parse(JSON.stringify(window.panelTelescope.state.operation)));
    await page.screenshot({ path: join(ARTIFACTS, 'telescope.png') });
    step(result, 'tracking Vega shown');

    // the hand pad: an arrow key (focused) and a button, 5″ steps on the sky
    await page.selectOption('select[name=hand-pad-frame]', 'sky');
    await page.selectOption('select[name=hand-pad-step]', '5');
    await page.focus('[data-testid=hand-pad]');
    await page.keyboard.press('ArrowUp');
    await page.click('[data-testid=hand-pad] button.pad-left');
    await waitField(page, 'offset-dec', '^5\\.000″$', 30_000);
    await waitField(page, 'offset-ra', '^5\\.000″$', 30_000);
    result.handPad = { dec: await field(page, 'offset-dec'), ra: await field(page, 'offset-ra'),
      mode: await field(page, 'corrections-mode'), labels: await page.$$eval('[data-testid=hand-pad] .hand-pad-grid button', (b) => b.map((x) => x.textContent.trim())),
      corrections: await page.evaluate(() => JSON.parse(JSON.stringify(window.panelTelescope.state.corrections))) };
    step(result, 'hand pad offsets');

    await page.click('[data-testid=stop-all]');
    await page.waitForFunction(() => /VSS: stop done/.test(document.querySelector('[data-testid=stop-outcome]')?.textContent ?? ''), null, { timeout: 30_000 });
    result.stopOutcome = await page.textContent('[data-testid=stop-outcome]');
    await waitField(page, 'phase', '^(stopped|aborted|done)$');
    result.afterStop = await readBoard(page);
    result.log = await page.textContent('[data-testid=log]');
    step(result, 'header STOP');
  } else if (env.SCENARIO === 'program') {
    // a plan sent by another client (as `vs run` does) shows on the board while it runs
    await waitField(page, 'program-state', '^running$');
    await waitField(page, 'program-current', '^(?!—)', 120_000);
    result.program = { state: await field(page, 'program-state'), current: await field(page, 'program-current') };
    await page.screenshot({ path: join(ARTIFACTS, 'telescope-program.png') });
    await page.click('[data-testid=stop-all]');
    await waitField(page, 'program-state', '^stopped$');
    result.programAfterStop = await field(page, 'program-state');
    step(result, 'program shown and stopped');
  } else if (env.SCENARIO === 'park') {
    await page.click('button.vss-park');
    await waitField(page, 'kind', '^park');
    await waitField(page, 'phase', '^done$', 120_000);
    await waitField(page, 'mount-state', '^off$');
    await nextPoll(page);
    result.parked = await readBoard(page);
    await page.screenshot({ path: join(ARTIFACTS, 'telescope-parked.png') });
    step(result, 'parked');
  }
});
