// The JavaScript ASTCom client: a standalone module (no Vue, no DOM beyond WebSocket).
export { Client, DEFAULT_TIMEOUT_MS, PROTOCOL_VERSION } from './client.js';
export { DTYPES, decodeFrame, encodeFrame, NdArray, Timestamp } from './codec.js';
export { AstcomError, AuthenticationFailed, ConnectionClosed, ProtocolError, RemoteError } from './errors.js';
export { Stream } from './stream.js';
export { coerce, isStreamable, parseSignature, parseType } from './types.js';
