// An ASTCom client over WebSocket, written from docs/astcom-protocol.md.
//
// One Client is one connection. Requests are numbered 1, 2, 3, ... and matched with
// their replies by seq (§3); DATA frames go to the Stream of their message ID (§6).
// A panel opens two: a private channel for LIST/READ/WRITE/INVOKE and a stream
// channel that only carries DATA, so a burst of samples never delays a reply.
import { clientMac, clientNonce, sameBytes, serverProof } from './auth.js';
import { decodeFrame, encodeFrame } from './codec.js';
import { AstcomError, AuthenticationFailed, ConnectionClosed, ProtocolError, RemoteError } from './errors.js';
import { Stream } from './stream.js';

export const PROTOCOL_VERSION = '1.0';
export const DEFAULT_TIMEOUT_MS = 10_000;

function openSocket(url, WebSocketImpl) {
  const WS = WebSocketImpl || globalThis.WebSocket;
  if (!WS) throw new ConnectionClosed('no WebSocket implementation: pass {WebSocket} (npm ws in Node 20)');
  if (!WebSocketImpl && !/^wss?:\/\//.test(url)) {
    throw new ConnectionClosed(`${url}: a browser reaches an endpoint by ws:// or wss:// only`);
  }
  return new Promise((resolve, reject) => {
    let ws;
    try {
      ws = new WS(url);
    } catch (err) {
      reject(new ConnectionClosed(`cannot open ${url}: ${err.message}`));
      return;
    }
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => resolve(ws);
    ws.onerror = () => reject(new ConnectionClosed(`cannot connect to ${url}`));
    ws.onclose = (ev) => reject(new ConnectionClosed(`cannot connect to ${url} (close code ${ev.code})`));
  });
}

export class Client {
  constructor(ws, url, { timeoutMs = DEFAULT_TIMEOUT_MS } = {}) {
    this.ws = ws;
    this.url = url;
    this.timeoutMs = timeoutMs;
    this.seq = 0;
    this.pending = new Map(); // seq -> {op, resolve, reject, timer}
    this.streams = new Map(); // msg -> Stream
    this.messages = new Map(); // names joined by \n -> {msg, types, names}
    this.hello = null;
    this.role = null;
    this.closed = false;
    this.closeReason = null;
    this.closeListeners = new Set();
    ws.onmessage = (ev) => this.receive(ev.data);
    ws.onclose = (ev) => this.lost(new ConnectionClosed(`connection closed (code ${ev.code}${ev.reason ? `: ${ev.reason}` : ''})`));
    ws.onerror = () => {};
  }

  /**
   * Connect, say HELLO and authenticate when the endpoint asks for it.
   * options: password, role ('observer'|'operator', the most wanted), clientName,
   * WebSocket (constructor: npm ws in Node 20, or TcpSocket from tcp-node.js for tcp://), timeoutMs.
   */
  static async connect(url, options = {}) {
    const ws = await openSocket(url, options.WebSocket);
    const client = new Client(ws, url, options);
    try {
      client.hello = await client.request('HELLO', { version: PROTOCOL_VERSION, client: options.clientName || 'panel' });
      if (client.hello.auth === 'hmac-sha256') {
        await client.authenticate(options.password, options.role);
      } else if (client.hello.auth == null) {
        client.role = client.hello.role || 'operator';
      } else {
        throw new ProtocolError(`unknown authentication scheme ${client.hello.auth}`);
      }
    } catch (err) {
      client.close();
      throw err;
    }
    return client;
  }

  async authenticate(password, role) {
    if (password == null || password === '') {
      throw new AuthenticationFailed('the endpoint asks for a password; none was given', 401);
    }
    const nonce = this.hello.nonce;
    const cnonce = clientNonce();
    const mac = await clientMac(password, nonce, cnonce);
    let reply;
    try {
      reply = await this.request('AUTH', { cnonce, mac, role: role || null });
    } catch (err) {
      if (err.code === 401) throw new AuthenticationFailed('wrong password (ERR 401)', 401);
      throw err;
    }
    if (!sameBytes(reply.proof, await serverProof(password, nonce, cnonce))) {
      throw new AuthenticationFailed('the endpoint does not prove it knows the password', 401);
    }
    this.role = reply.role;
  }

  get loopRateHz() {
    return this.hello?.loop_rate_hz;
  }

  onClose(listener) {
    this.closeListeners.add(listener);
    return () => this.closeListeners.delete(listener);
  }

  // ------------------------------------------------------------------ requests
  request(op, args = {}, timeoutMs = this.timeoutMs) {
    if (this.closed) return Promise.reject(this.closeReason || new ConnectionClosed('connection closed'));
    const seq = ++this.seq;
    return new Promise((resolve, reject) => {
      const timer = timeoutMs > 0
        ? setTimeout(() => {
          this.pending.delete(seq);
          reject(new AstcomError(`${op}: no reply within ${timeoutMs} ms`));
        }, timeoutMs)
        : null;
      this.pending.set(seq, { op, resolve, reject, timer });
      try {
        this.ws.send(encodeFrame([op, seq, args]));
      } catch (err) {
        this.pending.delete(seq);
        clearTimeout(timer);
        reject(new ConnectionClosed(`${op}: cannot send: ${err.message}`));
      }
    });
  }

