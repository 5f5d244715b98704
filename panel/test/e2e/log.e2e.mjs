// End-to-end: the Log tab following `vs server --emulator`'s two logs (the VSS's and its
// mount's). Run by tests/panel/test_panel_log_e2e.py, which talks with this script over
// stdin/stdout: the test sends commands with its own clients while the page follows, then
// checks what the page held and showed against the logs it reads itself.
//
// Protocol (one line each): this script prints `LOG-E2E READY` once both logs show; the
// test answers `SENT {json}` (the parameter it wrote and its value) after a slew and a
// write; this script applies the filters, pauses, prints `LOG-E2E PAUSED`; the test writes
// again and answers `SENT {json}`; this script checks the write waits, follows, and ends.
//
// env: PANEL_URL, ASTCOM_URL, ASTCOM_PASSWORD, VSS_URL, VSS_PASSWORD, ARTIFACTS, RESULT, FILTERS
// (a JSON list of {from, to, level, source, kind, text} to apply in turn; the last one is exported).
import { mkdirSync, readFileSync } from 'node:fs';
import { join } from 'node:path';
import { createInterface } from 'node:readline';
import { openAndConnect, runPageScript } from './browser.mjs';

const env = process.env;
const ARTIFACTS = env.ARTIFACTS || 'artifacts/panel';
mkdirSync(ARTIFACTS, { recursive: true });
const lines = createInterface({ input: process.stdin })[Symbol.asyncIterator]();
const say = (text) => console.log(`LOG-E2E ${text}`);
async function heard(word) {
  const { value } = await lines.next();
  if (!value?.startsWith(`${word} `)) throw new Error(`expected ${word} from the test, got ${value}`);
  return JSON.parse(value.slice(word.length + 1));
}
const held = (page) => page.evaluate(() => JSON.parse(JSON.stringify(window.panelEventLog.rows())));
const hasEvent = (page, source, kind, fields) => page.waitForFunction(([s, k, f]) => window.panelEventLog.rows().some(
  (e) => e.source === s && e.kind === k && Object.entries(f).every(([n, v]) => e.fields?.[n] === v)), [source, kind, fields], { timeout: 60_000 });

/** The table as the user sees it: one object per row, from the cells. */
const table = (page) => page.$$eval('[data-testid=log-table] tbody tr', (trs) => trs.map((tr) => ({
  key: `${tr.dataset.source}:${tr.dataset.seq}`,
  ...Object.fromEntries([...tr.querySelectorAll('td')].map((td) => [td.dataset.col, td.textContent.trim()])),
})));

async function applyFilter(page, f) {
  await page.fill('input[name=log-from]', f.from || '');
  await page.fill('input[name=log-to]', f.to || '');
  await page.selectOption('select[name=log-level]', f.level || 'debug');
  await page.fill('input[name=log-source]', f.source || '');
  await page.fill('input[name=log-kind]', f.kind || '');
  await page.fill('input[name=log-text]', f.text || '');
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => r()))); // Vue has drawn
}

await runPageScript(env.RESULT || join(ARTIFACTS, 'log-result.json'), join(ARTIFACTS, 'log-failure.png'), async (page, result) => {
  await openAndConnect(page, env.PANEL_URL, env.ASTCOM_URL, env.ASTCOM_PASSWORD);
  await page.click('button[data-tab=Telescope]');
  await page.fill('input[name=vss-url]', env.VSS_URL);
  await page.fill('input[name=vss-password]', env.VSS_PASSWORD);
  await page.click('button.vss-connect');
  await page.waitForFunction(() => window.panelTelescope.status === 'connected', null, { timeout: 15_000 });
  await page.click('button[data-tab=Log]');
  // both logs hold the page's own connections from the start
  await hasEvent(page, 'emulator', 'connection', { client: 'panel' });
  await hasEvent(page, 'vss', 'connection', {});
  result.steps.push('both logs followed');
  say('READY');

  const sent = await heard('SENT');
  await hasEvent(page, 'vss', 'command', { command: 'slew' });
  await hasEvent(page, 'emulator', 'param', { name: sent.param, new: sent.value });
  result.steps.push('the test\'s slew and write shown');

  // every event, routine ones included, as `vs log` shows them (test_panel_trust_e2e.py
  // checks that they are hidden by default)
  await page.check('input[name=log-routine]');
  // a still snapshot for the filters: paused, the table holds what it holds
  await page.click('button.log-follow');
  result.held = await held(page);
  result.filtered = [];
  for (const f of JSON.parse(env.FILTERS)) {
    await applyFilter(page, f);
    result.filtered.push({
      filter: f, rows: await table(page), count: await page.textContent('[data-testid=log-count]'),
      errors: await page.$$eval('[data-testid=log-filter-error]', (ps) => ps.map((p) => p.textContent)),
    });
  }
  await page.screenshot({ path: join(ARTIFACTS, 'log.png') });
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('button.log-export')]);
  const exportPath = join(ARTIFACTS, 'log-export.jsonl');
  await download.saveAs(exportPath);
  result.exported = readFileSync(exportPath, 'utf8');
  result.steps.push('filtered and exported');

  // paused: new events wait aside; Follow brings them in
  await applyFilter(page, {});
  const before = await table(page);
  say('PAUSED');
  const again = await heard('SENT');
  await page.waitForFunction(() => window.panelEventLog.eventLog.pending > 0, null, { timeout: 30_000 });
  // two more polls: the table must still not move
  const polls = await page.evaluate(() => window.panelEventLog.eventLog.polls);
  await page.waitForFunction((n) => window.panelEventLog.eventLog.polls >= n + 2, polls, { timeout: 30_000 });
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
  result.paused = { before: before.length, during: (await table(page)).length, button: (await page.textContent('button.log-follow')).trim() };
  await page.click('button.log-follow');
  await hasEvent(page, 'emulator', 'param', { name: again.param, new: again.value });
  await applyFilter(page, { kind: 'param' });
  result.afterFollow = { rows: await table(page), heldCount: (await held(page)).length };
  await page.screenshot({ path: join(ARTIFACTS, 'log-followed.png') });
  result.steps.push('follow adds rows');
});
