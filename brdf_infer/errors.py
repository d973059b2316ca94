"""Errors raised for bad user input (files, scenes, parameters, options).

The command line turns a :class:`BadInputError` into one line on stderr and exit code 2.
"""

from __future__ import annotations

from pathlib import Path


class BadInputError(ValueError):
    """Bad user input, described in one line that names the file, row and field.

    Args:
        problem: what is wrong, in plain words.
        file: the offending file, if any.
        row: 1-based data row (the header is row 0), if any.
        line: 1-based line in the file, if it differs from what ``row`` implies.
        field: the column, key or option at fault, if any.
    """

    def __init__(
        self,
        problem: str,
        *,
        file: str | Path | None = None,
        row: int | None = None,
        line: int | None = None,
        field: str | None = None,
    ) -> None:
        self.problem = problem
        self.file = None if file is None else str(file)
        self.row = row
        self.line = line
        self.field = field
        super().__init__(self._message())

    def _message(self) -> str:
        where = []
        if self.file is not None:
            where.append(self.file)
        if self.row is not None:
            where.append(f"row {self.row}" + (f" (line {self.line})" if self.line else ""))
        elif self.line is not None:
            where.append(f"line {self.line}")
        if self.field is not None:
            where.append(f"field '{self.field}'")
        return _one_line((", ".join(where) + ": " if where else "") + self.problem)


def _one_line(text: str) -> str:
    """``text`` with every unprintable character (a line break, a NUL in a key or a file
    name) escaped, so that the message stays one line."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
