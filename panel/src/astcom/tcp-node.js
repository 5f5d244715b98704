// tcp:// for Node (§1: each frame is a u32 big-endian length then the frame), shaped like a
// WebSocket so the Client drives it unchanged: Client.connect('tcp://host:port',
// {WebSocket: TcpSocket}). Browsers cannot open raw TCP; this is for Node tools and tests.
import { connect } from 'node:net';

const CONNECTING = 0;
const OPEN = 1;
const CLOSED = 3;

export class TcpSocket {
  constructor(url, { maxFrameBytes = 16 * 1024 * 1024 } = {}) {
    const m = /^tcp:\/\/(\[[^\]]+\]|[^:/]+):(\d+)\/?$/.exec(url);
    if (!m) throw new Error(`${url}: expected tcp://HOST:PORT`);
    this.url = url;
    this.maxFrameBytes = maxFrameBytes;
    this.readyState = CONNECTING;
    this.binaryType = 'arraybuffer';
    this.onopen = null;
    this.onmessage = null;
    this.onclose = null;
    this.onerror = null;
    this.pending = Buffer.alloc(0);
    this.socket = connect({ host: m[1].replace(/^\[|\]$/g, ''), port: Number(m[2]) });
    this.socket.setNoDelay(true);
    this.socket.on('connect', () => {
      this.readyState = OPEN;
      this.onopen?.({});
    });
    this.socket.on('data', (chunk) => this.receive(chunk));
    this.socket.on('error', (err) => this.onerror?.({ error: err }));
    this.socket.on('close', () => {
      const was = this.readyState;
      this.readyState = CLOSED;
      if (was !== CLOSED || this.onclose) this.onclose?.({ code: 1006, reason: '' });
    });
  }

  receive(chunk) {
    this.pending = this.pending.length ? Buffer.concat([this.pending, chunk]) : chunk;
    while (this.pending.length >= 4) {
      const n = this.pending.readUInt32BE(0);
      if (n > this.maxFrameBytes) {
        this.onerror?.({ error: new Error(`frame of ${n} bytes above ${this.maxFrameBytes}`) });
        this.close();
        return;
      }
      if (this.pending.length < 4 + n) return;
      const frame = this.pending.subarray(4, 4 + n);
      this.pending = this.pending.subarray(4 + n);
      // hand over an ArrayBuffer of exactly this frame, as a WebSocket would
      const data = frame.buffer.slice(frame.byteOffset, frame.byteOffset + frame.byteLength);
      this.onmessage?.({ data });
    }
  }

  send(bytes) {
    if (this.readyState !== OPEN) throw new Error('socket is not open');
    const header = Buffer.alloc(4);
    header.writeUInt32BE(bytes.length, 0);
    this.socket.write(Buffer.concat([header, Buffer.from(bytes.buffer, bytes.byteOffset, bytes.byteLength)]));
  }

  close() {
    if (this.readyState === CLOSED) return;
    this.socket.end();
  }
}

/** Return the bytes of one frame as sent over TCP (length prefix + frame). */
export function tcpFrame(bytes) {
  const out = new Uint8Array(4 + bytes.length);
  new DataView(out.buffer).setUint32(0, bytes.length, false);
  out.set(bytes, 4);
  return out;
}
