"""ArduPilot DataFlash (``.bin``): recognised by an FMT message head; read by :mod:`adapters.formats.dataflash`,
written by :mod:`adapters.formats.dataflash_write`."""

from __future__ import annotations

from adapters.formats.base import Format

__all__ = ["FORMAT", "MAGIC"]

#: An FMT message's head (``adapters.formats.dataflash.MAGIC``), here so that sniffing does not import numpy.
MAGIC = b"\xa3\x95\x80"


class DataFlash(Format):
    name = "dataflash"
    extensions = (".bin",)
    description = "ArduPilot DataFlash onboard log"
    order = 30

    def sniff(self, head):
        return head.startswith(MAGIC)

    def read(self, path, topics=None):
        from adapters.formats import dataflash

        return dataflash.read(path, topics)

    def write(self, path, streams, **options):
        from adapters.formats import dataflash_write

        return dataflash_write.write(path, streams, **options)


FORMAT = DataFlash()
