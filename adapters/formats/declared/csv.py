"""CSV in the documented long format: recognised as text with a comma-separated header; read and written by
:mod:`adapters.formats.csv`."""

from __future__ import annotations

from adapters.formats.base import Format

__all__ = ["FORMAT"]


class Csv(Format):
    name = "csv"
    extensions = (".csv",)
    description = "CSV long format: demo, t, states, inputs"
    order = 90  # text: tried last
    rerun_importer = False  # a CSV is too common a file for rerun's importer to claim

    def sniff(self, head):
        from adapters.formats.csv import looks_like_csv

        return looks_like_csv(head)

    def read(self, path, topics=None):
        from adapters.formats import csv

        return csv.read(path, topics)

    def write(self, path, streams, **options):
        from adapters.formats import csv

        return csv.write(path, streams)


FORMAT = Csv()
