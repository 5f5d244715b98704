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

// Spec §2.4: 64-bit integers beyond 2^53 stay exact (BigInt); the bounds of i64 and u64 hold.
test('an i64 of 2^53 + 1 decodes exactly and t_us stays a plain number', () => {
  // ["OK", 4, {"values": [2^53 + 1, 2^53 - 1], "t_us": 1763769604123000}] as Python's msgpack writes it
  const frame = Uint8Array.from(Buffer.from(
    '93a24f4b0482a676616c75657392cf0020000000000001cf001fffffffffffffa4745f7573cf000644239cb82978', 'hex'));
  const [, , body] = decodeFrame(frame);
  assert.equal(body.values[0], 9007199254740993n);
  assert.equal(body.values[1], 9007199254740991);
  assert.equal(typeof body.t_us, 'number');
  assert.equal(body.t_us, 1763769604123000);
});

test('typed i64 text beyond 2^53 goes out exactly, 2^63 is refused, u64 takes 2^64 - 1', () => {
  const i64 = parseType('i64');
  const u64 = parseType('u64');
  assert.equal(coerce(i64, '9007199254740993'), 9007199254740993n);
  assert.equal(coerce(i64, '9007199254740991'), 9007199254740991);
  assert.equal(coerce(i64, '9223372036854775807'), 2n ** 63n - 1n);
  assert.throws(() => coerce(i64, '9223372036854775808'), /\[-9223372036854775808, 9223372036854775807\]/);
  assert.throws(() => coerce(i64, 2 ** 63), /not an integer a Number holds exactly/);
  assert.equal(coerce(u64, '18446744073709551615'), 2n ** 64n - 1n);
  assert.throws(() => coerce(u64, '18446744073709551616'), /u64/);
  assert.throws(() => coerce(u64, '-1'), /u64/);
  const bytes = encodeFrame(['WRITE', 1, { msg: 1, values: [coerce(i64, '9007199254740993')] }]);
  assert.ok(hex(bytes).endsWith('cf 00 20 00 00 00 00 00 01'));
  assert.equal(decodeFrame(bytes)[2].values[0], 9007199254740993n);
  // a plain number at or above 2^32 still goes out as an integer, not a float
  assert.equal(hex(encodeFrame(1763769604123000)), 'cf 00 06 44 23 9c b8 29 78');
});

test('u64 and i64 arrays go out as ext 1 of their own type, exactly', () => {
  const u = coerce(parseType('u64[]'), '[18446744073709551615, 1]');
  assert.equal(u.dtype, 'u64');
  assert.deepEqual(Array.from(u.data), [2n ** 64n - 1n, 1n]);
  const back = decodeFrame(encodeFrame(u));
  assert.deepEqual(back.toNested(), [2n ** 64n - 1n, 1]);
  const i = coerce(parseType('i64[2]'), '[9007199254740993, -9007199254740993]');
  assert.deepEqual(decodeFrame(encodeFrame(i)).toNested(), [9007199254740993n, -9007199254740993n]);
});
