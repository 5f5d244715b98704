// The Telescope tab's hand pad: which VSS `offset` a button or an arrow key sends
// (docs/vss.md, "Offsets"). Pure: no Vue, no connection (test/unit/handpad.test.js).
//
// Three frames: on the sky (N/S/E/W move `dec` and `ra`, arcsec on the sky), along the
// mount's axes (up/down/left/right move `el` and `az`, arcsec of the axes), and along a
// satellite's pass (ahead/behind move `path` in seconds of time, left/right move
// `transverse` in arcsec across the track, + to the left of travel). Each press is an
// `add` of one step; the VSS applies it 20 ms after it arrives, within its limits.

export const FRAMES = {
  sky: { label: 'sky N/S/E/W', up: ['dec', +1, 'N'], down: ['dec', -1, 'S'], left: ['ra', +1, 'E'], right: ['ra', -1, 'W'] },
  axes: { label: 'axes az/el', up: ['el', +1, 'up'], down: ['el', -1, 'down'], left: ['az', -1, 'az−'], right: ['az', +1, 'az+'] },
  pass: { label: 'pass along/across', up: ['path', +1, 'ahead'], down: ['path', -1, 'behind'], left: ['transverse', +1, 'left'], right: ['transverse', -1, 'right'] },
};
export const ARCSEC_STEPS = [0.5, 1, 2, 5, 10, 30, 60, 300];
export const SECONDS_STEPS = [0.05, 0.1, 0.25, 0.5, 1, 2];
const KEYS = { ArrowUp: 'up', ArrowDown: 'down', ArrowLeft: 'left', ArrowRight: 'right' };
const MAX_ARCSEC = 3600; // the VSS's offset range (docs/vss-api.md, `offset`)
const MAX_SECONDS = 30;

/** The direction of an arrow key ('up', 'down', 'left', 'right'), or null. */
export function keyDirection(key) {
  return KEYS[key] ?? null;
}

/** The label of a frame's button in a direction (N, S, E, W, ahead, ...). */
export function buttonLabel(frame, direction) {
  return FRAMES[frame]?.[direction]?.[2] ?? '';
}

/**
 * The `offset` parameters of one press: {axis, op: 'add', arcsec | seconds}.
 * Throws with a message a user can act on when the frame, direction or step is wrong.
 */
export function offsetFor(frame, direction, stepArcsec, stepSeconds) {
  const f = FRAMES[frame];
  if (!f) throw new Error(`hand pad: unknown frame ${frame}`);
  const entry = f[direction];
  if (!entry) throw new Error(`hand pad: unknown direction ${direction}`);
  const [axis, sign] = entry;
  if (axis === 'path') {
    const s = Number(stepSeconds);
    if (!(s > 0 && s <= MAX_SECONDS)) throw new Error(`hand pad: the path step must be > 0 and at most ${MAX_SECONDS} s`);
    return { axis, op: 'add', seconds: sign * s };
  }
  const a = Number(stepArcsec);
  if (!(a > 0 && a <= MAX_ARCSEC)) throw new Error(`hand pad: the step must be > 0 and at most ${MAX_ARCSEC}″`);
  return { axis, op: 'add', arcsec: sign * a };
}

/** Rows for the offsets table from a VSS status: [{axis, total, rate, unit, moving}]. */
export function offsetRows(status) {
  const axes = status?.corrections?.offsets?.axes || {};
  return Object.entries(axes).map(([axis, a]) => {
    const seconds = 'total_s' in a;
    return { axis, unit: seconds ? 's' : '″', total: seconds ? a.total_s : a.total_arcsec,
             rate: seconds ? a.rate_s_per_s : a.rate_arcsec_per_s, moving: Boolean(a.moving) };
  });
}
