"""Indexed recordings (issue 44): chunked, compressed MCAP that the field's readers seek in, read
back here by independent readers (the Python mcap package's indexed reader, and the MCAP
authors' TypeScript @mcap/core indexed reader under node); files cut at random byte offsets read
to their last whole chunk and are recovered as indexed files."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import msgpack
import numpy as np
import pytest
from mcap.reader import make_reader

from swarmloc.deploy.cli import main as cli
from swarmloc.deploy.observe.batch_record import run_batch_recorded
from swarmloc.deploy.observe.record import CHUNK_S, FRAME_TOPIC, read_recording, rewrite
from swarmloc.deploy.scenario import load_scenario

HERE = Path(__file__).resolve().parent
NODE_MODULES = Path(os.environ.get("SWARMLOC_NODE_MODULES", HERE.parent / ".ci" / "node" / "node_modules"))
TICKS_PER_CHUNK = round(CHUNK_S / 0.1)


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "es1.mcap"
    run_batch_recorded(load_scenario("ES1", ["world.robots=4", "world.duration_s=10.0"]), path)
    return path


def _indexed_frames(path: Path, start_ns: int | None = None) -> list[dict]:
    with open(path, "rb") as handle:
        reader = make_reader(handle)
        return [msgpack.unpackb(m.data, strict_map_key=False)
                for _, _, m in reader.iter_messages(topics=[FRAME_TOPIC], starting_at=start_ns)]


def test_the_python_indexed_reader_finds_chunks_and_seeks_to_a_tick(recording):
    whole = read_recording(recording)
    with open(recording, "rb") as handle:
        summary = make_reader(handle).get_summary()
    assert summary is not None and len(summary.chunk_indexes) >= 10  # one per simulated second
    assert summary.statistics.message_count == sum(whole.topics.values())
    assert _indexed_frames(recording) == whole.frames
    seek = _indexed_frames(recording, start_ns=5_000_000_000)  # tick 50
    assert seek[0]["tick"] == 50 and seek == whole.frames[50:]


@pytest.mark.skipif(shutil.which("node") is None or not (NODE_MODULES / "@mcap" / "core").is_dir(),
                    reason="needs node and @mcap/core + fzstd in .ci/node (npm install --prefix .ci/node, "
                           "as .ci/run does)")
def test_the_typescript_indexed_reader_reads_every_message_and_seeks(recording):
    done = subprocess.run(["node", str(HERE / "mcap_indexed_count.cjs"), str(recording), "5000000000"],
                          capture_output=True, text=True, timeout=120, check=False,
                          env={**os.environ, "NODE_PATH": str(NODE_MODULES)})
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    whole = read_recording(recording)
    assert out["counts"] == whole.topics and out["chunks"] >= 10
    assert out["first_frame_ns"] == "5000000000"


def test_a_file_cut_anywhere_reads_to_its_last_whole_chunk_and_recovers(recording, tmp_path):
    data = recording.read_bytes()
    whole = read_recording(recording)
    rng = np.random.default_rng(44)
    from swarmloc.deploy.observe.record import RecordingError

    for cut_at in sorted(rng.integers(100, len(data) - 1, 8)):
        cut = tmp_path / f"cut-{cut_at}.mcap"
        cut.write_bytes(data[:cut_at])
        try:
            rec = read_recording(cut)
        except RecordingError as exc:  # cut inside the first chunk (scene, schemas): said so
            assert "before its first whole chunk" in str(exc), cut_at
            continue
        kept = len(rec.frames)
        assert rec.frames == whole.frames[:kept], cut_at
        # whole chunks only: the frames of the chunk the cut fell in are all lost
        assert kept % TICKS_PER_CHUNK == 0 or kept == len(whole.frames), (cut_at, kept)
        if kept == 0:
            continue
        fixed = tmp_path / f"fixed-{cut_at}.mcap"
        rewrite(cut, fixed)
        assert _indexed_frames(fixed) == rec.frames  # indexed again: the summary is there
        assert read_recording(fixed).truncated is None


def test_record_recover_on_the_command_line(recording, tmp_path, capsys):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(recording.read_bytes()[: recording.stat().st_size * 2 // 3])
    out = tmp_path / "fixed.mcap"
    assert cli(["record", str(out), "--recover", str(cut)]) == 0
    said = capsys.readouterr().out
    assert f"wrote {out}" in said and "truncated" in said
    assert len(_indexed_frames(out)) == len(read_recording(cut).frames) > 0
    assert cli(["record", str(out)]) == 2  # neither a run to record nor a file to recover
    assert "--recover" in capsys.readouterr().err
    assert cli(["record", str(cut), "--recover", str(cut)]) == 2  # never over its own input
