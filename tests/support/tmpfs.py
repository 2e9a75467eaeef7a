"""A real small disk for tests of what happens when it fills: a tmpfs mounted for one test."""

from __future__ import annotations

import os
import subprocess
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest


@contextmanager
def mounted_tmpfs(parent: Path, size: str, covered_by: str) -> Iterator[Path]:
    """A ``size`` tmpfs (``512k``, ``40m``) under ``parent``, unmounted afterwards.

    Mounting needs root: elsewhere the test is skipped, saying which test ``covered_by`` still
    covers the path without a real disk.
    """
    if os.geteuid() != 0:
        pytest.skip(f"mounting a tmpfs needs root; {covered_by}")
    mount = parent / f"tmpfs-{uuid.uuid4().hex[:8]}"
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mount)],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)
