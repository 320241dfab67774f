"""No output ever replaces something that is not a regular file.

A character device or a FIFO named as an output (`/dev/stdout`, `/dev/null`, a named
pipe) is written through, and is still the same device or FIFO afterwards; a socket or
a block device is refused. Every output flag of the command line is tried, with
private device nodes (`mknod`, skipped where the sandbox forbids it) and FIFOs made in
the test's own folder: never the system's own `/dev` entries.
"""

import errno
import os
import socket
import stat
import threading
import time

import pytest
from test_output_paths import COMMANDS, DATA_DIR, FLAGS, _command_line

from jaxunilat._cli._main import main
from jaxunilat._internal import special_kind, write_atomically

#: Arguments that make a command run to the end on its test input (the collision test's
#: rows need only get past the argument checks).
RUNS = {("import", "video"): ["--scale", "1"]}
NULL_DEVICE = os.makedev(1, 3)  # Linux's null device: what a stray write to it costs is nothing


def _null_node(path) -> str:
    """A private character device node equal to /dev/null, or skip where mknod is not allowed."""
    try:
        os.mknod(path, 0o666 | stat.S_IFCHR, NULL_DEVICE)
    except (PermissionError, OSError) as err:
        pytest.skip(f"cannot make a device node here ({err})")
    return str(path)


class _Reader:
    """Reads a FIFO to its end in a thread: what a shell's `cmd | other` reader does."""

    def __init__(self, path):
        self.path = str(path)
        self.data = b""
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self):
        with open(self.path, "rb") as f:  # blocks until the writer opens the FIFO
            self.data = f.read()

    def join(self) -> bytes:
        deadline = time.monotonic() + 10
        while self._thread.is_alive() and time.monotonic() < deadline:
            try:  # nobody wrote: open the write end (once the reader is there) so it ends
                os.close(os.open(self.path, os.O_WRONLY | os.O_NONBLOCK))
                break
            except OSError as err:
                if err.errno != errno.ENXIO:  # ENXIO: the reader has not opened it yet
                    raise
                time.sleep(0.01)
        self._thread.join(timeout=30)
        return self.data


def _is_null_device(path) -> bool:
    st = os.lstat(path)
    return stat.S_ISCHR(st.st_mode) and st.st_rdev == NULL_DEVICE


def _file_flags():
    for command, flag in FLAGS:
        if flag not in COMMANDS.get(command, {}).get("dirs", ()):
            yield pytest.param(command, flag, id=f"{' '.join(command)} {flag}")


# -- the writer itself ---------------------------------------------------------------


def test_a_device_is_written_through_and_stays_a_device(tmp_path):
    node = _null_node(tmp_path / "null")
    for mode, payload in (("w", "text\n"), ("wb", b"\x00bytes")):
        with write_atomically(node, mode) as f:
            f.write(payload)
        assert _is_null_device(node)
    assert os.listdir(tmp_path) == ["null"]  # no temporary file left beside it


def test_a_symlink_to_a_device_keeps_both(tmp_path):
    """`--out /dev/stderr 2>/dev/null`: the name is a link whose target is the null device."""
    node = _null_node(tmp_path / "null")
    link = tmp_path / "stderr"
    link.symlink_to(node)
    with write_atomically(link) as f:
        f.write("x\n")
    assert link.is_symlink() and _is_null_device(node)


