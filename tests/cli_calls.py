"""Calling the command line in process, as the CLI tests do: its exit code and output, and the one line a
refused command prints."""

from __future__ import annotations

import pytest

from pipelines.cli import main


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """``crowdmpc ARGV``'s exit code, stdout and stderr (output printed before the call is dropped)."""
    capsys.readouterr()
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def one_line(err: str) -> str:
    """The single line of ``err``, which holds no traceback."""
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def parser_error(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    """The one line of an argparse error (exit 2, nothing on stdout)."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(list(argv))
    assert exc.value.code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    return one_line(captured.err)
