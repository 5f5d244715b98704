// Codec and type tests against the byte examples of docs/astcom-protocol.md (no endpoint).
import assert from 'node:assert/strict';
import { test } from 'node:test';
import { decodeFrame, encodeFrame, NdArray } from '../../src/astcom/codec.js';
import { ProtocolError } from '../../src/astcom/errors.js';
import { tcpFrame } from '../../src/astcom/tcp-node.js';
import { coerce, isStreamable, parseSignature, parseType } from '../../src/astcom/types.js';

const hex = (bytes) => Buffer.from(bytes).toString('hex').match(/../g).join(' ');

test('hello request encodes to the bytes of spec section 9', () => {
  const bytes = encodeFrame(['HELLO', 1, { version: '1.0', client: 'x' }]);
  assert.equal(hex(bytes),
    '93 a5 48 45 4c 4c 4f 01 82 a7 76 65 72 73 69 6f 6e a3 31 2e 30 a6 63 6c 69 65 6e 74 a1 78');
});

test('read request encodes to the frame of spec section 1, and its tcp form to the prefixed bytes', () => {
  const frame = encodeFrame(['READ', 7, { msg: 3 }]);
  assert.equal(hex(frame), '93 a4 52 45 41 44 07 81 a3 6d 73 67 03');
  assert.equal(hex(tcpFrame(frame)), '00 00 00 0d 93 a4 52 45 41 44 07 81 a3 6d 73 67 03');
});

test('f64 2x3 array round-trips through the ext 1 header of spec section 2.1', () => {
  const nd = new NdArray('f64', [2, 3], Float64Array.from([1, 2, 3, 4, 5, 6]));
  const bytes = encodeFrame(nd);
  // fixext/ext8 header: c7 <len=64> 01, then the 16-byte array header of the spec
  assert.equal(hex(bytes.slice(0, 3)), 'c7 40 01');
  assert.equal(hex(bytes.slice(3, 19)), '0a 02 00 00 02 00 00 00 03 00 00 00 00 00 00 00');
  const back = decodeFrame(bytes);
  assert.deepEqual(back.shape, [2, 3]);
  assert.deepEqual(back.toNested(), [[1, 2, 3], [4, 5, 6]]);
  assert.deepEqual(Array.from(back.column(1)), [2, 5]);
});

test('ext 1 payload of the wrong length is a protocol error', () => {
  // i32 of shape [2] needs 8 header bytes + 8 data bytes; send 7 data bytes
  const header = [0x03, 0x01, 0, 0, 0x02, 0, 0, 0];
  const frame = Uint8Array.from([0xc7, 15, 0x01, ...header, 1, 0, 0, 0, 2, 0, 0]);
  assert.throws(() => decodeFrame(frame), (err) => err instanceof ProtocolError && /expected 16/.test(err.message));
});

test('timestamp ext 2 decodes to microseconds since 1970', () => {
  const tUs = 1_763_769_600_004_123;
  const payload = new Uint8Array(8);
  new DataView(payload.buffer).setBigInt64(0, BigInt(tUs), true);
  const frame = Uint8Array.from([0xd7, 0x02, ...payload]);
  assert.equal(decodeFrame(frame), tUs);
});

test('types and signatures parse and user text converts to wire values', () => {
  const sig = parseSignature('(t_us:i64[],az_rad:f64[])->u32');
  assert.deepEqual(sig.args.map((a) => a.name), ['t_us', 'az_rad']);
  assert.equal(sig.returns.scalar, 'u32');
  assert.deepEqual(parseType('f64[3,3]').shape, [3, 3]);
  assert.equal(parseType('{lat_deg:f64,lon_deg:f64}').fields[1].name, 'lon_deg');
  assert.equal(coerce(parseType('f64'), '2.5'), 2.5);
  assert.throws(() => coerce(parseType('u8'), '300'), /integer in \[0, 255\]/);
  assert.throws(() => coerce(parseType('f64[3]'), '[1, 2]'), /expected 3 elements/);
  const arr = coerce(parseType('i64[]'), '[1, 2, 3]');
  assert.equal(arr.dtype, 'i64');
  assert.deepEqual(coerce(parseType('{a:f64,b:bool}'), '{"a": 1, "b": true}'), { a: 1, b: true });
  assert.ok(isStreamable('f64[3]'));
  assert.ok(!isStreamable('f64[]'));
  assert.ok(!isStreamable('str'));
});
