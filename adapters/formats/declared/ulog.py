"""PX4 ULog: recognised by its magic; read and written by :mod:`adapters.formats.ulog`."""

from __future__ import annotations

from adapters.formats.base import Format

__all__ = ["FORMAT", "MAGIC"]

#: ULog's magic (``adapters.formats.ulog.MAGIC``), here so that sniffing does not import the reader and numpy.
MAGIC = b"ULog\x01\x12\x35"


class Ulog(Format):
    name = "ulog"
    extensions = (".ulg", ".ulog")
    description = "PX4 ULog"
    order = 20

    def sniff(self, head):
        return head.startswith(MAGIC)

    def read(self, path, topics=None):
        from adapters.formats import ulog

        return ulog.read(path, topics)

    def text_messages(self, streams):
        """The logged messages (``L`` and tagged ``C``) at their syslog level."""
        from adapters.events import shown
        from adapters.textlog import level_name

        return [(float(t), level_name(level), shown(text), "logged message")
                for t, level, text in streams.info.get("logged_messages", []) or []]

    def write(self, path, streams, **options):
        from adapters.formats import ulog

        return ulog.write(path, streams)


FORMAT = Ulog()
