"""Timetables for ``railpilot drive --timetable`` (railpilot.onboard.timetable)."""

import pytest

from railpilot.cli import main
from railpilot.errors import ConfigError
from railpilot.line import load_line
from railpilot.onboard.timetable import load_timetable, parse_timetable


def section(a, b, t):
    return {"from": a, "to": b, "running_time_s": t}


def test_the_shipped_timetable_chains_every_station_of_the_line():
    timetable = load_timetable("heavy-haul")
    ids = [s.id for s in load_line("heavy-haul").stations]
    assert [s.from_id for s in timetable.sections] == ids[:-1]
    assert [s.to_id for s in timetable.sections] == ids[1:]
    assert all(s.running_time_s > 0 for s in timetable.sections)


def test_between_picks_the_chained_sections():
    timetable = parse_timetable(
        {"sections": [section(1, 2, 10.0), section(2, 3, 20.0), section(3, 4, 30.0)]}
    )
    assert [s.to_id for s in timetable.between(2, 4)] == [3, 4]
    with pytest.raises(ConfigError) as err:
        timetable.between(5, 6)
    assert err.value.field == "--from"
    with pytest.raises(ConfigError) as err:
        timetable.between(2, 1)
    assert err.value.field == "--to"


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ({"sections": []}, "sections"),
        ({"sections": [section(1, 2, 0.0)]}, "sections[0].running_time_s"),
        ({"sections": [section(1, 2, 10.0), section(3, 4, 10.0)]}, "sections[1].from"),
        ({"sections": [section(1, 1, 10.0)]}, "sections[0].to"),
        ({"sections": [section(1, True, 10.0)]}, "sections[0].to"),
        ({"sections": [{**section(1, 2, 10.0), "dwell_s": 5}]}, "sections[0].dwell_s"),
    ],
)
def test_bad_timetables_name_the_entry(data, field):
    with pytest.raises(ConfigError) as err:
        parse_timetable(data)
    assert err.value.field == field


def test_a_missing_timetable_file_exits_2_and_writes_nothing(tmp_path, capsys):
    code = main(
        [
            "drive",
            "heavy-haul",
            "--from",
            "1",
            "--to",
            "3",
            "--timetable",
            str(tmp_path / "none.toml"),
            "--out",
            str(tmp_path / "out"),
            "--json",
        ]
    )
    assert code == 2
    assert capsys.readouterr().out == ""
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_two_sections_of_the_shipped_timetable(capsys):
    import json

    assert (
        main(
            [
                "drive",
                "heavy-haul",
                "--from",
                "1",
                "--to",
                "3",
                "--timetable",
                "heavy-haul",
                "--json",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert [(s["from"], s["to"]) for s in out["sections"]] == [(1, 2), (2, 3)]
    assert out["timetable_running_time_s"] == pytest.approx(
        sum(s.running_time_s for s in load_timetable("heavy-haul").between(1, 3))
    )
    for s in out["sections"]:
        assert s["conformity_pct"] == pytest.approx(
            (s["running_time_s"] - s["timetable_running_time_s"])
            / s["timetable_running_time_s"]
            * 100
        )
