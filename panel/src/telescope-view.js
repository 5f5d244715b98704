// What the Telescope tab shows, decided without Vue or I/O (tested in panel/test/unit/):
// the style of an operation's phase, which of its ends are errors, whether a tracking error
// means anything now, how a command ended, the program's outcome counts, and the last known
// place of a mount that went away.
//
// Tables, not if-chains: a new phase, command outcome, program outcome or operation figure
// is one row here (docs/panel.md, "Telescope tab: adding to it").

/**
 * Style of each operation phase (docs/vss-api.md, "Operation object"): `live` (green, the
 * operation runs), `warn` (amber: it runs but something went wrong), `done`, `bad` (red),
 * `ended` (neutral: ended as asked). A phase not listed is `unknown` (neutral, never green).
 */
export const PHASE_STYLES = {
  starting: 'live', preparing: 'live', 'pass planned': 'live', slewing: 'live', waiting: 'live',
  joining: 'live', settling: 'live', tracking: 'live', measuring: 'live', ending: 'live',
  interrupted: 'warn', done: 'done', failed: 'bad', aborted: 'ended',
};
export const ENDED_PHASES = new Set(['done', 'failed', 'aborted']);
// phases whose tracking error is the error of following a sky target
const TRACKING_PHASES = new Set(['tracking', 'measuring']);

/** True when the operation's error says a client's stop or a newer command ended it. */
export const endedAsAsked = (op) => op?.info?.error?.code === 'aborted';

/** Return {style, label} of an operation's phase ('—' for none). */
export function phaseView(op) {
  if (!op) return { style: 'none', label: '—' };
  let style = PHASE_STYLES[op.phase] ?? 'unknown';
  let label = op.phase;
  if (op.phase === 'aborted') {
    if (op.info?.error?.stopped) label = 'stopped';
    else if (!endedAsAsked(op)) style = 'warn'; // a lost mount or a shutdown, not a request
  }
  return { style, label };
}

/** Return how the operation ended, in words, or '' while it runs (the Operation card). */
export function endedText(op) {
  if (!op || !ENDED_PHASES.has(op.phase)) return '';
  const err = op.info?.error;
  if (op.phase === 'done') return 'done';
  if (err?.stopped) return err.message; // "stopped by a client": asked for, no error code
  if (err) return `${op.phase}: ${err.code}: ${err.message}`;
  return op.phase;
}

/**
 * Return the Errors card's lines [{text, level}] (level 'error' or 'warning'): latched
 * faults, a failure, an interruption, a lost mount. A stop or a replacement is no error.
 */
export function errorLines(state) {
  const s = state || {};
  const out = [];
  if (s.last_fault) out.push({ level: 'error', text: `last fault: ${typeof s.last_fault === 'string' ? s.last_fault : JSON.stringify(s.last_fault)}` });
  for (const [axis, a] of Object.entries(s.axes || {})) {
    if (a.faults) out.push({ level: 'error', text: `${axis}: ${a.fault_text} (0x${Number(a.faults).toString(16)})` });
  }
  const op = s.operation;
  const err = op?.info?.error;
  if (err && !endedAsAsked(op)) out.push({ level: op.phase === 'failed' ? 'error' : 'warning', text: `operation ${op.id}: ${err.code}: ${err.message}` });
  if (op?.phase === 'interrupted' && op.info?.interrupted) out.push({ level: 'warning', text: `interrupted: ${op.info.interrupted.message}` });
  if (s.connected === false) out.push({ level: 'error', text: 'the VSS has no connection to the mount (it keeps reconnecting)' });
  return out;
}

/**
 * Return why the tracking error is shown or not: {shown, why}. Only while a sky target is
 * being followed (tracking or measuring, not a fixed hold) and the mount is on; otherwise
 * the figures would be of a demand nobody tracks (0.000 with the mount off).
 */
