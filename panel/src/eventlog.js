// The structured event log (docs/events.md) in the browser: the filters of `vs log`
// (virtualstar/eventlog.py EventFilter, virtualstar/recorder/timeparse.py) with the same
// semantics, merging two sources' events by time, and JSON-lines export. Pure: no I/O.
//
// The text filter searches `message + " " + "k=v k=v"` where v is written as Python's
// str() writes it (True, None, 0.2, 1e-05, {'a': 1}), so `--grep` and this filter agree
// on the same event. JSON alone loses whether `0.0` was a float; `parseEventsJson` and
// `markFloats` (a JSON.parse reviver) remember it where the engine gives the number's
// source text (Chromium 114+, Node 21+, Node 20 with --harmony-json-parse-with-source).

export const LEVELS = ['debug', 'info', 'warning', 'error'];

/** Return the rank of `level` (debug 0 … error 3); throws naming the valid ones. */
export function levelRank(level) {
  const rank = LEVELS.indexOf(level);
  if (rank < 0) throw new RangeError(`level ${JSON.stringify(level)}: expected one of ${LEVELS.join(', ')}`);
  return rank;
}

// ------------------------------------------------------------------ Python's str() of JSON values
const floatKeys = new WeakMap(); // holder object -> Set of keys whose number was written as a float

/** JSON.parse reviver: remember the numbers written with a point or exponent (1.0, 2e3). */
export function markFloats(key, value, context) {
  if (typeof value === 'number' && Number.isInteger(value) && /[.eE]/.test(context?.source ?? '')) {
    let keys = floatKeys.get(this);
    if (!keys) floatKeys.set(this, (keys = new Set()));
    keys.add(key);
  }
  return value;
}

/** Python's repr() of a float. */
function floatRepr(x) {
  if (Number.isNaN(x)) return 'nan';
  if (!Number.isFinite(x)) return x > 0 ? 'inf' : '-inf';
  if (x === 0) return Object.is(x, -0) ? '-0.0' : '0.0';
  const [mantissa, expText] = x.toExponential().split('e'); // shortest round-trip digits
  const exp = Number(expText);
  const sign = mantissa.startsWith('-') ? '-' : '';
  const digits = mantissa.replace(/^-/, '').replace('.', '');
  if (exp < -4 || exp >= 16) {
    const m = digits.length > 1 ? `${digits[0]}.${digits.slice(1)}` : digits;
    return `${sign}${m}e${exp < 0 ? '-' : '+'}${String(Math.abs(exp)).padStart(2, '0')}`;
  }
  if (exp < 0) return `${sign}0.${'0'.repeat(-exp - 1)}${digits}`;
  const whole = digits.slice(0, exp + 1).padEnd(exp + 1, '0');
  return `${sign}${whole}.${digits.slice(exp + 1) || '0'}`;
}

const ESCAPES = { '\\': '\\\\', '\n': '\\n', '\r': '\\r', '\t': '\\t' };

/** Python's repr() of a str (quotes chosen as Python does). */
function strRepr(s) {
  const quote = s.includes("'") && !s.includes('"') ? '"' : "'";
  let out = '';
  for (const ch of s) {
    const code = ch.codePointAt(0);
    if (ESCAPES[ch]) out += ESCAPES[ch];
    else if (ch === quote) out += `\\${ch}`;
    else if (code < 0x20 || (code >= 0x7f && code < 0xa0)) out += `\\x${code.toString(16).padStart(2, '0')}`;
    else out += ch;
  }
  return quote + out + quote;
}

function numberText(x, holder, key) {
  return Number.isInteger(x) && !floatKeys.get(holder)?.has(key) ? String(x) : floatRepr(x);
}

function pyRepr(value, holder, key) {
  if (typeof value === 'string') return strRepr(value);
  return pyText(value, holder, key);
}

