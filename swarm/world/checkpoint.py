"""The world's checkpoint file: its complete state at one tick, written every tick, read by a restart.

One file, ``<dir>/world.ckpt``: an 8-byte magic, the body's length and CRC-32, then the body (a pickle of a
dict of numpy arrays, ints, lists, bytes and the random streams' ``bit_generator.state`` dicts). It is
written to ``world.ckpt.tmp`` and renamed over the old one (``os.replace``, atomic on POSIX), so a world
killed at any instant leaves either the previous checkpoint or the new one, never a mix. There is no
``fsync``: the file survives a killed process (the kernel's page cache has it), not a machine crash,
which is all a restart within a run needs and keeps the cost per tick small (``BENCHMARKS.md``).

The body is a pickle: read checkpoints only from a directory nobody else can write (``swarm launch``
makes a private one, mode 0700, and removes it at exit). The length and CRC catch a torn or damaged file
before anything is unpickled.
"""

from __future__ import annotations

import os
import pickle
import struct
import zlib
from pathlib import Path

from swarm.errors import SwarmError

MAGIC = b"TPODSWC1"
"""File signature and format version (the last byte)."""
_HEADER = struct.Struct("<8sQI")  # magic, body length, CRC-32 of the body
FILE_NAME = "world.ckpt"

EXIT_BAD_CHECKPOINT = 3
"""Exit status of ``python -m swarm.world --resume`` when its checkpoint is missing, torn or of another
run: the launcher then gives up on the world instead of restarting it again."""


class CheckpointError(SwarmError, ValueError):
    """A checkpoint cannot be read or does not belong to this run; the message names the file."""


def checkpoint_path(directory: str | os.PathLike) -> Path:
    """The checkpoint file of a world whose ``--checkpoint-dir`` is ``directory``."""
    return Path(directory) / FILE_NAME


def save(path: Path, state: dict) -> int:
    """Write ``state`` to ``path`` atomically (a temporary file renamed over it); returns its size [bytes]."""
    body = pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)
    data = _HEADER.pack(MAGIC, len(body), zlib.crc32(body)) + body
    tmp = path.with_name(path.name + ".tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)  # readable by its owner only
    try:
        written = os.write(fd, data)
        if written != len(data):  # tmpfs and disks write it whole; a short write is an error, not a retry
            raise OSError(f"short write: {written} of {len(data)} bytes")
    finally:
        os.close(fd)
    os.replace(tmp, path)
    return len(data)


def load(path: Path) -> dict:
    """The state :func:`save` wrote to ``path``; :class:`CheckpointError` naming the file if it is missing,
    not a checkpoint, torn (shorter than its header says) or damaged (CRC mismatch)."""
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise CheckpointError(f"checkpoint {path}: no such file (the world never wrote one)") from None
    except OSError as exc:
        raise CheckpointError(f"checkpoint {path}: cannot be read: {exc.strerror}") from None
    if len(data) < _HEADER.size or not data.startswith(MAGIC[:7]):
        raise CheckpointError(f"checkpoint {path}: not a world checkpoint ({len(data)} bytes)")
    magic, length, crc = _HEADER.unpack_from(data)
    if magic != MAGIC:
        raise CheckpointError(f"checkpoint {path}: format {magic!r}, this world reads {MAGIC!r}")
    body = data[_HEADER.size :]
    if len(body) != length:
        raise CheckpointError(f"checkpoint {path}: torn: {len(body)} of {length} bytes of state")
    if zlib.crc32(body) != crc:
        raise CheckpointError(f"checkpoint {path}: damaged: CRC-32 mismatch")
    try:
        state = pickle.loads(body)
    except Exception as exc:  # a CRC-valid body that does not unpickle: written by another version
        raise CheckpointError(f"checkpoint {path}: unreadable state: {exc}") from None
    if not isinstance(state, dict):
        raise CheckpointError(f"checkpoint {path}: unreadable state: a {type(state).__name__}, not a map")
    return state
