"""``swarm bench codec`` times what every receiver runs (no timing assertion: the machine is shared)."""

from __future__ import annotations

import json
import subprocess
import sys

from swarm.bench import codec
from swarm.transport import messages as m

HOT_PATH = {
    "Imu", "ImuBatch", "Uwb", "UwbBatch", "Vision", "VisionBatch", "Estimate", "Guidance", "Command",
    "CommandBatch", "Truth", "TruthBatch", "Bundle", "Clock",
}  # fmt: skip
"""The messages of every tick (docs/protocol.md, "Rates")."""


def test_the_benched_examples_are_the_hot_path_types_and_take_the_fast_path():
    examples = codec.examples()
    assert {type(x).__name__ for x in examples} == HOT_PATH
    for msg in examples:
        assert m._decode_fast(m.encode(msg), type(msg)) == msg


def test_bench_codec_writes_a_row_per_type(tmp_path):
    out = tmp_path / "codec.json"
    args = [sys.executable, "-m", "swarm.cli.main", "bench", "codec", "--quick", "--json", str(out)]
    r = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    rec = json.loads(out.read_text())
    assert [row["type"] for row in rec["messages"]] == [type(x).__name__ for x in codec.examples()]
    for row in rec["messages"]:
        assert row["bytes"] == len(
            m.encode(next(x for x in codec.examples() if type(x).__name__ == row["type"]))
        )
        assert all(row[k] > 0 for k in ("build_us", "encode_us", "decode_us", "decode_reference_us"))
        has_fast = row["type"] in codec.fast_encoders()
        assert (row["fast_encode_us"] is not None and row["fast_encode_us"] > 0) == has_fast, row["type"]
    assert "reference" in r.stdout and "Estimate" in r.stdout and "fast enc" in r.stdout