/** Return Python's str() of the JSON value `holder[key]`. */
export function pyText(value, holder = null, key = null) {
  if (value === null || value === undefined) return 'None';
  if (value === true) return 'True';
  if (value === false) return 'False';
  if (typeof value === 'number') return numberText(value, holder, key);
  if (typeof value === 'bigint') return value.toString();
  if (typeof value === 'string') return value;
  if (Array.isArray(value)) return `[${value.map((v, i) => pyRepr(v, value, String(i))).join(', ')}]`;
  return `{${Object.entries(value).map(([k, v]) => `${strRepr(k)}: ${pyRepr(v, value, k)}`).join(', ')}}`;
}

/** Parse a JSON list of events (the emulator's `log.since`), remembering float fields. */
export function parseEventsJson(text) {
  const doc = JSON.parse(text, markFloats);
  if (!Array.isArray(doc)) throw new TypeError('an event log must be a JSON list of events');
  return doc;
}

// ------------------------------------------------------------------ the filter
/**
 * Return a filter like `EventFilter`: `fromTUs`/`toTUs` (mount µs, `to` excluded, null for
 * none), `minLevel`, `sources`/`kinds` (empty keeps every one), `text` (case-insensitive,
 * in the message and the fields). Throws on an unknown level.
 */
export function eventFilter({ fromTUs = null, toTUs = null, minLevel = 'debug', sources = [], kinds = [], text = '' } = {}) {
  return { fromTUs, toTUs, minRank: levelRank(minLevel), sources: new Set(sources), kinds: new Set(kinds), text: text.toLowerCase() };
}

/** Return the text the `text` filter searches: the message, then `k=v` for every field. */
export function haystack(e) {
  const fields = e.fields || {};
  const parts = Object.entries(fields).map(([k, v]) => `${k}=${pyText(v, fields, k)}`);
  return `${e.message ?? ''} ${parts.join(' ')}`;
}

/**
 * Return what is wrong with `e` as an event, or '' for a well-formed one: integer `t_us`
 * and `seq`, a known `level`, text `source` and `kind` (what the filters and the table need;
 * the devices' logs write these so, docs/events.md).
 */
export function eventProblem(e) {
  if (e === null || typeof e !== 'object' || Array.isArray(e)) return 'not an object';
  if (!Number.isSafeInteger(e.t_us)) return `t_us ${JSON.stringify(e.t_us)} is not an integer (µs)`;
  if (!Number.isSafeInteger(e.seq ?? 0)) return `seq ${JSON.stringify(e.seq)} is not an integer`;
  if (!LEVELS.includes(e.level)) return `level ${JSON.stringify(e.level)}: expected one of ${LEVELS.join(', ')}`;
  for (const key of ['source', 'kind']) if (typeof e[key] !== 'string') return `${key} is missing`;
  return '';
}

const hayCache = new WeakMap(); // event -> its haystack, lowercased (events never change)

/** Return whether event `e` passes filter `f` (from `eventFilter`). */
export function matches(f, e) {
  if (f.fromTUs !== null && e.t_us < f.fromTUs) return false;
  if (f.toTUs !== null && e.t_us >= f.toTUs) return false;
  if (levelRank(e.level) < f.minRank) return false;
  if (f.sources.size && !f.sources.has(e.source)) return false;
  if (f.kinds.size && !f.kinds.has(e.kind)) return false;
  // Python's lower() and JS's toLowerCase() agree on the text such logs hold
  if (!f.text) return true;
  let hay = hayCache.get(e);
  if (hay === undefined) hayCache.set(e, (hay = haystack(e).toLowerCase()));
  return hay.includes(f.text);
}

/** Split comma-separated words as `vs log --kind a,b` does. */
export const splitWords = (text) => String(text).split(',').map((w) => w.trim()).filter(Boolean);

// ------------------------------------------------------------------ time bounds
const FORMS = "expected 'start', 'end', +SECONDS (after the first event), -SECONDS (before the "
  + 'last), an ISO-8601 UTC time such as 2026-03-01T20:00:00Z, or mount time in integer µs';
const ISO = /^(\d{4})-(\d{2})-(\d{2})(?:[T ](\d{2}):(\d{2})(?::(\d{2})(?:\.(\d{1,6}))?)?)?(Z|[+-]\d{2}:?\d{2})?$/i;

