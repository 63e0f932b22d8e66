"""One module per log format, each with one :class:`~adapters.formats.base.Format` named ``FORMAT``.

:mod:`adapters.formats` imports every module here and registers what it declares; adding a format is adding a
module here (its reader and writer inside it or imported from beside it) and its tests.
"""
