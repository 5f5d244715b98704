// ASTCom type texts (§2.3) and function signatures (§4, LIST entries), and the
// conversion of what a user types into a value of that type.
import { NdArray } from './codec.js';

const SCALARS = new Set(['bool', 'i8', 'i16', 'i32', 'i64', 'u8', 'u16', 'u32', 'u64', 'f32', 'f64',
  'str', 'bytes']);
const INT_RANGE = {
  i8: [-128, 127], i16: [-32768, 32767], i32: [-(2 ** 31), 2 ** 31 - 1],
  u8: [0, 255], u16: [0, 65535], u32: [0, 2 ** 32 - 1],
};
// 64-bit bounds as BigInt: as Numbers, 2^63 - 1 and 2^63 are the same double.
const BIG_RANGE = {
  i64: [-(2n ** 63n), 2n ** 63n - 1n], u64: [0n, 2n ** 64n - 1n],
};
const TYPED = {
  i8: Int8Array, i16: Int16Array, i32: Int32Array, u16: Uint16Array, u32: Uint32Array,
  f32: Float32Array, f64: Float64Array,
};

/** Split `text` at top-level commas (outside brackets and braces). */
function splitTop(text) {
  const parts = [];
  let depth = 0;
  let start = 0;
  for (let i = 0; i < text.length; i++) {
    const c = text[i];
    if (c === '[' || c === '{' || c === '(') depth++;
    else if (c === ']' || c === '}' || c === ')') depth--;
    else if (c === ',' && depth === 0) {
      parts.push(text.slice(start, i));
      start = i + 1;
    }
  }
  if (text.slice(start).trim() !== '' || parts.length) parts.push(text.slice(start));
  return parts.map((p) => p.trim());
}

/**
 * Parse a type text into {kind: 'scalar'|'array'|'struct'|'none', scalar, shape, fields}.
 * `shape` is null for `f64[]` (any length). Throws TypeError naming the text.
 */
export function parseType(text) {
  const t = text.trim();
  if (t === 'none') return { kind: 'none', text: t };
  if (t.startsWith('{')) {
    if (!t.endsWith('}')) throw new TypeError(`type ${text}: unclosed struct`);
    const fields = splitTop(t.slice(1, -1)).map((f) => {
      const colon = f.indexOf(':');
      if (colon < 1) throw new TypeError(`type ${text}: field ${f} is not name:type`);
      return { name: f.slice(0, colon).trim(), type: parseType(f.slice(colon + 1)) };
    });
    return { kind: 'struct', fields, text: t };
  }
  const m = /^([a-z0-9]+)(?:\[([0-9,\s]*)\])?$/.exec(t);
  if (!m || !SCALARS.has(m[1])) throw new TypeError(`type ${text}: not an ASTCom type`);
  if (m[2] === undefined) return { kind: 'scalar', scalar: m[1], text: t };
  const shape = m[2].trim() === '' ? null : m[2].split(',').map((s) => Number.parseInt(s, 10));
  return { kind: 'array', scalar: m[1], shape, text: t };
}

/** Parse a function signature `(a:f64,b:i64[])->u32` into {args: [{name, type}], returns}. */
export function parseSignature(text) {
  const m = /^\((.*)\)\s*->\s*(.+)$/.exec(text.trim());
  if (!m) throw new TypeError(`signature ${text}: expected (name:type,...)->type`);
  const args = splitTop(m[1]).map((a) => {
    const colon = a.indexOf(':');
    if (colon < 1) throw new TypeError(`signature ${text}: argument ${a} is not name:type`);
    return { name: a.slice(0, colon).trim(), type: parseType(a.slice(colon + 1)) };
  });
  return { args, returns: parseType(m[2]) };
}

function scalarFrom(scalar, value, where) {
  if (scalar === 'str') return String(value);
  if (scalar === 'bool') {
    if (value === true || value === 1 || value === 'true' || value === '1') return true;
    if (value === false || value === 0 || value === 'false' || value === '0') return false;
    throw new TypeError(`${where}: expected true or false, got ${JSON.stringify(value)}`);
  }
  if (scalar === 'bytes') return new TextEncoder().encode(String(value));
  if (scalar in BIG_RANGE) return bigIntegerFrom(scalar, value, where);
  const n = typeof value === 'number' ? value : Number(String(value).trim());
  if (String(value).trim() === '' || Number.isNaN(n)) {
    throw new TypeError(`${where}: expected a number (${scalar}), got ${JSON.stringify(value)}`);
  }
  if (scalar in INT_RANGE) {
    const [lo, hi] = INT_RANGE[scalar];
    if (!Number.isInteger(n) || n < lo || n > hi) {
      throw new TypeError(`${where}: expected an integer in [${lo}, ${hi}] (${scalar}), got ${value}`);
    }
  }
  return n;
}