export function trackingView(state) {
  const op = state?.operation;
  if (state?.mount_state === 'off') return { shown: false, why: 'the mount is off' };
  if (!op || !TRACKING_PHASES.has(op.phase)) return { shown: false, why: 'nothing is tracked' };
  if (op.info?.fixed) return { shown: false, why: 'a fixed az/el is held: nothing is tracked' };
  return { shown: true, why: '' };
}

// Error codes that mean the server refused the command before it did anything
// (docs/vss-api.md, "Error codes"); others mean it was tried and failed.
const REFUSALS = new Set(['bad_request', 'unknown_command', 'passive', 'unauthorized', 'forbidden',
  'mount_offline', 'unreachable', 'stale_tle', 'exclusion_zone', 'not_tracking', 'mapping', 'throttled']);

/**
 * Style of each command outcome: `sent` (waiting for the answer), `started` (under way),
 * `done`, `ended` (ended by a stop or a newer command), `refused`, `failed`.
 */
export const OUTCOME_STYLES = { sent: 'live', started: 'live', done: 'done', ended: 'ended', refused: 'bad', failed: 'bad' };

const targetOf = (params) => ['star', 'radec', 'altaz'].map((k) => params?.[k]).find((v) => typeof v === 'string') ?? '';

/** Return the words of a command as sent: "slew Sun", "track Vega for 60 s", "park". */
export function commandText(cmd, params = {}) {
  if (cmd === 'offset') return offsetText(params);
  const target = targetOf(params);
  const duration = params.duration_s ? ` for ${params.duration_s} s` : '';
  return `${cmd}${target ? ` ${target}` : ''}${duration}`;
}

/**
 * Return {outcome, text} of a command from its answer: `result` (the reply's result) or
 * `error` (a VssError with `.code`). An operation still running (park without waiting) has
 * `started`; a finished one `done`.
 */
export function commandOutcome(cmd, { result, error } = {}) {
  if (error) {
    const code = error.code || 'error';
    if (code === 'aborted') return { outcome: 'ended', text: `ended: ${error.message}` };
    if (code === 'closed' || code === 'timeout') return { outcome: 'failed', text: `no answer: ${error.message}` };
    return { outcome: REFUSALS.has(code) ? 'refused' : 'failed', text: `${REFUSALS.has(code) ? 'refused' : 'failed'}: ${code}: ${error.message}` };
  }
  if (result && typeof result === 'object' && typeof result.phase === 'string') {
    const id = result.id != null ? ` (${result.kind ?? 'operation'} #${result.id})` : '';
    if (result.phase === 'done') return { outcome: 'done', text: `done${id}` };
    if (ENDED_PHASES.has(result.phase)) return { outcome: 'failed', text: `${result.phase}${id}` };
    if (['starting', 'preparing'].includes(result.phase)) return { outcome: 'started', text: `started${id}` };
    return { outcome: 'started', text: `${result.phase}${id}` };
  }
  if (result && typeof result === 'object' && result.mount_state) return { outcome: 'done', text: `done (mount ${result.mount_state})` };
  if (result && typeof result === 'object' && typeof result.lead_ms === 'number') {
    return { outcome: 'done', text: `done: acts ${result.lead_ms.toFixed(0)} ms after acceptance (${result.sent})` };
  }
  return { outcome: 'done', text: 'done' };
}

/**
 * Program block outcomes in the order shown, with their style; counts of outcomes not
 * listed are shown after them, neutral (a server newer than the page).
 */
export const PROGRAM_OUTCOMES = [['done', 'done'], ['degraded', 'warn'], ['late', 'warn'], ['missed', 'warn'], ['faulted', 'bad'], ['stopped', 'ended']];

// summary keys that are integers but not outcome counts
const NOT_OUTCOMES = new Set(['blocks']);

