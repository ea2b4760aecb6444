"""Atomic output: old file intact on failure, no temporary left behind, normal permissions."""
from __future__ import annotations

import os

import pytest

from agvdyn._files import write_atomically, write_text_atomically


def test_failed_write_keeps_old_file_and_leaves_no_temporary(tmp_path):
    target = write_text_atomically(tmp_path / "out.txt", "old")

    def broken(tmp):
        tmp.write_text("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        write_atomically(target, broken)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_permissions_follow_umask(tmp_path):
    umask = os.umask(0o022)
    try:
        path = write_text_atomically(tmp_path / "p.txt", "x")
    finally:
        os.umask(umask)
    assert os.stat(path).st_mode & 0o777 == 0o644
