"""Exception hierarchy: every error a user can cause is an `RtsError` with one clear message."""

from __future__ import annotations


class RtsError(Exception):
    """Base of every error the package raises on purpose."""


class ScenarioError(RtsError):
    """A scene, rig or profile file is invalid.

    The message reads ``file:line:col: key.path: message`` so editors and people can jump to it.
    """

    def __init__(
        self,
        message: str,
        *,
        file: str | None = None,
        line: int | None = None,
        column: int | None = None,
        key_path: str | None = None,
    ) -> None:
        self.file = file
        self.line = line
        self.column = column
        self.key_path = key_path
        self.detail = message
        where = ""
        if file is not None:
            where = str(file)
            if line is not None:
                where += f":{line}"
                if column is not None:
                    where += f":{column}"
            where += ": "
        key = f"{key_path}: " if key_path else ""
        super().__init__(f"{where}{key}{message}")


class SettingError(RtsError, ValueError):
    """An environment variable the package reads holds a value it does not know."""


class ArrayError(RtsError):
    """A radar virtual array definition is invalid."""


class RigError(RtsError):
    """An RTS rig definition is invalid.

    ``key`` names the offending field (``az_deg``, ``limits.doppler_min_hz``) and ``fe`` the
    front end (row-major index), when the error is about one, so that a rig file can point at it.
    """

    def __init__(self, message: str, *, key: str | None = None, fe: int | None = None) -> None:
        self.key = key
        self.fe = fe
        super().__init__(message)


class SolverError(RtsError):
    """The weight solver was called with invalid input."""


class OutputError(RtsError):
    """An output cannot be created or written."""


class CheckError(RtsError):
    """Detections cannot be checked against ground truth."""


class BusError(CheckError):
    """A CAN interface or channel the arguments name cannot be opened (bad input)."""


class MeasurementError(CheckError):
    """A measurement through the bench (`Pipeline.play`) whose cycles cannot be trusted.

    The radar's identifiers came on several channels, or none on ``--radar-channel``: what
    was measured would mix another bus's cycles in, or hold none of the radar's; or a
    calibration's FE alone or pair was not reported, or missed cycles when measured twice.
    ``survey`` and ``calibrate`` fail with it
    (exit 1), as with any other measurement that failed.
    """


def one_line(exc: BaseException) -> str:
    """Return an exception's message on one line (the CLI prints one ``error:`` line)."""
    return " ".join(part.strip() for part in str(exc).splitlines() if part.strip()) or repr(exc)


def located(path: str, exc: BaseException) -> str:
    """Return the error's message, starting with the scene file when the error does not name it."""
    message = one_line(exc)
    if isinstance(exc, ScenarioError) and exc.file is not None:
        return message
    return f"{path}: {message}"
