// A trajectory given as one formula of time per axis, sampled into time-tagged points and
// fed through the endpoint's trajectory functions (found by name in LIST; the user may
// change every name).
//
// Units: a push argument named `*_rad` takes radians, but users think in degrees: its
// formula is in degrees and converted. `p0` in a formula is the axis's position when the
// run starts (read from a signal, converted from rad to degrees when its unit is rad).
import { parseSignature } from './astcom/index.js';
import { NdArray } from './astcom/codec.js';
import { compileExpression } from './expressions.js';

export const DEG = Math.PI / 180;

/** Return default function names {push, init, start, reset, free} from LIST entries. */
export function defaultTrajectoryFunctions(functionEntries) {
  const names = functionEntries.map((e) => e.name);
  const push = functionEntries.find((e) => /(^|\.)push$/.test(e.name) && /^\([^:]+:i64\[\]/.test(e.type))?.name || '';
  const prefix = push.includes('.') ? push.slice(0, push.lastIndexOf('.') + 1) : '';
  const pick = (word) => (names.includes(prefix + word) ? prefix + word : '');
  return { push, init: pick('init'), start: pick('start'), reset: pick('reset'), free: pick('free') };
}

/**
 * Return the axes of a push function: every array argument after the time argument, with a
 * default start-position signal `<group>.<axis>.position` when such a signal exists.
 */
export function trajectoryAxes(pushEntry, signalEntries) {
  const sig = parseSignature(pushEntry.type);
  if (!sig.args.length || sig.args[0].type.scalar !== 'i64' || sig.args[0].type.kind !== 'array') {
    throw new Error(`${pushEntry.name}${pushEntry.type}: its first argument must be the time tags (i64[])`);
  }
  const signals = signalEntries.map((e) => e.name);
  return sig.args.slice(1).map((a) => {
    const axis = a.name.split('_')[0];
    const p0Signal = signals.find((n) => n.endsWith(`.${axis}.position`)) || '';
    return { arg: a.name, degrees: /_rad($|_)/.test(a.name), p0Signal, isRate: /_rate/.test(a.name) };
  });
}

/** Return the ramp's weight at x = t / ramp: 0 → 1 with zero slope and curvature at both ends. */
export function rampWeight(x) {
  if (x <= 0) return 0;
  if (x >= 1) return 1;
  return x * x * x * (10 + x * (6 * x - 15)); // 6x⁵ − 15x⁴ + 10x³
}

/**
 * Blend sampled positions `raw` (at i·stepS) into a trajectory that leaves `start` and arrives
 * at the last value at rest: over the first `rampS` seconds from `start` to the formula, over
 * the last `rampS` from the formula to its final value. Velocity and acceleration are zero
 * at both ends, so the mount sees no step (a formula like sin(t) starts at full speed).
 */
export function rampPositions(raw, stepS, rampS, start = raw[0]) {
  const n = raw.length;
  const totalS = (n - 1) * stepS;
  const end = raw[n - 1];
  return raw.map((v, i) => {
    const t = i * stepS;
    const inRamp = start + rampWeight(t / rampS) * (v - start);
    return end + rampWeight((totalS - t) / rampS) * (inRamp - end);
  });
}

/**
 * Sample the formulas at t = 0, step, 2·step, … ≤ duration (seconds from the first point).
 * axes: [{arg, expr, degrees, p0, start?, isRate?}] (p0 and start in the formula's units).
 * rampS > 0 starts and ends every position argument with a ramp (rampPositions) from
 * `start` (default: the formula at t = 0); rate arguments are left as written.
 * Returns {tUs: BigInt64Array, values: [Float64Array] (wire units), formula: [Float64Array]
 * (formula units, ramps included), n}. Throws with the axis name on a bad formula.
 */
export function sampleTrajectory(axes, { durationS, stepS, t0Us, rampS = 0 }) {
  if (!(durationS > 0)) throw new Error(`duration must be > 0 s, got ${durationS}`);
  if (!(stepS > 0)) throw new Error(`sample step must be > 0 s, got ${stepS}`);
  if (!(rampS >= 0)) throw new Error(`ramp must be >= 0 s, got ${rampS}`);
  if (2 * rampS > durationS + 1e-9) {
    throw new Error(`duration ${durationS} s is shorter than its two ramps (start and end, ${rampS} s each)`);
  }
  const n = Math.floor(durationS / stepS + 1e-9) + 1;
  const tUs = new BigInt64Array(n);
  for (let i = 0; i < n; i++) tUs[i] = BigInt(t0Us + Math.round(i * stepS * 1e6));
  const values = axes.map((ax) => {
    let expr;
    try {
      expr = compileExpression(ax.expr, [], { t: 0, p0: 0 });
    } catch (err) {
      throw new Error(`formula of ${ax.arg}: ${err.message}`);
    }
    let raw = new Float64Array(n);
    for (let i = 0; i < n; i++) {
      const v = expr.evaluateWith({ t: i * stepS, p0: ax.p0 });
      if (!Number.isFinite(v)) throw new Error(`formula of ${ax.arg} is not finite at t = ${i * stepS} s`);
      raw[i] = v;
    }
    if (rampS > 0 && !ax.isRate) raw = rampPositions(raw, stepS, rampS, ax.start ?? raw[0]);
    return raw;
  });
  const scaled = values.map((raw, j) => (axes[j].degrees ? raw.map((v) => v * DEG) : raw));
  return { tUs, values: scaled, formula: values, n };
}

/**
 * Push sampled points through `fns` ({init, push, start, free}) with `invoke(name, args)`,
 * never more than the buffer has room for, starting the trajectory after the first push.
 * `progress(pushed, total)` is called after every push; `cancelled()` stops feeding.
 */
export async function feedTrajectory(points, fns, invoke, { progress = () => {}, cancelled = () => false, chunk = 1000 } = {}) {
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
  if (fns.init) await invoke(fns.init, []);
  let offset = 0;
  let accepted = 0;
  let started = false;
  while (offset < points.n && !cancelled()) {
    const room = fns.free ? Number(await invoke(fns.free, [])) : chunk;
    const take = Math.min(room, chunk, points.n - offset);
    if (take <= 0) {
      await sleep(100);
      continue;
    }
    const args = [new NdArray('i64', [take], points.tUs.slice(offset, offset + take)),
      ...points.values.map((v) => v.slice(offset, offset + take))];
    accepted += Number(await invoke(fns.push, args));
    offset += take;
    progress(offset, points.n, accepted);
    if (!started && fns.start) {
      await invoke(fns.start, []);
      started = true;
    }
  }
  return { pushed: offset, accepted };
}
