"""A rate-driven mount's reports as ASTCom signals, so the recorder records them like any other.

An Alpaca or INDI driver has no ASTCom endpoint of its own. With `vs server --signals
URL`, the VSS serves one: each new report of the driver is one *tick* (numbered, stamped
with the report's mount time), carrying the reported place, its age, the rates in force
and the error against the path being followed (NaN when nothing is followed). `vs record
URL report.ra_deg error.sky_arcsec … --rate 50` then stores them at the rate the driver
is polled; lost reports show as gaps like any lost sample.

| name | unit | what |
|---|---|---|
| `report.ra_deg`, `report.dec_deg` | deg | the place of date the driver reported |
| `report.az_deg`, `report.el_deg` | deg | its observed place (ERFA, the site's refraction) |
| `report.age_s` | s | how old the report was when the VSS took it (0 for a push) |
| `report.time_uncertainty_s` | s | how well its mount time is known |
| `rate.axis1_arcsec_s`, `rate.axis2_arcsec_s` | arcsec/s | the coordinate rates in force |
| `error.axis1_arcsec`, `error.axis2_arcsec`, `error.sky_arcsec` | arcsec | path − report at the report's time (first axis × cos of the second) |
"""

from __future__ import annotations

import math

import numpy as np

from astcom_client import Collection, Endpoint, EndpointConfig

__all__ = ["NAMES", "ReportSignals"]

NAMES = (("report.ra_deg", "deg"), ("report.dec_deg", "deg"), ("report.az_deg", "deg"),
         ("report.el_deg", "deg"), ("report.age_s", "s"), ("report.time_uncertainty_s", "s"),
         ("rate.axis1_arcsec_s", "arcsec/s"), ("rate.axis2_arcsec_s", "arcsec/s"),
         ("error.axis1_arcsec", "arcsec"), ("error.axis2_arcsec", "arcsec"),
         ("error.sky_arcsec", "arcsec"))
LOOP_RATE_HZ = 50.0  # no driver reports faster; a stream at this rate carries every report


class ReportSignals:
    """Serve a rate-driven link's reports over ASTCom (one tick per report)."""

    def __init__(self, link, *, passwords=None) -> None:
        self.values = np.full(len(NAMES), math.nan)
        coll = Collection()
        for k, (name, unit) in enumerate(NAMES):
            coll.add_slot(name, self.values, k, type="f64", unit=unit, traced=True,
                          doc=f"the mount backend's {name.replace('.', ' ').replace('_', ' ')}")
        self.collection = coll
        self.columns = [coll[name].trace_column for name, _ in NAMES]
        self.endpoint = Endpoint(coll, EndpointConfig(loop_rate_hz=LOOP_RATE_HZ,
                                                      passwords=passwords,
                                                      name="virtualstar-backend"))
        self.tick = 0
        self.last_t_us = 0
        self.url: str | None = None
        link.report_listeners.append(self.on_report)

    async def serve(self, url: str) -> str:
        self.url = await self.endpoint.serve(url)
        return self.url

    async def close(self) -> None:
        await self.endpoint.close()

    def on_report(self, row: dict) -> None:
        t_us = int(row["t_us"])
        if t_us <= self.last_t_us:
            return  # a tick's time only moves forward
        self.values[:] = [row.get(name, math.nan) for name, _ in NAMES]
        trace = np.full((1, self.collection.trace_width), math.nan)
        trace[0, self.columns] = self.values
        self.endpoint.publish(self.tick, t_us, 1, trace)
        self.tick += 1
        self.last_t_us = t_us
