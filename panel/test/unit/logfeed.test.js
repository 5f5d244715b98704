// The Log tab's follower (src/logfeed.js) against in-memory logs that behave as
// astcom_client.events.EventLog does: numbered from 1, `since(seq)` gives what follows,
// a restarted device starts again from 1.
import assert from 'node:assert/strict';
import { test } from 'node:test';
import { LogFeed } from '../../src/logfeed.js';

const T0 = 1_772_395_200_000_000;

/** A device's log behind a connection; `restart()` is a new device behind a new link. */
function fakeSource(name, { page = Infinity, step = 1000 } = {}) {
  const src = {
    name, page, offline: `${name} offline`, events: [], asked: [], currentLink: null,
    link: () => src.currentLink,
    lastSeq: async () => src.events.length,
    since: async (_, seq) => {
      src.asked.push(seq);
      return src.events.slice(seq, seq + page);
    },
    add(n, t0 = T0) {
      for (let i = 0; i < n; i++) {
        const seq = src.events.length + 1;
        src.events.push({ seq, t_us: t0 + seq * step, source: name, level: 'info', kind: 'state', message: `${name} ${seq}`, fields: {} });
      }
    },
    connect() {
      src.currentLink = {};
    },
    restart() {
      src.events = [];
      src.currentLink = {};
    },
  };
  return src;
}

/** A connected source holding `n` events, and a feed that has polled it once. */
async function polledOnce(name, n) {
  const src = fakeSource(name);
  src.connect();
  src.add(n);
  const feed = new LogFeed([src]);
  await feed.poll();
  return { a: src, feed };
}

const seqs = (feed, name) => feed.rows.filter((e) => e.source === name).map((e) => e.seq);

test('two logs are followed from the last seq seen and merged by mount time', async () => {
  const a = fakeSource('emulator', { step: 1000 });
  const b = fakeSource('vss', { step: 1500 });
  const feed = new LogFeed([a, b]);
  await feed.poll();
  assert.equal(feed.state.status.emulator, 'emulator offline');
  a.connect();
  b.connect();
  a.add(3);
  b.add(2);
  await feed.poll();
  a.add(2);
  await feed.poll();
  assert.deepEqual(seqs(feed, 'emulator'), [1, 2, 3, 4, 5]);
  assert.deepEqual(seqs(feed, 'vss'), [1, 2]);
  assert.deepEqual(a.asked, [0, 3]);
  const times = feed.rows.map((e) => e.t_us);
  assert.deepEqual(times, [...times].sort((x, y) => x - y));
  assert.equal(feed.state.status.emulator, 'following (seq 5)');
  assert.equal(feed.state.total, 7);
});

test('a full page is followed at once by the next, so a long backlog comes in one poll', async () => {
  const v = fakeSource('vss', { page: 4 });
  v.connect();
  v.add(10);
  const feed = new LogFeed([v]);
  await feed.poll();
  assert.deepEqual(seqs(feed, 'vss'), [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]);
  assert.deepEqual(v.asked, [0, 4, 8]);
});

test('a restarted device behind a new link is read from its first event', async () => {
  const { a, feed } = await polledOnce('emulator', 5);
  a.restart();
  a.add(2, T0 + 1e9);
  await feed.poll();
  assert.deepEqual(seqs(feed, 'emulator'), [1, 2, 3, 4, 5, 1, 2]);
  // the same device reached again (a new link, its log went on): nothing read twice
  a.currentLink = {};
  a.add(1, T0 + 1e9);
  await feed.poll();
  assert.deepEqual(seqs(feed, 'emulator'), [1, 2, 3, 4, 5, 1, 2, 3]);
});

test('a restarted device that logged more than the old one before its link came back is read from its first event', async () => {
  const { a, feed } = await polledOnce('emulator', 3);
  a.restart(); // its log numbered from 1 again, and already past seq 3 when the panel is back
  a.add(6, T0 + 1e9);
  await feed.poll();
  assert.deepEqual(seqs(feed, 'emulator'), [1, 2, 3, 1, 2, 3, 4, 5, 6]);
  assert.equal(feed.state.status.emulator, 'following (seq 6)');
  // the same device again behind a new link, its log gone on: nothing read twice
  a.currentLink = {};
  a.add(2, T0 + 1e9);
  await feed.poll();
  assert.deepEqual(seqs(feed, 'emulator'), [1, 2, 3, 1, 2, 3, 4, 5, 6, 7, 8]);
});

test('paused, new events wait aside and follow adds them; clear forgets without reading again', async () => {
  const { a, feed } = await polledOnce('emulator', 2);
  feed.setFollowing(false);
  a.add(3);
  await feed.poll();
  assert.equal(feed.rows.length, 2);
  assert.equal(feed.state.pending, 3);
  feed.setFollowing(true);
  assert.deepEqual(seqs(feed, 'emulator'), [1, 2, 3, 4, 5]);
  assert.equal(feed.state.pending, 0);
  feed.clear();
  a.add(1);
  await feed.poll();
  assert.deepEqual(seqs(feed, 'emulator'), [6]);
});

test('the oldest rows go beyond the limit, and a failing source is said without stopping the other', async () => {
  const a = fakeSource('emulator');
  const b = fakeSource('vss');
  a.connect();
  b.connect();
  a.add(8);
  b.since = async () => {
    throw new Error('not connected to ws://x');
  };
  const feed = new LogFeed([a, b], { maxRows: 5 });
  await feed.poll();
  assert.deepEqual(seqs(feed, 'emulator'), [4, 5, 6, 7, 8]);
  assert.equal(feed.state.status.vss, 'error: not connected to ws://x');
});

test('a malformed event is left out and said, the well-formed ones around it kept', async () => {
  const { a, feed } = await polledOnce('emulator', 1);
  a.add(3);
  a.events[1] = { ...a.events[1], level: 'fatal' };
  a.events[2] = { ...a.events[2], t_us: '12' };
  await feed.poll();
  assert.deepEqual(seqs(feed, 'emulator'), [1, 4]);
  assert.match(feed.state.status.emulator, /^following \(seq 4\); 2 malformed events left out \(last: t_us "12" is not an integer/);
  a.add(1);
  await feed.poll();
  assert.deepEqual(seqs(feed, 'emulator'), [1, 4, 5]);
});
