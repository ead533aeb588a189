"""`partial.removed_if_unfinished`: an output a command could not finish is removed; one
that existed before, or a finished one, is kept."""

from pathlib import Path

import pytest

from ssa_fusion.apps.partial import removed_if_unfinished


def test_an_unfinished_file_or_directory_is_removed_and_the_error_goes_on(tmp_path: Path):
    f, d = tmp_path / "x.oem", tmp_path / "bag"
    with pytest.raises(OSError, match="No space"), removed_if_unfinished(f):
        f.write_text("half")
        raise OSError(28, "No space left on device")
    with pytest.raises(KeyboardInterrupt), removed_if_unfinished(d):
        d.mkdir()
        (d / "bag.mcap").write_bytes(b"\x89MCAP0\r\n")
        raise KeyboardInterrupt
    assert not f.exists() and not d.exists()


def test_what_existed_before_and_what_was_finished_are_kept(tmp_path: Path):
    before = tmp_path / "before.txt"
    before.write_text("the user's")
    with pytest.raises(OSError), removed_if_unfinished(before):
        raise OSError(28, "No space left on device")
    assert before.read_text() == "the user's"
    done = tmp_path / "done.txt"
    with removed_if_unfinished(done):
        done.write_text("whole")
    assert done.read_text() == "whole"
