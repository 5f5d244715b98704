// The Log tab's filters (src/eventlog.js) against the Python ones `vs log` uses
// (virtualstar.eventlog.EventFilter, virtualstar.recorder.timeparse.parse_time_bound):
// the same events and filters go to both, run here in the project's Python.
import assert from 'node:assert/strict';
import { spawnSync } from 'node:child_process';
import { existsSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { test } from 'node:test';
import { fileURLToPath } from 'node:url';
import {
  eventFilter, haystack, jsonLines, levelRank, matches, mergeEvents, parseEventsJson, parseTimeBound, splitWords, utcText,
} from '../../src/eventlog.js';

const ROOT = join(dirname(fileURLToPath(import.meta.url)), '..', '..', '..');
const PYTHON = process.env.VS_PYTHON || join(ROOT, '.venv', 'bin', 'python');
const T0 = 1772395200000000; // 2026-03-01T20:00:00Z

/** Run `code` in the project's Python with `input` as JSON on stdin; return its JSON output. */
function python(code, input) {
  if (!existsSync(PYTHON)) throw new Error(`${PYTHON} is missing: run make (or set VS_PYTHON)`);
  const run = spawnSync(PYTHON, ['-c', code], { input: JSON.stringify(input), cwd: ROOT, encoding: 'utf8' });
  if (run.status !== 0) throw new Error(`python failed: ${run.stderr}`);
  return JSON.parse(run.stdout);
}

// The events as one JSON text, as `log.since` returns them: both sides parse these bytes.
const EVENTS_JSON = `[
 {"seq": 1, "t_us": ${T0}, "source": "emulator", "level": "info", "kind": "connection", "message": "client panel connected", "fields": {"what": "connected", "client": "panel", "role": "operator", "client_id": 3}},
 {"seq": 2, "t_us": ${T0 + 220020}, "source": "emulator", "level": "warning", "kind": "param", "message": "axis.az.inject_winding_fault: 0 \\u2192 0.2", "fields": {"name": "axis.az.inject_winding_fault", "old": 0.0, "new": 0.2, "client": "panel", "role": "operator"}},
 {"seq": 1, "t_us": ${T0 + 500000}, "source": "vss", "level": "info", "kind": "command", "message": "slew from 127.0.0.1:5000 (operator)", "fields": {"command": "slew", "client": "127.0.0.1:5000", "role": "operator", "params": "{\\"altaz\\": \\"120 45\\"}"}},
 {"seq": 2, "t_us": ${T0 + 600000}, "source": "vss", "level": "info", "kind": "phase", "message": "slew 7: slewing", "fields": {"id": 7, "phase": "slewing", "operation_kind": "slew", "target": {"az_deg": 120.0, "el_deg": 45.5, "name": null}}},
 {"seq": 3, "t_us": ${T0 + 600000}, "source": "emulator", "level": "error", "kind": "fault", "message": "az axis faulted: Following Error", "fields": {"axis": "az", "bits": 8, "latched": true, "list": [1, 2.5, "it's"]}},
 {"seq": 4, "t_us": ${T0 + 2000000}, "source": "emulator", "level": "debug", "kind": "clock_sync", "message": "PPS", "fields": {"utc_second": 1772395202, "pps_error_us": -0.0, "tiny": 1e-05, "huge": 1e16, "mid": 123456789012.5, "ok": false}},
 {"seq": 3, "t_us": ${T0 + 3000000}, "source": "recorder", "level": "warning", "kind": "gap", "message": "lost 12 samples", "fields": {"after_t_us": ${T0 + 2900000}, "before_t_us": ${T0 + 2950000}, "lost_samples": 12, "reason": "stream\\tdropped"}},
 {"seq": 5, "t_us": ${T0 + 4000000}, "source": "emulator", "level": "info", "kind": "state", "message": "state HOLDING -> SLEWING", "fields": {}}
]`;

const FILTERS = [
  {},
  { fromTUs: T0 + 500000 },
  { toTUs: T0 + 600000 },
  { fromTUs: T0 + 600000, toTUs: T0 + 3000001 },
  { minLevel: 'info' }, { minLevel: 'warning' }, { minLevel: 'error' },
  { sources: ['emulator'] }, { sources: ['vss', 'recorder'] },
  { kinds: ['fault', 'fault_reset'] }, { kinds: ['command', 'phase'], sources: ['vss'] },
  { text: 'SLEW' }, { text: 'old=0.0' }, { text: 'old=0 ' }, { text: 'new=0.2' }, { text: 'latched=true' },
  { text: "'it's'" }, { text: '"it\'s"' }, { text: "[1, 2.5, " }, { text: "'name': none" }, { text: 'el_deg' },
  { text: 'pps_error_us=-0.0' }, { text: 'tiny=1e-05' }, { text: 'huge=1e+16' }, { text: 'mid=123456789012.5' },
  { text: 'ok=false' }, { text: 'client_id=3' }, { text: 'stream\\tdropped' }, { text: '→ 0.2' },
  { text: '{"altaz"' }, { text: 'hold' }, { text: 'nothing of this' },
  { minLevel: 'warning', sources: ['emulator'], text: 'inject' },
];

const PY_FILTER = `
import json, sys
from astcom_client.events import Event
from virtualstar.eventlog import EventFilter
doc = json.load(sys.stdin)
events = [Event.from_dict(d) for d in json.loads(doc["events"])]
out = []
for f in doc["filters"]:
    flt = EventFilter(f.get("fromTUs"), f.get("toTUs"), f.get("minLevel", "debug"),
                      tuple(f.get("sources", ())), tuple(f.get("kinds", ())), f.get("text", ""))
    out.append([i for i, e in enumerate(events) if flt.matches(e)])
print(json.dumps(out))
`;

test('the JSON parser keeps a float written as 0.0 apart from an integer (source text of numbers)', () => {
  const [e] = parseEventsJson('[{"fields": {"a": 0.0, "b": 0, "c": [1.0, 1]}}]');
  assert.equal(haystack({ message: 'm', fields: e.fields }), "m a=0.0 b=0 c=[1.0, 1]",
    'run node with --harmony-json-parse-with-source (Node 20) so JSON.parse gives numbers\' source text');
});

test('event filters keep the same events as vs log (EventFilter) for every case', () => {
  const events = parseEventsJson(EVENTS_JSON);
  const want = python(PY_FILTER, { events: EVENTS_JSON, filters: FILTERS });
  FILTERS.forEach((f, n) => {
    const flt = eventFilter(f);
    const got = events.flatMap((e, i) => (matches(flt, e) ? [i] : []));
    assert.deepEqual(got, want[n], `filter ${JSON.stringify(f)}`);
  });
  // the cases are not trivial: most keep some and drop some, a few keep none
  const sizes = want.map((w) => w.length);
  assert.equal(sizes[0], events.length);
  assert.ok(sizes.filter((k) => k > 0 && k < events.length).length >= 25, String(sizes));
  assert.ok(sizes.filter((k) => k === 0).length >= 3, String(sizes));
});

test('the text filter searches the fields as Python writes them (haystack equal for every event)', () => {
  const events = parseEventsJson(EVENTS_JSON);
  const want = python(`
import json, sys
from astcom_client.events import Event
doc = json.load(sys.stdin)
print(json.dumps([e.message + " " + " ".join(f"{k}={v}" for k, v in e.fields.items())
                  for e in (Event.from_dict(d) for d in json.loads(doc))]))
`, EVENTS_JSON);
  assert.deepEqual(events.map(haystack), want);
});

test('an unknown level is refused naming the valid ones', () => {
  assert.throws(() => eventFilter({ minLevel: 'fatal' }), /expected one of debug, info, warning, error/);
  assert.throws(() => levelRank('Warning'), /expected one of/);
  assert.equal(levelRank('error'), 3);
});

const BOUNDS = ['start', 'end', '+0', '+1.5', '-2', '-0.25', '+1e-3', String(T0 + 7), '2026-03-01T20:00:01Z',
  '2026-03-01T20:00:01.5Z', '2026-03-01T20:00:01.123456Z', '2026-03-01 21:00:02+01:00', '2026-03-01T20:00:03',
  '2026-03-01', '2026-03-01T19:30:00-00:30', 'yesterday', '+', '-x', '+-1', '2026-13-01T00:00:00Z', '12:00'];

test('time bounds name the same mount µs as parse_time_bound, and the same ones are refused', () => {
  const [first, last] = [T0, T0 + 4_000_000];
  const want = python(`
import json, sys
from virtualstar.recorder.exceptions import QueryError
from virtualstar.recorder.timeparse import parse_time_bound
doc = json.load(sys.stdin)
out = []
for text in doc["texts"]:
    try:
        out.append(parse_time_bound(text, doc["first"], doc["last"]))
    except QueryError:
        out.append(None)
print(json.dumps(out))
`, { texts: BOUNDS, first, last });
  BOUNDS.forEach((text, i) => {
    if (want[i] === null) assert.throws(() => parseTimeBound(text, first, last), /expected 'start', 'end'/, text);
    else assert.equal(parseTimeBound(text, first, last), want[i], text);
  });
  assert.ok(want.filter((w) => w === null).length >= 4);
});

test('events of two sources merge in mount-time order whatever order the polls bring them', () => {
  const events = parseEventsJson(EVENTS_JSON);
  const emu = events.filter((e) => e.source === 'emulator');
  const other = events.filter((e) => e.source !== 'emulator');
  const rows = [];
  mergeEvents(rows, other.slice(0, 2));
  mergeEvents(rows, emu.slice(0, 3));
  mergeEvents(rows, other.slice(2));
  mergeEvents(rows, emu.slice(3));
  const times = rows.map((e) => e.t_us);
  assert.deepEqual(times, [...times].sort((a, b) => a - b));
  assert.equal(rows.length, events.length);
  // equal times: by source, so the order does not depend on which poll came first
  const tied = rows.filter((e) => e.t_us === T0 + 600000).map((e) => e.source);
  assert.deepEqual(tied, ['emulator', 'vss']);
});

test('export writes one event per line that reads back to the same events, with UTC', () => {
  const events = parseEventsJson(EVENTS_JSON).slice(0, 3);
  const lines = jsonLines(events).trimEnd().split('\n').map((l) => JSON.parse(l));
  assert.equal(lines.length, 3);
  assert.deepEqual(lines.map((l) => l.message), events.map((e) => e.message));
  assert.equal(lines[1].utc, '2026-03-01T20:00:00.220020Z');
  assert.equal(jsonLines([]), '');
  assert.equal(utcText(T0 + 999999), '2026-03-01T20:00:00.999999Z');
  assert.deepEqual(splitWords(' command, phase,,'), ['command', 'phase']);
});