/** Return [{name, count, style}] of a program summary's outcome counts (`run_summary`). */
export function programOutcomes(summary) {
  if (!summary || typeof summary !== 'object') return [];
  const known = new Map(PROGRAM_OUTCOMES);
  const extra = Object.keys(summary).filter((k) => !known.has(k) && !NOT_OUTCOMES.has(k)
    && /^[a-z]+$/.test(k) && Number.isInteger(summary[k]));
  return [...known.keys(), ...extra].filter((n) => Number.isInteger(summary[n]))
    .map((name) => ({ name, count: summary[name], style: known.get(name) ?? 'unknown' }));
}

/**
 * Figures of an operation's `info` shown on the Operation card: [label, key, format] with
 * format(value, info) -> text. A key absent from `info` is not shown.
 */
const arcsecText = (v, decimals) => `${Number(v).toFixed(decimals)}″`;
export const OPERATION_INFO_ROWS = [
  ['Slew time', 'slew_time_s', (v) => `${Number(v).toFixed(1)} s`],
  ['Left', 'seconds_left', (v) => `${Number(v).toFixed(0)} s`],
  ['Resumes', 'resumes', (v) => String(v)],
  // a finished track (docs/vss-api.md, "Operation object"): the error on target is the truth;
  // what the server chose to send apart from the target is shown apart
  ['On target RMS', 'tracking_rms_arcsec', (v) => arcsecText(v, 3)],
  ['On target peak', 'tracking_peak_arcsec', (v) => arcsecText(v, 3)],
  ['Off target', 'off_target_s', (v, info) => `${Number(v).toFixed(1)} s beyond ${info.off_target_threshold_arcsec ?? 5}″`],
  ['Planned deviation', 'planned_deviation_peak_arcsec',
    (v, info) => `${arcsecText(v, 1)}${info.planned_deviation?.length ? ` (${info.planned_deviation.join(', ')})` : ''}`],
  ['Following RMS', 'following_rms_arcsec', (v) => arcsecText(v, 3)],
  ['Outcome', 'outcome', (v) => (v === 'degraded' ? 'degraded: off target' : String(v))],
  ['Closed loop', 'closed_loop', (v) => `${v.state ?? '—'}: ${v.accepted ?? 0} frames used, ${v.refused ?? 0} refused, ${v.held ?? 0} held`],
];

/** `offset dec add +5″`, `offset path add +1.5 s`, `offset all reset`: a hand pad's command. */
function offsetText(p) {
  const value = p.seconds != null ? ` ${p.seconds > 0 ? '+' : ''}${p.seconds} s`
    : p.arcsec != null ? ` ${p.arcsec > 0 ? '+' : ''}${p.arcsec}″` : '';
  return `offset ${p.axis} ${p.op ?? 'add'}${value}`;
}

/** Return [{label, text, key}] of the OPERATION_INFO_ROWS present in `op.info`. */
export function operationFigures(op) {
  const info = op?.info || {};
  return OPERATION_INFO_ROWS.filter(([, key]) => info[key] !== undefined && info[key] !== null)
    .map(([label, key, format]) => ({ label, key, text: format(info[key], info) }));
}

/** The parts of a status that say where the mount points. */
export const PLACE_KEYS = ['encoder', 'observed', 'radec', 'mount_time_us', 'mount_time_utc'];

/**
 * Return the place to show: the status's own when it has one (fresh), else the last known
 * one kept in `last` ({place, atMs}), marked `kept`. Returns {place, kept, atMs}.
 */
export function placeToShow(state, last) {
  if (state?.encoder) return { place: state, kept: false, atMs: null };
  if (last?.place) return { place: last.place, kept: true, atMs: last.atMs };
  return { place: {}, kept: false, atMs: null };
}

/** Return what to remember of a status with a place ({place, atMs}), or `last` unchanged. */
export function rememberPlace(state, last, nowMs) {
  if (!state?.encoder) return last;
  return { place: Object.fromEntries(PLACE_KEYS.map((k) => [k, state[k]])), atMs: nowMs };
}
