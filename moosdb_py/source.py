"""Where a line of a mission file came from, so every error can name file and line."""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple


class SourceLine(NamedTuple):
    """One line of preprocessed text and the file and 1-based line number it came from."""

    text: str
    file: Path
    line: int


class MissionFileError(ValueError):
    """A mission (.moos/.bhv) file that cannot be read; str() is `file:line: message`."""

    def __init__(self, file: Path | str, line: int, message: str):
        self.file = Path(file)
        self.line = line
        self.message = message
        super().__init__(f"{self.file}:{line}: {message}")

    @classmethod
    def at(cls, where: SourceLine, message: str) -> "MissionFileError":
        return cls(where.file, where.line, message)
