// The Log tab's live feed: the mount endpoint's event log through ASTCom (`log.since(seq)`,
// a JSON list) and the VirtualStar Server's (`log`, observer role), polled with the last
// `seq` seen from each and merged by mount time (docs/events.md, docs/panel.md).
//
// Rows live outside Vue's reactivity (up to MAX_ROWS); `eventLog.version` tells the tab
// when they changed. Paused, new events wait aside and join the table on Follow, so a
// pause never loses one. A link that comes back to a restarted device (its log numbered
// from 1 again) is read from its start.
import { reactive } from 'vue';
import { mergeEvents, parseEventsJson } from './eventlog.js';
import { requireControl, session } from './session.js';
import { vssLink, vssQuiet } from './telescope.js';

export const POLL_MS = 500; // as `vs log --follow`
export const MAX_ROWS = 20_000; // two sources' logs of 10 000 each
const VSS_PAGE = 1000;
const SINCE_FN = 'log.since';
const LAST_SEQ = 'log.last_seq';

export const eventLog = reactive({
  version: 0,
  following: true,
  pending: 0,
  total: 0,
  astcom: 'not polled yet',
  vss: 'not polled yet',
});

const rows = [];
let waiting = [];
const feeds = {
  astcom: { since: 0, link: null, busy: false },
  vss: { since: 0, link: null, busy: false },
};
let timer = null;
if (typeof window !== 'undefined') window.panelEventLog = { eventLog, rows: () => rows };

/** The events held, oldest first (read it again after `eventLog.version` changes). */
export const heldEvents = () => rows;

function take(events) {
  if (!events.length) return;
  if (!eventLog.following) {
    waiting.push(...events);
    eventLog.pending = waiting.length;
    return;
  }
  mergeEvents(rows, events);
  if (rows.length > MAX_ROWS) rows.splice(0, rows.length - MAX_ROWS);
  eventLog.total = rows.length;
  eventLog.version++;
}

async function pollAstcom(feed) {
  if (session.status !== 'connected') {
    eventLog.astcom = 'ASTCom not connected';
    return;
  }
  if (!session.entries.some((e) => e.name === SINCE_FN)) {
    eventLog.astcom = `the endpoint has no ${SINCE_FN} function`;
    return;
  }
  const c = requireControl();
  if (c !== feed.link) {
    // a new connection: the device may have restarted with its log numbered from 1
    if (session.entries.some((e) => e.name === LAST_SEQ)) {
      const last = Number((await c.read([LAST_SEQ])).values[LAST_SEQ]);
      if (last < feed.since) feed.since = 0;
    }
    feed.link = c;
  }
  const events = parseEventsJson(await c.invoke(SINCE_FN, [feed.since]));
  if (events.length) feed.since = events[events.length - 1].seq;
  take(events);
  eventLog.astcom = `following (seq ${feed.since})`;
}

async function pollVss(feed) {
  const c = vssLink();
  if (!c) {
    eventLog.vss = 'VSS not connected';
    return;
  }
  for (;;) {
    const doc = await vssQuiet('log', { since: feed.since, limit: VSS_PAGE });
    if (c !== feed.link) {
      feed.link = c;
      if (doc.last_seq < feed.since) {
        feed.since = 0; // a restarted server: read its log from the start
        continue;
      }
    }
    if (doc.events.length) feed.since = doc.events[doc.events.length - 1].seq;
    take(doc.events);
    if (doc.events.length < VSS_PAGE) break;
  }
  eventLog.vss = `following (seq ${feed.since})`;
}

async function pollOne(name, fn) {
  const feed = feeds[name];
  if (feed.busy) return; // a slow answer: the next poll asks again from the same seq
  feed.busy = true;
  try {
    await fn(feed);
  } catch (err) {
    eventLog[name] = `error: ${err.message}`;
  } finally {
    feed.busy = false;
  }
}

/** Poll both logs once now. */
export const pollLogs = () => Promise.all([pollOne('astcom', pollAstcom), pollOne('vss', pollVss)]);

/** Start polling both logs every POLL_MS (once; it goes on while the page lives). */
export function startLogs() {
  if (timer) return;
  timer = setInterval(pollLogs, POLL_MS);
  pollLogs();
}

/** Pause (`false`: new events wait aside) or follow (`true`: they join the table). */
export function setFollowing(on) {
  eventLog.following = on;
  if (on && waiting.length) {
    const events = waiting;
    waiting = [];
    eventLog.pending = 0;
    take(events);
  }
}

/** Forget the events held (the next polls go on after the last seq seen). */
export function clearLogs() {
  rows.length = 0;
  waiting = [];
  eventLog.pending = 0;
  eventLog.total = 0;
  eventLog.version++;
}
