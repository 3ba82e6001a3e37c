"""Output paths are checked before any long work, errors name the user's path, and reports are
written with the user's umask."""

from __future__ import annotations

import json
import os
import stat
import sys

import pytest

from vibid.cli import main
from vibid.cli.paths import check_output_dir, check_output_file
from vibid.errors import VibidError
from vibid.hardware_mocks.records import synthetic_step
from vibid.report import write_report
from vibid.session import SessionWriter
from vibid.setup_model import example_setup


def _unwritable_dir(tmp_path):
    """A folder nobody may write in: a read-only folder, or /sys where root is refused too."""
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        if not sys.platform.startswith("linux"):
            pytest.skip("running as root: no folder refuses writing")
        return "/sys"
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(stat.S_IRUSR | stat.S_IXUSR)
    return str(folder)


@pytest.fixture
def session(tmp_path):
    path = tmp_path / "S.h5"
    with SessionWriter(path, example_setup()) as w:
        for k, f in enumerate((100.0, 200.0, 300.0)):
            base, response = synthetic_step(
                f,
                0.5 + 0.2j,
                sample_rate_hz=25600.0,
                n_samples=512,
                noise_std_m_s2=(1e-3, 1e-3),
                rng=k,
            )
            w.append(frequency_hz=f, sample_rate_hz=25600.0, base=base, response=response)
    return str(path)


@pytest.fixture
def no_work(monkeypatch):
    """Every long stage fails loudly if it is reached."""
    import vibid.cli.identify
    import vibid.hardware_mocks.simulated_session
    import vibid.identify.fit
    import vibid.session

    def reached(*_a, **_k):
        raise AssertionError("long work started before the output path was checked")

    monkeypatch.setattr(vibid.cli.identify, "_source", reached)
    monkeypatch.setattr(vibid.identify.fit, "identify", reached)
    monkeypatch.setattr(vibid.session, "read_session", reached)
    monkeypatch.setattr(vibid.hardware_mocks.simulated_session, "simulate_session", reached)


def _bad_targets(tmp_path):
    """(label, path, what the one line must say) for paths where no file can be written."""
    a_dir = tmp_path / "a-folder"
    a_dir.mkdir()
    return [
        ("missing folder", str(tmp_path / "no-such-folder" / "report.json"), "does not exist"),
        ("a directory", str(a_dir), "is a directory"),
        (
            "unwritable folder",
            os.path.join(_unwritable_dir(tmp_path), "report.json"),
            "cannot write in",
        ),
    ]


@pytest.mark.parametrize("command", ["identify", "afc"])
def test_json_path_is_refused_in_one_line_before_any_work(
    command, session, tmp_path, no_work, capsys
):
    for label, target, says in _bad_targets(tmp_path):
        argv = [command, session, "--json", target] + (
            ["--no-progress"] if command == "identify" else []
        )
        assert main(argv) == 1, label
        out, err = capsys.readouterr()
        assert out == ""
        assert err.count("\n") == 1, err
        assert err.startswith(f"vibid {command}: error: {target}: "), err
        assert says in err, (label, err)
        assert ".report-" not in err and "internal error" not in err


def test_simulate_refuses_an_existing_out_before_any_work(tmp_path, no_work, capsys):
    setup = tmp_path / "setup.json"
    setup.write_text(example_setup().to_json())
    existing = tmp_path / "S.h5"
    existing.write_bytes(b"precious")
    for target, says in [
        (str(existing), "already exists; a session file is never overwritten"),
        (str(tmp_path / "nowhere" / "S.h5"), "does not exist"),
        (str(tmp_path), "is a directory"),
    ]:
        assert main(["simulate", str(setup), "--out", target]) == 1
        err = capsys.readouterr().err
        assert err == f"vibid simulate: error: {target}: {err.split(': ', 3)[3]}"
        assert err.count("\n") == 1 and says in err, err
    assert existing.read_bytes() == b"precious"


def test_campaign_refuses_a_report_that_is_a_file_before_the_stand_opens(tmp_path, capsys):
    from vibid.hardware_mocks.virtual_stand import _STANDS

    setup = tmp_path / "setup.json"
    setup.write_text(example_setup().to_json())
    stand = tmp_path / "stand.json"
    stand.write_text(json.dumps({"generator": {"url": "vibidsim://report-is-a-file"}}))
    target = tmp_path / "report"
    target.write_text("a file, not a folder")
    assert (
        main(
            [
                "campaign",
                str(setup),
                "--stand",
                "simulated",
                "--stand-config",
                str(stand),
                "--out",
                str(tmp_path / "s.h5"),
                "--report",
                str(target),
            ]
        )
        == 1
    )
    assert (
        capsys.readouterr().err == f"vibid campaign: error: {target}: exists and is not a folder\n"
    )
    assert "report-is-a-file" not in _STANDS and not (tmp_path / "s.h5").exists()


def test_check_output_file_accepts_what_can_be_written(tmp_path):
    check_output_file(tmp_path / "new.json", overwrite=False)
    (tmp_path / "old.json").write_text("{}")
    check_output_file(tmp_path / "old.json", overwrite=True)
    check_output_dir(tmp_path / "made" / "here")
    assert (tmp_path / "made" / "here").is_dir()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "made",
        "old.json",
    ]  # no probe left behind
    with pytest.raises(VibidError, match="already exists"):
        check_output_file(tmp_path / "old.json", overwrite=False)


@pytest.mark.skipif(
    not hasattr(os, "umask") or sys.platform.startswith("win"), reason="POSIX modes"
)
@pytest.mark.parametrize(("umask", "mode"), [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_report_mode_follows_the_umask(umask, mode, tmp_path):
    old = os.umask(umask)
    try:
        path = tmp_path / "report.json"
        write_report({"a": 1.5}, path)
        assert stat.S_IMODE(os.stat(path).st_mode) == mode
        assert json.loads(path.read_text()) == {"a": 1.5}
        assert os.umask(umask) == umask  # the mask is left as it was
    finally:
        os.umask(old)


def test_report_error_names_the_users_path_not_a_temporary_file(tmp_path):
    target = tmp_path / "gone" / "report.json"
    with pytest.raises(VibidError) as exc:
        write_report({"a": 1}, target)
    assert str(exc.value).startswith(f"{target}: cannot write the report (")
    assert ".report-" not in str(exc.value)
    a_dir = tmp_path / "a-folder"
    a_dir.mkdir()
    with pytest.raises(VibidError, match=rf"^{a_dir}: cannot write the report"):
        write_report({"a": 1}, a_dir)
    assert list(a_dir.iterdir()) == [] and sorted(p.name for p in tmp_path.iterdir()) == [
        "a-folder"
    ]


def test_identify_refuses_a_report_folder_that_is_a_file_before_any_work(tmp_path, capsys, no_work):
    target = tmp_path / "report"
    target.write_text("a file, not a folder")
    assert main(["identify", str(tmp_path / "s.h5"), "--report", str(target), "--no-progress"]) == 1
    assert (
        capsys.readouterr().err == f"vibid identify: error: {target}: exists and is not a folder\n"
    )
