// The Log tab's two sources (docs/panel.md, "Log"): the mount endpoint's event log through
// ASTCom (`log.since(seq)`, a JSON list; `log.last_seq`) on the Board's connection, and the
// VirtualStar Server's (`log`) on the Telescope tab's, polled every POLL_MS by a LogFeed.
import { parseEventsJson } from './eventlog.js';
import { LogFeed } from './logfeed.js';
import { requireControl, session } from './session.js';
import { vssLink, vssQuiet } from './telescope.js';

export const POLL_MS = 500; // as `vs log --follow`
const SINCE_FN = 'log.since';
const LAST_SEQ = 'log.last_seq';
const listed = (name) => session.entries.some((e) => e.name === name);

const astcom = {
  name: 'astcom',
  page: Infinity, // log.since answers every event after seq at once
  get offline() {
    return session.status !== 'connected' ? 'ASTCom not connected' : `the endpoint has no ${SINCE_FN} function`;
  },
  link: () => (session.status === 'connected' && listed(SINCE_FN) ? requireControl() : null),
  lastSeq: async (c) => (listed(LAST_SEQ) ? Number((await c.read([LAST_SEQ])).values[LAST_SEQ]) : null),
  since: async (c, seq) => parseEventsJson(await c.invoke(SINCE_FN, [seq])),
};

const VSS_PAGE = 1000;
const vss = {
  name: 'vss',
  page: VSS_PAGE,
  offline: 'VSS not connected',
  link: vssLink,
  lastSeq: async () => Number((await vssQuiet('log', { since: 0, limit: 1 })).last_seq),
  since: async (_, seq) => (await vssQuiet('log', { since: seq, limit: VSS_PAGE })).events,
};

export const logFeed = new LogFeed([astcom, vss]);
export const eventLog = logFeed.state;
let timer = null;
if (typeof window !== 'undefined') window.panelEventLog = { eventLog, rows: () => logFeed.rows };

/** Start polling both logs every POLL_MS (once; it goes on while the page lives). */
export function startLogs() {
  if (timer) return;
  timer = setInterval(() => logFeed.poll(), POLL_MS);
  logFeed.poll();
}
