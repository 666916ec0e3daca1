"""Run directories and the files they hold: read only as bounded regular files, written only
where the user asked, never through a link, and every damaged one a named error."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from mjx_arm.inputs import (
    InputFileError,
    MiB,
    MissingInputError,
    OversizedInputError,
    open_regular,
    read_bytes,
    read_json_object,
    read_npz_members,
    read_text,
)

# --------------------------------------------------------------------------- bounded reads


def test_read_bytes_takes_a_regular_file_within_its_bound(tmp_path: Path) -> None:
    path = tmp_path / "a.json"
    path.write_bytes(b'{"step": 3}')
    assert read_bytes(path, "file", 11) == b'{"step": 3}'
    assert read_json_object(path, "file", within=tmp_path) == {"step": 3}
    with open_regular(path, "file", 11) as f:
        assert f.read() == b'{"step": 3}'
    with pytest.raises(OversizedInputError, match=r"file '.*a\.json' holds 11 bytes or more"):
        read_bytes(path, "file", 10)


def test_a_fifo_a_device_or_a_folder_is_refused_without_reading(tmp_path: Path) -> None:
    """A FIFO with no writer would block a plain open; /dev/zero would read without end."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    zero = tmp_path / "zero"
    zero.symlink_to("/dev/zero")
    for path in (fifo, zero):
        with pytest.raises(InputFileError, match="not a regular file"):
            read_text(path, "meta")
    with pytest.raises(InputFileError, match="is a folder"):
        read_text(tmp_path, "meta")
    with pytest.raises(MissingInputError, match="does not exist"):
        read_text(tmp_path / "none", "meta")


def test_within_refuses_a_link_out_of_the_folder_and_keeps_one_inside(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (tmp_path / "elsewhere.json").write_text("{}")
    (run / "out.json").symlink_to(tmp_path / "elsewhere.json")
    (run / "in.json").write_text('{"a": 1}')
    (run / "link.json").symlink_to("in.json")
    with pytest.raises(InputFileError, match=r"is a link to .*elsewhere\.json, outside"):
        read_json_object(run / "out.json", "config", within=run)
    assert read_json_object(run / "out.json", "config") == {}  # no folder given: followed
    assert read_json_object(run / "link.json", "config", within=run) == {"a": 1}


def test_an_npz_that_is_a_fifo_is_refused_unread(tmp_path: Path) -> None:
    """zipfile would block on opening a FIFO with no writer."""
    fifo = tmp_path / "resume.npz"
    os.mkfifo(fifo)
    with pytest.raises(InputFileError, match="not a regular file"):
        read_npz_members(fifo, "resume state", max_member_bytes=MiB, max_total_bytes=MiB)
