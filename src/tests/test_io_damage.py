"""Damaged files: truncation and corruption give DataFileError (never a traceback or a hang); salvage works."""
from __future__ import annotations

import contextlib
import signal
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from hasel.errors import DataFileError
from hasel.io import Ros2McapWriter, info, load_signals, salvage
from hasel.io.mcapfile import MAGIC, McapStream

from cdrwrite import encode

STROKE = "hasel_msgs/msg/Stroke"
BATCH = "hasel_msgs/msg/SampleBatch"


class Hang(Exception):
    pass


@contextlib.contextmanager
def time_limit(seconds: float):
    def boom(signum, frame):
        raise Hang(f"took more than {seconds} s")

    old = signal.signal(signal.SIGALRM, boom)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    """~25 kB, 12+ chunks of two topics; returns (path, bytes, per-chunk (end offset, messages))."""
    path = tmp_path_factory.mktemp("damage") / "small.mcap"
    rng = np.random.default_rng(21)
    with Ros2McapWriter(path, chunk_size=1500) as w:
        cb = w.add_topic("/plant/batch", BATCH)
        cs = w.add_topic("/s", STROKE)
        for i in range(80):
            t = 10**9 + i * 5_000_000
            hdr = {"stamp": {"sec": t // 10**9, "nanosec": t % 10**9}}
            w.write(cb, encode(BATCH, {"header": hdr, "sample_period_s": 1e-4, "voltage_kv": rng.normal(size=10),
                                       "stroke_mm": rng.normal(size=10)}), t, t, i)
            w.write(cs, encode(STROKE, {"header": hdr, "stroke_mm": float(i)}), t, t, i)
    data = path.read_bytes()
    per_chunk = _messages_per_chunk(data)
    assert len(per_chunk) >= 12 and sum(n for _, n in per_chunk) == 160
    return path, data, per_chunk


def _messages_per_chunk(data: bytes) -> list[tuple[int, int]]:
    """(end offset, message count) of each chunk, by walking the records independently of the reader."""
    out = []
    pos = 8
    import zstandard

    while pos < len(data):
        op, ln = struct.unpack_from("<BQ", data, pos)
        if op == 0x06:
            body = data[pos + 9:pos + 9 + ln]
            usize = struct.unpack_from("<Q", body, 16)[0]
            clen = struct.unpack_from("<I", body, 28)[0]
            comp = body[32:32 + clen]
            records = body[32 + clen + 8:]
            raw = zstandard.ZstdDecompressor().decompress(records, max_output_size=usize) if comp else records
            n, p = 0, 0
            while p < len(raw):
                rop, rln = struct.unpack_from("<BQ", raw, p)
                n += rop == 0x05
                p += 9 + rln
            out.append((pos + 9 + ln, n))
        if op == 0x0F:
            break
        pos += 9 + ln
    return out


def test_truncation_anywhere(small_log, tmp_path):
    path, data, per_chunk = small_log
    total = sum(n for _, n in per_chunk)
    cut_file = tmp_path / "cut.mcap"
    out = tmp_path / "out.mcap"
    for cut in list(range(0, len(data), 211)) + [len(data) - 1, len(data) - 8, 9, 17]:
        cut_file.write_bytes(data[:cut])
        with time_limit(5):
            with pytest.raises(DataFileError):
                load_signals(cut_file, ["/plant/batch.voltage_kv"])
            if cut < 8:
                with pytest.raises(DataFileError):
                    info(cut_file)
                continue
            report = info(cut_file)
            assert not report.complete and report.damages
            expected = sum(n for end, n in per_chunk if end <= cut)
            assert report.message_count == expected
            rep = salvage(cut_file, out, overwrite=True)
        assert rep.messages == expected <= total
        with open(out, "rb") as f:
            reader = make_reader(f, validate_crcs=True)
            assert reader.get_summary().statistics.message_count == expected
            assert sum(1 for _ in reader.iter_messages(log_time_order=False)) == expected


def test_random_corruption(small_log, tmp_path):
    path, data, per_chunk = small_log
    rng = np.random.default_rng(8)
    bad = tmp_path / "bad.mcap"
    out = tmp_path / "out.mcap"
    for _ in range(60):
        buf = bytearray(data)
        for pos in rng.integers(0, len(buf), size=int(rng.integers(1, 4))):
            buf[pos] ^= int(rng.integers(1, 256))
        bad.write_bytes(bytes(buf))
        with time_limit(5):
            with pytest.raises(DataFileError):
                load_signals(bad, ["/plant/batch.voltage_kv", "/s.stroke_mm"])
            try:
                report = info(bad)
            except DataFileError:
                continue  # the magic or header itself was hit
            assert not report.complete
            rep = salvage(bad, out, overwrite=True)
        with open(out, "rb") as f:
            reader = make_reader(f, validate_crcs=True)
            assert sum(1 for _ in reader.iter_messages(log_time_order=False)) == rep.messages


def test_salvage_skips_one_corrupt_chunk_and_keeps_the_rest(small_log, tmp_path):
    path, data, per_chunk = small_log
    (end3, n3) = per_chunk[3]
    buf = bytearray(data)
    buf[end3 - 40] ^= 0xFF  # inside the compressed records of chunk 3
    bad = tmp_path / "one.mcap"
    bad.write_bytes(bytes(buf))
    rep = salvage(bad, tmp_path / "fixed.mcap")
    assert rep.chunks_lost == 1
    assert rep.messages == sum(n for _, n in per_chunk) - n3
    assert "chunk at byte" in str(rep.damages[0])


def test_absurd_lengths_do_not_allocate_or_hang(tmp_path):
    p = tmp_path / "absurd.mcap"
    p.write_bytes(MAGIC + struct.pack("<BQ", 0x01, 2**62) + b"x" * 100)
    with time_limit(2), pytest.raises(DataFileError, match=r"header at byte 8: claims 4611686018427387904 bytes"):
        load_signals(p, ["/x.y"])
    stream = McapStream(p, tolerant=True, max_record_bytes=1 << 20)
    assert list(stream) == [] and stream.damages
    p.write_bytes(b"")
    with pytest.raises(DataFileError, match="empty file"):
        load_signals(p, ["/x.y"])
    p.write_bytes(b"not an mcap file at all")
    with pytest.raises(DataFileError, match="not an MCAP file"):
        info(p)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                  HealthCheck.too_slow])
@given(st.data())
def test_fuzz_mutations_raise_only_data_file_error(small_log, tmp_path, data):
    _, original, _ = small_log
    buf = bytearray(original[:data.draw(st.integers(0, len(original)))])
    for _ in range(data.draw(st.integers(0, 6))):
        if buf:
            buf[data.draw(st.integers(0, len(buf) - 1))] = data.draw(st.integers(0, 255))
    f = tmp_path / "fuzz.mcap"
    f.write_bytes(bytes(buf))
    with time_limit(5):
        try:
            load_signals(f, ["/plant/batch.voltage_kv"])
        except DataFileError:
            pass
        try:
            info(f)
            salvage(f, tmp_path / "fuzz_out.mcap", overwrite=True)
        except DataFileError:
            pass