  /** Return the LIST entries ({name, type, kind, access, unit, doc}) under `prefix`. */
  async list(prefix = '') {
    return (await this.request('LIST', { prefix })).entries;
  }

  /** DEFINE `names` once per connection; return {msg, types, names}. */
  async define(names) {
    const key = names.join('\n');
    let info = this.messages.get(key);
    if (!info) {
      const reply = await this.request('DEFINE', { names });
      info = { msg: reply.msg, types: reply.types, names: [...names] };
      this.messages.set(key, info);
    }
    return info;
  }

  async undefine(names) {
    const key = names.join('\n');
    const info = this.messages.get(key);
    if (!info) return;
    this.messages.delete(key);
    await this.request('UNDEFINE', { msg: info.msg });
  }

  /** Return {values: {name: value}, tick, tUs}: every value at one tick. */
  async read(names) {
    const { msg } = await this.define(names);
    const reply = await this.request('READ', { msg });
    const values = {};
    names.forEach((name, i) => {
      values[name] = reply.values[i];
    });
    return { values, tick: reply.tick, tUs: reply.t_us };
  }

  /** Write {name: value} between two ticks (all or none); return the tick before. */
  async write(values) {
    const names = Object.keys(values);
    const { msg } = await this.define(names);
    const reply = await this.request('WRITE', { msg, values: names.map((n) => values[n]) });
    return reply.tick;
  }

  /** Call a device function; return its value. */
  async invoke(name, args = [], timeoutMs = this.timeoutMs) {
    return (await this.request('INVOKE', { name, args }, timeoutMs)).value;
  }

  async ping() {
    return this.request('PING');
  }

  async stats() {
    return this.request('STATS');
  }

  /** Start streaming `names` at `rateHz`; return the Stream (bind callbacks with onPacket). */
  async stream(names, rateHz) {
    const { msg } = await this.define(names);
    let stream = this.streams.get(msg);
    if (!stream) {
      stream = new Stream(this, msg, names);
      this.streams.set(msg, stream);
    }
    try {
      stream.started(await this.request('STREAM_START', { msg, rate_hz: rateHz }));
    } catch (err) {
      this.streams.delete(msg);
      throw err;
    }
    return stream;
  }

  async stopStream(stream) {
    if (this.streams.get(stream.msg) !== stream) return;
    this.streams.delete(stream.msg);
    if (!this.closed) {
      await this.request('STREAM_STOP', { msg: stream.msg });
      await this.undefine(stream.names);
    }
  }

  /** Say BYE (best effort) and close. */
  async close() {
    if (this.closed) return;
    try {
      await this.request('BYE', {}, 1000);
    } catch {
      // the connection may already be gone; closing is all that is left
    }
    this.lost(new ConnectionClosed('closed by the client'));
    try {
      this.ws.close();
    } catch {
      // already closed
    }
  }

  // ------------------------------------------------------------------ receiving
  receive(data) {
    if (typeof data === 'string') {
      this.fail(new ProtocolError('the endpoint sent a text message; ASTCom frames are binary'));
      return;
    }
    let frame;
    try {
      frame = decodeFrame(new Uint8Array(data));
    } catch (err) {
      this.fail(err);
      return;
    }
    if (!Array.isArray(frame) || frame.length < 3) {
      this.fail(new ProtocolError('frame is not an array [kind, ...]'));
      return;
    }
    const kind = frame[0];
    if (kind === 'DATA') {
      const stream = this.streams.get(frame[1]);
      try {
        stream?.receive(frame);
      } catch (err) {
        this.fail(err);
      }
      return;
    }
    if (kind !== 'OK' && kind !== 'ERR') {
      this.fail(new ProtocolError(`unknown frame kind ${JSON.stringify(kind)}`));
      return;
    }
    const seq = frame[1];
    if (seq == null) {
      const { code, message } = frame[2] || {};
      this.fail(new RemoteError('connection', code, message));
      return;
    }
    const pending = this.pending.get(seq);
    if (!pending) return; // the reply to a request that timed out
    this.pending.delete(seq);
    clearTimeout(pending.timer);
    if (kind === 'OK') pending.resolve(frame[2]);
    else pending.reject(new RemoteError(pending.op, frame[2]?.code, frame[2]?.message));
  }

  fail(error) {
    this.lost(error);
    try {
      this.ws.close();
    } catch {
      // already closed
    }
  }

  lost(error) {
    if (this.closed) return;
    this.closed = true;
    this.closeReason = error;
    for (const p of this.pending.values()) {
      clearTimeout(p.timer);
      p.reject(error);
    }
    this.pending.clear();
    for (const s of this.streams.values()) s.ended(error);
    this.streams.clear();
    for (const listener of this.closeListeners) listener(error);
  }
}
