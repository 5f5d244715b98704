// ASTCom frames: msgpack values with two extension types (docs/astcom-protocol.md §2).
//
// Ext 1 carries a typed numeric array, decoded into an NdArray whose `data` is a JS
// typed array of the element type (BigInt64Array for i64/u64). Ext 2 is a timestamp in
// µs since 1970 UTC, decoded into a plain Number (exact until year 2255).
import { decode, encode, ExtensionCodec } from '@msgpack/msgpack';
import { ProtocolError } from './errors.js';

export const EXT_NDARRAY = 1;
export const EXT_TIMESTAMP = 2;
export const MAX_NDIM = 8;

// code -> [name, itemsize, typed array constructor]; the table of §2.1.
export const DTYPES = [
  ['bool', 1, Uint8Array],
  ['i8', 1, Int8Array],
  ['i16', 2, Int16Array],
  ['i32', 4, Int32Array],
  ['i64', 8, BigInt64Array],
  ['u8', 1, Uint8Array],
  ['u16', 2, Uint16Array],
  ['u32', 4, Uint32Array],
  ['u64', 8, BigUint64Array],
  ['f32', 4, Float32Array],
  ['f64', 8, Float64Array],
];
export const DTYPE_CODE = Object.fromEntries(DTYPES.map(([name], code) => [name, code]));

// Sending a typed array picks its ext dtype from its class (Uint8Array stays msgpack bin).
const CODE_OF_CLASS = new Map([
  [Int8Array, 1], [Int16Array, 2], [Int32Array, 3], [BigInt64Array, 4],
  [Uint16Array, 6], [Uint32Array, 7], [BigUint64Array, 8], [Float32Array, 9], [Float64Array, 10],
]);

const LITTLE_ENDIAN_HOST = new Uint8Array(new Uint16Array([1]).buffer)[0] === 1;

/** A typed numeric array with a shape (C order), as carried by ext type 1. */
export class NdArray {
  constructor(dtype, shape, data) {
    if (!(dtype in DTYPE_CODE)) throw new TypeError(`unknown dtype ${dtype}`);
    const n = shape.reduce((a, b) => a * b, 1);
    if (data.length !== n) {
      throw new RangeError(`NdArray: ${data.length} elements do not fill shape [${shape}]`);
    }
    this.dtype = dtype;
    this.shape = shape;
    this.data = data;
  }

  /** Return the elements nested by shape: numbers, and BigInt for 64-bit integers beyond 2^53. */
  toNested() {
    const flat = Array.from(this.data, (v) => (typeof v === 'bigint' ? exactInteger(v) : v));
    const values = this.dtype === 'bool' ? flat.map(Boolean) : flat;
    if (this.shape.length === 0) return values[0];
    const nest = (offset, dims) => {
      if (dims.length === 1) return values.slice(offset, offset + dims[0]);
      const step = dims.slice(1).reduce((a, b) => a * b, 1);
      return Array.from({ length: dims[0] }, (_, i) => nest(offset + i * step, dims.slice(1)));
    };
    return nest(0, this.shape);
  }

  /** Return column `j` of a 2-D array as a Float64Array. */
  column(j) {
    const [rows, cols] = this.shape;
    const out = new Float64Array(rows);
    const d = this.data;
    if (typeof d[0] === 'bigint') for (let i = 0; i < rows; i++) out[i] = Number(d[i * cols + j]);
    else for (let i = 0; i < rows; i++) out[i] = d[i * cols + j];
    return out;
  }
}

function headerLength(ndim) {
  return Math.ceil((4 + 4 * ndim) / 8) * 8;
}

/** Decode an ext-1 payload; raise ProtocolError on any inconsistency. */
export function decodeNdArray(payload) {
  if (!LITTLE_ENDIAN_HOST) throw new ProtocolError('big-endian hosts are not supported');
  if (payload.length < 4) throw new ProtocolError('ext 1: payload shorter than its header');
  const view = new DataView(payload.buffer, payload.byteOffset, payload.byteLength);
  const code = view.getUint8(0);
  const ndim = view.getUint8(1);
  if (code >= DTYPES.length) throw new ProtocolError(`ext 1: unknown dtype code ${code}`);
  if (ndim > MAX_NDIM) throw new ProtocolError(`ext 1: ndim ${ndim} above ${MAX_NDIM}`);
  const h = headerLength(ndim);
  if (payload.length < h) throw new ProtocolError('ext 1: payload shorter than its header');
  const shape = [];
  for (let i = 0; i < ndim; i++) shape.push(view.getUint32(4 + 4 * i, true));
  const [name, itemsize, Ctor] = DTYPES[code];
  const n = shape.reduce((a, b) => a * b, 1);
  if (payload.length !== h + n * itemsize) {
    throw new ProtocolError(`ext 1: ${payload.length} bytes, expected ${h + n * itemsize} for ${name}[${shape}]`);
  }
  // Copy: the payload may sit at an offset that is not a multiple of the item size.
  const bytes = payload.slice(h, h + n * itemsize);
  return new NdArray(name, shape, new Ctor(bytes.buffer, 0, n));
}

