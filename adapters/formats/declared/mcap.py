"""MCAP (ROS 2 / Foxglove): recognised by its magic; read and written by :mod:`adapters.formats.mcap`."""

from __future__ import annotations

from adapters.formats.base import Format

__all__ = ["FORMAT", "MAGIC"]

#: MCAP's magic (``adapters.formats.mcap.MAGIC``), here too so that sniffing a file does not import the MCAP reader
#: and pyarrow behind it (tests/adapters/test_read_path.py checks that both are the same).
MAGIC = b"\x89MCAP0\r\n"


class Mcap(Format):
    name = "mcap"
    extensions = (".mcap",)
    description = "MCAP (ROS 2 / Foxglove): JSON, ROS 2 CDR, protobuf channels"
    order = 10
    rerun_importer = False  # rerun's own loader reads MCAP; two loaders would log it twice

    def sniff(self, head):
        return head.startswith(MAGIC)

    def read(self, path, topics=None):
        from adapters.formats import mcap

        return mcap.read(path, topics)

    def text_messages(self, streams):
        """ROS 2 ``/rosout`` and every text-only topic (``std_msgs/String``)."""
        from adapters.textlog import mcap_rows

        return mcap_rows(streams)

    def write(self, path, streams, **options):
        from adapters.formats import mcap

        return mcap.write(path, streams, **options)


FORMAT = Mcap()
