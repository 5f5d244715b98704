"""The demonstration runs end to end against the example device on loopback."""

from astcom_helpers import run

from astcom_client.demo import tour


def test_demo_tour_streams_without_loss(capsys) -> None:
    figures = run(tour(stream_s=0.3))
    assert figures["lost"] == 0 and figures["samples"] > 0 and figures["rate_hz"] == 500.0
    printed = capsys.readouterr().out
    for step in ("LIST", "READ / WRITE", "INVOKE", "STREAM", "observer over TCP"):
        assert step in printed
