// The JS client against a live Python endpoint: astcom_client's example device, started by
// tests/panel/test_js_client.py, which passes ASTCOM_URL, ASTCOM_PASSWORD and ASTCOM_RATE_HZ.
import assert from 'node:assert/strict';
import { after, before, test } from 'node:test';
import WebSocket from 'ws';
import { Client } from '../../src/astcom/client.js';
import { NdArray } from '../../src/astcom/codec.js';
import { AuthenticationFailed, RemoteError } from '../../src/astcom/errors.js';
import { TcpSocket } from '../../src/astcom/tcp-node.js';

const URL = process.env.ASTCOM_URL;
const PASSWORD = process.env.ASTCOM_PASSWORD;
const RATE_HZ = Number(process.env.ASTCOM_RATE_HZ || 1000);
if (!URL) throw new Error('set ASTCOM_URL (tests/panel/test_js_client.py starts the endpoint)');

const connect = (options = {}) => Client.connect(URL, { password: PASSWORD, WebSocket, clientName: 'js-unit', ...options });
let c;

before(async () => {
  c = await connect();
});

after(async () => {
  await c.close();
});

test('hmac authentication grants operator and checks the endpoint proof', () => {
  assert.equal(c.role, 'operator');
  assert.equal(c.hello.version, '1.0');
  assert.equal(c.loopRateHz, RATE_HZ);
});

test('asking for observer gets observer, which may read but not write', async () => {
  const obs = await connect({ role: 'observer' });
  try {
    assert.equal(obs.role, 'observer');
    await obs.read(['wave.amplitude']);
    await assert.rejects(obs.write({ 'wave.amplitude': 1 }), (err) => err.code === 403);
  } finally {
    await obs.close();
  }
});

test('a wrong password is refused with 401', async () => {
  await assert.rejects(connect({ password: 'not-the-password' }),
    (err) => err instanceof AuthenticationFailed && err.code === 401);
});

test('list names every variable with kind, access and type', async () => {
  const entries = await c.list();
  const byName = Object.fromEntries(entries.map((e) => [e.name, e]));
  assert.equal(byName['wave.sine'].kind, 'signal');
  assert.equal(byName['wave.amplitude'].access, 'rw');
  assert.equal(byName['math.add'].type, '(a:f64,b:f64)->f64');
  const waves = await c.list('wave.');
  assert.ok(waves.length >= 3 && waves.every((e) => e.name.startsWith('wave.')));
});

test('written scalars, arrays and structs read back equal', async () => {
  await c.write({ 'wave.offset': 0.25, 'pair.a': 3, 'pair.b': 3 });
  await c.write({ gains: [2, 0.5, 0.125] });
  await c.write({ site: { lat_deg: -30.25, lon_deg: -70.75 } });
  await c.write({ label: 'from-js' });
  const { values, tick } = await c.read(['wave.offset', 'pair.a', 'gains', 'site', 'label']);
  assert.equal(values['wave.offset'], 0.25);
  assert.equal(values['pair.a'], 3);
  assert.ok(values.gains instanceof NdArray);
  assert.deepEqual(values.gains.toNested(), [2, 0.5, 0.125]);
  assert.deepEqual(values.site, { lat_deg: -30.25, lon_deg: -70.75 });
  assert.equal(values.label, 'from-js');
  assert.ok(tick >= 0);
  await c.write({ 'wave.offset': 0 });
});

test('writing a signal is refused with 405 and a bad value with 422', async () => {
  await assert.rejects(c.write({ 'wave.sine': 1 }), (err) => err instanceof RemoteError && err.code === 405);
  await assert.rejects(c.write({ gains: [1, 2] }), (err) => err.code === 422);
  await assert.rejects(c.read(['no.such.name']), (err) => err.code === 404);
});

test('invoke returns values, takes typed arrays, reports device errors as 500', async () => {
  assert.equal(await c.invoke('math.add', [1.5, 2]), 3.5);
  assert.equal(await c.invoke('math.sum', [Float64Array.from([1, 2, 3.5])]), 6.5);
  assert.equal(await c.invoke('math.sum', [[1, 2, 3]]), 6);
  await assert.rejects(c.invoke('device.fail'), (err) => err.code === 500 && /always fails/.test(err.message));
  await assert.rejects(c.invoke('math.add', [1]), (err) => err.code === 422);
});

