"""One schema layer for the files a user writes.

Each file format is declared once, as a tree of pydantic models
(:mod:`railpilot.schema.fields`); from that declaration come the checks a reader runs
(:func:`~railpilot.schema.validate.check`, errors naming the key as the file writes it,
the value and what is allowed) and the format's JSON Schema
(:mod:`railpilot.schema.formats`, ``railpilot schema FORMAT``). Files are opened and
parsed in one place, :mod:`railpilot.schema.reading` (TOML, or JSON).
"""

from railpilot.schema.fields import FileTable
from railpilot.schema.formats import FORMATS, json_schema
from railpilot.schema.reading import read_document
from railpilot.schema.validate import check

__all__ = ["FORMATS", "FileTable", "check", "json_schema", "read_document"]
