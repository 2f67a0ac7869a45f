"""An option the command line cannot parse is one line, like every other error: exit 2,
``railpilot: error: ...`` naming the option, and where the help is; no usage block."""

from __future__ import annotations

import pytest

from railpilot.cli import main


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["line", "run", "x.toml", "--http-port", "dashboard"], "--http-port"),
        (["drive", "heavy-haul", "--from", "1"], "--to"),
        (["simulate"], "scenario"),
        (["montecarlo", "x.toml", "--runs", "many"], "--runs"),
        (["no-such-command"], "COMMAND"),
    ],
)
def test_a_bad_option_is_one_line_naming_it(
    argv: list[str], named: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as ended:
        main(argv)
    assert ended.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("railpilot: error: ")
    assert named in err and "--help" in err
