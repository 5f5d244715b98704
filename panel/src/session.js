// The panel's one connection to an endpoint and what every tab shares.
//
// Two ASTCom connections, as the protocol suggests (§6 "Private and stream channels"):
// `control` carries LIST/READ/WRITE/INVOKE/STATS, `data` carries only the stream, so a
// burst of samples never delays a reply and a slow reply never stalls the plot.
//
// A lost connection is retried until the user disconnects (a wrong password ends the
// retries): the last values stay on screen marked stale, and the stream that ran is
// started again once the endpoint is back.
import { markRaw, reactive } from 'vue';
import { AuthenticationFailed, Client } from './astcom/index.js';
import { compileExpression } from './expressions.js';
import { keepTrying } from './reconnect.js';
import { SeriesStore } from './series.js';

export const session = reactive({
  url: 'ws://127.0.0.1:8765',
  role: 'operator',
  status: 'disconnected', // disconnected | connecting | connected | reconnecting
  stale: false, // values on screen are from before the connection was lost
  hello: null,
  grantedRole: null,
  entries: [],
  log: [],
  stream: { names: [], rateHz: 1000, active: false, samples: 0, lost: 0, packets: 0, actualRateHz: 0 },
  computes: [], // {name, expr, unit, error}
});

export const series = new SeriesStore();
const links = { control: null, data: null, stream: null, compiled: [], password: '', retry: null, streamWanted: null };

/** Debug counters the end-to-end tests and the benchmark read from the page. */
export const probe = { plotUpdates: 0, plotFrames: 0, plotPoints: 0, lastPlotSeries: [] };
if (typeof window !== 'undefined') window.panelProbe = { session, series, probe };

export function logEvent(text, level = 'error') {
  session.log.unshift({ time: new Date().toISOString().slice(11, 23), level, text });
  if (session.log.length > 100) session.log.length = 100;
}

function connectOne(url, password, role, clientName) {
  return Client.connect(url, { password, role, clientName });
}

async function openLinks(url, password) {
  const control = await connectOne(url, password, session.role, 'panel');
  let data;
  try {
    data = await connectOne(url, password, 'observer', 'panel-stream');
  } catch (err) {
    await control.close();
    throw err;
  }
  links.control = markRaw(control);
  links.data = markRaw(data);
  control.onClose((err) => lost(control, err));
  data.onClose((err) => lost(data, err));
  session.hello = { server: control.hello.server, loopRateHz: control.hello.loop_rate_hz, limits: control.hello.limits };
  session.grantedRole = control.role;
  session.entries = await control.list();
  session.status = 'connected';
  session.stale = false;
}

/** Open both channels and list the endpoint; errors land in the log and are rethrown. */
export async function connect(url, password) {
  await disconnect();
  session.url = url;
  links.password = password;
  session.status = 'connecting';
  try {
    await openLinks(url, password);
    logEvent(`connected to ${session.hello.server} at ${url} as ${session.grantedRole}`, 'info');
  } catch (err) {
    await disconnect();
    logEvent(`connect ${url}: ${err.message}`);
    throw err;
  }
}

async function closeLinks() {
  const { control, data } = links;
  links.control = null;
  links.data = null;
  links.stream = null;
  session.stream.active = false;
  await Promise.all([control?.close(), data?.close()]);
}

function lost(which, err) {
  if (session.status !== 'connected' || (which !== links.control && which !== links.data)) return;
  logEvent(`connection lost: ${err.message}; reconnecting`);
  const wanted = session.stream.names.length && links.stream ? { names: [...session.stream.names], rateHz: session.stream.rateHz } : links.streamWanted;
  links.streamWanted = wanted;
  session.status = 'reconnecting';
  session.stale = true;
  closeLinks();
  links.retry = keepTrying(() => reopen(), { giveUp: (e) => e instanceof AuthenticationFailed });
  links.retry.done.then((ok) => {
    if (ok) return;
    if (session.status === 'reconnecting') {
      session.status = 'disconnected';
      logEvent('reconnection given up: the password is no longer accepted');
    }
  });
}

async function reopen() {
  try {
    await openLinks(session.url, links.password);
  } catch (err) {
    await closeLinks();
    session.status = 'reconnecting';
    throw err;
  }
  logEvent(`reconnected to ${session.hello.server} at ${session.url}`, 'info');
  const wanted = links.streamWanted;
  links.streamWanted = null;
  if (wanted) {
    try {
      await startStream(wanted.names, wanted.rateHz);
    } catch {
      // logged by startStream
    }
  }
}

/**
 * The VirtualStar Server says its mount answers ASTCom at `to` (status `mount_endpoint`),
 * where it said `from` before. When this page's link is the one to `from` (connected or
 * retrying), it moves to `to` with the same password and role: a restarted `vs server
 * --emulator` whose endpoint came back elsewhere is found again. A link to another
 * endpoint is left alone. Returns true when the link moved.
 */
export function mountEndpointMoved(from, to) {
  if (!to || !from || to === from || session.url !== from) return false;
  if (session.status !== 'connected' && session.status !== 'reconnecting') return false;
  logEvent(`the VSS says the mount's ASTCom endpoint moved from ${from} to ${to}: following it`, 'info');
  session.url = to;
  if (session.status === 'connected') {
    // the old endpoint still answers: leave it as a lost link would, and retry at the new one
    const control = links.control;
    if (control) lost(control, new Error(`the mount's endpoint moved to ${to}`));
  } else if (links.retry) {
    links.retry.now?.(); // the next attempt goes to session.url at once
  }
  return true;
}

