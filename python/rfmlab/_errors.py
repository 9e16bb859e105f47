"""The exceptions of rfmlab (raised by the native module with the fields of the Rust errors)."""

from __future__ import annotations


class RfmlabError(Exception):
    """Base class of every error rfmlab raises."""


class StudyError(RfmlabError, ValueError):
    """A study or experiment file is wrong: names the file, the key and what to change.

    Attributes:
        file: the study (or experiment) file.
        key: the key in it, as dotted TOML path (``measurements.levels[0].files[0]``).
        message: what is wrong and how to fix it.
        fix: the part of the message that says what to do (the text after the last ``"; "``,
            or the whole message when it has no such part).
    """

    def __init__(self, file: str, key: str, message: str):
        self.file = file
        self.key = key
        self.message = message
        head, sep, tail = message.rpartition("; ")
        self.fix = tail if sep else message
        super().__init__(f"{file}: {key}: {message}")


class DataError(RfmlabError, ValueError):
    """A data file (UFF58, CSV) cannot be used: names the file, dataset and line when known."""

    def __init__(self, file: str, dataset: int | None, line: int | None, message: str):
        self.file = file
        self.dataset = dataset
        self.line = line
        self.message = message
        where = file
        if dataset is not None:
            where += f", dataset {dataset}"
        if line is not None:
            where += f", line {line}"
        super().__init__(f"{where}: {message}")


class RunError(RfmlabError, RuntimeError):
    """A computation failed (numerical failure, an engine that cannot be built, output)."""

    def __init__(self, message: str):
        self.message = message
        super().__init__(message)