/**
 * Return the mount time (µs) that `text` names given the first and last event's `t_us`,
 * as `parse_time_bound` does (`end` is just after the last; +S after the first, -S before
 * the end). Throws RangeError naming the accepted forms.
 */
export function parseTimeBound(text, startUs, endUs, option = 'from') {
  const s = String(text).trim();
  const bad = () => new RangeError(`${option} ${JSON.stringify(String(text))}: ${FORMS}`);
  const low = s.toLowerCase();
  if (low === 'start') return startUs;
  if (low === 'end') return endUs + 1;
  if (s.length > 1 && '+-'.includes(s[0])) {
    const body = s.slice(1).trim();
    const seconds = Number(body);
    if (!/^\+?(\d+\.?\d*|\.\d+)(e[+-]?\d+)?$/i.test(body) || !Number.isFinite(seconds)) throw bad();
    const offset = Math.round(seconds * 1e6);
    return s[0] === '+' ? startUs + offset : endUs + 1 - offset;
  }
  if (/^\d+$/.test(s)) return Number(s);
  const m = ISO.exec(s);
  if (!m) throw bad();
  const [, y, mo, d, h = '0', mi = '0', sec = '0', frac = '', zone = 'Z'] = m;
  const ms = Date.UTC(+y, +mo - 1, +d, +h, +mi, +sec);
  if (Number.isNaN(ms) || +mo < 1 || +mo > 12 || +d < 1 || +d > 31 || +h > 23 || +mi > 59 || +sec > 59) throw bad();
  let offsetMin = 0;
  if (zone.toUpperCase() !== 'Z') {
    const z = /^([+-])(\d{2}):?(\d{2})$/.exec(zone);
    offsetMin = (z[1] === '-' ? -1 : 1) * (Number(z[2]) * 60 + Number(z[3]));
  }
  return (ms / 1000 - offsetMin * 60) * 1_000_000 + Number(frac.padEnd(6, '0') || 0);
}

// ------------------------------------------------------------------ rows: merge, show, export
/** Return mount time `tUs` as ISO-8601 UTC with microseconds (`utc_text`). */
export function utcText(tUs) {
  const seconds = Math.floor(tUs / 1e6);
  const micro = tUs - seconds * 1e6;
  return `${new Date(seconds * 1000).toISOString().slice(0, 19)}.${String(micro).padStart(6, '0')}Z`;
}

/** Order of two events: mount time, then source, then seq (stable for equal times). */
export function byTime(a, b) {
  return a.t_us - b.t_us || (a.source < b.source ? -1 : a.source > b.source ? 1 : 0) || a.seq - b.seq;
}

/**
 * Insert `fresh` events into `rows` (sorted by `byTime`) in place; return how many went in.
 * Events come in order from each source, so each is placed by a search from the end.
 */
export function mergeEvents(rows, fresh) {
  for (const e of fresh) {
    let i = rows.length;
    while (i > 0 && byTime(rows[i - 1], e) > 0) i--;
    rows.splice(i, 0, e);
  }
  return fresh.length;
}

/** The filtered rows as JSON lines (one event per line, as `vs log --follow --json`). */
export function jsonLines(events) {
  return events.map((e) => JSON.stringify({
    seq: e.seq, t_us: e.t_us, utc: e.utc ?? utcText(e.t_us), source: e.source, level: e.level,
    kind: e.kind, message: e.message, fields: e.fields ?? {},
  })).join('\n') + (events.length ? '\n' : '');
}

// ------------------------------------------------------------------ routine events
/**
 * Events that come every few seconds whatever happens, hidden on the Log tab unless asked
 * for: [kind, field, value] (field null: every event of that kind). The mount's clock syncs
 * (`clock_sync`) and the VSS's `time.set_utc` calls that arm them were about 80 % of a
 * night's rows.
 */
export const ROUTINE_EVENTS = [['clock_sync', null, null], ['command', 'command', 'time.set_utc']];

/** True when `e` is a routine event (ROUTINE_EVENTS). */
export function isRoutine(e) {
  return ROUTINE_EVENTS.some(([kind, field, value]) => e.kind === kind && (field === null || e.fields?.[field] === value));
}
