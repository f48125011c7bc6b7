"""A file that a command writes at the end of its run (``--json``, ``--plot``, ``--series``) is checked when
the command line is read: a launch, a campaign or a bench of minutes is not lost to a mistyped folder."""

from __future__ import annotations

import os

import pytest

from swarm.cli.main import build_parser

COMMANDS = [
    ["sim", "docking", "--json"],
    ["sim", "docking", "--plot"],
    ["launch", "docking", "--json"],
    ["montecarlo", "docking", "--json"],
    ["bench", "transport", "--json"],
    ["bench", "swarm", "--json"],
    ["replay", "LOG", "--json"],
    ["replay", "LOG", "--plot"],
    ["replay", "LOG", "--series"],
]


def _refused(capsys, argv: list[str]) -> str:
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2
    return capsys.readouterr().err


@pytest.mark.parametrize("argv", COMMANDS, ids=lambda a: " ".join(a))
def test_an_output_file_in_a_missing_folder_or_a_folder_is_refused_before_the_run(argv, tmp_path, capsys):
    flag = argv[-1]
    missing = tmp_path / "no-such-folder" / "out.json"
    err = _refused(capsys, [*argv, str(missing)])
    assert f"argument {flag}: {flag}: no such folder {str(missing.parent)!r}" in err, err
    err = _refused(capsys, [*argv, str(tmp_path)])
    assert f"{flag} must name a file to write, got {str(tmp_path)!r} (a folder)" in err, err
    ok = build_parser().parse_args([*argv, str(tmp_path / "out.x")])
    assert getattr(ok, flag.lstrip("-")) == tmp_path / "out.x"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder")
def test_an_output_file_in_a_folder_without_write_permission_is_refused(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        err = _refused(capsys, ["sim", "docking", "--json", str(ro / "out.json")])
    finally:
        ro.chmod(0o700)
    assert f"--json: folder {str(ro)!r} is not writable" in err, err


def test_a_dash_stays_none_for_replays_series_and_a_bare_name_is_in_the_current_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert str(build_parser().parse_args(["replay", "LOG", "--series", "-"]).series) == "-"
    assert str(build_parser().parse_args(["sim", "docking", "--json", "out.json"]).json) == "out.json"
