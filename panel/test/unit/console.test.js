// The operator's console's pure parts: the VSS's challenge–response (checked against
// node:crypto's HMAC, a second implementation of the documented formula), reconnection
// pauses, number formatting and the CSV export. No server needed.
import assert from 'node:assert/strict';
import { createHmac, randomBytes } from 'node:crypto';
import { test } from 'node:test';
import { decimalsForStep, dms, fixed, hms, niceTicks, readable, tickLabels, toCsv } from '../../src/format.js';
import { formatValue } from '../../src/grouping.js';
import { keepTrying, RECONNECT_DELAYS_MS, reconnectDelayMs } from '../../src/reconnect.js';
import { authRequest, fromHex, toHex } from '../../src/vss/auth.js';

// docs/vss-api.md: mac = HMAC-SHA256(key = password, msg = b"ASTCom-1 client\x00" + nonce + client_nonce)
const documented = (label, password, nonceHex, cnonceHex) => createHmac('sha256', Buffer.from(password, 'utf8'))
  .update(Buffer.concat([Buffer.from(`ASTCom-1 ${label}\0`, 'latin1'), Buffer.from(nonceHex, 'hex'), Buffer.from(cnonceHex, 'hex')]))
  .digest('hex');

test('vss auth mac is the documented HMAC of the label and both nonces', async () => {
  const nonce = randomBytes(32).toString('hex');
  const { params } = await authRequest('pässwörd', nonce, 'observer');
  assert.equal(params.role, 'observer');
  assert.match(params.client_nonce, /^[0-9a-f]{64}$/);
  assert.equal(params.mac, documented('client', 'pässwörd', nonce, params.client_nonce));
});

test('vss auth believes only the server proof made with the same password', async () => {
  const nonce = randomBytes(32).toString('hex');
  const answer = await authRequest('secret', nonce);
  assert.equal(answer.params.role, undefined); // no role asked: the highest the password gives
  assert.ok(answer.proofMatches(documented('server', 'secret', nonce, answer.params.client_nonce)));
  assert.ok(!answer.proofMatches(documented('server', 'other', nonce, answer.params.client_nonce)));
  assert.ok(!answer.proofMatches(documented('client', 'secret', nonce, answer.params.client_nonce)));
  assert.ok(!answer.proofMatches(null) && !answer.proofMatches('zz'));
});

test('hex round-trips bytes and refuses text that is not hex', () => {
  const bytes = Uint8Array.from([0, 1, 0xab, 0xff]);
  assert.equal(toHex(bytes), '0001abff');
  assert.deepEqual(fromHex('0001ABff'), bytes);
  assert.throws(() => fromHex('abc'), /expected hex text/);
  assert.throws(() => fromHex('zz'), /expected hex text/);
});

test('reconnection pauses grow then stay at the longest', () => {
  assert.deepEqual([0, 1, 2, 3, 4, 50].map(reconnectDelayMs), [500, 1000, 2000, 2000, 2000, 2000]);
  assert.ok(RECONNECT_DELAYS_MS.every((d, i) => i === 0 || d >= RECONNECT_DELAYS_MS[i - 1]));
  assert.ok(Math.max(...RECONNECT_DELAYS_MS) <= 2000); // a restarted endpoint is found within 2 s
});

test('keepTrying retries after each failure until an attempt succeeds', async () => {
  const tries = [];
  const r = keepTrying(async (n) => {
    tries.push(n);
    if (n < 2) throw new Error('refused');
  }, { delayMs: () => 1 });
  assert.equal(await r.done, true);
  assert.deepEqual(tries, [0, 1, 2]);
});

test('keepTrying stops on a failure it must give up on, and on cancel', async () => {
  let n = 0;
  const wrongPassword = keepTrying(async () => {
    n += 1;
    throw Object.assign(new Error('wrong password'), { code: 'unauthorized' });
  }, { delayMs: () => 1, giveUp: (e) => e.code === 'unauthorized' });
  assert.equal(await wrongPassword.done, false);
  assert.equal(n, 1);
  let calls = 0;
  const cancelled = keepTrying(async () => {
    calls += 1;
  }, { delayMs: () => 50 });
  cancelled.cancel();
  assert.equal(await cancelled.done, false);
  await new Promise((r) => setTimeout(r, 80));
  assert.equal(calls, 0);
});

