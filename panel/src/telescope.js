// The panel's connection to the VirtualStar Server: the telescope seen from the sky side
// (target, operation, observed place, tracking error), beside the ASTCom view of the mount.
//
// The status and the program are polled every second, and at once on an `operation`,
// `fault` or `program` event. A lost connection is retried until the user disconnects;
// meanwhile the last status stays on screen, marked stale. The server says where its mount
// answers ASTCom (`mount_endpoint`); when that moves, the Board's link follows it.
import { markRaw, reactive } from 'vue';
import { keepTrying } from './reconnect.js';
import { logEvent, mountEndpointMoved } from './session.js';
import { commandOutcome, commandText, rememberPlace } from './telescope-view.js';
import { VssClient } from './vss/client.js';

export const DEFAULT_VSS_URL = 'ws://127.0.0.1:8740';
const POLL_MS = 1000;
// a slew answers when it has landed: long slews take minutes of mount time
const MOVE_TIMEOUT_MS = 15 * 60_000;

export const telescope = reactive({
  url: DEFAULT_VSS_URL,
  role: 'operator',
  status: 'disconnected', // disconnected | connecting | connected | reconnecting
  server: null,
  grantedRole: null,
  state: null, // the last status object
  program: null, // the last program run, or null
  updatedMs: null, // wall time of the last status
  stale: false, // the status on screen is from before the connection was lost
  faults: [], // recent fault events {time, text}
  lastPlace: null, // {place, atMs}: where the mount last pointed, kept while it is away
  mountEndpoint: null, // where the server last said its mount answers ASTCom
  lastCommand: null, // the Telescope tab's last command: {atMs (sent, page clock), what, outcome, text}
});

const link = { client: null, password: '', retry: null, timer: null };
if (typeof window !== 'undefined') window.panelTelescope = telescope;

async function refresh() {
  const c = link.client;
  if (!c) return;
  try {
    const [state, program] = await Promise.all([c.request('status'), c.request('program')]);
    if (c !== link.client) return;
    telescope.lastPlace = rememberPlace(state, telescope.lastPlace, Date.now());
    noteMountEndpoint(state.mount_endpoint);
    telescope.state = state;
    telescope.program = program?.state && program.state !== 'none' ? program : null;
    telescope.updatedMs = Date.now();
    telescope.stale = false;
  } catch (err) {
    if (c === link.client && err.code !== 'closed') logEvent(`VSS status: ${err.message}`);
  }
}

/** The server said where its mount answers ASTCom (null: nowhere, or not said). */
function noteMountEndpoint(url) {
  if (typeof url !== 'string' || !url) return;
  const before = telescope.mountEndpoint;
  telescope.mountEndpoint = url;
  if (before && before !== url) mountEndpointMoved(before, url);
}

function onEvent(event, data) {
  if (event === 'fault') {
    const text = Object.entries(data.faults || {}).map(([axis, t]) => `${axis}: ${t}`).join(', ') || JSON.stringify(data);
    telescope.faults.unshift({ time: new Date().toISOString().slice(11, 19), text });
    telescope.faults.length = Math.min(telescope.faults.length, 20);
    logEvent(`VSS fault: ${text}`);
  } else if (event === 'mount_disconnected') {
    logEvent(`VSS: the mount is disconnected (${data.url || ''})`);
  } else if (event === 'mount_connected') {
    logEvent(`VSS: the mount is connected (${data.url || ''})`, 'info');
  } else if (event === 'safety_override') {
    logEvent(`VSS: ${data.kind} ${data.target} started inside a Sun/Moon zone (allow_sun)`, 'info');
  }
  if (['operation', 'fault', 'program', 'mount_connected', 'mount_disconnected', 'mode'].includes(event)) refresh();
}

async function open(url, password, role) {
  const client = await VssClient.connect(url, { password, role });
  link.client = markRaw(client);
  telescope.server = client.hello.server;
  telescope.grantedRole = client.role;
  telescope.status = 'connected';
  client.onEvent(onEvent);
  client.onClose((err) => lost(client, err));
  noteMountEndpoint(client.hello.mount_endpoint); // said in the hello when no password is needed
  await refresh();
}

function lost(client, err) {
  if (client !== link.client) return;
  link.client = null;
  telescope.status = 'reconnecting';
  telescope.stale = true;
  logEvent(`VSS connection lost: ${err.message}; reconnecting`);
  link.retry = keepTrying(() => open(link.url, link.password, link.role), {
    giveUp: (e) => e.code === 'unauthorized',
  });
  link.retry.done.then((ok) => {
    if (ok) logEvent(`VSS reconnected to ${link.url}`, 'info');
    else if (telescope.status === 'reconnecting') {
      telescope.status = 'disconnected';
      logEvent('VSS: reconnection given up (the password is no longer accepted)');
    }
  });
}

/** Connect to the VSS at `url`; errors land in the log and are rethrown. */
export async function connectVss(url, password, role = telescope.role) {
  await disconnectVss();
  Object.assign(link, { url, password, role });
  telescope.url = url;
  telescope.status = 'connecting';
  try {
    await open(url, password, role);
    logEvent(`connected to the VirtualStar Server ${telescope.server} at ${url} as ${telescope.grantedRole}`, 'info');
    link.timer = setInterval(refresh, POLL_MS);
  } catch (err) {
    telescope.status = 'disconnected';
    logEvent(`connect ${url}: ${err.message}`);
    throw err;
  }
}

export async function disconnectVss() {
  link.retry?.cancel();
  link.retry = null;
  clearInterval(link.timer);
  link.timer = null;
  const c = link.client;
  link.client = null;
  telescope.status = 'disconnected';
  c?.close();
}

/**
 * Send a command to the VSS and log what was asked and how it ended; rethrows errors.
 * `show` (the Telescope tab's own commands): also keep the outcome in
 * `telescope.lastCommand`, shown on the tab that sent it.
 */
export async function vssCommand(cmd, params = {}, { show = false } = {}) {
  const c = link.client;
  const what = commandText(cmd, params);
  const sentMs = Date.now();
  const record = (outcome, text) => {
    if (show) telescope.lastCommand = { atMs: sentMs, what, outcome, text };
  };
  if (!c) {
    const err = new Error(`VSS ${what}: not connected to the VirtualStar Server (Telescope tab)`);
    record('refused', 'not sent: not connected to the VirtualStar Server');
    logEvent(err.message);
    throw err;
  }
  logEvent(`VSS ${what} sent`, 'info');
  record('sent', 'sent, waiting for the answer');
  try {
    const result = await c.request(cmd, params, MOVE_TIMEOUT_MS);
    const { outcome, text } = commandOutcome(cmd, { result });
    record(outcome, text);
    logEvent(`VSS ${what}: ${text}`, 'info');
    refresh();
    return result;
  } catch (err) {
    const { outcome, text } = commandOutcome(cmd, { error: err });
    record(outcome, text);
    logEvent(`VSS ${what}: ${text}`, outcome === 'ended' ? 'info' : 'error');
    refresh();
    throw err;
  }
}

export const vssConnected = () => link.client !== null;

/** Send a read-only request (the Log tab's polls) without logging it; rejects when not connected. */
export function vssQuiet(cmd, params = {}) {
  const c = link.client;
  if (!c) return Promise.reject(new Error('VSS not connected'));
  return c.request(cmd, params);
}

/** The VSS connection in use (a new object after a reconnection), or null. */
export const vssLink = () => link.client;
