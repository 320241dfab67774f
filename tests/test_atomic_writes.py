"""Files are written whole or not at all: an error or an interrupt while writing leaves
the earlier file as it was and no partial or temporary file beside it."""

import os
import stat

import pytest

from jaxunilat._internal import write_atomically
from jaxunilat.plot import save_figure

OLD = "earlier contents\n"


@pytest.fixture
def existing(tmp_path):
    path = tmp_path / "out.csv"
    path.write_text(OLD)
    return path


def _names(folder):
    return sorted(os.listdir(folder))


def test_a_finished_block_replaces_the_file(existing):
    with write_atomically(existing) as f:
        f.write("new\n")
    assert existing.read_text() == "new\n"
    assert _names(existing.parent) == ["out.csv"]


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_an_error_midway_leaves_the_old_file(existing, error):
    with pytest.raises(error):
        with write_atomically(existing) as f:
            f.write("half of the new")
            raise error
    assert existing.read_text() == OLD
    assert _names(existing.parent) == ["out.csv"]


def test_no_replace_refuses_an_existing_file(existing):
    with pytest.raises(FileExistsError):
        with write_atomically(existing, replace=False) as f:
            f.write("new\n")
    assert existing.read_text() == OLD
    fresh = existing.parent / "fresh.csv"
    with write_atomically(fresh, replace=False) as f:
        f.write("new\n")
    assert fresh.read_text() == "new\n"


def test_a_file_that_appears_meanwhile_is_not_replaced(tmp_path):
    path = tmp_path / "late.csv"
    with pytest.raises(FileExistsError):
        with write_atomically(path, replace=False) as f:
            path.write_text(OLD)  # another program writes it first
            f.write("new\n")
    assert path.read_text() == OLD
    assert _names(tmp_path) == ["late.csv"]


def test_a_symlink_is_followed_and_kept(existing):
    link = existing.parent / "link.csv"
    link.symlink_to(existing.name)
    with write_atomically(link) as f:
        f.write("new\n")
    assert link.is_symlink() and existing.read_text() == "new\n"


def test_permissions_follow_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        with write_atomically(tmp_path / "a.txt") as f:
            f.write("x")
    finally:
        os.umask(old)
    assert stat.S_IMODE(os.stat(tmp_path / "a.txt").st_mode) == 0o644


def test_bytes_and_bad_modes(tmp_path):
    with write_atomically(tmp_path / "b.bin", "wb") as f:
        f.write(b"\x00\x01")
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    with pytest.raises(ValueError, match="mode = 'a'"):
        with write_atomically(tmp_path / "c.txt", "a"):
            pass


def test_save_figure_writes_the_suffixs_format_or_keeps_the_old_file(tmp_path):
    from matplotlib.figure import Figure

    fig = Figure()
    fig.add_subplot().plot([0, 1], [1, 0])
    save_figure(fig, tmp_path / "f.png")
    save_figure(fig, tmp_path / "f.svg")
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in (tmp_path / "f.svg").read_bytes()[:400]
    (tmp_path / "g.nosuchformat").write_text(OLD)
    with pytest.raises(ValueError):
        save_figure(fig, tmp_path / "g.nosuchformat")
    assert (tmp_path / "g.nosuchformat").read_text() == OLD
    assert _names(tmp_path) == ["f.png", "f.svg", "g.nosuchformat"]
