// The panel's own pure modules: ring buffers and decimation, expressions, trajectory sampling
// and feeding, grouping by prefix. No endpoint needed.
import assert from 'node:assert/strict';
import { test } from 'node:test';
import { compileExpression } from '../../src/expressions.js';
import { groupByPrefix } from '../../src/grouping.js';
import { SeriesStore } from '../../src/series.js';
import { DEG, defaultTrajectoryFunctions, feedTrajectory, rampWeight, sampleTrajectory, trajectoryAxes } from '../../src/trajectory.js';

function fill(store, n, rateHz, f, start = 0) {
  const tUs = Float64Array.from({ length: n }, (_, i) => 1e15 + (start + i) * 1e6 / rateHz);
  store.append(tUs, { a: Float64Array.from({ length: n }, (_, i) => f(start + i)) });
}

test('ring buffer keeps the newest samples in order after wrapping', () => {
  const s = new SeriesStore();
  s.reset(['a'], 20); // capacity 1024 (the minimum)
  for (let k = 0; k < 5; k++) fill(s, 300, 20, (i) => i, k * 300);
  assert.equal(s.count, s.capacity);
  const [x, y] = s.plotData(['a'], 1e9, 10_000); // no decimation: every sample
  assert.equal(y.length, s.capacity);
  assert.equal(y[0], 1500 - s.capacity);
  assert.equal(y[y.length - 1], 1499);
  for (let i = 1; i < x.length; i++) assert.ok(x[i] > x[i - 1]);
  assert.equal(s.latest('a'), 1499);
});

test('the store tells its subscribers of each change, and only while subscribed', () => {
  const s = new SeriesStore();
  let calls = 0;
  const unsubscribe = s.subscribe(() => { calls += 1; });
  const v0 = s.version;
  s.reset(['a'], 100);
  fill(s, 10, 100, (i) => i);
  fill(s, 10, 100, (i) => i, 10);
  assert.equal(calls, 3);
  assert.equal(s.version, v0 + 3); // a reset moves the version on too (never back to 0)
  unsubscribe();
  fill(s, 10, 100, (i) => i, 20);
  assert.equal(calls, 3);
});

test('decimated plot data keeps every bucket minimum and maximum of the window', () => {
  const s = new SeriesStore();
  s.reset(['a'], 10_000);
  const f = (i) => Math.sin(i / 50) + (i % 997 === 0 ? 5 : 0); // spikes must survive
  fill(s, 40_000, 10_000, f);
  const [x, y] = s.plotData(['a'], 2.0, 200); // the window [t_last - 2 s, t_last]: 20 001 samples
  assert.equal(x.length, 400);
  const raw = Array.from({ length: 20_001 }, (_, i) => f(19_999 + i));
  assert.equal(Math.max(...y), Math.max(...raw));
  assert.equal(Math.min(...y), Math.min(...raw));
  const per = raw.length / 200;
  for (let b = 0; b < 200; b++) {
    const chunk = raw.slice(Math.floor(b * per), Math.floor((b + 1) * per));
    assert.equal(y[2 * b], Math.min(...chunk));
    assert.equal(y[2 * b + 1], Math.max(...chunk));
  }
});

test('a computed series not yet filled plots as gaps (null), not NaN', () => {
  const s = new SeriesStore();
  s.reset(['a'], 100);
  fill(s, 10, 100, (i) => i);
  s.ensure('c');
  const [, , c] = s.plotData(['a', 'c'], 10, 100);
  assert.ok(Array.isArray(c) && c.every((v) => v === null));
});

test('expressions name streamed signals and refuse unknown names and assignments', () => {
  const e = compileExpression('sqrt(axis.az.e^2 + axis.el.e^2) * 3600', ['axis.az.e', 'axis.el.e']);
  assert.deepEqual(e.uses, ['axis.az.e', 'axis.el.e']);
  assert.equal(e.evaluate({ 'axis.az.e': 3, 'axis.el.e': 4 }), 18000);
  assert.throws(() => compileExpression('axis.az.x * 2', ['axis.az.e']), /unknown name axis/);
  assert.throws(() => compileExpression('a = 2', ['b']), /assignments are not allowed/);
  assert.throws(() => compileExpression('1 +', []), /Unexpected end/);
  assert.throws(() => compileExpression('import({x: 1}, {})', ['x']).evaluate({ x: 1 }), /disabled/);
});

const LIST = [
  { name: 'traj.init', kind: 'function', type: '()->none', doc: '' },
  { name: 'traj.start', kind: 'function', type: '()->none', doc: '' },
  { name: 'traj.free', kind: 'function', type: '()->u32', doc: '' },
  { name: 'traj.reset', kind: 'function', type: '()->none', doc: '' },
  { name: 'other.push', kind: 'function', type: '(x:f64[])->u32', doc: '' },
  { name: 'traj.push', kind: 'function', type: '(t_us:i64[],az_rad:f64[],el_rad:f64[])->u32', doc: '' },
];