def test_a_fifo_gets_the_whole_output_and_stays_a_fifo(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    reader = _Reader(fifo)
    with write_atomically(fifo, encoding="utf-8") as f:
        f.write("t,x\n" + "0,1\n" * 50_000)  # larger than a pipe's buffer
    assert reader.join() == ("t,x\n" + "0,1\n" * 50_000).encode()
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_a_fifo_nobody_reads_is_refused_without_waiting(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="FIFO that no process is reading"):
        with write_atomically(fifo) as f:
            f.write("x")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_a_failed_block_writes_nothing_to_a_fifo(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    reader = _Reader(fifo)
    with pytest.raises(RuntimeError):
        with write_atomically(fifo) as f:
            f.write("half")
            raise RuntimeError
    assert reader.join() == b"" and stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_a_socket_is_refused_and_kept(tmp_path):
    path = str(tmp_path / "sock")
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(path)
        assert special_kind(path) == "socket"
        with pytest.raises(ValueError, match="is a socket; give a regular file"):
            with write_atomically(path) as f:
                f.write("x")
        assert stat.S_ISSOCK(os.lstat(path).st_mode)


def test_a_cache_refuses_any_special_file(tmp_path):
    fifo = tmp_path / "entry"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="is a FIFO"):
        with write_atomically(fifo, "wb", special="refuse") as f:
            f.write(b"x")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_a_special_file_that_appears_before_the_move_is_not_replaced(tmp_path):
    target = tmp_path / "late"
    with pytest.raises(ValueError, match="is a FIFO; refusing to replace it"):
        with write_atomically(target) as f:
            os.mkfifo(target)  # another program makes a FIFO there meanwhile
            f.write("x")
    assert stat.S_ISFIFO(os.lstat(target).st_mode)
    assert os.listdir(tmp_path) == ["late"]


# -- every output flag of the command line -----------------------------------------------


@pytest.mark.parametrize("command, flag", list(_file_flags()))
@pytest.mark.parametrize("kind", ["device", "fifo"])
def test_every_output_flag_writes_through_a_special_file(kind, command, flag, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv, inputs = _command_line(command, tmp_path)
    argv += RUNS.get(command, [])
    if command == ("qualify",):  # a real fit to qualify
        assert main(["identify", os.path.join(DATA_DIR, "drop_trace.csv"), "--json", str(inputs["FIT"])]) == 0
    name = tmp_path / ("special.png" if flag == "--plot" else "special.out")
    reader = None
    if kind == "device":
        _null_node(name)
    else:
        os.mkfifo(name)
        reader = _Reader(name)
    code = main([*argv, flag, str(name)])
    err = capsys.readouterr().err
    got = reader.join() if reader is not None else None
    assert code == 0, err
    if kind == "device":
        assert _is_null_device(name), f"{flag} replaced the device node"
    else:
        assert stat.S_ISFIFO(os.lstat(name).st_mode), f"{flag} replaced the FIFO"
        assert got, f"{flag} wrote nothing into the FIFO"
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]


@pytest.mark.parametrize("command, flag", list(_file_flags()))
def test_every_output_flag_refuses_a_socket_up_front(command, flag, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv, _ = _command_line(command, tmp_path)
    path = str(tmp_path / ("sock.png" if flag == "--plot" else "sock.out"))
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(path)
        code = main([*argv, flag, path])
        err = capsys.readouterr().err
        assert stat.S_ISSOCK(os.lstat(path).st_mode)
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and flag in lines[0] and "socket" in lines[0], err


def test_an_output_directory_with_a_device_in_place_of_a_file(tmp_path, capsys):
    """reproduce --out DIR: a device node where a file of DIR goes is written through."""
    import jaxunilat.paper._reproduce as reproduce

    out = tmp_path / "out"
    out.mkdir()
    node = _null_node(out / reproduce.SUMMARY)
    assert main(["reproduce", "--quick", "--out", str(out)]) == 0, capsys.readouterr().err
    assert _is_null_device(node)


def test_the_executable_cache_never_opens_or_replaces_a_planted_fifo(tmp_path):
    """A FIFO at an entry's name: the call neither hangs reading it nor renames over it."""
    import jaxunilat as ju
    from jaxunilat._internal._executables import disable_executable_cache, enable_executable_cache

    ball = ju.Ball.table1(2)
    run = lambda: ju.simulate(ball, ball.paper_initial_state(), 0.1, solver="event", samples=5, throw=False)  # noqa: E731
    path = tmp_path / "executables"
    try:
        enable_executable_cache(str(path))
        expected = run()
        (entry,) = [f for f in os.listdir(path) if f.endswith(".jaxexe")]
        os.remove(path / entry)
        os.mkfifo(path / entry)
        enable_executable_cache(str(path))  # a new process: nothing loaded yet
        again = run()
    finally:
        disable_executable_cache()
    assert stat.S_ISFIFO(os.lstat(path / entry).st_mode)
    assert float(abs(again["x"][-1] - expected["x"][-1])) == 0.0
