"""ArduPilot DataFlash (``.bin``): recognised by an FMT message head; read by :mod:`adapters.formats.dataflash`,
written by :mod:`adapters.formats.dataflash_write`."""

from __future__ import annotations

from adapters.formats.base import Format

__all__ = ["FORMAT", "MAGIC"]

#: An FMT message's head (``adapters.formats.dataflash.MAGIC``), here so that sniffing does not import numpy.
MAGIC = b"\xa3\x95\x80"
_FMT_LENGTH = 89  # an FMT message's bytes (adapters.formats.dataflash.FMT_LENGTH)


class DataFlash(Format):
    name = "dataflash"
    extensions = (".bin",)
    description = "ArduPilot DataFlash onboard log"
    order = 30

    def sniff(self, head):
        """An FMT head at byte 0, or, past damaged leading bytes (where DFReader resynchronises), two FMT messages
        in a row: a log's own description, which no other format's first bytes hold."""
        if head.startswith(MAGIC):
            return True
        at = head.find(MAGIC)
        while at != -1 and at + _FMT_LENGTH + len(MAGIC) <= len(head):
            if head[at + _FMT_LENGTH: at + _FMT_LENGTH + len(MAGIC)] == MAGIC:
                return True
            at = head.find(MAGIC, at + 1)
        return False

    def read(self, path, topics=None):
        from adapters.formats import dataflash

        return dataflash.read(path, topics)

    def text_messages(self, streams):
        """``MSG`` text, ``ERR`` and ``EV`` named as ArduPilot names them (:mod:`adapters.events`)."""
        from adapters.textlog import dataflash_rows

        return dataflash_rows(streams)

    def write(self, path, streams, **options):
        from adapters.formats import dataflash_write

        return dataflash_write.write(path, streams, **options)


FORMAT = DataFlash()