test('trajectory functions and axes are found by name and signature in the list', () => {
  assert.deepEqual(defaultTrajectoryFunctions(LIST),
    { push: 'traj.push', init: 'traj.init', start: 'traj.start', reset: 'traj.reset', free: 'traj.free' });
  const axes = trajectoryAxes(LIST[5], [{ name: 'axis.az.position' }, { name: 'axis.el.position' }]);
  assert.deepEqual(axes.map((a) => [a.arg, a.degrees, a.p0Signal]),
    [['az_rad', true, 'axis.az.position'], ['el_rad', true, 'axis.el.position']]);
  assert.throws(() => trajectoryAxes(LIST[4], []), /first argument must be the time tags/);
});

test('formulas are sampled every step, in degrees converted to radians', () => {
  const p = sampleTrajectory([{ arg: 'az_rad', expr: 'p0 + 2 * sin(2 * pi * t)', degrees: true, p0: 10 }],
    { durationS: 1, stepS: 0.25, t0Us: 1_000_000 });
  assert.equal(p.n, 5);
  assert.deepEqual(Array.from(p.tUs, Number), [1_000_000, 1_250_000, 1_500_000, 1_750_000, 2_000_000]);
  [0, 0.25, 0.5, 0.75, 1].forEach((t, i) => {
    assert.ok(Math.abs(p.values[0][i] - (10 + 2 * Math.sin(2 * Math.PI * t)) * DEG) < 1e-15);
  });
  assert.throws(() => sampleTrajectory([{ arg: 'az_rad', expr: 'log(t - 1)', degrees: false, p0: 0 }],
    { durationS: 1, stepS: 0.5, t0Us: 0 }), /not finite|formula of az_rad/);
});

test('the feeder never pushes more than the buffer has room for and starts after the first push', async () => {
  // a device double: a 7-point buffer that drains 3 points per free() call
  const calls = [];
  let stored = 0;
  let drained = 0;
  const device = {
    'traj.init': () => null,
    'traj.start': () => null,
    'traj.free': () => {
      drained = Math.min(stored, drained + 3);
      return 7 - (stored - drained);
    },
    'traj.push': (args) => {
      const n = args[0].data.length;
      assert.ok(stored - drained + n <= 7, 'pushed beyond the free space');
      stored += n;
      return n;
    },
  };
  const invoke = async (name, args) => {
    calls.push(name);
    return device[name](args);
  };
  const points = sampleTrajectory([{ arg: 'az_rad', expr: 't', degrees: false, p0: 0 }],
    { durationS: 2, stepS: 0.1, t0Us: 0 });
  const fns = defaultTrajectoryFunctions(LIST);
  const r = await feedTrajectory(points, fns, invoke, { chunk: 5 });
  assert.deepEqual(r, { pushed: 21, accepted: 21 });
  assert.deepEqual(calls.slice(0, 4), ['traj.init', 'traj.free', 'traj.push', 'traj.start']);
  assert.equal(calls.filter((c) => c === 'traj.start').length, 1);
});

test('entries group by their dotted prefix', () => {
  const groups = groupByPrefix([{ name: 'b.x' }, { name: 'a.y.z' }, { name: 'top' }, { name: 'a.y.w' }]);
  assert.deepEqual(groups.map((g) => [g.group, g.entries.map((e) => e.name)]),
    [['', ['top']], ['a.y', ['a.y.z', 'a.y.w']], ['b', ['b.x']]]);
});

test('a ramped trajectory leaves its start and reaches its end at rest, and follows the formula between', () => {
  const stepS = 0.001;
  const f = (t) => 5 + 0.3 * Math.sin(2 * Math.PI * 0.5 * t); // full speed at t = 0
  const p = sampleTrajectory([{ arg: 'az', expr: 'p0 + 0.3 * sin(2 * pi * 0.5 * t)', degrees: false, p0: 5, start: 4.9 }],
    { durationS: 3, stepS, t0Us: 0, rampS: 1 });
  const v = p.values[0];
  assert.equal(v[0], 4.9); // from where the axis is, not from the formula's first value
  assert.ok(Math.abs(v[p.n - 1] - f(3)) < 1e-12);
  const speed = (i) => (v[i + 1] - v[i]) / stepS;
  // the formula alone starts at 0.94 per second; ramped, the first step moves at a millionth of that
  assert.ok(Math.abs(speed(0)) < 1e-4 && Math.abs(speed(p.n - 2)) < 1e-4, `${speed(0)} ${speed(p.n - 2)}`);
  // no sample-to-sample speed jump anywhere: the largest change of speed per step is small
  let worst = 0;
  for (let i = 1; i < p.n - 1; i++) worst = Math.max(worst, Math.abs(speed(i) - speed(i - 1)));
  assert.ok(worst < 0.01, `speed jumps by ${worst} per step`);
  for (let i = 1000; i <= 2000; i++) assert.ok(Math.abs(v[i] - f(i * stepS)) < 1e-12); // between the ramps
  assert.equal(p.formula[0][0], v[0]); // formula units: not in degrees, so the same values
  assert.deepEqual([0, 0.5, 1].map(rampWeight), [0, 0.5, 1]);
  assert.throws(() => sampleTrajectory([{ arg: 'az', expr: 't', p0: 0 }], { durationS: 1, stepS: 0.1, t0Us: 0, rampS: 0.6 }),
    /shorter than its two ramps/);
});
