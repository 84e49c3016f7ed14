"""A file in the state directory written atomically: a temporary file in the same directory,
fsync, rename, fsync of the directory — a crash leaves the old file or the new one, never
half of one (the calibration record, the last brake test) — and read back, refused in one
line when missing, unreadable or of another format."""

from __future__ import annotations

import dataclasses
import datetime
import json
import os
import tempfile
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")


def write_atomically(path: Path, text: str) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=path.suffix, dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    dfd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)
    return path


def write_json(path: Path, fmt: int, record: Any) -> Path:
    """The dataclass ``record`` as a JSON object of format ``fmt`` (what :func:`read_json`
    reads back), written atomically to ``path``."""
    text = json.dumps({"format": fmt, **dataclasses.asdict(record)}, indent=1)
    return write_atomically(path, text + "\n")


def read_json(path: Path, fmt: int, what: str, error: type[Exception]) -> dict[str, Any]:
    """The JSON object a state file of format ``fmt`` holds (without its ``format``);
    ``error`` saying what is wrong with it (``what``: the file as a user calls it)."""
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise error(f"no {what} at {path}") from None
    except (OSError, ValueError) as exc:
        raise error(f"{path}: unreadable ({exc})") from None
    if not isinstance(data, dict) or data.pop("format", None) != fmt:
        raise error(f"{path}: not a {what} of format {fmt}")
    return data


def read_dataclass(cls: type[T], path: Path, fmt: int, what: str,
                   error: type[Exception]) -> T:  # fmt: skip
    """The dataclass ``cls`` a state file of format ``fmt`` holds (``read_json``): its keys
    that are fields of ``cls`` (a newer program's extra keys left out); ``error`` naming the
    file when a field is missing or its value does not fit."""
    data = read_json(path, fmt, what, error)
    fields = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    try:
        return cls(**{k: v for k, v in data.items() if k in fields})
    except TypeError as exc:
        raise error(f"{path}: {exc}") from None


def iso_utc(t: float | None = None) -> str:
    """``t`` (s since the epoch; now when None) as the state files write times: ISO 8601,
    UTC, to the second."""
    when = datetime.datetime.now(datetime.UTC) if t is None else (
        datetime.datetime.fromtimestamp(t, datetime.UTC))  # fmt: skip
    return when.isoformat(timespec="seconds")
