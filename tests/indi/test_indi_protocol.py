"""INDI XML without I/O: the reader across arbitrary chunk boundaries, the messages, switch rules."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from virtualstar.indi.driver import IndiTelescope, properties
from virtualstar.indi.protocol import Reader

STREAM = (b'<getProperties version="1.7"/>\n'
          b'<newNumberVector device="VirtualStar" name="EQUATORIAL_EOD_COORD">'
          b'<oneNumber name="RA">16.7</oneNumber><oneNumber name="DEC"> 36.4 </oneNumber>'
          b'</newNumberVector><newSwitchVector device="VirtualStar" name="TELESCOPE_PARK">'
          b'<oneSwitch name="PARK">On</oneSwitch></newSwitchVector>')


@pytest.mark.parametrize("chunk", [1, 7, 64, len(STREAM)])
def test_the_reader_yields_each_request_whole_however_the_bytes_arrive(chunk):
    reader = Reader()
    got = [r for i in range(0, len(STREAM), chunk) for r in reader.feed(STREAM[i:i + chunk])]
    assert [r.tag for r in got] == ["getProperties", "newNumberVector", "newSwitchVector"]
    assert got[1].members == {"RA": "16.7", "DEC": "36.4"}
    assert got[2].device == "VirtualStar" and got[2].members == {"PARK": "On"}


def test_every_definition_and_update_is_well_formed_xml_with_its_members():
    for vector in properties():
        for text in (vector.define_xml(), vector.set_xml('a <message> & "quotes"')):
            root = ET.fromstring(text)
            assert root.get("name") == vector.name and root.get("device") == "VirtualStar"
            assert [c.get("name") for c in root] == [e.name for e in vector.elements]


def test_switch_rules_refuse_what_libindi_refuses_and_change_nothing():
    props = {v.name: v for v in properties()}
    coord_set = props["ON_COORD_SET"]
    with pytest.raises(ValueError, match="exactly one"):
        IndiTelescope._store(coord_set, {"TRACK": "Off"})
    assert coord_set["TRACK"].value is True
    IndiTelescope._store(coord_set, {"SLEW": "On"})
    assert (coord_set["TRACK"].value, coord_set["SLEW"].value) == (False, True)
    motion = props["TELESCOPE_MOTION_NS"]
    with pytest.raises(ValueError, match="at most one"):
        IndiTelescope._store(motion, {"MOTION_NORTH": "On", "MOTION_SOUTH": "On"})
    with pytest.raises(ValueError, match="no member"):
        IndiTelescope._store(motion, {"MOTION_UP": "On"})
    with pytest.raises(ValueError, match="On or Off"):
        IndiTelescope._store(motion, {"MOTION_NORTH": "yes"})
    assert (motion["MOTION_NORTH"].value, motion["MOTION_SOUTH"].value) == (False, False)
