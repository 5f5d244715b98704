"""What the façades read from a VSS operation object, one reading for both."""

from __future__ import annotations

from virtualstar.vss_operations import hand_pad_rates, is_moving, is_parked, is_tracking


def op(kind: str, phase: str, **info) -> dict:
    return {"id": 7, "kind": kind, "phase": phase, "target": "x", "info": info}


def test_a_sky_track_is_tracking_until_it_ends_and_a_held_place_never_is():
    assert is_tracking(op("track", "slewing")) and is_tracking(op("slew", "tracking"))
    assert not is_tracking(op("track", "aborted"))
    assert not is_tracking(op("slew", "slewing", fixed=True))
    assert not is_tracking(None) and not is_tracking(op("park", "slewing"))


def test_moving_covers_the_way_there_but_not_a_pass_not_yet_risen():
    assert is_moving(op("slew", "joining")) and is_moving(op("park", "ending"))
    assert not is_moving(op("slew", "tracking")) and not is_moving(op("park", "done"))
    assert not is_moving(op("track_satellite", "waiting"))
    assert is_moving(op("move", "tracking")) and not is_moving(op("move", "done"))


def test_parked_until_released_and_hand_pad_rates_only_while_moving():
    assert is_parked(op("park", "done"), None) and not is_parked(op("park", "done"), 7)
    assert not is_parked(op("park", "slewing"), None)
    assert hand_pad_rates(op("move", "slewing", az_rate_deg_s=1.5, el_rate_deg_s=-0.5)) == \
        [1.5, -0.5]
    assert hand_pad_rates(op("move", "aborted", az_rate_deg_s=1.5)) == [0.0, 0.0]
    assert hand_pad_rates(op("track", "tracking")) == [0.0, 0.0]
