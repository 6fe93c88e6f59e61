"""An unknown option is reported with the usage of the subcommand it was given
to, on every command line (issue 19: ``linksim arm-server --json`` printed
linksim's top-level usage, which lists subcommands, not options)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import pytest

from linksim.cli import _main as linksim_cli
from serialsocket import _cli as serial_cli
from tcpstream import _cli as tcpstream_cli

Main = Callable[[Sequence[str] | None], int]

CASES: list[tuple[Main, list[str], str]] = [
    (linksim_cli.main, ["arm-server", "--bogus"], "linksim arm-server"),
    (linksim_cli.main, ["demo", "--virtual", "--bogus"], "linksim demo"),
    (linksim_cli.main, ["bench", "goodput", "--bogus"], "linksim bench goodput"),
    (linksim_cli.main, ["relay", "--bogus"], "linksim relay"),
    (serial_cli.main, ["listen", "--bogus", "/dev/null"], "listen"),
    (tcpstream_cli.main, ["decode", "--bogus"], "decode"),
]


@pytest.mark.parametrize(("main", "argv", "command"), CASES)
def test_an_unknown_option_shows_its_subcommand_s_usage(
    main: Main, argv: list[str], command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    usage = err.splitlines()[0]
    assert usage.startswith("usage: "), err
    assert f"{command} [-h]" in usage, err
    assert f"{command}: error: unrecognized arguments: --bogus" in err
