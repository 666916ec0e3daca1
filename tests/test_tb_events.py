"""The TensorBoard event files a run writes, read back with tensorboardX's own protocol buffers
and checksum (an independent reader), and written without importing a TensorBoard library."""

from __future__ import annotations

import struct
import subprocess
import sys

import pytest

from mjx_arm.train.tb_events import ScalarWriter, crc32c, event_file_name, masked_crc32c


def read_records(data: bytes) -> list[bytes]:
    """The payloads of TFRecord-framed ``data``, each checksum checked with tensorboardX's
    CRC-32C."""
    from tensorboardX.crc32c import crc32c as their_crc

    def masked(b: bytes) -> int:
        crc = their_crc(b)
        return (((crc >> 15) | (crc << 17)) + 0xA282EAD8) & 0xFFFFFFFF

    out, at = [], 0
    while at < len(data):
        header = data[at : at + 8]
        (length,) = struct.unpack("<Q", header)
        assert struct.unpack("<I", data[at + 8 : at + 12])[0] == masked(header)
        payload = data[at + 12 : at + 12 + length]
        assert struct.unpack("<I", data[at + 12 + length : at + 16 + length])[0] == masked(payload)
        out.append(payload)
        at += 16 + length
    return out


def test_crc32c_matches_the_standard_check_value():
    """CRC-32C of "123456789" is 0xE3069283 (RFC 3720's check value); the mask is TFRecord's."""
    assert crc32c(b"123456789") == 0xE3069283
    assert crc32c(b"") == 0
    assert masked_crc32c(b"") == 0xA282EAD8


def test_scalars_read_back_as_tensorboard_events(tmp_path):
    """A version record, then one event per step with every scalar: wall times, steps, tags
    and float32 values as written."""
    from tensorboardX.proto.event_pb2 import Event

    path = tmp_path / event_file_name()
    assert "tfevents" in path.name
    writer = ScalarWriter(path.open("ab"))
    writer.add_scalars(573_440, {"eval/episode_success": 0.25, "training/kl_mean": 3e12})
    writer.add_scalars(30_883_840, {"eval/episode_reward/contact": -1.5})
    writer.close()
    events = [Event.FromString(r) for r in read_records(path.read_bytes())]
    assert events[0].file_version == "brain.Event:2"
    got = [(e.step, {v.tag: v.simple_value for v in e.summary.value}) for e in events[1:]]
    assert got == [
        (573_440, {"eval/episode_success": 0.25, "training/kl_mean": pytest.approx(3e12, 1e-6)}),
        (30_883_840, {"eval/episode_reward/contact": -1.5}),
    ]
    assert all(abs(e.wall_time - events[0].wall_time) < 60 for e in events)


def test_a_run_logs_metrics_without_importing_tensorboardx(tmp_path):
    """Logging a metrics row writes the event file without importing tensorboardX (which
    imports torch wherever it is installed: seconds at a run's first evaluation)."""
    code = (
        "import sys; from pathlib import Path; from mjx_arm.train.rundir import RunDir\n"
        f"run = RunDir(Path({str(tmp_path / 'run')!r}))\n"
        "run.log_metrics(0, {'eval/episode_success': 0.5}); run.close()\n"
        "print('tensorboardX' in sys.modules, 'torch' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
    files = list((tmp_path / "run" / "tb").iterdir())
    assert len(files) == 1 and len(read_records(files[0].read_bytes())) == 2