/** Encode an NdArray (or a typed array, one-dimensional) as an ext-1 payload. */
export function encodeNdArray(array) {
  const nd = array instanceof NdArray ? array : toNdArray(array);
  const code = DTYPE_CODE[nd.dtype];
  const h = headerLength(nd.shape.length);
  const body = new Uint8Array(nd.data.buffer, nd.data.byteOffset, nd.data.byteLength);
  const out = new Uint8Array(h + body.length);
  const view = new DataView(out.buffer);
  view.setUint8(0, code);
  view.setUint8(1, nd.shape.length);
  nd.shape.forEach((size, i) => view.setUint32(4 + 4 * i, size, true));
  out.set(body, h);
  return out;
}

function toNdArray(typed) {
  const code = CODE_OF_CLASS.get(typed.constructor);
  return new NdArray(DTYPES[code][0], [typed.length], typed);
}

function encodeTimestamp(tUs) {
  const out = new Uint8Array(8);
  new DataView(out.buffer).setBigInt64(0, BigInt(tUs), true);
  return out;
}

/** A mount time to send as ext 2 (µs since 1970 UTC). */
export class Timestamp {
  constructor(tUs) {
    this.tUs = tUs;
  }
}

export const extensionCodec = new ExtensionCodec();
extensionCodec.register({
  type: EXT_NDARRAY,
  encode: (value) =>
    value instanceof NdArray || (ArrayBuffer.isView(value) && CODE_OF_CLASS.has(value.constructor))
      ? encodeNdArray(value)
      : null,
  decode: (data) => decodeNdArray(data),
});
extensionCodec.register({
  type: EXT_TIMESTAMP,
  encode: (value) => (value instanceof Timestamp ? encodeTimestamp(value.tUs) : null),
  decode: (data) => {
    if (data.length !== 8) throw new ProtocolError(`ext 2: ${data.length} bytes, expected 8`);
    const view = new DataView(data.buffer, data.byteOffset, 8);
    return Number(view.getBigInt64(0, true));
  },
});

/** Return a BigInt as a Number when that is exact (|v| < 2^53), else the BigInt itself. */
export function exactInteger(v) {
  const n = Number(v);
  return Number.isSafeInteger(n) ? n : v;
}

// Spec §2.4: an integer field may exceed 2^53 (i64/u64 values, seq). Frames are decoded with
// int 64 / uint 64 as BigInt, then every BigInt that a Number holds exactly becomes a Number:
// t_us, ticks and counts stay plain numbers, an i64 of 2^53 + 1 stays exact.
function fromWire(v) {
  if (typeof v === 'bigint') return exactInteger(v);
  if (Array.isArray(v)) {
    for (let i = 0; i < v.length; i++) v[i] = fromWire(v[i]);
    return v;
  }
  if (v !== null && typeof v === 'object' && v.constructor === Object) {
    for (const k of Object.keys(v)) v[k] = fromWire(v[k]);
  }
  return v;
}

// The encoder writes BigInt as int 64 / uint 64 and, so told, a Number at or above 2^32 as a
// float: such integers are sent as BigInt instead, so they stay integers on the wire.
function toWire(v) {
  if (typeof v === 'number') return Number.isSafeInteger(v) && Math.abs(v) >= 2 ** 32 ? BigInt(v) : v;
  if (Array.isArray(v)) return v.map(toWire);
  if (v !== null && typeof v === 'object' && v.constructor === Object) {
    const out = {};
    for (const k of Object.keys(v)) out[k] = toWire(v[k]);
    return out;
  }
  return v;
}

/** Return the bytes of one frame. */
export function encodeFrame(value) {
  return encode(toWire(value), { extensionCodec, ignoreUndefined: true, useBigInt64: true });
}

/** Decode one frame; raise ProtocolError when it is not valid msgpack. */
export function decodeFrame(bytes) {
  try {
    return fromWire(decode(bytes, { extensionCodec, useBigInt64: true }));
  } catch (err) {
    if (err instanceof ProtocolError) throw err;
    throw new ProtocolError(`undecodable frame: ${err.message}`);
  }
}