export async function disconnect() {
  links.retry?.cancel();
  links.retry = null;
  links.streamWanted = null;
  session.status = 'disconnected';
  session.stale = false;
  await closeLinks();
}

/**
 * Why this page may not write or call on the endpoint now ('' when it may): the reason a
 * WRITE/INVOKE button is disabled, shown beside it (ASTCom: only operators write and call).
 */
export function writeBlocked() {
  if (session.status !== 'connected') return 'connect on the Board tab first';
  if (session.grantedRole !== 'operator') return `operator only (this connection is ${session.grantedRole})`;
  return '';
}

export function requireControl() {
  if (!links.control) throw new Error('not connected: connect on the Board tab first');
  return links.control;
}

/** Run a request on the control channel, logging its error before rethrowing. */
export async function guarded(what, fn) {
  try {
    return await fn(requireControl());
  } catch (err) {
    logEvent(`${what}: ${err.message}`);
    throw err;
  }
}

export const read = (names) => guarded(`read ${names.length > 3 ? `${names.length} values` : names.join(', ')}`, (c) => c.read(names));
export async function write(values) {
  const what = Object.entries(values).map(([k, v]) => `${k} = ${typeof v === 'number' ? v : JSON.stringify(v)}`).join(', ');
  const result = await guarded(`write ${Object.keys(values).join(', ')}`, (c) => c.write(values));
  logEvent(`wrote ${what}`, 'info');
  return result;
}
export const invoke = (name, args = []) => guarded(`call ${name}`, (c) => c.invoke(name, args, 60_000));
export const stats = () => guarded('stats', (c) => c.stats());
export const ping = () => guarded('ping', (c) => c.ping());

// ------------------------------------------------------------------ streaming
function recompile() {
  const names = session.stream.names;
  links.compiled = [];
  for (const c of session.computes) {
    try {
      const expr = compileExpression(c.expr, names);
      c.error = '';
      series.ensure(c.name);
      links.compiled.push({ name: c.name, expr });
    } catch (err) {
      c.error = err.message;
      series.drop(c.name);
    }
  }
}

/** Replace the compute list (from the Compute tab or a loaded file). */
export function setComputes(list) {
  for (const c of session.computes) series.drop(c.name);
  session.computes = list.map((c) => ({ name: c.name, expr: c.expr, unit: c.unit || '', error: '' }));
  recompile();
}

function onPacket(packet, stream) {
  const columns = {};
  stream.columns.forEach((name, j) => {
    columns[name] = packet.columns[j];
  });
  if (links.compiled.length) {
    const row = {};
    for (const { name } of links.compiled) columns[name] = new Float64Array(packet.n);
    for (let i = 0; i < packet.n; i++) {
      for (const name of stream.columns) row[name] = columns[name][i];
      for (const { name, expr } of links.compiled) {
        try {
          columns[name][i] = expr.evaluate(row);
        } catch {
          columns[name][i] = Number.NaN;
        }
      }
    }
  }
  series.append(packet.tUs, columns);
  const s = session.stream;
  s.samples = stream.samples;
  s.lost = stream.lost;
  s.packets = stream.packets;
}

/** Stream `names` at `rateHz` on the data channel; replaces any running stream. */
export async function startStream(names, rateHz) {
  if (!links.data) throw new Error('not connected: connect on the Board tab first');
  await stopStream();
  try {
    const stream = await links.data.stream(names, rateHz);
    links.stream = markRaw(stream);
    Object.assign(session.stream, {
      names: [...stream.columns], rateHz, active: true, samples: 0, lost: 0, packets: 0,
      actualRateHz: stream.rateHz,
    });
    series.reset(stream.columns, stream.rateHz);
    recompile();
    stream.onPacket(onPacket);
    stream.onEnd(() => {
      session.stream.active = false;
    });
  } catch (err) {
    logEvent(`stream ${names.join(', ')}: ${err.message}`);
    throw err;
  }
}

export async function stopStream() {
  const stream = links.stream;
  links.stream = null;
  session.stream.active = false;
  if (stream) {
    try {
      await stream.stop();
    } catch (err) {
      logEvent(`stop stream: ${err.message}`);
    }
  }
}

// ------------------------------------------------------------------ LIST helpers
export const signals = () => session.entries.filter((e) => e.kind === 'signal');
export const parameters = () => session.entries.filter((e) => e.kind === 'parameter');
export const functions = () => session.entries.filter((e) => e.kind === 'function');

/**
 * Return the name of a function without arguments called one of `words` (a name or its last
 * dotted part, in that order of preference), the one whose doc matches `docHint` first; ''.
 */
export function findFunction(words, docHint = null) {
  const fns = functions().filter((e) => e.type.startsWith('()'));
  for (const w of words) {
    const hits = fns.filter((e) => e.name === w || e.name.endsWith(`.${w}`));
    const hinted = docHint ? hits.find((e) => docHint.test(e.doc)) : null;
    if (hinted || hits.length) return (hinted || hits[0]).name;
  }
  return '';
}

/** Return the unit of a streamed signal (from LIST) or of a compute (as typed); '' if none. */
export function unitOf(name) {
  const c = session.computes.find((x) => x.name === name);
  if (c) return c.unit || '';
  return session.entries.find((e) => e.name === name)?.unit || '';
}

/** The mount's stop function (the header's STOP calls it): `*.stop`, else `*.halt`. */
export const stopFunction = () => findFunction(['stop', 'halt']);
