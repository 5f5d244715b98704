// What the panel shows, decided by pure modules (issue 29): phase styles, errors that are
// errors, tracking figures only while something is tracked, command outcomes, program
// outcome counts, the last known place, routine log events, plot unit choices, time cells
// and ages, and the reconnection's "try now".
import assert from 'node:assert/strict';
import { test } from 'node:test';
import { ROUTINE_EVENTS, isRoutine } from '../../src/eventlog.js';
import { ageText, utcCell, utcClock } from '../../src/format.js';
import { keepTrying } from '../../src/reconnect.js';
import {
  OPERATION_INFO_ROWS, PHASE_STYLES, commandOutcome, commandText, endedText, errorLines, operationFigures,
  phaseView, placeToShow, programOutcomes, rememberPlace, trackingView,
} from '../../src/telescope-view.js';
import { unitChoices, unitFactor } from '../../src/units.js';

// every phase of the VSS's operations table (virtualstar/server/operations.py, docs/vss-api.md)
const VSS_PHASES = ['starting', 'preparing', 'pass planned', 'slewing', 'waiting', 'joining', 'settling',
  'tracking', 'measuring', 'interrupted', 'ending', 'done', 'failed', 'aborted'];
const op = (phase, info = {}) => ({ id: 3, kind: 'track', target: 'Vega', phase, info });
const STOPPED = { code: 'aborted', message: 'stopped by a client', stopped: true };

test('only running phases are green: interrupted is amber, failed red, the ends neutral', () => {
  for (const p of VSS_PHASES) assert.ok(p in PHASE_STYLES, p);
  assert.equal(phaseView(op('tracking')).style, 'live');
  assert.equal(phaseView(op('interrupted')).style, 'warn');
  assert.equal(phaseView(op('failed', { error: { code: 'not_arrived', message: 'x' } })).style, 'bad');
  assert.equal(phaseView(op('done')).style, 'done');
  assert.equal(phaseView(op('some new phase')).style, 'unknown'); // never green by default
  assert.equal(phaseView(null).label, '—');
});

test('a stopped operation reads as stopped, neutral; one ended by a lost mount is amber', () => {
  assert.deepEqual(phaseView(op('aborted', { error: STOPPED })), { style: 'ended', label: 'stopped' });
  assert.equal(endedText(op('aborted', { error: STOPPED })), 'stopped by a client');
  const replaced = op('aborted', { error: { code: 'aborted', message: 'replaced by a new slew (Deneb)' } });
  assert.deepEqual(phaseView(replaced), { style: 'ended', label: 'aborted' });
  const lost = op('aborted', { error: { code: 'mount_offline', message: 'the mount is gone' } });
  assert.equal(phaseView(lost).style, 'warn');
  assert.equal(endedText(lost), 'aborted: mount_offline: the mount is gone');
  assert.equal(endedText(op('tracking')), '');
});

test('a stop or a replacement is no error; a failure, an interruption, faults and a lost mount are', () => {
  assert.deepEqual(errorLines({ operation: op('aborted', { error: STOPPED }) }), []);
  assert.deepEqual(errorLines({ operation: op('aborted', { error: { code: 'aborted', message: 'replaced' } }) }), []);
  const failed = errorLines({ operation: op('failed', { error: { code: 'not_arrived', message: 'off by 9″' } }) });
  assert.deepEqual(failed, [{ level: 'error', text: 'operation 3: not_arrived: off by 9″' }]);
  const interrupted = errorLines({ operation: op('interrupted', { interrupted: { code: 'tracking_lost', message: 'buffer ran dry' } }) });
  assert.deepEqual(interrupted, [{ level: 'warning', text: 'interrupted: buffer ran dry' }]);
  const faults = errorLines({ connected: false, axes: { az: { faults: 4, fault_text: 'OVERCURRENT' }, el: { faults: 0 } } });
  assert.deepEqual(faults.map((l) => l.text), ['az: OVERCURRENT (0x4)', 'the VSS has no connection to the mount (it keeps reconnecting)']);
});

