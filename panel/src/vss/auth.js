// The VSS's challenge–response (docs/vss-api.md, "Access"): ASTCom's HMAC-SHA256 of §5,
// carried as hex text in JSON instead of bytes in msgpack.
import { clientMac, clientNonce, sameBytes, serverProof } from '../astcom/auth.js';

/** Return lower-case hex of a byte array. */
export function toHex(bytes) {
  return Array.from(bytes, (b) => b.toString(16).padStart(2, '0')).join('');
}

/** Return the bytes of hex text; throws naming what was given when it is not hex. */
export function fromHex(text) {
  if (typeof text !== 'string' || !/^(?:[0-9a-fA-F]{2})*$/.test(text)) {
    throw new Error(`expected hex text (pairs of 0-9a-f), got ${JSON.stringify(String(text).slice(0, 80))}`);
  }
  const out = new Uint8Array(text.length / 2);
  for (let i = 0; i < out.length; i++) out[i] = parseInt(text.slice(2 * i, 2 * i + 2), 16);
  return out;
}

/**
 * Return {params, proofMatches(hex)} for an `auth` request answering the server's hello
 * nonce (hex): params = {client_nonce, mac[, role]}; proofMatches checks the server_proof
 * of the reply, so a server that does not know the password is not believed.
 */
export async function authRequest(password, nonceHex, role = null, cnonce = clientNonce()) {
  const nonce = fromHex(nonceHex);
  const mac = await clientMac(password, nonce, cnonce);
  const expected = await serverProof(password, nonce, cnonce);
  const params = { client_nonce: toHex(cnonce), mac: toHex(mac) };
  if (role) params.role = role;
  return {
    params,
    proofMatches(proofHex) {
      try {
        return sameBytes(fromHex(proofHex ?? ''), expected);
      } catch {
        return false;
      }
    },
  };
}
