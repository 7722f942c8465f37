"""The command line's boundary: an error no check foresaw is one sentence on stderr and a crash log with
the traceback, never a traceback on the terminal (issue 17)."""
from __future__ import annotations

import app.cli as cli


def test_unexpected_error_is_one_sentence_and_a_crash_log(monkeypatch, tmp_path, capsys):
    def broken(args):
        raise KeyError("neutral")   # what a reader bug looks like from outside
    monkeypatch.setattr(cli, "cmd_info", broken)
    monkeypatch.setenv("BLENDSHAPE_STUDIO_LOGS", str(tmp_path / "logs"))
    code = cli.main(["info", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == cli.EXIT_UNEXPECTED != cli.EXIT_INPUT
    assert "Traceback" not in err and err.count("\n") == 1
    assert err.startswith("error: 'info' failed unexpectedly (KeyError: 'neutral'); the details are in ")
    logs = list((tmp_path / "logs").glob("crash-*.log"))
    assert len(logs) == 1 and str(logs[0]) in err
    text = logs[0].read_text()
    assert "Traceback (most recent call last)" in text and "in broken" in text and "KeyError: 'neutral'" in text


def test_bad_input_stays_exit_2_without_a_crash_log(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv("BLENDSHAPE_STUDIO_LOGS", str(tmp_path / "logs"))
    code = cli.main(["info", str(tmp_path / "no-such-rig")])
    assert code == cli.EXIT_INPUT
    assert not (tmp_path / "logs").exists()
    assert "no-such-rig" in capsys.readouterr().err


def test_out_of_memory_says_so(monkeypatch, tmp_path, capsys):
    def hungry(args):
        raise MemoryError()
    monkeypatch.setattr(cli, "cmd_info", hungry)
    monkeypatch.setenv("BLENDSHAPE_STUDIO_LOGS", str(tmp_path / "logs"))
    assert cli.main(["info", str(tmp_path)]) == cli.EXIT_UNEXPECTED
    assert "'info' ran out of memory; the details are in" in capsys.readouterr().err
