"""The timetable file's format (``railpilot drive --timetable FILE``): planned running
times between consecutive stops.

These models check each key alone; that a section runs between two stations and that the
sections chain (each starts where the one before ended) are the reader's rules,
railpilot.onboard.timetable.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated

from pydantic import Field

from railpilot.schema.fields import NOT_GIVEN, FileTable, Says, Unit, WhenMissing, Words

#: the longest running time of a section [s]: a day
MAX_RUNNING_TIME_S = 86_400.0

STATION_ID = "a station id (an integer >= 0)"
RUNNING_TIME = f"a running time in (0, {MAX_RUNNING_TIME_S:g}] s"
SECTIONS = "a non-empty list of [[sections]] tables"


class TimetableWords(Words):
    """The timetable's way: an unknown key is told the table's keys; a key's words are
    the same whether it is wrong or missing."""

    unknown_key = "one of {keys}"

    @staticmethod
    def table(keys: Sequence[str]) -> str:
        return "a table with " + ", ".join(keys)


class TimetableTable(FileTable):
    WORDS = TimetableWords


StationId = Annotated[int, Field(ge=0), Says(STATION_ID), WhenMissing(STATION_ID)]


class SectionTable(TimetableTable):
    """``[[sections]]``: the planned run from station ``from`` to station ``to`` (station
    ids of the line); each section starts where the one before ended."""

    from_: Annotated[StationId, Field(alias="from")]
    to: StationId
    running_time_s: Annotated[
        float,
        Field(gt=0.0, le=MAX_RUNNING_TIME_S),
        Unit("s"),
        Says(RUNNING_TIME),
        WhenMissing(RUNNING_TIME),
    ]


class TimetableFile(TimetableTable):
    """A timetable: planned running times between consecutive stops of a run."""

    #: default: the file's name without its extension
    name: str = NOT_GIVEN
    sections: Annotated[
        list[SectionTable], Field(min_length=1), Says(SECTIONS), WhenMissing(SECTIONS)
    ]
