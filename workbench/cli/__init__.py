"""The ``workbench`` command: from flight logs to a model of how a human flies, its report and a rerun view.

Run ``workbench demo`` first: it imports the sample logs, fits one model per control strategy, compares it with
its two baselines, and writes a report and a rerun recording. Every command has ``--help`` with an example.

Bad input (a missing file, a corrupt log, a wrong mapping, a model file from a newer version) prints one line,
``error: <what>: <cause>``, and exits with status 1; ``--debug`` shows the traceback instead. Every output file
is written atomically (a temp file renamed into place), so a failed run never leaves half a file behind.

One module per command group (:mod:`.data`: simulate, inspect, import; :mod:`.model`: fit, predict;
:mod:`.study`: evaluate, report, demo; :mod:`.view`: view, replay, live), the parser in :mod:`.parser`, what the
commands share (loading, printing the plant) in :mod:`.context`. Commands parse, call the library and print: no
domain decision lives here.
"""

from workbench.cli.app import main
from workbench.cli.parser import build_parser

__all__ = ["main", "build_parser"]