/** An i64/u64 from a BigInt, an exact Number or decimal text; a Number past 2^53 is refused. */
function bigIntegerFrom(scalar, value, where) {
  let b;
  if (typeof value === 'bigint') {
    b = value;
  } else if (typeof value === 'number') {
    if (!Number.isSafeInteger(value)) {
      throw new TypeError(`${where}: ${value} is not an integer a Number holds exactly (${scalar}); ` +
        'give integers beyond 2^53 as text or as a BigInt');
    }
    b = BigInt(value);
  } else {
    const text = String(value).trim();
    if (!/^[+-]?\d+$/.test(text)) {
      throw new TypeError(`${where}: expected an integer (${scalar}), got ${JSON.stringify(value)}`);
    }
    b = BigInt(text);
  }
  const [lo, hi] = BIG_RANGE[scalar];
  if (b < lo || b > hi) {
    throw new TypeError(`${where}: expected an integer in [${lo}, ${hi}] (${scalar}), got ${value}`);
  }
  const n = Number(b);
  return Number.isSafeInteger(n) ? n : b;
}

/**
 * Return the wire value of `value` (a JS value, or user text: JSON for arrays and structs)
 * for the parsed type `type`. Throws TypeError saying what was expected.
 */
export function coerce(type, value, where = 'value') {
  if (type.kind === 'scalar') {
    return scalarFrom(type.scalar, value, where);
  }
  let v = value;
  if (typeof v === 'string') {
    try {
      // JSON.parse would round integers beyond 2^53: keep every long integer literal as text
      // (bigIntegerFrom reads it exactly); a struct's fields may be 64-bit integers too
      v = JSON.parse(v.replace(/(?<![\d."])-?\d{16,}(?![\d.eE])/g, '"$&"'));
    } catch {
      const example = type.kind === 'struct' ? '{"name": 1}' : '[1, 2, 3]';
      throw new TypeError(`${where}: expected JSON such as ${example} for ${type.text}, got ${value}`);
    }
  }
  if (type.kind === 'struct') {
    if (v === null || typeof v !== 'object' || Array.isArray(v)) {
      throw new TypeError(`${where}: expected an object with fields ${type.fields.map((f) => f.name)}`);
    }
    const out = {};
    for (const f of type.fields) {
      if (!(f.name in v)) throw new TypeError(`${where}: missing field ${f.name}`);
      out[f.name] = coerce(f.type, v[f.name], `${where}.${f.name}`);
    }
    return out;
  }
  if (type.kind === 'array') {
    if (ArrayBuffer.isView(v) || v instanceof NdArray) return v;
    if (!Array.isArray(v)) throw new TypeError(`${where}: expected an array for ${type.text}`);
    const flat = v.flat(4);
    if (type.shape) {
      const n = type.shape.reduce((a, b) => a * b, 1);
      if (flat.length !== n) {
        throw new TypeError(`${where}: expected ${n} elements for ${type.text}, got ${flat.length}`);
      }
    }
    const values = flat.map((x, i) => scalarFrom(type.scalar, x, `${where}[${i}]`));
    const shape = type.shape || [values.length];
    if (type.scalar in TYPED) return new NdArray(type.scalar, shape, TYPED[type.scalar].from(values));
    if (type.scalar === 'i64') return new NdArray('i64', shape, BigInt64Array.from(values.map(BigInt)));
    if (type.scalar === 'u64') return new NdArray('u64', shape, BigUint64Array.from(values.map(BigInt)));
    return values;
  }
  throw new TypeError(`${where}: cannot send a value of type ${type.text}`);
}

/** Return true when a variable of this type can be streamed (numeric/bool scalar or fixed array). */
export function isStreamable(typeText) {
  try {
    const t = parseType(typeText);
    const numeric = t.scalar && t.scalar !== 'str' && t.scalar !== 'bytes';
    return numeric && (t.kind === 'scalar' || (t.kind === 'array' && t.shape !== null));
  } catch {
    return false;
  }
}
