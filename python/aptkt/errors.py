"""Typed errors of aptkt. Everything raised on purpose derives from :class:`AptktError`."""

from __future__ import annotations

from typing import Any

#: An :class:`aptkt.skin.samples.Recording`. Errors are the bottom layer: they name no module
#: above them, not even for annotations (the layers test reads those as a cycle).
Recording = Any

__all__ = [
    "AptktError",
    "InvalidInputError",
    "InvalidTypeError",
    "UnknownNameError",
    "IndexOutOfRangeError",
    "InvalidStateError",
    "SkinError",
    "SkinDisconnectedError",
    "SilentCellError",
    "RobotError",
    "SafetyLimitError",
    "ProtectiveStopError",
    "RobotConnectionError",
    "ProgramStoppedError",
    "TrialFault",
    "TrialInterrupted",
    "ConfigError",
    "FeatureTableError",
    "RawDataError",
    "PriorFileError",
    "IncompatiblePriorsError",
    "DatasetError",
    "Terminated",
    "WorkerDiedError",
    "NotFittedError",
    "ModelFileError",
    "KernelNotPositiveDefiniteError",
    "ProblemTooLargeError",
    "NonFiniteResultError",
]


class AptktError(Exception):
    """Base class of every error raised on purpose by aptkt.

    Each typed error also derives from the builtin a Python user would catch for the same
    mistake (as numpy's ``AxisError`` is a ``ValueError`` and an ``IndexError``), so
    ``except ValueError`` written before the typed errors existed keeps working.
    """


class InvalidInputError(AptktError, ValueError):
    """An argument or an input array has a bad value: a wrong shape, a value out of range, NaN
    or infinity where a finite number is needed; the message names it. The Rust core's checks
    of its input raise this too."""


class InvalidTypeError(AptktError, TypeError):
    """An argument is of the wrong type or dtype; the message names the argument."""


class UnknownNameError(AptktError, KeyError):
    """A name (an action, an object, a field, a stored result) that is not among the known
    ones; the message names it and, where they are few, the known ones."""

    def __str__(self) -> str:
        # KeyError's own __str__ shows the repr of its argument, quotes and escapes included:
        # the message is a sentence, not a key.
        return str(self.args[0]) if len(self.args) == 1 else super().__str__()


class IndexOutOfRangeError(AptktError, IndexError):
    """An index (a recording, a classifier) outside the valid range, which the message gives."""


class InvalidStateError(AptktError, RuntimeError):
    """An operation the object cannot do in its current state: used before it was fitted or
    given data, outside its ``with`` block, twice at once; or a state the work cannot go on
    from (a stored result that disappeared, a worker thread that failed)."""


class KernelNotPositiveDefiniteError(AptktError, ValueError):
    """A kernel matrix stayed non-positive-definite even after the largest permitted jitter.

    A ``ValueError``, as numpy's ``LinAlgError`` is: the matrix is degenerate because of the
    input (duplicate rows, hyper-parameters such as a transfer lambda outside [0, 1]), not
    because of a fault of the machine. The message says what to check.
    """


class ProblemTooLargeError(AptktError, MemoryError):
    """The work needs more memory than this machine has; found before allocating it. The
    message names the rows and the bytes needed.

    A ``MemoryError``, which is what the allocation would have raised had it been tried.
    """


class NonFiniteResultError(InvalidInputError):
    """A computation on finite input overflowed to infinity or NaN (the input's values are too
    large for float64 arithmetic); the message names the input. A ``ValueError``: the remedy
    is to rescale the input."""


class ConfigError(AptktError, ValueError):
    """A configuration file or value is invalid; the message names the file and the field."""


class FeatureTableError(ConfigError):
    """A feature table (CSV or HDF5) is malformed; the message names the file, row and column."""


class RawDataError(ConfigError):
    """An imported data set's raw files are missing or malformed; the message names the file and
    the line."""


class PriorFileError(AptktError, ValueError):
    """A prior-knowledge file is not one, is damaged, or is inconsistent; the message names the
    file and the member."""


class IncompatiblePriorsError(AptktError, ValueError):
    """Prior-knowledge files that cannot be merged into one library: other actions, feature
    columns, extraction settings, metric or action definitions, or an object in two of them;
    the message names the difference."""


class DatasetError(AptktError):
    """A data set file is missing, not an aptkt data set, of another schema version, or
    cannot be written (e.g. a writer died: run ``aptkt dataset repair``)."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, a scheduler ending a job): handled exactly like Ctrl-C — the arm
    stops and retracts, the partial recording is saved — then the command exits with 143."""


class WorkerDiedError(AptktError):
    """A worker process ended abruptly (killed, out of memory, crashed) in the middle of a
    task. What the main process had already written is kept; the message says how to go on."""


class NotFittedError(AptktError, AttributeError):
    """A model was used before ``fit``."""


class ModelFileError(AptktError, ValueError):
    """A saved model (``LaplaceGPC.save``) is not one, is damaged, inconsistent or too large;
    the message names the file and the member."""


class SkinError(AptktError):
    """The skin link failed."""


class SkinDisconnectedError(SkinError):
    """The port is missing, busy, or was unplugged mid-stream. Data recorded so far is kept."""


class SilentCellError(SkinError):
    """A cell of the patch stopped sending during a recording."""


class RobotError(AptktError):
    """The robot could not complete a motion. It has been stopped; recorded data is kept."""


class SafetyLimitError(RobotError):
    """A force, speed, acceleration or workspace limit would have been or was exceeded."""


class ProtectiveStopError(RobotError):
    """The controller entered a protective or emergency stop."""


class RobotConnectionError(RobotError):
    """The connection to the controller was lost or could not be established."""


class ProgramStoppedError(RobotError):
    """The control program on the controller stopped or paused (pendant or dashboard stop, the
    controller's communication watchdog, a script error); the arm no longer follows commands."""


class TrialFault(AptktError):
    """A robot or skin fault ended an exploratory trial after its recording had started.

    ``cause`` is the robot or skin error (also ``__cause__``); the backend has stopped the arm.
    ``recording`` is what the skin recorded: the partial recording of the movement that failed
    (``metadata["aborted"]`` names the error), or the whole, cropped recording when ``complete``
    is True, i.e. the action itself finished and the fault came afterwards (lifting, waiting).
    """

    def __init__(self, cause: BaseException, recording: Recording, *, complete: bool = False):
        super().__init__(f"{type(cause).__name__}: {cause}")
        self.cause = cause
        self.recording = recording
        self.complete = complete


class TrialInterrupted(KeyboardInterrupt):
    """Ctrl-C in the middle of a trial. Still a :class:`KeyboardInterrupt` (everything stops as
    for any Ctrl-C), with what the skin had recorded, as on a :class:`TrialFault` (``complete``:
    the action had finished, the signal came while lifting off or waiting)."""

    def __init__(self, cause: KeyboardInterrupt, recording: Recording, *, complete: bool = False):
        super().__init__(*cause.args)
        self.cause = cause
        self.recording = recording
        self.complete = complete
