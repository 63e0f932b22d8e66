"""``workbench collect`` (floor 5): the paper's human-subject landing experiment as a local server and a browser page.

The page (plain ES modules in ``static/``, served locally) flies the landing task with the plant the server hands
it (:mod:`.task`), following a protocol file (:mod:`.protocol`); the server (:mod:`.server`, Starlette on uvicorn,
127.0.0.1 by default) replays every finished trial through the plant and writes it at once into the session folder
(:mod:`.session`), a dataset that ``workbench fit/evaluate/report/view`` read as it is. The server is guarded for a
lab's network (:mod:`.guard`); a protocol's ``fit`` step fits the subject's own model between blocks
(:mod:`.fitting`); :mod:`.records` writes ``trials.csv``, the data dictionary and the experimenter's exclusions.
"""

from workbench.exports import lazy_exports

_EXPORTS = {
    "Protocol": "protocol",
    "SHIPPED": "protocol",
    "load_protocol": "protocol",
    "Session": "session",
    "set_exclusion": "records",
    "Server": "server",
    "make_app": "server",
    "task_spec": "task",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
