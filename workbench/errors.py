"""The workbench's exceptions.

Every failure a user can cause (a bad file, bad data, an ill-posed model) raises a subclass of
:class:`WorkbenchError` whose message names the file, the place and the cause, so that the CLI can print one
clear line instead of a traceback.
"""

from __future__ import annotations

__all__ = [
    "WorkbenchError",
    "DataError",
    "FormatError",
    "MappingError",
    "AbsentSource",
    "RequestError",
    "ModelError",
    "PlantRefused",
    "SolverError",
    "UsageError",
    "WorkbenchWarning",
    "ConvergenceWarning",
    "DegenerateFitWarning",
]


class WorkbenchError(Exception):
    """Base class of every error the workbench raises on purpose."""


class DataError(WorkbenchError, ValueError):
    """Demonstration data or a data file is invalid (lengths, non-finite values, time, format)."""


class FormatError(DataError):
    """A file is not of the format it claims to be, or is of a newer format version."""


class MappingError(DataError):
    """A channel mapping names something the log does not contain, or is malformed."""


class AbsentSource(MappingError):
    """A mapping's source names a stream or field this log does not hold (or holds only in damaged data, or declares
    and never wrote): the log lacks it, the mapping may be right. Every other MappingError is the mapping's own."""


class ModelError(WorkbenchError, ValueError):
    """A model cannot be fitted or used: rank-deficient data, a non-stabilizing gain, a bad model file."""


class PlantRefused(ModelError):
    """An identified plant the recorded data show is not physics (:func:`workbench.plant.choice.choose_plant`): the
    message is the one-line refusal, ``report`` the identification report it refers to (printed before it)."""

    def __init__(self, message: str, report: object = None) -> None:
        super().__init__(message)
        self.report = report


class SolverError(ModelError):
    """Every solver in the chain failed or returned a solution that did not pass the post-checks."""


class UsageError(WorkbenchError, ValueError):
    """A command's arguments do not go together, or one is malformed in a way the parser cannot check (``predict``
    without a trial or a state, ``-o -`` for a folder): the command line says so in one line with argparse's exit
    status, 2."""


class RequestError(DataError):
    """A request to the testbed's server that it refuses (``workbench collect``): ``status`` is its HTTP status
    (400 bad input, 403 a foreign origin or a missing token, 409 to be confirmed, 413 too large, 415 not JSON …);
    ``extra`` is sent with the one-line message (e.g. what the page should ask the subject to confirm)."""

    def __init__(self, message: str, status: int = 400, **extra: object) -> None:
        super().__init__(message)
        self.status = status
        self.extra = extra


class WorkbenchWarning(UserWarning):
    """Base class of every warning the workbench gives on purpose (the result exists, but look at it)."""


class ConvergenceWarning(WorkbenchWarning):
    """An iterative fit (EM) stopped at ``max_iter`` before meeting its tolerance."""


class DegenerateFitWarning(WorkbenchWarning):
    """A model was fitted on too few distinct demonstrations to say much about how an operator flies."""
