"""Shared fixtures: the repository root, the built binaries, unique namespaces."""

from __future__ import annotations

import itertools
import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
_COUNTER = itertools.count()


def unique(prefix: str) -> str:
    """A namespace (or file prefix) unique to this process and call."""
    return f"{prefix}_{os.getpid()}_{next(_COUNTER)}"


def binary(name: str) -> pathlib.Path:
    """The newest built Rust binary ``name`` (target/release or target/debug)."""
    found = [ROOT / "target" / p / name for p in ("release", "debug")]
    found = [p for p in found if p.exists()]
    if not found:
        pytest.fail(f"{name} is not built: run `cargo build --workspace --bins` first")
    return max(found, key=lambda p: p.stat().st_mtime)


@pytest.fixture(scope="session")
def root() -> pathlib.Path:
    """The repository root."""
    return ROOT


def cargo_json(*args: str) -> str:
    """Runs cargo in the repository and returns its standard output."""
    out = subprocess.run(
        ["cargo", *args], cwd=ROOT, check=True, capture_output=True, text=True
    )
    return out.stdout