test('numbers show the decimals asked, without a negative zero', () => {
  assert.equal(fixed(-0.008274955, 3), '-0.008');
  assert.equal(fixed(-0.0001, 3), '0.000');
  assert.equal(fixed(null, 3), '—');
  assert.equal(fixed(Number.NaN, 3), '—');
  assert.equal(readable(-0.008274955, 4), '-0.008275');
  assert.equal(readable(123456.789, 4), '123457');
  assert.equal(readable(3e-7, 3), '3.00e-7');
});

test('tick labels share the decimals their step needs', () => {
  assert.equal(decimalsForStep(0.25), 2);
  assert.equal(decimalsForStep(5), 0);
  assert.equal(decimalsForStep(2e-4), 4);
  assert.deepEqual(tickLabels([-0.01, -0.005, 0, 0.005, 0.01]), ['-0.010', '-0.005', '0.000', '0.005', '0.010']);
  assert.deepEqual(tickLabels([40, 40.5, 41]), ['40.0', '40.5', '41.0']);
  const tiny = tickLabels([-2e-7, 0, 2e-7, 4e-7]);
  assert.deepEqual(tiny, ['-2e-7', '0', '2e-7', '4e-7']);
  for (const labels of [tickLabels([0.1, 0.2, 0.3]), tickLabels([1e6, 2e6])]) {
    assert.equal(new Set(labels).size, labels.length); // distinct ticks never read the same
  }
});

test('right ascension and declination read as sexagesimal', () => {
  assert.equal(hms(279.2347), '18:36:56.33'); // Vega, 279.2347° = 18.615647 h
  assert.equal(dms(38.78369), '+38:47:01.3');
  assert.equal(dms(-0.5), '-00:30:00.0');
  assert.equal(hms(359.99999999), '00:00:00.00');
});

test('csv export has a header with units and every sample in full precision', () => {
  const t = Float64Array.from([0, 0.001, 0.002]);
  const csv = toCsv([
    { name: 't', unit: 's', values: t },
    { name: 'axis.az.error', unit: 'rad', values: Float64Array.from([1.5e-9, Number.NaN, -0.1 + 0.2]) },
    { name: 'a,"b"', unit: '', values: [null, 2, 3] },
  ]);
  const lines = csv.trimEnd().split('\n');
  assert.equal(lines[0], 't [s],axis.az.error [rad],"a,""b"""');
  assert.deepEqual(lines.slice(1), ['0,1.5e-9,', '0.001,,2', '0.002,0.1,3'.replace('0.1', String(-0.1 + 0.2))]);
  assert.equal(Number(lines[3].split(',')[1]), -0.1 + 0.2); // reads back the same double
});

test('nice ticks give at least the asked count at a round step, inside the range', () => {
  for (const [min, max] of [[0, 1], [-0.0083, 0.0079], [76.784, 76.786], [1e-9, 3e-9], [-5, 1e5], [41.2024, 41.2025]]) {
    const ticks = niceTicks(min, max, 4);
    assert.ok(ticks.length >= 4, `${min}..${max}: ${ticks}`);
    assert.ok(ticks.every((v) => v >= min - 1e-12 * Math.abs(min) && v <= max + 1e-12 * Math.abs(max)), `${ticks}`);
    const step = ticks[1] - ticks[0];
    const mantissa = Number((step / 10 ** Math.floor(Math.log10(step))).toPrecision(6));
    assert.ok([1, 2, 2.5, 5].includes(mantissa), `step ${step}`);
    assert.equal(new Set(tickLabels(ticks)).size, ticks.length, `labels of ${ticks}: ${tickLabels(ticks)}`);
  }
  assert.deepEqual(niceTicks(0, 1, 4), [0, 0.25, 0.5, 0.75, 1]);
  assert.deepEqual(niceTicks(3, 3), [3]);
});

test('table values show the digits their type carries, on one line', () => {
  assert.equal(formatValue(-0.008274955123456, 'f32'), '-0.008274955');
  assert.equal(formatValue(-0.008274955123456, 'f64'), '-0.008274955123');
  assert.equal(formatValue(29.75, 'f64'), '29.75');
  assert.equal(formatValue(1.5e-7, 'f64'), '1.5e-7');
  assert.equal(formatValue(-0, 'f64'), '0');
  assert.equal(formatValue(12, 'i32'), '12');
  assert.equal(formatValue(null), '—');
});
