"""Codec: a stream packet of 100 samples x 16 float64 signals, ASTCom vs plain msgpack lists.

Run: .venv/bin/python benchmarks/bench_astcom_codec.py [--repeat N]
Goal (issue 2): encode/decode at least 10x faster than msgpack of the same data as nested lists.
"""

from __future__ import annotations

import argparse
import timeit

import msgpack
import numpy as np

from astcom_client.codec import Codec
from astcom_client.commands import DataFrame, data_frame

N_SAMPLES, N_SIGNALS = 100, 16


def best_us(fn, number: int, repeat: int) -> float:
    """Return the best time of one call, in microseconds."""
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7, help="timing repeats (best is kept)")
    parser.add_argument("--number", type=int, default=2000, help="calls per repeat")
    args = parser.parse_args()

    rng = np.random.default_rng(0)
    samples = rng.standard_normal((N_SAMPLES, N_SIGNALS))
    codec = Codec()
    header = dict(msg=1, seq=42, first_tick=1_000_000, first_t_us=1_763_769_600_000_000,
                  period_us=100.0, period_ticks=1, n=N_SAMPLES)

    def ours_encode() -> bytes:
        return codec.encode(data_frame(arrays=[samples], **header))

    frame = ours_encode()

    def ours_decode() -> np.ndarray:
        return DataFrame.from_frame(codec.decode(frame)).arrays[0]

    def plain_encode() -> bytes:
        return msgpack.packb(["DATA", *header.values(), samples.tolist()])

    plain = plain_encode()

    def plain_decode() -> list:
        return msgpack.unpackb(plain)[-1]

    np.testing.assert_array_equal(ours_decode(), samples)
    np.testing.assert_array_equal(np.array(plain_decode()), samples)

    rows = []
    for label, fn_ours, fn_plain in (("encode", ours_encode, plain_encode),
                                     ("decode", ours_decode, plain_decode)):
        t_ours = best_us(fn_ours, args.number, args.repeat)
        t_plain = best_us(fn_plain, args.number, args.repeat)
        rows.append((label, t_ours, t_plain))
    t_ours_rt = sum(r[1] for r in rows)
    t_plain_rt = sum(r[2] for r in rows)
    print(f"stream packet {N_SAMPLES} samples x {N_SIGNALS} f64: ASTCom {len(frame)} bytes, "
          f"plain msgpack lists {len(plain)} bytes")
    print(f"{'':12}{'ASTCom us':>12}{'msgpack lists us':>18}{'speed-up':>10}")
    for label, t_ours, t_plain in [*rows, ("round trip", t_ours_rt, t_plain_rt)]:
        print(f"{label:12}{t_ours:12.2f}{t_plain:18.2f}{t_plain / t_ours:9.1f}x")
    t_plain_array = best_us(lambda: np.array(plain_decode()), args.number // 4, args.repeat)
    print(f"{'decode to an ndarray':20} ASTCom {rows[1][1]:.2f} us, msgpack lists + np.array "
          f"{t_plain_array:.2f} us ({t_plain_array / rows[1][1]:.0f}x)")
    verdict = "met" if t_plain_rt / t_ours_rt >= 10 else "NOT met"
    print(f"goal >= 10x on the round trip: {verdict}")


if __name__ == "__main__":
    main()
