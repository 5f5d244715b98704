// The header's STOP: the mount stopped through ASTCom and the VSS's operation (and any
// program) ended, both sent at once so that neither waits for the other. The VSS's `stop`
// is final (nothing moves until the next command); the ASTCom stop reaches the drives even
// when the VSS is gone, or when something outside the VSS moves the mount.
//
// The outcome is shown in a message over the page (components/StopOutcome.vue), never in
// the header: the button keeps its place and size whatever the answers say.
import { reactive } from 'vue';
import { invoke, logEvent, session, stopFunction } from './session.js';
import { telescope, vssCommand } from './telescope.js';

export const STOP_OUTCOME_FADE_MS = 8000; // a stop that worked fades; a failure stays until dismissed

export const lastStop = reactive({
  presses: 0, // counts presses: a new press shows the message again
  time: null, // UTC HH:MM:SS of the press
  pending: false, // answers still awaited
  mount: '',
  vss: '',
  failed: false, // one of the two failed
  shown: false, // the message is on screen (dismissed or faded: false)
});

if (typeof window !== 'undefined') window.panelStop = lastStop;

/** Stop everything connected; return {mount, vss} outcomes as text. */
export async function stopEverything() {
  const press = lastStop.presses + 1; // every press sends again; the newest one's answers are shown
  Object.assign(lastStop, {
    presses: press, time: new Date().toISOString().slice(11, 19), pending: true,
    mount: 'sent', vss: 'sent', failed: false, shown: true,
  });
  const fn = session.status === 'connected' ? stopFunction() : '';
  const mount = fn
    ? invoke(fn, []).then(() => `${fn}() done`)
    : Promise.resolve(session.status === 'connected' ? 'no stop function in LIST' : 'ASTCom not connected');
  const vss = telescope.status === 'connected'
    ? vssCommand('stop').then((r) => `stop done (mount ${r?.mount_state ?? '?'})`)
    : Promise.resolve('VSS not connected');
  const [m, v] = await Promise.allSettled([mount, vss]);
  const mountText = m.status === 'fulfilled' ? m.value : `failed: ${m.reason.message}`;
  const vssText = v.status === 'fulfilled' ? v.value : `failed: ${v.reason.message}`;
  const failed = m.status === 'rejected' || v.status === 'rejected';
  logEvent(`STOP: mount: ${mountText}; VSS: ${vssText}`, failed ? 'error' : 'info');
  if (press === lastStop.presses) Object.assign(lastStop, { mount: mountText, vss: vssText, failed, pending: false });
  return { mount: mountText, vss: vssText };
}

/** Take the message off the screen (its × button, or the fade). */
export function dismissStopOutcome() {
  lastStop.shown = false;
}
