"""How well the 10 kHz loop keeps its time: overruns, the worst block, the worst lag.

A real controller counts the periods its interrupt ran late; the emulator's loop computes
ticks in blocks on a general-purpose host, so it counts the same things per block. Updated
once per block (a few integer and float operations), read as ASTCom signals `loop.*`.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["LoopHealth"]


@dataclass
class LoopHealth:
    """Counters of the device loop since start (wall times in µs)."""

    blocks: int = 0
    overruns: int = 0  # wake-ups that found more than one block of ticks due (the loop fell behind)
    late_ticks: int = 0  # ticks computed while the loop was behind by more than one block
    worst_block_us: float = 0.0  # longest wall time of computing one block
    worst_lag_us: float = 0.0  # largest lag of mount time behind its wall-clock due time
    last_block_us: float = 0.0

    def block_done(self, wall_us: float) -> None:
        """Count one computed block that took `wall_us` µs of wall time."""
        self.blocks += 1
        self.last_block_us = wall_us
        if wall_us > self.worst_block_us:
            self.worst_block_us = wall_us

    def woke(self, due_ticks: int, block_ticks: int, tick_us: float) -> None:
        """Count one wake-up of a paced loop that found `due_ticks` ticks due."""
        lag_us = due_ticks * tick_us
        if lag_us > self.worst_lag_us:
            self.worst_lag_us = lag_us
        if due_ticks > block_ticks:
            self.overruns += 1
            self.late_ticks += due_ticks - block_ticks

    def reset(self) -> None:
        """Start counting again (e.g. after the first compile)."""
        self.blocks = self.overruns = self.late_ticks = 0
        self.worst_block_us = self.worst_lag_us = self.last_block_us = 0.0
