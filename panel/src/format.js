// Numbers an engineer can read: as many decimals as the value's precision carries, never
// a float's full 17 digits, and the same decimals on every tick of an axis.

/** Return `v` with `decimals` digits after the point ('—' for null/NaN, no "-0.000"). */
export function fixed(v, decimals) {
  if (v === null || v === undefined || !Number.isFinite(Number(v))) return '—';
  const text = Number(v).toFixed(decimals);
  return /^-0\.?0*$/.test(text) ? text.slice(1) : text;
}

/** Return the decimals that show steps of `step` (0.25 -> 2, 5 -> 0, 2e-4 -> 4). */
export function decimalsForStep(step) {
  const s = Math.abs(Number(step));
  if (!Number.isFinite(s) || s === 0) return 0;
  for (let d = 0; d <= 15; d++) {
    if (Math.abs(Math.round(s * 10 ** d) - s * 10 ** d) < 1e-6 * s * 10 ** d) return d;
  }
  return 15;
}

/**
 * Return tick labels for the values of one axis: one format for all (fixed decimals read off
 * the tick step, or exponents with the same mantissa digits when the ticks are tiny or huge).
 */
export function tickLabels(ticks) {
  const finite = ticks.filter((v) => Number.isFinite(v));
  if (!finite.length) return ticks.map(() => '');
  const step = finite.length > 1 ? Math.min(...finite.slice(1).map((v, i) => Math.abs(v - finite[i])).filter((d) => d > 0)) : Math.abs(finite[0]);
  const big = Math.max(...finite.map(Math.abs));
  if (big >= 1e6 || (big > 0 && big < 1e-4) || (step > 0 && step < 1e-6)) {
    const digits = Math.min(6, Math.max(1, Math.floor(Math.log10(big)) - Math.floor(Math.log10(step || big)) + 1));
    return ticks.map((v) => (!Number.isFinite(v) ? '' : v === 0 ? '0' : v.toExponential(digits - 1)));
  }
  const d = decimalsForStep(step || big);
  return ticks.map((v) => (Number.isFinite(v) ? fixed(v, d) : ''));
}

/** Return a value with `significant` digits in plain notation when it reads well (legends). */
export function readable(v, significant = 6) {
  if (v === null || v === undefined || !Number.isFinite(Number(v))) return '—';
  const x = Number(v);
  if (x === 0) return '0';
  const a = Math.abs(x);
  if (a < 1e-4 || a >= 1e9) return x.toExponential(significant - 1);
  const d = Math.max(0, significant - 1 - Math.floor(Math.log10(a)));
  return fixed(x, Math.min(d, 12));
}

/** Return degrees as sexagesimal hours "hh:mm:ss.ss" (right ascension). */
export function hms(deg) {
  if (!Number.isFinite(deg)) return '—';
  const cs = Math.round((((deg % 360) + 360) % 360) / 15 * 360_000) % (24 * 360_000); // centiseconds
  const h = Math.floor(cs / 360_000);
  const m = Math.floor((cs % 360_000) / 6000);
  const s = (cs % 6000) / 100;
  return `${String(h).padStart(2, '0')}:${String(m).padStart(2, '0')}:${s.toFixed(2).padStart(5, '0')}`;
}

/** Return degrees as signed sexagesimal "+dd:mm:ss.s" (declination). */
export function dms(deg) {
  if (!Number.isFinite(deg)) return '—';
  const ds = Math.round(Math.abs(deg) * 36_000); // tenths of an arcsecond
  const d = Math.floor(ds / 36_000);
  const m = Math.floor((ds % 36_000) / 600);
  const s = (ds % 600) / 10;
  return `${deg < 0 ? '-' : '+'}${String(d).padStart(2, '0')}:${String(m).padStart(2, '0')}:${s.toFixed(1).padStart(4, '0')}`;
}

function csvField(text) {
  return /[",\n\r]/.test(text) ? `"${text.replace(/"/g, '""')}"` : text;
}

/**
 * Return CSV text of plot columns: a header `name [unit]` per column, then one row per
 * sample, numbers in full precision (shortest text that reads back the same double),
 * empty cells for missing values. columns: [{name, unit, values}] of equal length.
 */
export function toCsv(columns) {
  const header = columns.map((c) => csvField(c.unit ? `${c.name} [${c.unit}]` : c.name)).join(',');
  const n = columns.length ? columns[0].values.length : 0;
  const rows = [header];
  for (let i = 0; i < n; i++) {
    rows.push(columns.map((c) => {
      const v = c.values[i];
      return v === null || v === undefined || Number.isNaN(v) ? '' : String(v);
    }).join(','));
  }
  return `${rows.join('\n')}\n`;
}

const NICE = [1, 2, 2.5, 5];

/**
 * Return tick values between `min` and `max` at a round step (1, 2, 2.5 or 5 × 10^k), the
 * largest step that still gives at least `minTicks` ticks, so that a short plot of a nearly
 * flat signal still reads off several values.
 */
export function niceTicks(min, max, minTicks = 4) {
  if (!Number.isFinite(min) || !Number.isFinite(max)) return [];
  if (!(max > min)) return [min];
  const span = max - min;
  let k = Math.floor(Math.log10(span));
  for (let guard = 0; guard < 40; guard++, k--) {
    for (let j = NICE.length - 1; j >= 0; j--) {
      const step = NICE[j] * 10 ** k;
      const first = Math.ceil(min / step - 1e-9);
      const last = Math.floor(max / step + 1e-9);
      if (last - first + 1 >= minTicks) {
        const ticks = [];
        for (let i = first; i <= last; i++) ticks.push(Number((i * step).toPrecision(15)));
        return ticks;
      }
    }
  }
  return [min, max];
}

/**
 * Return a time cell: UTC as `YYYY-MM-DD HH:MM:SS.sss` from µs since 1970 (mount time or a
 * clock), '—' when unknown. Every clock value on the Board and Telescope tabs uses it: one
 * format, millisecond precision (the label says UTC and which clock).
 */
export function utcCell(tUs) {
  if (tUs === null || tUs === undefined || !Number.isFinite(Number(tUs))) return '—';
  return new Date(Math.floor(Number(tUs) / 1000)).toISOString().replace('T', ' ').slice(0, 23);
}

/** Return `HH:MM:SS` (UTC) of a wall time in ms, for "last update" notes; '—' when unknown. */
export function utcClock(ms) {
  return ms ? new Date(ms).toISOString().slice(11, 19) : '—';
}

/** Return how long ago `thenMs` was at `nowMs`: "4 s ago", "2 min 5 s ago", "3 h 10 min ago". */
export function ageText(thenMs, nowMs) {
  if (!thenMs) return '';
  const s = Math.max(0, Math.floor((nowMs - thenMs) / 1000));
  if (s < 60) return `${s} s ago`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${s % 60} s ago`;
  return `${Math.floor(s / 3600)} h ${Math.floor((s % 3600) / 60)} min ago`;
}
