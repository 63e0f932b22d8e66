"""``python -m workbench`` runs the ``workbench`` command."""

import sys

try:
    from workbench.cli import main
except KeyboardInterrupt:  # Ctrl-C while the command line is still loading: the same one line as later
    import ctypes
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    ctypes.pythonapi.PyRun_SimpleString(b"")  # see workbench.cli.app._forget_escaped_interrupt
    print("interrupted", file=sys.stderr)
    raise SystemExit(130) from None

# guarded: a worker process started with ``spawn`` imports this module again (as ``__mp_main__``)
if __name__ == "__main__":
    raise SystemExit(main())
