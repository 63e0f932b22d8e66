"""``python -m workbench`` runs the ``workbench`` command."""

from workbench.cli import main

# guarded: a worker process started with ``spawn`` imports this module again (as ``__mp_main__``)
if __name__ == "__main__":
    raise SystemExit(main())
