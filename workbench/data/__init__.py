"""The common format (floor 1): demonstrations, datasets of them, and the vehicle roles.

The only part of the workbench that :mod:`adapters` may import: readers and the model meet here.
"""

from workbench.exports import lazy_exports

_EXPORTS = {
    "Partition": "dataset",
    "Manifest": "dataset",
    "DatasetWriter": "dataset",
    "DataRef": "dataset",
    "is_dataset": "dataset",
    "read_manifest": "dataset",
    "load_dataset": "dataset",
    "write_dataset": "dataset",
    "write_partitions": "dataset",
    "join_sets": "dataset",
    "Demonstration": "demonstrations",
    "DemonstrationSet": "demonstrations",
    "PilotTask": "pilot_task",
    "Roles": "roles",
    "Selection": "selection",
    "select_trials": "selection",
    "ResolvedRoles": "roles",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
