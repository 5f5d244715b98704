// HMAC-SHA256 challenge-response of §5, on WebCrypto (browsers and Node >= 20).
const encoder = new TextEncoder();
const CLIENT_LABEL = encoder.encode('ASTCom-1 client\0');
const SERVER_LABEL = encoder.encode('ASTCom-1 server\0');

function concat(...parts) {
  const out = new Uint8Array(parts.reduce((n, p) => n + p.length, 0));
  let at = 0;
  for (const p of parts) {
    out.set(p, at);
    at += p.length;
  }
  return out;
}

async function hmac(password, message) {
  const subtle = globalThis.crypto?.subtle;
  if (!subtle) {
    throw new Error('WebCrypto is not available: open the panel from http://127.0.0.1 or https');
  }
  const key = await subtle.importKey('raw', encoder.encode(password), { name: 'HMAC', hash: 'SHA-256' },
    false, ['sign']);
  return new Uint8Array(await subtle.sign('HMAC', key, message));
}

/** Return a fresh 32-byte client nonce. */
export function clientNonce() {
  return globalThis.crypto.getRandomValues(new Uint8Array(32));
}

/** Return the MAC a client sends in AUTH. */
export function clientMac(password, serverNonce, cnonce) {
  return hmac(password, concat(CLIENT_LABEL, serverNonce, cnonce));
}

/** Return the proof an endpoint that knows the password answers. */
export function serverProof(password, serverNonce, cnonce) {
  return hmac(password, concat(SERVER_LABEL, serverNonce, cnonce));
}

/** Compare two byte arrays without an early exit. */
export function sameBytes(a, b) {
  if (!a || !b || a.length !== b.length) return false;
  let diff = 0;
  for (let i = 0; i < a.length; i++) diff |= a[i] ^ b[i];
  return diff === 0;
}
