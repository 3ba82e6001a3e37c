"""`vibid identify`: bad input gives a one-line error and exit code 1."""

from vibid.cli import main


def test_missing_session_is_a_one_line_error(tmp_path, capsys):
    rc = main(["identify", str(tmp_path / "nope.h5"), "--json", str(tmp_path / "r.json")])
    err = capsys.readouterr().err.strip()
    assert rc == 1
    assert err.startswith("vibid identify: error:") and "\n" not in err
    assert not (tmp_path / "r.json").exists()


def test_help_lists_the_options(capsys):
    try:
        main(["identify", "--help"])
    except SystemExit as exc:
        assert exc.code == 0
    out = capsys.readouterr().out
    assert "--json" in out and "--method" in out and "--seed" in out
