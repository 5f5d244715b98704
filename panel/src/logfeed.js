// Follow several event logs (docs/events.md) by polling each for the events after the
// last `seq` seen, and keep them merged by mount time. No I/O of its own: each source
// says how to reach its log, so the same logic runs against fakes in the unit tests.
//
// A source: {name, link() -> the connection in use or null, offline -> text shown when
// link() is null, lastSeq(link) -> the newest seq of the log (or null if unknown),
// since(link, seq) -> the events after seq, oldest first, page -> the most one answer
// holds (a full page is followed at once by the next)}. A new link may reach a restarted
// device, numbered from 1 again: its log is read from the start when it is behind the seq
// seen, or when the event held as that seq is not the one it has under that number (a
// restarted device may have logged more events than the old one before the link is back).
//
// Rows live outside Vue's reactivity (up to maxRows, the oldest dropped); `state.version`
// says when they changed. Paused, new events wait aside and join on follow: a pause loses none.
import { reactive } from 'vue';
import { eventProblem, mergeEvents } from './eventlog.js';

/** The same logged event: number, mount time, kind and text. */
const sameEvent = (a, b) => a.seq === b.seq && a.t_us === b.t_us && a.kind === b.kind && a.message === b.message;

export class LogFeed {
  constructor(sources, { maxRows = 20_000 } = {}) {
    this.sources = sources;
    this.maxRows = maxRows;
    this.rows = [];
    this.waiting = [];
    this.feeds = Object.fromEntries(sources.map((s) => [s.name, { since: 0, last: null, link: null, busy: false, skipped: 0, problem: '' }]));
    this.state = reactive({
      version: 0, following: true, pending: 0, total: 0, polls: 0, // polls: rounds completed
      status: Object.fromEntries(sources.map((s) => [s.name, 'not polled yet'])),
    });
  }

  take(events) {
    if (!events.length) return;
    if (!this.state.following) {
      this.waiting.push(...events);
      this.state.pending = this.waiting.length;
      return;
    }
    mergeEvents(this.rows, events);
    if (this.rows.length > this.maxRows) this.rows.splice(0, this.rows.length - this.maxRows);
    this.state.total = this.rows.length;
    this.state.version++;
  }

  async pollSource(src) {
    const feed = this.feeds[src.name];
    const link = src.link();
    if (!link) {
      this.state.status[src.name] = src.offline;
      return;
    }
    if (link !== feed.link) {
      if (await this.restarted(src, link, feed)) [feed.since, feed.last] = [0, null];
      feed.link = link;
    }
    for (;;) {
      const events = await src.since(link, feed.since);
      const good = events.filter((e) => {
        const problem = eventProblem(e);
        if (problem) [feed.skipped, feed.problem] = [feed.skipped + 1, problem];
        return !problem;
      });
      if (good.length && good[good.length - 1].seq > feed.since) {
        feed.last = good[good.length - 1];
        feed.since = feed.last.seq;
      }
      this.take(good);
      if (events.length < src.page) break;
    }
    const skipped = feed.skipped ? `; ${feed.skipped} malformed events left out (last: ${feed.problem})` : '';
    this.state.status[src.name] = `following (seq ${feed.since})${skipped}`;
  }

  /** Is the log behind a new link another device's (a restart) than the one followed? */
  async restarted(src, link, feed) {
    if (!feed.since) return false;
    const last = await src.lastSeq(link);
    if (last !== null && last < feed.since) return true;
    if (!feed.last) return false;
    // the event held as seq `since`, asked for again: a restarted log has another one there
    const [again] = await src.since(link, feed.since - 1);
    return !!again && again.seq === feed.last.seq && !sameEvent(again, feed.last);
  }

  async pollOne(src) {
    const feed = this.feeds[src.name];
    if (feed.busy) return; // a slow answer: the next poll asks again from the same seq
    feed.busy = true;
    try {
      await this.pollSource(src);
    } catch (err) {
      this.state.status[src.name] = `error: ${err.message}`;
    } finally {
      feed.busy = false;
    }
  }

  /** Poll every source once. */
  async poll() {
    await Promise.all(this.sources.map((s) => this.pollOne(s)));
    this.state.polls += 1;
  }

  /** Pause (`false`: new events wait aside) or follow (`true`: they join the rows). */
  setFollowing(on) {
    this.state.following = on;
    if (on && this.waiting.length) {
      const events = this.waiting;
      this.waiting = [];
      this.state.pending = 0;
      this.take(events);
    }
  }

  /** Forget the events held; polling goes on after the last seq seen. */
  clear() {
    this.rows.length = 0;
    this.waiting = [];
    this.state.pending = 0;
    this.state.total = 0;
    this.state.version++;
  }
}
