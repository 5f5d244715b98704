"""INDI façade: `vs-indi`, a telescope driver that indiserver runs, translating to the VSS.

`protocol` is the INDI XML without I/O (vectors, def/set messages, an incremental
reader); `driver` holds the telescope's properties and their VSS commands.
"""
