"""The command line's backstop (issue 62): whatever message an exception carries, `vibid`
prints it as one line on stderr, never two."""

import pytest

import vibid.cli.modes
from vibid.cli import main, one_line
from vibid.errors import VibidError
from vibid.setup_model import SetupError

ARGV = ["modes", "setup.json", "--params", "D=1"]


def _raising(exc):
    def run(args):
        raise exc

    return run


@pytest.mark.parametrize(
    "exc, shown",
    [
        (VibidError("a\nb"), "vibid modes: error: a; b"),
        (
            VibidError("first\r\n\n  second\rthird\u2028fourth\x85fifth\n"),
            "vibid modes: error: first; second; third; fourth; fifth",
        ),
        (
            SetupError(["setup.x: bad\nvalue", "setup.y: missing"]),
            "vibid modes: error: setup.x: bad; value; setup.y: missing",
        ),
        (
            RuntimeError("boom\non two lines"),
            (
                "vibid modes: internal error: RuntimeError: boom; on "
                "two lines (run with --debug for the traceback)"
            ),
        ),
    ],
)
def test_an_error_message_with_line_breaks_is_printed_on_one_line(monkeypatch, capsys, exc, shown):
    monkeypatch.setattr(vibid.cli.modes, "run", _raising(exc))
    assert main(ARGV) == 1
    captured = capsys.readouterr()
    assert captured.err == shown + "\n"
    assert captured.err.splitlines() == [shown]
    assert captured.out == ""


def test_debug_still_raises_the_exception_itself(monkeypatch):
    monkeypatch.setattr(vibid.cli.modes, "run", _raising(VibidError("a\nb")))
    with pytest.raises(VibidError, match="^a\nb$"):
        main(["--debug", *ARGV])


def test_a_one_line_message_is_left_as_it_is():
    assert one_line("setup.x: must be positive, got -1.0") == "setup.x: must be positive, got -1.0"
    assert one_line(VibidError("--params: D is given twice")) == "--params: D is given twice"
