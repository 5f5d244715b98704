"""Exceptions and warnings of the catalogs package.

    CatalogError
    ├── UnknownStar(KeyError)           a name / HIP / designation not in the catalog
    ├── UnknownSampleSet(KeyError)      a bundled TLE set name that does not exist
    ├── UnknownSatellite(KeyError)      no satellite of that name/number in the elements
    ├── TleFormatError(ValueError)      a TLE line breaks the column layout
    │   └── TleChecksumError            ... or its modulo-10 checksum
    ├── OmmFormatError(ValueError)      an OMM JSON record lacks or mangles a field
    ├── ElementFileError(ValueError)    an element file that is no file to read (a device,
    │                                   a directory, too big, not text)
    └── StarCsvError(ValueError)        a user star catalog CSV row is wrong

    TleEpochWarning(UserWarning)        elements used far from their epoch
"""

from __future__ import annotations


class CatalogError(Exception):
    """Base of every error raised by the catalogs package."""


class UnknownStar(KeyError, CatalogError):
    """No star answers to the query; carries the query and close matches."""

    def __init__(self, query: str, suggestions: list[str]):
        self.query = query
        self.suggestions = list(suggestions)
        hint = f"; did you mean: {', '.join(self.suggestions)}?" if self.suggestions else ""
        super().__init__(
            f"unknown star {query!r}{hint} (give a name, 'HIP 91262' or a designation like 'alf Lyr')"
        )

    def __str__(self) -> str:  # KeyError would quote the whole message
        return str(self.args[0])


class UnknownSampleSet(KeyError, CatalogError):
    """The requested bundled TLE set does not exist."""

    def __init__(self, name: str, available: list[str]):
        self.name = name
        self.available = list(available)
        super().__init__(f"no bundled TLE set {name!r}; available: {', '.join(self.available)}")

    def __str__(self) -> str:
        return str(self.args[0])


class UnknownSatellite(KeyError, CatalogError):
    """No element set in the file answers to the satellite name or number."""

    def __init__(self, query: str, suggestions: list[str]):
        self.query = query
        self.suggestions = list(suggestions)
        hint = f"; did you mean: {', '.join(self.suggestions)}?" if self.suggestions else ""
        super().__init__(f"no satellite {query!r} in the elements{hint}")

    def __str__(self) -> str:
        return str(self.args[0])


class TleFormatError(ValueError, CatalogError):
    """A TLE line does not follow the two-line element layout.

    ``str(err)`` shows the file and line number, what is wrong, the expected column
    template and the offending line with a caret under the first bad column.
    """

    def __init__(self, source: str, line_number: int, line: str, problem: str,
                 template: str = "", column: int | None = None):
        self.source = source
        self.line_number = line_number
        self.line = line
        self.problem = problem
        self.template = template
        self.column = column  # 1-based, as in the TLE documentation
        text = f"{source}, line {line_number}: {problem}"
        if template:
            text += f"\nexpected layout:\n  {template}\ngot:\n  {line}"
            if column is not None:
                text += "\n  " + " " * (column - 1) + "^"
        super().__init__(text)


class TleChecksumError(TleFormatError):
    """The modulo-10 checksum in column 69 does not match the line."""


class OmmFormatError(ValueError, CatalogError):
    """An OMM (JSON) record is missing a field or has a value of the wrong form."""

    def __init__(self, source: str, index: int, problem: str):
        self.source = source
        self.index = index
        self.problem = problem
        super().__init__(f"{source}, OMM record {index}: {problem}")


class ElementFileError(ValueError, CatalogError):
    """A TLE/OMM file cannot be read as one: missing, not a regular file, too big, not text."""


class StarCsvError(ValueError, CatalogError):
    """A row of a user star catalog CSV cannot be read."""

    def __init__(self, source: str, line_number: int, problem: str):
        self.source = source
        self.line_number = line_number
        self.problem = problem
        super().__init__(f"{source}, line {line_number}: {problem}")


class TleEpochWarning(UserWarning):
    """Orbital elements are used more than the allowed number of days from their epoch."""
