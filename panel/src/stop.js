// The header's STOP: the mount stopped through ASTCom and the VSS's operation (and any
// program) ended, both sent at once so that neither waits for the other. The VSS's `stop`
// is final (nothing moves until the next command); the ASTCom stop reaches the drives even
// when the VSS is gone, or when something outside the VSS moves the mount.
import { reactive } from 'vue';
import { invoke, logEvent, session, stopFunction } from './session.js';
import { telescope, vssCommand } from './telescope.js';

export const lastStop = reactive({ time: null, mount: '', vss: '' });

/** Stop everything connected; return {mount, vss} outcomes as text. */
export async function stopEverything() {
  lastStop.time = new Date().toISOString().slice(11, 19);
  const fn = session.status === 'connected' ? stopFunction() : '';
  const mount = fn
    ? invoke(fn, []).then(() => `${fn}() done`)
    : Promise.resolve(session.status === 'connected' ? 'no stop function in LIST' : 'ASTCom not connected');
  const vss = telescope.status === 'connected'
    ? vssCommand('stop').then((r) => `stop done (mount ${r?.mount_state ?? '?'})`)
    : Promise.resolve('VSS not connected');
  const [m, v] = await Promise.allSettled([mount, vss]);
  lastStop.mount = m.status === 'fulfilled' ? m.value : `failed: ${m.reason.message}`;
  lastStop.vss = v.status === 'fulfilled' ? v.value : `failed: ${v.reason.message}`;
  const failed = m.status === 'rejected' || v.status === 'rejected';
  logEvent(`STOP: mount: ${lastStop.mount}; VSS: ${lastStop.vss}`, failed ? 'error' : 'info');
  return { ...lastStop };
}
