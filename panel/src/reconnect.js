// Reconnection after a lost link: retry with growing pauses, forever, until the user
// disconnects. The pause never exceeds 2 s, so an endpoint that restarts (a VSS or an
// emulator is up again 2-3 s after a crash) is found again within 2 s of its start, not 5;
// the first retry is fast because most losses are restarts. A refused connection attempt
// every 2 s costs the endpoint's host nothing measurable.

export const RECONNECT_DELAYS_MS = [500, 1000, 2000];

/** Return the pause before retry number `attempt` (0, 1, 2, …). */
export function reconnectDelayMs(attempt) {
  return RECONNECT_DELAYS_MS[Math.min(Math.max(0, attempt), RECONNECT_DELAYS_MS.length - 1)];
}

/**
 * Call `attempt(n)` after a pause, again after each failure, until one resolves or
 * `cancel()`. `giveUp(err)` true stops after that failure (e.g. a wrong password).
 * Returns {now(), cancel(), done: Promise<boolean>} (done: true once an attempt succeeded).
 */
export function keepTrying(attempt, { delayMs = reconnectDelayMs, giveUp = () => false } = {}) {
  let cancelled = false;
  let timer = null;
  let finish;
  const done = new Promise((resolve) => {
    finish = resolve;
  });
  let n = 0;
  const run = async () => {
    timer = null;
    if (cancelled) return;
    try {
      await attempt(n);
      if (cancelled) return;
      finish(true);
    } catch (err) {
      if (cancelled) return;
      if (giveUp(err)) {
        finish(false);
        return;
      }
      n += 1;
      timer = setTimeout(run, delayMs(n));
    }
  };
  timer = setTimeout(run, delayMs(0));
  return {
    /** Try again at once instead of after the pause (when something says where to look). */
    now() {
      if (cancelled || !timer) return; // an attempt is under way: it or the next one will do
      clearTimeout(timer);
      timer = setTimeout(run, 0);
    },
    cancel() {
      cancelled = true;
      if (timer) clearTimeout(timer);
      finish(false);
    },
    done,
  };
}
