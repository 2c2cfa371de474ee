"""Typed errors of aptkt. Everything raised on purpose derives from :class:`AptktError`."""

from __future__ import annotations

from typing import TYPE_CHECKING

from aptkt._core import (
    AptktError,
    KernelNotPositiveDefiniteError,
    NonFiniteResultError,
    ProblemTooLargeError,
)

if TYPE_CHECKING:  # for annotations only: errors are the bottom layer and import nothing above
    from aptkt.skin.samples import Recording

__all__ = [
    "AptktError",
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
    for any Ctrl-C), with what the skin had recorded, as on a :class:`TrialFault`."""

    def __init__(self, cause: KeyboardInterrupt, recording: Recording):
        super().__init__(*cause.args)
        self.cause = cause
        self.recording = recording
        self.complete = False
