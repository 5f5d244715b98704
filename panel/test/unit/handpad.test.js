// The hand pad's mapping from buttons and arrow keys to the VSS `offset` command.
import assert from 'node:assert/strict';
import { test } from 'node:test';
import { buttonLabel, keyDirection, offsetFor, offsetRows } from '../../src/handpad.js';

test('on the sky north and east add to dec and ra, south and west subtract', () => {
  assert.deepEqual(offsetFor('sky', 'up', 5, 1), { axis: 'dec', op: 'add', arcsec: 5 });
  assert.deepEqual(offsetFor('sky', 'down', 5, 1), { axis: 'dec', op: 'add', arcsec: -5 });
  assert.deepEqual(offsetFor('sky', 'left', 2, 1), { axis: 'ra', op: 'add', arcsec: 2 });
  assert.deepEqual(offsetFor('sky', 'right', 2, 1), { axis: 'ra', op: 'add', arcsec: -2 });
  assert.equal(buttonLabel('sky', 'left'), 'E'); // north up, east left: the sky as seen
});

test('along a pass the vertical buttons move the path in seconds, the others across it', () => {
  assert.deepEqual(offsetFor('pass', 'up', 10, 0.25), { axis: 'path', op: 'add', seconds: 0.25 });
  assert.deepEqual(offsetFor('pass', 'down', 10, 0.25), { axis: 'path', op: 'add', seconds: -0.25 });
  assert.deepEqual(offsetFor('pass', 'left', 10, 0.25), { axis: 'transverse', op: 'add', arcsec: 10 });
  assert.deepEqual(offsetFor('axes', 'right', 3, 1), { axis: 'az', op: 'add', arcsec: 3 });
});

test('arrow keys are directions and other keys are not', () => {
  assert.equal(keyDirection('ArrowUp'), 'up');
  assert.equal(keyDirection('ArrowLeft'), 'left');
  assert.equal(keyDirection('a'), null);
});

test('a step out of the VSS range or an unknown frame is refused with the range', () => {
  assert.throws(() => offsetFor('sky', 'up', 0, 1), /at most 3600/);
  assert.throws(() => offsetFor('sky', 'up', 1e5, 1), /at most 3600/);
  assert.throws(() => offsetFor('pass', 'up', 1, 60), /at most 30 s/);
  assert.throws(() => offsetFor('moon', 'up', 1, 1), /unknown frame/);
});

test('the offsets table reads totals and rates in their own units', () => {
  const rows = offsetRows({ corrections: { offsets: { axes: {
    dec: { total_arcsec: 5, rate_arcsec_per_s: 0, moving: false },
    path: { total_s: 1.5, rate_s_per_s: 0.1, moving: true } } } } });
  assert.deepEqual(rows, [{ axis: 'dec', unit: '″', total: 5, rate: 0, moving: false },
                          { axis: 'path', unit: 's', total: 1.5, rate: 0.1, moving: true }]);
  assert.deepEqual(offsetRows({}), []);
});

test('the command outcome of an offset says when it acts, and its text says what moved', async () => {
  const { commandOutcome, commandText, operationFigures } = await import('../../src/telescope-view.js');
  assert.equal(commandText('offset', { axis: 'dec', op: 'add', arcsec: 5 }), 'offset dec add +5″');
  assert.equal(commandText('offset', { axis: 'path', op: 'add', seconds: -0.25 }), 'offset path add -0.25 s');
  assert.equal(commandText('offset', { axis: 'all', op: 'reset' }), 'offset all reset');
  const out = commandOutcome('offset', { result: { lead_ms: 20, sent: 'replace_from', offsets: {} } });
  assert.deepEqual(out, { outcome: 'done', text: 'done: acts 20 ms after acceptance (replace_from)' });
  const figures = operationFigures({ info: { closed_loop: { state: 'locked', accepted: 12, refused: 1, held: 3 } } });
  assert.deepEqual(figures.map((f) => f.text), ['locked: 12 frames used, 1 refused, 3 held']);
});
