// The browser's clock, ticking once a second, for the ages of stale values ("12 s ago").
import { reactive } from 'vue';

export const wall = reactive({ nowMs: Date.now() });
if (typeof window !== 'undefined') setInterval(() => { wall.nowMs = Date.now(); }, 1000);
