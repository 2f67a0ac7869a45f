"""The trains railpilot ships, by the name ``railpilot drive --train`` and a line run's
service ``kind`` give them.

Names and data only, so that the command line lists them without building one (building a
train pulls in the whole simulation core): onboard/drive.py builds each from its consist
preset (scenario/consist_file.py).
"""

from __future__ import annotations

from typing import NamedTuple


class ShippedTrain(NamedTuple):
    """A shipped train: the consist preset it is made of and its speed-limit category."""

    consist: str
    category: str


#: the trains ``railpilot drive --train`` and a line run's services can name
SHIPPED_TRAINS: dict[str, ShippedTrain] = {
    "heavy-haul-loaded": ShippedTrain("heavy-haul-10kt", "freight_loaded"),
    "heavy-haul-empty": ShippedTrain("heavy-haul-10kt-empty", "freight_empty"),
    "heavy-haul-20kt": ShippedTrain("heavy-haul-20kt-dp", "freight_loaded"),
}
