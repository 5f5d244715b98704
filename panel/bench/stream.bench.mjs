// Stream signals at a high rate into the panel's Plot tab in headless chromium; report lost
// samples and the page's frame times (requestAnimationFrame intervals). Run by
// benchmarks/bench_panel_stream.py, which starts the emulator and prints the Python reference.
//
// env: PANEL_URL, ASTCOM_URL, ASTCOM_PASSWORD, SIGNALS (comma list), RATE_HZ, SECONDS, RESULT
import { writeFileSync } from 'node:fs';
import { launch, openAndConnect, streamSignals } from '../test/e2e/browser.mjs';

const env = process.env;
const signals = env.SIGNALS.split(',');
const seconds = Number(env.SECONDS);
const browser = await launch();
const page = await browser.context.newPage();
const result = { ok: false };
try {
  await openAndConnect(page, env.PANEL_URL, env.ASTCOM_URL, env.ASTCOM_PASSWORD);
  await streamSignals(page, signals, Number(env.RATE_HZ));
  await page.click('button[data-tab=Plot]');
  await page.waitForTimeout(1000); // let the plot settle before measuring
  const start = await page.evaluate(() => {
    window.benchFrames = [];
    let last = performance.now();
    const frame = (t) => {
      window.benchFrames.push(t - last);
      last = t;
      if (!window.benchStop) requestAnimationFrame(frame);
    };
    requestAnimationFrame(frame);
    const s = window.panelProbe.session.stream;
    return { samples: s.samples, lost: s.lost, plotUpdates: window.panelProbe.probe.plotUpdates };
  });
  const t0 = Date.now();
  await page.waitForTimeout(seconds * 1000);
  const wallS = (Date.now() - t0) / 1000;
  const end = await page.evaluate(() => {
    window.benchStop = true;
    const s = window.panelProbe.session.stream;
    return { samples: s.samples, lost: s.lost, plotUpdates: window.panelProbe.probe.plotUpdates,
      plotPoints: window.panelProbe.probe.plotPoints, frames: window.benchFrames, rateHz: s.actualRateHz };
  });
  const frames = end.frames.slice(1).sort((a, b) => a - b);
  const pct = (p) => frames[Math.min(frames.length - 1, Math.floor(p * frames.length))];
  Object.assign(result, {
    ok: true, wall_s: wallS, rate_hz: end.rateHz, signals,
    samples: end.samples - start.samples, samples_total: end.samples, lost_total: end.lost,
    plot_updates: end.plotUpdates - start.plotUpdates, plot_points: end.plotPoints,
    frames: frames.length, frame_p50_ms: pct(0.5), frame_p95_ms: pct(0.95), frame_max_ms: frames[frames.length - 1],
  });
} catch (err) {
  result.error = String(err.stack || err);
} finally {
  writeFileSync(env.RESULT, JSON.stringify(result, null, 2));
  await browser.close();
}
process.exit(result.ok ? 0 : 1);