test('the tracking error is shown only while a sky target is followed with the mount on', () => {
  assert.equal(trackingView({ operation: op('tracking') }).shown, true);
  assert.equal(trackingView({ operation: op('measuring') }).shown, true);
  assert.deepEqual(trackingView({ mount_state: 'off', operation: op('tracking') }), { shown: false, why: 'the mount is off' });
  assert.equal(trackingView({ operation: op('aborted', { error: STOPPED }) }).why, 'nothing is tracked');
  assert.equal(trackingView({ operation: op('slewing') }).shown, false);
  assert.equal(trackingView({ operation: op('tracking', { fixed: true }) }).shown, false);
  assert.equal(trackingView({}).shown, false);
});

test('command outcomes: refused, failed, ended, started and done, each with the server\'s words', () => {
  const err = (code, message) => Object.assign(new Error(message), { code });
  assert.deepEqual(commandOutcome('slew', { error: err('unreachable', 'sun is at elevation -14°') }),
    { outcome: 'refused', text: 'refused: unreachable: sun is at elevation -14°' });
  assert.equal(commandOutcome('slew', { error: err('forbidden', 'observer') }).outcome, 'refused');
  assert.equal(commandOutcome('slew', { error: err('not_arrived', 'off by 9″') }).outcome, 'failed');
  assert.deepEqual(commandOutcome('slew', { error: err('aborted', 'stopped by a client') }), { outcome: 'ended', text: 'ended: stopped by a client' });
  assert.equal(commandOutcome('slew', { error: err('closed', 'lost') }).text, 'no answer: lost');
  // park without waiting answers at once: "started", not "done (starting)"
  assert.deepEqual(commandOutcome('park', { result: { id: 5, kind: 'park', phase: 'starting' } }), { outcome: 'started', text: 'started (park #5)' });
  assert.deepEqual(commandOutcome('slew', { result: { id: 6, kind: 'slew', phase: 'tracking' } }), { outcome: 'started', text: 'tracking (slew #6)' });
  assert.deepEqual(commandOutcome('track', { result: { id: 7, kind: 'track', phase: 'done' } }), { outcome: 'done', text: 'done (track #7)' });
  assert.deepEqual(commandOutcome('stop', { result: { mount_state: 'holding' } }), { outcome: 'done', text: 'done (mount holding)' });
  assert.equal(commandText('track', { star: 'Vega', duration_s: 60 }), 'track Vega for 60 s');
  assert.equal(commandText('slew', { altaz: '120 45' }), 'slew 120 45');
  assert.equal(commandText('park', { wait: false }), 'park');
});

test('program outcome counts in order, blocks left out, outcomes a newer server adds shown too', () => {
  const summary = { blocks: 5, done: 2, late: 1, missed: 0, faulted: 1, stopped: 1, degraded: 3, postponed: 4, observed_hours: 0.5 };
  assert.deepEqual(programOutcomes(summary).map((o) => [o.name, o.count, o.style]), [
    ['done', 2, 'done'], ['degraded', 3, 'warn'], ['late', 1, 'warn'], ['missed', 0, 'warn'], ['faulted', 1, 'bad'], ['stopped', 1, 'ended'], ['postponed', 4, 'unknown']]);
  assert.deepEqual(programOutcomes(null), []);
});

test('operation figures come from the table, in its order, only when present', () => {
  assert.deepEqual(operationFigures(op('tracking', { seconds_left: 12.4, slew_time_s: 20.04 })).map((f) => [f.label, f.text]),
    [['Slew time', '20.0 s'], ['Left', '12 s']]);
  assert.ok(OPERATION_INFO_ROWS.every(([label, key, format]) => label && key && typeof format === 'function'));
});

