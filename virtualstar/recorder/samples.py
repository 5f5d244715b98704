"""What flows from the subscriber to a store: signal descriptions, sample blocks, gaps."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Gap", "SampleBlock", "SignalInfo", "concat_blocks"]

UNKNOWN_LOST = -1  # a gap across an endpoint restart: the number of missed samples is unknown


@dataclass(frozen=True)
class SignalInfo:
    """One recorded signal: its ASTCom name, unit and numpy dtype name (float64, int64...)."""

    name: str
    unit: str = ""
    dtype: str = "float64"


@dataclass
class SampleBlock:
    """Samples of several signals at common times.

    `t_us` is mount time in integer µs (int64, increasing); `columns[name]` holds one
    value per time in the signal's own dtype, exactly as streamed.
    """

    t_us: np.ndarray
    columns: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.t_us.shape[0])

    @property
    def names(self) -> list[str]:
        return list(self.columns)

    def slice(self, start: int, stop: int) -> SampleBlock:
        """Return rows [start, stop) as views."""
        return SampleBlock(self.t_us[start:stop],
                           {k: v[start:stop] for k, v in self.columns.items()})


def concat_blocks(blocks: list[SampleBlock]) -> SampleBlock:
    """Return one block of `blocks` in order (they must share their column names)."""
    if len(blocks) == 1:
        return blocks[0]
    names = blocks[0].names
    return SampleBlock(np.concatenate([b.t_us for b in blocks]),
                       {k: np.concatenate([b.columns[k] for b in blocks]) for k in names})


@dataclass(frozen=True)
class Gap:
    """Samples missing between two received samples.

    `after_t_us` is the last sample received before the gap (-1 when the gap opens a
    session), `before_t_us` the first one after it (mount time, µs). `lost_samples` is
    exact when the ticks tell it and `UNKNOWN_LOST` (-1) across an endpoint restart;
    `reason` is "dropped" (sequence/tick gap on a live stream) or "reconnect".
    """

    after_t_us: int
    before_t_us: int
    lost_samples: int
    reason: str
    session: str = ""
