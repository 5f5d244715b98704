// Ring buffers of streamed samples, kept outside Vue's reactivity: at 10 kHz a reactive
// array would cost more than the plot itself. One time base (seconds since the first
// sample of the stream) is shared by every series of the stream, streamed or computed.

export const MAX_WINDOW_S = 60;
export const MAX_CAPACITY = 1_200_000;

// uPlot reads null as a gap but NaN breaks its auto-range: hand it a plain array then.
function withGaps(y) {
  for (let i = 0; i < y.length; i++) {
    if (Number.isNaN(y[i])) return Array.from(y, (v) => (Number.isNaN(v) ? null : v));
  }
  return y;
}

export class SeriesStore {
  constructor() {
    this.listeners = new Set();
    this.version = 0; // +1 per change (append, reset): the plot redraws only when it moved
    this.reset([], 1000);
  }

  /** Call `fn` after each change of the samples (append, reset); return the unsubscribe. */
  subscribe(fn) {
    this.listeners.add(fn);
    return () => this.listeners.delete(fn);
  }

  changed() {
    this.version++;
    for (const fn of this.listeners) fn();
  }

  /** Start over for a stream of `names` at `rateHz`. */
  reset(names, rateHz) {
    this.capacity = Math.max(1024, Math.min(MAX_CAPACITY, Math.ceil(rateHz * MAX_WINDOW_S)));
    this.t = new Float64Array(this.capacity);
    this.series = new Map();
    for (const name of names) this.series.set(name, new Float64Array(this.capacity));
    this.head = 0; // index of the next write
    this.count = 0;
    this.t0Us = null;
    this.lastTUs = null;
    this.changed();
  }

  /** Add (or replace) a computed series; it fills from the next packet on. */
  ensure(name) {
    if (!this.series.has(name)) this.series.set(name, new Float64Array(this.capacity).fill(Number.NaN));
    return this.series.get(name);
  }

  drop(name) {
    this.series.delete(name);
  }

  names() {
    return [...this.series.keys()];
  }

  /** Append one packet: `tUs` (n), `columns` {name: Float64Array(n)}. */
  append(tUs, columns) {
    const n = tUs.length;
    if (this.t0Us === null) this.t0Us = tUs[0];
    const cap = this.capacity;
    for (let i = 0; i < n; i++) {
      const k = (this.head + i) % cap;
      this.t[k] = (tUs[i] - this.t0Us) * 1e-6;
    }
    for (const [name, values] of Object.entries(columns)) {
      const ring = this.series.get(name);
      if (!ring) continue;
      for (let i = 0; i < n; i++) ring[(this.head + i) % cap] = values[i];
    }
    this.head = (this.head + n) % cap;
    this.count = Math.min(cap, this.count + n);
    this.lastTUs = tUs[n - 1];
    this.changed();
  }

  /** Return the ring index range [start, end) (end may exceed capacity) of the last `windowS`. */
  windowRange(windowS, endS = null) {
    if (this.count === 0) return [0, 0];
    const cap = this.capacity;
    const last = (this.head - 1 + cap) % cap;
    const tEnd = endS ?? this.t[last];
    // binary search over the logical order for the first sample at or after tEnd - windowS
    const first = (this.head - this.count + cap) % cap;
    let lo = 0;
    let hi = this.count;
    const tStart = tEnd - windowS;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (this.t[(first + mid) % cap] < tStart) lo = mid + 1;
      else hi = mid;
    }
    return [first + lo, first + this.count];
  }

  /**
   * Return uPlot data [x, ...series] for the last `windowS`, decimated to about `buckets`
   * min/max pairs so drawing costs the same at 10 Hz and at 10 kHz.
   */
  plotData(names, windowS, buckets) {
    const [start, end] = this.windowRange(windowS);
    const n = end - start;
    const cap = this.capacity;
    const rings = names.map((nm) => this.series.get(nm) || null);
    if (n <= 2 * buckets) {
      const x = new Float64Array(n);
      const ys = rings.map(() => new Float64Array(n));
      for (let i = 0; i < n; i++) {
        const k = (start + i) % cap;
        x[i] = this.t[k];
        rings.forEach((r, s) => {
          ys[s][i] = r ? r[k] : Number.NaN;
        });
      }
      return [x, ...ys.map(withGaps)];
    }
    const per = n / buckets;
    const x = new Float64Array(2 * buckets);
    const ys = rings.map(() => new Float64Array(2 * buckets));
    for (let b = 0; b < buckets; b++) {
      const i0 = start + Math.floor(b * per);
      const i1 = start + Math.floor((b + 1) * per);
      x[2 * b] = this.t[i0 % cap];
      x[2 * b + 1] = this.t[((i0 + i1) >> 1) % cap];
      rings.forEach((r, s) => {
        let lo = Infinity;
        let hi = -Infinity;
        if (r) {
          for (let i = i0; i < i1; i++) {
            const v = r[i % cap];
            if (v < lo) lo = v;
            if (v > hi) hi = v;
          }
        }
        ys[s][2 * b] = lo === Infinity ? Number.NaN : lo;
        ys[s][2 * b + 1] = hi === -Infinity ? Number.NaN : hi;
      });
    }
    return [x, ...ys.map(withGaps)];
  }

  /**
   * Return every sample (not decimated) with fromS <= t <= toS: {tUs, t, columns} in time
   * order, `tUs` the mount time in µs, `t` seconds since the stream's first sample.
   */
  rows(names, fromS, toS) {
    const cap = this.capacity;
    const first = (this.head - this.count + cap) % cap;
    const keep = [];
    for (let i = 0; i < this.count; i++) {
      const k = (first + i) % cap;
      if (this.t[k] >= fromS && this.t[k] <= toS) keep.push(k);
    }
    const t = Float64Array.from(keep, (k) => this.t[k]);
    const tUs = Float64Array.from(t, (v) => this.t0Us + Math.round(v * 1e6));
    const columns = names.map((nm) => {
      const r = this.series.get(nm);
      return Float64Array.from(keep, (k) => (r ? r[k] : Number.NaN));
    });
    return { tUs, t, columns };
  }

  /** Return the newest value of a series (NaN when empty). */
  latest(name) {
    const r = this.series.get(name);
    if (!r || this.count === 0) return Number.NaN;
    return r[(this.head - 1 + this.capacity) % this.capacity];
  }
}
