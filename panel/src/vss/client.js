// A client of the VirtualStar Server's JSON API over WebSocket (docs/vss-api.md).
//
// The server speaks first (`hello`, with the auth challenge); requests carry an id the
// answer echoes; events arrive between answers. The server sends a heartbeat every
// `heartbeat_s`: a connection silent for several heartbeats is treated as gone even when
// the socket looks open (a frozen server, a dead network), as VssClient does in Python.
import { markFloats } from '../eventlog.js';
import { authRequest } from './auth.js';

export const HEARTBEATS_MISSED = 5; // silent this many heartbeats (and at least SILENT_MIN_MS): gone
export const SILENT_MIN_MS = 5000;
export const DEFAULT_TIMEOUT_MS = 10_000;

/** An error answer of the server ({code, message}), or a lost connection (code 'closed'). */
export class VssError extends Error {
  constructor(code, message) {
    super(message);
    this.name = 'VssError';
    this.code = code;
  }
}

function openSocket(url, WS) {
  if (!WS) throw new VssError('closed', 'no WebSocket implementation: pass {WebSocket} (npm ws in Node)');
  if (!/^wss?:\/\//.test(url)) throw new VssError('bad_request', `${url}: the VirtualStar Server is reached by ws:// or wss://`);
  return new Promise((resolve, reject) => {
    let ws;
    try {
      ws = new WS(url);
    } catch (err) {
      reject(new VssError('closed', `cannot open ${url}: ${err.message}`));
      return;
    }
    ws.onopen = () => resolve(ws);
    ws.onerror = () => reject(new VssError('closed', `cannot connect to ${url}`));
    ws.onclose = (ev) => reject(new VssError('closed', `cannot connect to ${url} (close code ${ev.code})`));
  });
}

export class VssClient {
  constructor(ws, url) {
    this.ws = ws;
    this.url = url;
    this.nextId = 1;
    this.pending = new Map(); // id -> {resolve, reject, timer}
    this.eventListeners = new Set();
    this.closeListeners = new Set();
    this.hello = null;
    this.role = null;
    this.closed = false;
    this.lastHeardMs = Date.now();
    this.firstFrame = null; // resolves with the hello
    this.helloWaiter = new Promise((resolve) => {
      this.firstFrame = resolve;
    });
    ws.onmessage = (ev) => this.receive(ev.data);
    ws.onclose = (ev) => this.lost(new VssError('closed', `connection to ${url} closed (code ${ev.code}${ev.reason ? `: ${ev.reason}` : ''})`));
    ws.onerror = () => {};
  }

  /**
   * Connect, read the hello and authenticate when the server asks for a password.
   * options: password, role ('observer'|'operator': the most wanted), WebSocket, timeoutMs.
   */
  static async connect(url, { password = '', role = null, WebSocket = globalThis.WebSocket, timeoutMs = DEFAULT_TIMEOUT_MS } = {}) {
    const client = new VssClient(await openSocket(url, WebSocket), url);
    try {
      const hello = await client.within(client.helloWaiter, timeoutMs, 'no hello from the server');
      if (hello?.server === undefined) throw new VssError('bad_request', `${url} is not a VirtualStar Server (no hello)`);
      client.hello = hello;
      const auth = hello.auth || {};
      if (auth.required) {
        if (!password) throw new VssError('unauthorized', `the VirtualStar Server at ${url} needs a password`);
        const answer = await authRequest(password, auth.nonce, role);
        const result = await client.request('auth', answer.params, timeoutMs);
        if (!answer.proofMatches(result.server_proof)) {
          throw new VssError('unauthorized', `${url} answered with a wrong server proof: it does not know the password`);
        }
        client.role = result.role;
      } else {
        client.role = auth.role || 'operator';
      }
      client.watchdog = setInterval(() => client.checkHeartbeat(), 1000);
      return client;
    } catch (err) {
      client.close();
      throw err;
    }
  }

  within(promise, ms, what) {
    let timer;
    const timeout = new Promise((_, reject) => {
      timer = setTimeout(() => reject(new VssError('timeout', `${this.url}: ${what} within ${ms / 1000} s`)), ms);
    });
    return Promise.race([promise, timeout]).finally(() => clearTimeout(timer));
  }

  receive(data) {
    this.lastHeardMs = Date.now();
    let doc;
    try {
      // markFloats: an event field written 0.0 stays a float for the Log tab's text filter
      doc = JSON.parse(typeof data === 'string' ? data : new TextDecoder().decode(data), markFloats);
    } catch {
      return; // not ours to answer: the server sends JSON only
    }
    if (doc && typeof doc.event === 'string') {
      if (doc.event === 'hello') this.firstFrame(doc.data || {});
      for (const fn of this.eventListeners) fn(doc.event, doc.data ?? {});
      return;
    }
    const waiting = this.pending.get(doc?.id);
    if (!waiting) return;
    this.pending.delete(doc.id);
    clearTimeout(waiting.timer);
    if (doc.ok) waiting.resolve(doc.result);
    else waiting.reject(new VssError(doc.error?.code || 'internal', doc.error?.message || 'refused without a message'));
  }

  checkHeartbeat() {
    const beatMs = 1000 * (Number(this.hello?.heartbeat_s) || 1);
    const silentMs = Date.now() - this.lastHeardMs;
    if (silentMs > Math.max(SILENT_MIN_MS, HEARTBEATS_MISSED * beatMs)) {
      this.lost(new VssError('closed', `${this.url} silent for ${(silentMs / 1000).toFixed(1)} s (no heartbeat)`));
      try {
        this.ws.close();
      } catch {
        // already closing
      }
    }
  }

  /** Send `cmd` with `params`; resolve with the result or reject with a VssError. */
  request(cmd, params = {}, timeoutMs = DEFAULT_TIMEOUT_MS) {
    if (this.closed) return Promise.reject(new VssError('closed', `not connected to ${this.url}`));
    const id = this.nextId++;
    return new Promise((resolve, reject) => {
      const timer = setTimeout(() => {
        this.pending.delete(id);
        reject(new VssError('timeout', `${cmd}: no answer from ${this.url} within ${timeoutMs / 1000} s`));
      }, timeoutMs);
      this.pending.set(id, { resolve, reject, timer });
      this.ws.send(JSON.stringify({ id, cmd, params }));
    });
  }

  onEvent(fn) {
    this.eventListeners.add(fn);
    return () => this.eventListeners.delete(fn);
  }

  onClose(fn) {
    this.closeListeners.add(fn);
    return () => this.closeListeners.delete(fn);
  }

  lost(err) {
    if (this.closed) return;
    this.closed = true;
    clearInterval(this.watchdog);
    for (const { reject, timer } of this.pending.values()) {
      clearTimeout(timer);
      reject(err);
    }
    this.pending.clear();
    for (const fn of this.closeListeners) fn(err);
  }

  close() {
    this.lost(new VssError('closed', 'closed by this client'));
    try {
      this.ws.close();
    } catch {
      // already closed
    }
  }
}
