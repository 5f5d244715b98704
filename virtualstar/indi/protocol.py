"""The INDI protocol without I/O: property vectors, the XML a driver writes, what it reads.

A driver speaks XML on stdin/stdout with `indiserver`: it answers `getProperties` with
`def*Vector` elements, reports changes with `set*Vector`, and receives a client's
requests as `new*Vector`. The stream has no root element, so `Reader` parses it
incrementally inside an invented one and yields each complete top-level element as a
`Request`.
"""

from __future__ import annotations

import time
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Literal

__all__ = ["IDLE", "OK", "BUSY", "ALERT", "Element", "Reader", "Request", "Vector",
           "message_xml"]

IDLE, OK, BUSY, ALERT = "Idle", "Ok", "Busy", "Alert"
Kind = Literal["Number", "Switch", "Text", "Light"]


@dataclass
class Element:
    """One member of a vector: its name, label, value; number format and range."""

    name: str
    label: str
    value: float | str | bool
    format: str = "%g"
    min: float = 0.0
    max: float = 0.0
    step: float = 0.0


@dataclass
class Vector:
    """A property: device, name, kind, group, permission, state, its elements."""

    device: str
    name: str
    kind: Kind
    label: str
    group: str
    elements: list[Element]
    perm: str = "rw"
    state: str = IDLE
    rule: str = "OneOfMany"  # switches only
    timeout: int = 60
    index: dict[str, Element] = field(init=False)

    def __post_init__(self) -> None:
        self.index = {e.name: e for e in self.elements}

    def __getitem__(self, name: str) -> Element:
        return self.index[name]

    def values(self) -> dict[str, float | str | bool]:
        return {e.name: e.value for e in self.elements}

    def define_xml(self) -> str:
        """The `def*Vector` element describing this property."""
        tag = f"def{self.kind}Vector"
        attrs = {"device": self.device, "name": self.name, "label": self.label,
                 "group": self.group, "state": self.state, "timestamp": _now()}
        if self.kind != "Light":
            attrs["perm"] = self.perm
            attrs["timeout"] = str(self.timeout)
        if self.kind == "Switch":
            attrs["rule"] = self.rule
        root = ET.Element(tag, attrs)
        for e in self.elements:
            child = ET.SubElement(root, f"def{self.kind}", _element_attrs(self.kind, e))
            child.text = _value_text(self.kind, e.value)
        return ET.tostring(root, encoding="unicode")

    def set_xml(self, message: str | None = None) -> str:
        """The `set*Vector` element reporting the current values and state."""
        attrs = {"device": self.device, "name": self.name, "state": self.state,
                 "timestamp": _now()}
        if message:
            attrs["message"] = message
        root = ET.Element(f"set{self.kind}Vector", attrs)
        for e in self.elements:
            child = ET.SubElement(root, f"one{self.kind}", {"name": e.name})
            child.text = _value_text(self.kind, e.value)
        return ET.tostring(root, encoding="unicode")


def _element_attrs(kind: str, e: Element) -> dict[str, str]:
    attrs = {"name": e.name, "label": e.label}
    if kind == "Number":
        attrs.update(format=e.format, min=repr(e.min), max=repr(e.max), step=repr(e.step))
    return attrs


def _value_text(kind: str, value) -> str:
    if kind == "Switch":
        return "On" if value else "Off"
    if kind == "Light":
        return str(value)
    if kind == "Number":
        return repr(float(value))
    return str(value)


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime())


def message_xml(device: str, text: str) -> str:
    """A `message` element: text a client shows in its log."""
    return ET.tostring(ET.Element("message", {"device": device, "message": text,
                                              "timestamp": _now()}), encoding="unicode")


@dataclass(frozen=True)
class Request:
    """What a client sent: getProperties, or new*Vector with its (name → text) members."""

    tag: str
    device: str | None
    name: str | None
    members: dict[str, str]


class Reader:
    """Feed bytes from indiserver; iterate the complete requests they hold."""

    def __init__(self) -> None:
        self._parser = ET.XMLPullParser(events=("start", "end"))
        self._parser.feed(b"<indi>")
        self._depth = 0

    def feed(self, data: bytes) -> Iterator[Request]:
        self._parser.feed(data)
        for event, el in self._parser.read_events():
            if event == "start":
                self._depth += 1
                continue
            self._depth -= 1
            if self._depth != 1:
                continue
            members = {c.get("name", ""): (c.text or "").strip() for c in el}
            yield Request(el.tag, el.get("device"), el.get("name"), members)
            el.clear()
