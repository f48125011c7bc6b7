"""A checkpoint file: a process's complete state at one tick, written every tick, read by a restart (the
world's, ``world.ckpt``; a landing agent's, ``agent-<id>.ckpt``: :mod:`agents.landing`).

One file, ``<dir>/world.ckpt``, with two slots written in turn (a double buffer): a world killed while it
writes one leaves the other, the checkpoint of the tick before, whose samples it had not published yet
(the world writes a tick's checkpoint before it publishes the tick), so resuming from it is right. A slot
holds the world's state (a pickle of a dict of numpy arrays as bytes, ints, lists and the random streams'
``bit_generator.state`` dicts) and the encoded samples of the recent ticks (:func:`swarm.world.process.
unconfirmed_ticks`), each with its own CRC-32 computed once: a tick's samples are written ~10 times while
they are recent, and checksummed once.

Layout (little-endian): the file header ``magic (8 bytes), slot capacity (u64)``; then slot 0 and slot 1 at
``16 + i * capacity``, each ``seq (u64, 0: never written), body length (u32), body CRC-32 (u32), state length
(u32), samples (u32)``, the body (the state's pickle, then per sample ``tick (i64), length (u32), CRC-32
(u32)``), then the samples' bytes. The valid slot with the higher ``seq`` is the checkpoint. A slot is
rewritten in place (``os.pwritev``, no new file, no rename: a 38 kB state took 16 us so against 67 us as a
new file renamed over the old one on tmpfs, ``BENCHMARKS.md`` "World checkpoint"); a slot that outgrows the
capacity makes a new file, twice the size, written to ``world.ckpt.tmp`` and renamed over the old one
(atomic on POSIX). There is no ``fsync``: the file survives a killed process (the kernel's page cache has
it), not a machine crash, which is all a restart within a run needs.

The state is a pickle: read checkpoints only from a directory nobody else can write (``swarm launch``
makes a private one, mode 0700, and removes it at exit). The lengths and CRCs catch a torn or damaged slot
before anything is unpickled.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import struct
import zlib
from collections.abc import Sequence
from pathlib import Path

from swarm.errors import SwarmError

MAGIC = b"TPODSWC2"
"""File signature and format version (the last byte)."""
_FILE = struct.Struct("<8sQ")  # magic, slot capacity [bytes]
_SLOT = struct.Struct("<QIIII")  # seq, body length, body CRC-32, state length, samples
_ENTRY = struct.Struct("<qII")  # a sample's tick, length, CRC-32
FILE_NAME = "world.ckpt"

EXIT_BAD_CHECKPOINT = 3
"""Exit status of ``python -m swarm.world --resume`` when its checkpoint is missing, torn or of another
run: the launcher then gives up on the world instead of restarting it again."""

Samples = Sequence[tuple[int, bytes, int]]
"""A checkpoint's recent samples: ``(tick, encoded samples, their CRC-32)``, oldest first."""


class CheckpointError(SwarmError, ValueError):
    """A checkpoint cannot be read or does not belong to this run; the message names the file."""


def checkpoint_path(directory: str | os.PathLike, name: str = FILE_NAME) -> Path:
    """The checkpoint file of a world whose ``--checkpoint-dir`` is ``directory`` (``name``: another
    process's, such as a landing agent's ``agent-<id>.ckpt``, in the same format)."""
    return Path(directory) / name


def fingerprint(scenario) -> str:
    """A scenario's fingerprint, overrides included: a checkpoint's run says which scenario wrote it."""
    return hashlib.sha256(repr(scenario).encode()).hexdigest()[:16]


def check_run(where: str, run: object, mine: dict, who: str = "world") -> None:
    """:class:`CheckpointError` (``where``: the file) if a checkpoint's ``run`` is not ``mine`` (what this
    process runs: scenario, fingerprint, seed, ...), naming each field that differs and both values."""
    theirs = run if isinstance(run, dict) else {}
    if theirs != mine:
        diff = ", ".join(f"{k} {theirs.get(k)!r} (this {who}: {mine[k]!r})" for k in mine
                         if theirs.get(k) != mine[k])  # fmt: skip
        raise CheckpointError(f"{where}: of another run: {diff}")


def sample_entry(tick: int, data: bytes) -> tuple[int, bytes, int]:
    """One tick's encoded samples as a checkpoint carries them, with their CRC-32 (computed here, once)."""
    return tick, data, zlib.crc32(data)


