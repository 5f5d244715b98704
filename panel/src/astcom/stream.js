// One stream of a message (§6): decodes DATA frames into columns and counts lost samples.
import { ProtocolError } from './errors.js';

/**
 * A decoded stream packet: `tUs` (Float64Array, mount time µs of every sample),
 * `columns` (one Float64Array per column name, same order as `stream.columns`),
 * `lost` (samples missing just before this packet), plus the frame's header fields.
 */
export class Stream {
  constructor(client, msg, names) {
    this.client = client;
    this.msg = msg;
    this.names = names;
    this.info = null;
    this.columns = [];
    this.samples = 0;
    this.packets = 0;
    this.lost = 0;
    this.lostPackets = 0;
    this.nextTick = null;
    this.nextSeq = null;
    this.early = []; // DATA that came before the STREAM_START reply
    this.listeners = new Set();
    this.endListeners = new Set();
    this.error = null;
  }

  started(reply) {
    this.info = reply;
    this.columns = reply.columns;
    this.rateHz = reply.rate_hz;
    // column index -> [group, position in the group]
    this.where = new Array(reply.columns.length);
    reply.groups.forEach((cols, g) => cols.forEach((c, j) => {
      this.where[c] = [g, j];
    }));
    const early = this.early;
    this.early = [];
    for (const frame of early) this.receive(frame);
  }

  /** Call `listener(packet, stream)` for every packet; return an unsubscribe function. */
  onPacket(listener) {
    this.listeners.add(listener);
    return () => this.listeners.delete(listener);
  }

  onEnd(listener) {
    this.endListeners.add(listener);
    return () => this.endListeners.delete(listener);
  }

  receive(frame) {
    if (!this.info) {
      this.early.push(frame);
      return;
    }
    const [, msg, seq, firstTick, firstTUs, periodUs, periodTicks, n, arrays] = frame;
    if (!Array.isArray(arrays) || arrays.length !== this.info.groups.length) {
      throw new ProtocolError(`DATA of message ${msg}: ${arrays?.length} arrays for ${this.info.groups.length} groups`);
    }
    let lost = 0;
    if (this.nextTick !== null && firstTick > this.nextTick) {
      lost = Math.round((firstTick - this.nextTick) / Math.max(1, periodTicks));
      this.lostPackets += Math.max(0, seq - this.nextSeq);
    }
    this.nextTick = firstTick + n * periodTicks;
    this.nextSeq = seq + 1;
    const columns = this.where.map(([g, j]) => arrays[g].column(j));
    const tUs = new Float64Array(n);
    for (let i = 0; i < n; i++) tUs[i] = firstTUs + Math.round(i * periodUs);
    this.samples += n;
    this.packets += 1;
    this.lost += lost;
    const packet = { msg, seq, firstTick, firstTUs, periodUs, periodTicks, n, lost, tUs, columns };
    for (const listener of this.listeners) {
      try {
        listener(packet, this);
      } catch (err) {
        // a consumer's bug must not cost the connection or the other consumers
        console.error('stream listener failed:', err);
      }
    }
  }

  ended(error) {
    this.error = error;
    for (const listener of this.endListeners) listener(error);
  }

  /** STREAM_STOP and UNDEFINE the message on this connection. */
  stop() {
    return this.client.stopStream(this);
  }
}
