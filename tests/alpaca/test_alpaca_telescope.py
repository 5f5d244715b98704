"""The Alpaca telescope driven by alpyca (ASCOM's Python client) against the VSS and emulator.

Truth is independent of the façade: the emulator's encoders (read over ASTCom at known
mount times) against astropy's observed place of the J2000 coordinates sent, the
declination moved by a guide pulse against guide rate × duration, azimuth rates of
MoveAxis against the emulator's own readings.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
from alpaca.exceptions import (
    ActionNotImplementedException,
    InvalidOperationException,
    InvalidValueException,
    NotImplementedException,
    ParkedException,
)
from alpaca.telescope import GuideDirections, TelescopeAxes
from sky_truth import observed_frame, sky_sep_arcsec

AXES = ["axis.az.position", "axis.el.position"]
ICRS = (250.0, 36.5)  # high in the east at 21:00 UTC


def wait_for(predicate, timeout_s: float = 90.0, what: str = "") -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def j2000_of(ra_deg: float, dec_deg: float) -> tuple[float, float]:
    import astropy.units as u
    from astropy.coordinates import FK5, SkyCoord

    f = SkyCoord(ra_deg * u.deg, dec_deg * u.deg, frame="icrs").transform_to(FK5(equinox="J2000"))
    return f.ra.hour, f.dec.deg


def encoders(rig, n: int = 3):
    reads = [rig.rig.run(rig.rig.mount_read(AXES)) for _ in range(n)]
    t = np.array([r[1] for r in reads])
    return (np.degrees([r[0][AXES[0]] for r in reads]) % 360.0,
            np.degrees([r[0][AXES[1]] for r in reads]), t)


def truth(ra_deg, dec_deg, t_us, site):
    import astropy.units as u
    from astropy.coordinates import SkyCoord

    aa = SkyCoord(ra_deg * u.deg, dec_deg * u.deg, frame="icrs").transform_to(
        observed_frame(t_us, site))
    return aa.az.deg, aa.alt.deg


@pytest.fixture
def scope(night):
    t = night.telescope()
    t.Unpark()
    t.AbortSlew()
    t.Tracking = False
    yield t
    t.AbortSlew()
    t.Tracking = False


def test_the_device_describes_itself_and_its_capabilities_honestly(night):
    from alpaca import management

    assert management.apiversions(night.address) == [1]
    devices = management.configureddevices(night.address)
    assert devices[0]["DeviceType"] == "Telescope" and devices[0]["DeviceNumber"] == 0
    t = night.telescope()
    assert t.InterfaceVersion == 4
    assert t.AlignmentMode.value == 0 and t.EquatorialSystem.value == 2
    assert (t.CanSlewAsync, t.CanSlewAltAzAsync, t.CanPark, t.CanUnpark, t.CanPulseGuide,
            t.CanSetTracking, t.CanSetGuideRates) == (True,) * 7
    assert (t.CanSync, t.CanSyncAltAz, t.CanFindHome, t.CanSetPark, t.CanSetPierSide,
            t.CanSetRightAscensionRate, t.CanSetDeclinationRate, t.CanSlew,
            t.CanSlewAltAz) == (False,) * 9
    assert t.CanMoveAxis(TelescopeAxes.axisPrimary) and not t.CanMoveAxis(TelescopeAxes.axisTertiary)
    assert t.AxisRates(TelescopeAxes.axisPrimary)[0].Maximum > 0
    assert "TrackSatellite" in t.SupportedActions
    with pytest.raises(NotImplementedException):
        t.SyncToCoordinates(1.0, 2.0)
    with pytest.raises(NotImplementedException):
        t.FindHome()


def test_site_time_and_sidereal_time_are_the_servers_and_astropys(night):
    import astropy.units as u
    from astropy.time import Time

    t = night.telescope()
    site = night.site
    assert t.SiteLatitude == pytest.approx(site.lat_deg)
    assert t.SiteLongitude == pytest.approx(site.lon_deg)
    utc = t.UTCDate.replace(tzinfo=None)  # dateutil reads the Z as local time: it is UTC
    lst = t.SiderealTime
    truth_lst = Time(utc, scale="utc").sidereal_time("apparent", site.lon_deg * u.deg).hour
    # the two reads are a request apart: allow the mount time that passed between them
    assert abs((lst - truth_lst + 12) % 24 - 12) * 3600 < 30.0


def test_slew_to_j2000_coordinates_lands_on_astropys_place_and_tracks(night, scope):
    scope.SlewToAltAzAsync(120.0, 45.0)
    wait_for(lambda: not scope.Slewing, what="the alt-az slew")
    assert scope.Azimuth == pytest.approx(120.0, abs=1 / 3600)
    assert scope.Altitude == pytest.approx(45.0, abs=1 / 3600)
    assert not scope.Tracking
    with pytest.raises(InvalidOperationException):  # ASCOM: equatorial slews need Tracking
        scope.SlewToCoordinatesAsync(*j2000_of(*ICRS))
    scope.Tracking = True
    assert scope.Tracking and not scope.Slewing  # holding the sky still: not a slew
    ra_h, dec = j2000_of(*ICRS)
    scope.SlewToCoordinatesAsync(ra_h, dec)
    assert scope.TargetRightAscension == pytest.approx(ra_h)
    wait_for(lambda: not scope.Slewing, what="the equatorial slew")
    assert scope.Tracking
    az, el, t_us = encoders(night)
    assert sky_sep_arcsec(az, el, *truth(*ICRS, t_us, night.site)).max() < 1.0
    d_ra = (scope.RightAscension - ra_h) * 15 * 3600 * math.cos(math.radians(dec))
    assert math.hypot(d_ra, (scope.Declination - dec) * 3600) < 1.0


def mount_sleep(night, mount_s: float) -> None:
    """Wait until `mount_s` seconds of mount time have passed (the host's speed aside)."""
    t0 = encoders(night, 1)[2][0]
    wait_for(lambda: encoders(night, 1)[2][0] >= t0 + mount_s * 1e6, what="mount time")


def az_el_rates(night, mount_s: float = 3.0) -> tuple[float, float]:
    """Axis rates (deg/s) from two emulator readings at least `mount_s` mount seconds apart."""
    a0, e0, t0 = encoders(night, 1)
    mount_sleep(night, mount_s)
    a1, e1, t1 = encoders(night, 1)
    dt = (t1[0] - t0[0]) / 1e6
    return ((a1[0] - a0[0] + 180) % 360 - 180) / dt, (e1[0] - e0[0]) / dt


def test_abort_slew_stops_the_slew_and_tracking_goes_on_where_it_stopped(night, scope):
    scope.Tracking = True
    assert not scope.Slewing  # holding the sky still is not a slew
    ra_h, dec = j2000_of(ICRS[0] + 60.0, 20.0)
    with night.paced(1.0):  # the slew takes many wall seconds: the abort comes on the way
        with night.frozen():
            scope.SlewToCoordinatesAsync(ra_h, dec)
            assert scope.Slewing
        scope.AbortSlew()
    assert scope.Tracking  # ASCOM: tracking as before the slew
    wait_for(lambda: not scope.Slewing, what="the track of where it stopped to settle")
    here = (scope.RightAscension, scope.Declination)
    mount_sleep(night, 10.0)
    now = (scope.RightAscension, scope.Declination)
    assert abs(now[0] - here[0]) * 15 * 3600 < 1 and abs(now[1] - here[1]) * 3600 < 1
    assert abs(now[0] - ra_h) * 15 > 1.0  # it stopped on the way, not at the target


def _device_states(scope, mount_s: float) -> list[dict]:
    """DeviceState read over and over for `mount_s` seconds of mount time (its TimeStamp)."""
    from virtualstar.astro import UtcTimes

    reads = []
    while True:
        state = {item["Name"]: item["Value"] for item in scope.DeviceState}
        stamp = state["TimeStamp"]
        if not isinstance(stamp, str):
            stamp = stamp.strftime("%Y-%m-%dT%H:%M:%S.%fZ")
        state["t_us"] = int(UtcTimes.from_iso([stamp.replace("+00:00", "")]).to_unix_us()[0])
        reads.append(state)
        if state["t_us"] - reads[0]["t_us"] > mount_s * 1e6:
            return reads


def test_after_abort_slew_slewing_stays_true_until_the_mount_holds_the_sky_within_5_arcsec(
        night, scope):
    """ASCOM: AbortSlew while tracking stops the slew and tracking goes on where it stopped.
    Slewing may read false only once RA/Dec hold still: never tens of arcseconds of drift
    after it (polled through DeviceState for 20 mount seconds, mount time from TimeStamp)."""
    scope.Tracking = True
    ra_h, dec = j2000_of(ICRS[0] + 60.0, 20.0)
    with night.paced(1.0):  # the slew takes many wall seconds: the abort comes on the way
        scope.SlewToCoordinatesAsync(ra_h, dec)
        mount_sleep(night, 3.0)
        assert scope.Slewing
        scope.AbortSlew()
    with night.paced(4.0):  # fine steps of mount time between the reads
        reads = _device_states(scope, 20.0)
    assert reads[0]["Tracking"]  # ASCOM: tracking as before the slew
    settled = [k for k, r in enumerate(reads) if not r["Slewing"]]
    assert settled, "Slewing never went false within 20 mount seconds of the abort"
    first = settled[0]
    assert all(not r["Slewing"] for r in reads[first:])  # and stays false
    final = reads[-1]
    for r in reads[first:]:
        d_ra = ((r["RightAscension"] - final["RightAscension"] + 12) % 24 - 12) * 15 * 3600
        d_dec = (r["Declination"] - final["Declination"]) * 3600
        assert math.hypot(d_ra * math.cos(math.radians(final["Declination"])), d_dec) < 5.0, (
            (r["t_us"] - reads[0]["t_us"]) / 1e6, d_ra, d_dec)
    assert abs(final["RightAscension"] - ra_h) * 15 > 1.0  # stopped on the way


def test_abort_slew_with_nothing_slewing_changes_nothing(night, scope):
    scope.Tracking = True
    scope.AbortSlew()
    assert scope.Tracking and not scope.Slewing
    scope.Tracking = False
    scope.AbortSlew()
    assert not scope.Tracking
    assert max(abs(r) for r in az_el_rates(night)) * 3600 < 1.0


def test_park_holds_the_park_position_refuses_slews_and_unpark_releases(night, scope):
    scope.Park()
    wait_for(lambda: scope.AtPark, what="AtPark")
    assert not scope.Slewing
    with pytest.raises(ParkedException):
        scope.SlewToAltAzAsync(100.0, 40.0)
    with pytest.raises(ParkedException):
        scope.Tracking = True
    scope.Unpark()
    assert not scope.AtPark
    scope.SlewToAltAzAsync(100.0, 40.0)
    wait_for(lambda: not scope.Slewing, what="the slew after unpark")
    assert scope.Azimuth == pytest.approx(100.0, abs=1 / 3600)


def test_move_axis_turns_each_axis_at_its_rate_and_stopping_both_resumes_tracking(night, scope):
    scope.SlewToAltAzAsync(120.0, 60.0)  # from a known place: no limit near while it moves
    wait_for(lambda: not scope.Slewing, what="the slew")
    scope.Tracking = True
    scope.MoveAxis(TelescopeAxes.axisPrimary, 1.5)
    assert scope.Slewing
    scope.MoveAxis(TelescopeAxes.axisSecondary, -0.5)
    mount_sleep(night, 15.0)  # past the stop, the lead and the run-up
    az_rate, el_rate = az_el_rates(night)
    assert az_rate == pytest.approx(1.5, rel=1e-3) and el_rate == pytest.approx(-0.5, rel=1e-3)
    scope.MoveAxis(TelescopeAxes.axisPrimary, 0.0)
    mount_sleep(night, 15.0)
    az_rate, el_rate = az_el_rates(night)
    assert abs(az_rate) < 1e-4 and el_rate == pytest.approx(-0.5, rel=1e-3)
    with pytest.raises(InvalidValueException):
        scope.MoveAxis(TelescopeAxes.axisSecondary, 1000.0)
    scope.MoveAxis(TelescopeAxes.axisSecondary, 0.0)
    assert scope.Tracking and not scope.Slewing


def test_move_axis_zero_with_no_move_running_leaves_a_slew_alone(night, scope):
    scope.MoveAxis(TelescopeAxes.axisPrimary, 1.0)
    scope.SlewToAltAzAsync(150.0, 50.0)  # the slew replaces the hand pad's move
    scope.MoveAxis(TelescopeAxes.axisSecondary, 0.0)  # nothing moves at rates: no-op
    wait_for(lambda: not scope.Slewing, what="the slew")
    assert scope.Azimuth == pytest.approx(150.0, abs=1 / 3600)
    assert max(abs(r) for r in az_el_rates(night)) * 3600 < 1.0


def test_pulse_guide_right_after_tracking_is_turned_on_is_accepted(night, scope):
    scope.Tracking = True
    with night.frozen():
        scope.PulseGuide(GuideDirections.guideWest, 1000)  # as ConformU does: at once
        assert scope.IsPulseGuiding
    wait_for(lambda: not scope.IsPulseGuiding, what="the pulse to end")


def test_connect_disconnect_and_device_state_platform_7(night):
    t = night.telescope(connect=False)
    t.Connect()
    assert not t.Connecting and t.Connected
    state = {item["Name"]: item["Value"] for item in t.DeviceState}
    assert {"Altitude", "Azimuth", "RightAscension", "Declination", "SiderealTime", "Slewing",
            "Tracking", "AtPark", "IsPulseGuiding", "UTCDate", "TimeStamp"} <= set(state)
    assert state["Altitude"] == pytest.approx(t.Altitude, abs=0.01)
    t.Disconnect()
    assert not t.Connected
    from alpaca.exceptions import NotConnectedException

    with pytest.raises(NotConnectedException):
        _ = t.Altitude
    t.Connected = True


def test_pulse_guide_moves_the_track_north_by_rate_times_duration(night, scope):
    scope.Tracking = True
    scope.SlewToCoordinatesAsync(*j2000_of(*ICRS))
    wait_for(lambda: not scope.Slewing, what="the slew")
    mount_sleep(night, 5.0)  # the track has settled
    dec0 = scope.Declination
    rate = scope.GuideRateDeclination
    with night.frozen():
        scope.PulseGuide(GuideDirections.guideNorth, 2000)
        assert scope.IsPulseGuiding
    wait_for(lambda: not scope.IsPulseGuiding, what="the pulse to end")
    mount_sleep(night, 3.0)  # settling after the pulse
    moved_arcsec = (scope.Declination - dec0) * 3600
    assert moved_arcsec == pytest.approx(rate * 3600 * 2.0, abs=0.3)
    scope.Tracking = False
    with pytest.raises(InvalidOperationException):  # not tracking: nothing to guide
        scope.PulseGuide(GuideDirections.guideEast, 500)


def test_track_satellite_action_tracks_the_iss_pass(night, scope):
    from catalogs import sample_tle_path

    text = sample_tle_path("stations").read_text()
    lines = text.splitlines()
    i = next(k for k, line in enumerate(lines) if "ISS" in line)
    tle = "\n".join(lines[i:i + 3])
    op = json.loads(scope.Action("TrackSatellite", tle))
    assert op["kind"] == "track_satellite" and "ISS" in op["target"]
    assert json.loads(scope.Action("OperationStatus", ""))["id"] == op["id"]
    with pytest.raises(ActionNotImplementedException):
        scope.Action("MakeCoffee", "")


def test_a_place_below_the_horizon_limit_is_refused_with_the_servers_reason(night, scope):
    with pytest.raises(InvalidValueException) as exc:
        scope.SlewToAltAzAsync(200.0, 2.0)
    assert "elevation" in str(exc.value) and "5" in str(exc.value)
    assert not scope.Slewing


def test_offset_action_moves_the_track_on_the_sky_and_reports_the_offsets(night, scope):
    scope.Tracking = True
    scope.SlewToCoordinatesAsync(*j2000_of(*ICRS))
    wait_for(lambda: not scope.Slewing, what="the slew")
    mount_sleep(night, 3.0)
    assert "Offset" in scope.SupportedActions
    answer = json.loads(scope.Action("Offset", "dec add 12"))
    assert answer["lead_ms"] == pytest.approx(20.0) and answer["sent"] == "replace_from"
    mount_sleep(night, 2.0)
    az, el, t = encoders(night)
    shifted = truth(ICRS[0], ICRS[1] + 12.0 / 3600.0, t, night.site)
    assert sky_sep_arcsec(az, el, *shifted).max() < 0.3
    json.loads(scope.Action("Offset", '{"axis": "all", "op": "reset"}'))
    mount_sleep(night, 2.0)
    az, el, t = encoders(night)
    assert sky_sep_arcsec(az, el, *truth(*ICRS, t, night.site)).max() < 0.3
    for bad in ("dec add twelve", "", "dec add 1 2 3", '{"axis": "dec", "by": 1}'):
        with pytest.raises(InvalidValueException):
            scope.Action("Offset", bad)
    scope.Tracking = False
    with pytest.raises(InvalidOperationException):  # nothing tracked: nothing to offset
        scope.Action("Offset", "ra add 1")
