// Group LIST entries by their dotted-name prefix (`axis.az.kp` -> `axis.az`), so any
// device's names lay out by module without the panel knowing the device.

/** Return [{group, entries}] sorted by group, entries in LIST order; '' for names without a dot. */
export function groupByPrefix(entries) {
  const groups = new Map();
  for (const e of entries) {
    const dot = e.name.lastIndexOf('.');
    const group = dot < 0 ? '' : e.name.slice(0, dot);
    if (!groups.has(group)) groups.set(group, []);
    groups.get(group).push(e);
  }
  return [...groups.entries()]
    .sort(([a], [b]) => a.localeCompare(b))
    .map(([group, list]) => ({ group, entries: list }));
}

/** Return the entries whose name, unit or doc contains every word of `filter`. */
export function filterEntries(entries, filter) {
  const words = filter.toLowerCase().split(/\s+/).filter(Boolean);
  if (!words.length) return entries;
  return entries.filter((e) => {
    const text = `${e.name} ${e.unit} ${e.doc}`.toLowerCase();
    return words.every((w) => text.includes(w));
  });
}

/** Return the part of a name after its group, for compact tables. */
export function shortName(name) {
  const dot = name.lastIndexOf('.');
  return dot < 0 ? name : name.slice(dot + 1);
}

// Significant digits a float type carries: an f32 holds about 7, an f64 about 16 — shown to
// 10, finer than any angle, rate or time the mount measures (1e-10 rad = 0.00002″).
const SIGNIFICANT = { f32: 7, f64: 10 };

/** Return whether formatValue gives a number (one line) rather than text that may wrap. */
export const isScalarNumber = (v) => typeof v === 'number' || typeof v === 'bigint' || typeof v === 'boolean';

/** Format a value read from the endpoint for a table cell, to the precision of its `type`. */
export function formatValue(v, type = 'f64') {
  if (v === null || v === undefined) return '—';
  if (typeof v === 'number') {
    if (Number.isInteger(v)) return String(v);
    const digits = SIGNIFICANT[type] ?? SIGNIFICANT.f64;
    const a = Math.abs(v);
    if (a < 1e-4 || a >= 1e9) return v.toExponential(digits - 1).replace(/\.?0+e/, 'e');
    return String(Number(v.toPrecision(digits)));
  }
  if (typeof v === 'boolean' || typeof v === 'string' || typeof v === 'bigint') return String(v);
  if (v instanceof Uint8Array) return `bytes(${v.length})`;
  if (typeof v.toNested === 'function') return jsonText(v.toNested());
  return jsonText(v);
}

/** JSON text of a value whose integers may be BigInt (written as exact digits). */
export function jsonText(v) {
  return JSON.stringify(v, (_, x) => (typeof x === 'bigint' ? `\u0000${x}\u0000` : x))
    .replace(/"\\u0000(-?\d+)\\u0000"/g, '$1');
}

/** Return the JSON-able form of a value (NdArray -> nested array). */
export function plainValue(v) {
  if (v && typeof v.toNested === 'function') return v.toNested();
  if (v instanceof Uint8Array) return Array.from(v);
  return v;
}