test('a finished track shows the error on target, the planned deviation apart, and degraded', () => {
  const info = { tracking_rms_arcsec: 15556.73, off_target_s: 54.45, off_target_threshold_arcsec: 5,
    planned_deviation_peak_arcsec: 34097.7, planned_deviation: ['keyhole'], following_rms_arcsec: 0.0855, outcome: 'degraded' };
  assert.deepEqual(operationFigures(op('done', info)).map((f) => [f.label, f.text]), [
    ['On target RMS', '15556.730″'], ['Off target', '54.5 s beyond 5″'], ['Planned deviation', '34097.7″ (keyhole)'],
    ['Following RMS', '0.086″'], ['Outcome', 'degraded: off target']]);
});

test('the last known place stays when the mount goes away, marked as kept', () => {
  const fresh = { encoder: { az_deg: 10, el_deg: 40 }, observed: { az_deg: 10, el_deg: 40 }, radec: { ra_deg: 279, dec_deg: 38 }, mount_time_us: 1e15 };
  const kept = rememberPlace(fresh, null, 1000);
  assert.deepEqual(placeToShow(fresh, kept), { place: fresh, kept: false, atMs: null });
  const away = { connected: false };
  assert.equal(rememberPlace(away, kept, 2000), kept); // nothing new to remember
  const shown = placeToShow(away, kept);
  assert.equal(shown.kept, true);
  assert.equal(shown.atMs, 1000);
  assert.deepEqual(shown.place.encoder, fresh.encoder);
  assert.deepEqual(placeToShow(away, null), { place: {}, kept: false, atMs: null });
});

test('routine events: clock syncs and the set_utc calls behind them, nothing else', () => {
  assert.ok(ROUTINE_EVENTS.length >= 2);
  assert.ok(isRoutine({ kind: 'clock_sync', fields: {} }));
  assert.ok(isRoutine({ kind: 'command', fields: { command: 'time.set_utc' } }));
  assert.ok(!isRoutine({ kind: 'command', fields: { command: 'mount.stop' } }));
  assert.ok(!isRoutine({ kind: 'param', fields: { name: 'time.set_utc' } }));
});

test('angle units convert among rad, deg and arcsec (rates too); other units stay', () => {
  assert.deepEqual(unitChoices('rad'), ['rad', 'deg', 'arcsec']);
  assert.deepEqual(unitChoices('rad/s'), ['rad/s', 'deg/s', 'arcsec/s']);
  assert.deepEqual(unitChoices('A'), ['A']);
  assert.deepEqual(unitChoices(''), ['']);
  assert.ok(Math.abs(unitFactor('rad', 'deg') * Math.PI - 180) < 1e-12);
  assert.ok(Math.abs(unitFactor('deg', 'arcsec') - 3600) < 1e-9);
  assert.ok(Math.abs(unitFactor('arcsec/s', 'rad/s') * 206264.80624709636 - 1) < 1e-12);
  assert.equal(unitFactor('rad/s', 'deg'), 1); // not the same kind of quantity: no conversion
  assert.equal(unitFactor('A', 'deg'), 1);
});

test('time cells have one format and millisecond precision; ages read as durations', () => {
  assert.equal(utcCell(1716066151123456), '2024-05-18 21:02:31.123');
  assert.equal(utcCell(null), '—');
  assert.equal(utcClock(Date.UTC(2024, 4, 18, 21, 2, 31)), '21:02:31');
  assert.equal(ageText(1000, 13_999), '12 s ago');
  assert.equal(ageText(0, 5000), '');
  assert.equal(ageText(1000, 1000 + 125_000), '2 min 5 s ago');
  assert.equal(ageText(1000, 1000 + 3 * 3600_000 + 600_000), '3 h 10 min ago');
});

test('a retry told where to look tries at once instead of after its pause', async () => {
  let calls = 0;
  let firstTried;
  const tried = new Promise((r) => { firstTried = r; });
  const retry = keepTrying(async () => {
    calls += 1;
    if (calls < 2) {
      firstTried();
      throw new Error('not yet');
    }
  }, { delayMs: (n) => (n === 0 ? 0 : 3_600_000) });
  await tried;
  await new Promise((r) => setImmediate(r)); // its failure handled: the next try an hour away
  assert.equal(calls, 1);
  retry.now();
  assert.equal(await retry.done, true);
  assert.equal(calls, 2);
});