class CheckpointFile:
    """The checkpoint file of a running world, written every tick (:meth:`write`), one slot after the other.

    ``after``: ``(seq, slot)`` of the checkpoint a resumed world read (:func:`load` returns them as
    ``state["checkpoint"]``): its writes go on from there, to the other slot first, so the checkpoint it
    resumed from stays whole until a newer one is."""

    def __init__(self, path: Path, after: tuple[int, int] | None = None) -> None:
        self.path = Path(path)
        self.seq, self.slot = after if after is not None else (0, 1)
        self.capacity = 0
        self.fd: int | None = None
        if after is not None:
            try:
                fd = os.open(self.path, os.O_RDWR)
            except OSError:
                return  # gone meanwhile: the next write makes a new file
            try:
                header = os.pread(fd, _FILE.size, 0)
                magic, capacity = _FILE.unpack(header) if len(header) == _FILE.size else (b"", 0)
            except OSError:
                magic, capacity = b"", 0
            if magic == MAGIC and capacity > 0:
                self.fd, self.capacity = fd, capacity
            else:
                os.close(fd)

    def write(self, state: dict, samples: Samples = ()) -> int:
        """Write ``state`` and the recent ``samples`` (:func:`sample_entry`) as the newest checkpoint; returns
        the slot's size [bytes]. ``OSError`` if the file cannot be written (a short write is one)."""
        body = pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)
        table = b"".join(_ENTRY.pack(t, len(data), crc) for t, data, crc in samples)
        crc = zlib.crc32(table, zlib.crc32(body))
        self.seq += 1
        header = _SLOT.pack(self.seq, len(body) + len(table), crc, len(body), len(samples))
        parts = [header, body, table, *(data for _, data, _ in samples)]
        size = sum(len(p) for p in parts)
        if self.fd is None or size > self.capacity:
            self._new_file(parts, size)
            return size
        self.slot = 1 - self.slot
        written = os.pwritev(self.fd, parts, _FILE.size + self.slot * self.capacity)
        if written != size:  # tmpfs and disks write it whole; a short write is an error, not a retry
            raise OSError(f"short write: {written} of {size} bytes")
        return size

    def _new_file(self, parts: list[bytes], size: int) -> None:
        """A file of twice the slot's size, this checkpoint in slot 0, renamed over the old one."""
        self.close()
        capacity = max(2 * size, 4096)
        tmp = self.path.with_name(self.path.name + ".tmp")
        fd = os.open(tmp, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o600)  # readable by its owner only
        try:
            data = _FILE.pack(MAGIC, capacity) + b"".join(parts)
            written = os.write(fd, data)
            if written != len(data):
                raise OSError(f"short write: {written} of {len(data)} bytes")
            os.replace(tmp, self.path)
        except BaseException:
            os.close(fd)
            raise
        self.fd, self.capacity, self.slot = fd, capacity, 0

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def _slot(data: bytes, offset: int, capacity: int) -> tuple[int, dict | None, str]:
    """``(seq, state or None, what is wrong)`` of the slot at ``offset`` (``seq`` 0: never written)."""
    end = min(len(data), offset + capacity)
    if end - offset < _SLOT.size:
        return 0, None, f"torn: {max(0, end - offset)} of {_SLOT.size} bytes of a slot's header"
    seq, body_len, crc, state_len, n = _SLOT.unpack_from(data, offset)
    if seq == 0:
        return 0, None, "no checkpoint written"
    start = offset + _SLOT.size
    if state_len + n * _ENTRY.size != body_len or start + body_len > offset + capacity:
        return seq, None, "damaged: slot header"
    if start + body_len > end:
        return seq, None, f"torn: {end - start} of {body_len} bytes of state"
    body = data[start : start + body_len]
    if zlib.crc32(body) != crc:
        return seq, None, "damaged: CRC-32 mismatch"
    samples, at = [], start + body_len
    for i in range(n):
        tick, length, s_crc = _ENTRY.unpack_from(body, state_len + i * _ENTRY.size)
        if at + length > end:
            return seq, None, f"torn: {max(0, end - at)} of {length} bytes of tick {tick}'s samples"
        blob = data[at : at + length]
        if zlib.crc32(blob) != s_crc:
            return seq, None, f"damaged: CRC-32 mismatch of tick {tick}'s samples"
        samples.append((tick, blob))
        at += length
    try:
        state = pickle.loads(body[:state_len])
    except Exception as exc:  # a CRC-valid body that does not unpickle: written by another version
        return seq, None, f"unreadable state: {exc}"
    if not isinstance(state, dict):
        return seq, None, f"unreadable state: a {type(state).__name__}, not a map"
    state["samples"] = samples
    return seq, state, ""


def load(path: Path) -> dict:
    """The newest whole checkpoint in ``path``: the state :meth:`CheckpointFile.write` wrote, with
    ``"samples"`` (the recent ticks' ``(tick, encoded samples)``, oldest first) and ``"checkpoint"`` (its
    ``(seq, slot)``, for :class:`CheckpointFile`'s ``after``). A slot torn by a world killed while writing
    it gives way to the other. :class:`CheckpointError` naming the file if it is missing, not a checkpoint,
    or has no whole slot (torn: shorter than its header says; damaged: a CRC mismatch)."""
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise CheckpointError(f"checkpoint {path}: no such file (the world never wrote one)") from None
    except OSError as exc:
        raise CheckpointError(f"checkpoint {path}: cannot be read: {exc.strerror}") from None
    if len(data) < _FILE.size or not data.startswith(MAGIC[:7]):
        raise CheckpointError(f"checkpoint {path}: not a world checkpoint ({len(data)} bytes)")
    magic, capacity = _FILE.unpack_from(data)
    if magic != MAGIC:
        raise CheckpointError(f"checkpoint {path}: format {magic!r}, this world reads {MAGIC!r}")
    if capacity < _SLOT.size:
        raise CheckpointError(f"checkpoint {path}: damaged: a slot capacity of {capacity} bytes")
    slots = [_slot(data, _FILE.size + i * capacity, capacity) for i in (0, 1)]
    whole = [(seq, i, st) for i, (seq, st, _) in enumerate(slots) if st is not None]
    if not whole:
        seq, _, why = max(slots, key=lambda s: s[0])  # what is wrong with the newest slot written
        raise CheckpointError(f"checkpoint {path}: {why}")
    seq, i, state = max(whole, key=lambda w: w[0])
    state["checkpoint"] = (seq, i)
    return state