test('a stream on a second connection carries every tick of the counter without loss', async () => {
  const data = await connect({ role: 'observer', clientName: 'js-stream' });
  try {
    const got = { ticks: [], counter: [], sine: [], tUs: [], lost: 0 };
    const stream = await data.stream(['counter', 'wave.sine'], RATE_HZ);
    assert.equal(stream.info.period_ticks, 1);
    assert.deepEqual(stream.columns, ['counter', 'wave.sine']);
    assert.deepEqual(stream.info.dtypes, ['i64', 'f64']);
    stream.onPacket((p) => {
      for (let i = 0; i < p.n; i++) {
        got.ticks.push(p.firstTick + i * p.periodTicks);
        got.counter.push(p.columns[0][i]);
        got.sine.push(p.columns[1][i]);
        got.tUs.push(p.tUs[i]);
      }
      got.lost += p.lost;
    });
    const { values } = await c.read(['wave.amplitude', 'wave.frequency_hz', 'wave.offset']);
    while (got.ticks.length < RATE_HZ / 2) await new Promise((r) => setTimeout(r, 20));
    await stream.stop();
    assert.equal(got.lost, 0);
    assert.equal(stream.lost, 0);
    for (let i = 1; i < got.ticks.length; i++) {
      assert.equal(got.ticks[i], got.ticks[i - 1] + 1);
      assert.equal(got.tUs[i] - got.tUs[i - 1], Math.round(1e6 / RATE_HZ));
    }
    // The counter restarts at counter.reset only; no test resets it, so counter == tick.
    got.counter.forEach((v, i) => assert.equal(v, got.ticks[i]));
    const w = 2 * Math.PI * values['wave.frequency_hz'] / RATE_HZ;
    got.sine.forEach((v, i) => {
      const expected = values['wave.amplitude'] * Math.sin(w * got.ticks[i]) + values['wave.offset'];
      assert.ok(Math.abs(v - expected) < 1e-9, `sample at tick ${got.ticks[i]}: ${v} != ${expected}`);
    });
  } finally {
    await data.close();
  }
});

test('stats counts this client by the name it gave in hello', async () => {
  const stats = await c.stats();
  assert.ok(stats.per_client.some((p) => p.name === 'js-unit' && p.role === 'operator'));
  const ping = await c.ping();
  assert.ok(ping.t_us > 1.7e15 && ping.tick >= -1);
});

test('a closed client rejects requests with ConnectionClosed', async () => {
  const other = await connect();
  await other.close();
  await assert.rejects(other.list(), (err) => err.name === 'ConnectionClosed');
});

test('the same client speaks tcp:// with length-prefixed frames (Node only)', async () => {
  const tcpUrl = process.env.ASTCOM_TCP_URL;
  assert.ok(tcpUrl, 'set ASTCOM_TCP_URL');
  const t = await Client.connect(tcpUrl, { password: PASSWORD, WebSocket: TcpSocket, clientName: 'js-tcp' });
  try {
    assert.equal(t.role, 'operator');
    assert.equal(await t.invoke('math.add', [2, 0.5]), 2.5);
    await t.write({ 'pair.a': 7, 'pair.b': 7 });
    assert.deepEqual((await t.read(['pair.a', 'pair.b'])).values, { 'pair.a': 7, 'pair.b': 7 });
    const stream = await t.stream(['counter'], RATE_HZ / 10);
    const ticks = [];
    stream.onPacket((p) => {
      for (let i = 0; i < p.n; i++) ticks.push([p.firstTick + i * p.periodTicks, p.columns[0][i]]);
    });
    while (ticks.length < 200) await new Promise((r) => setTimeout(r, 20));
    await stream.stop();
    assert.equal(stream.lost, 0);
    ticks.forEach(([tick, counter]) => assert.equal(counter, tick));
    assert.ok(ticks.every(([tick]) => tick % 10 === 0), 'samples are phase-aligned on multiples of k');
  } finally {
    await t.close();
  }
});
