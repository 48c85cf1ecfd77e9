"""Every input a fuzzer crashed on (tests/fuzz/regressions/, docs/hardening.md) is refused
with the loader's own error naming the file, through the Python API. (ctest replays the C++
targets' inputs through the fuzz harnesses themselves: fuzz_regressions_*.)"""
from pathlib import Path

import pytest

import mmrl
from mmrl.rl.checkpoints import CheckpointError
from mmrl.rl.trained_policy import load_policy

REGRESSIONS = Path(__file__).resolve().parent / "fuzz" / "regressions"
# cpp/fuzz/fuzz_bvh.cpp: the first byte picks the import options.
UP = {0: None, 1: "y", 2: "z"}
FPS = {0: None, 1: 24.0, 2: 30.0, 3: 60.0}


def inputs(target):
    files = sorted(p for p in (REGRESSIONS / target).iterdir() if p.name != ".gitkeep")
    assert files, f"no regression inputs for {target}"
    return files


def parse_fuzz_bvh(data: bytes):
    flags, text = data[0], data[1:].decode("latin-1")
    return mmrl.parse_bvh(text, "fuzz.bvh", 0.01 if flags & 4 else None, up=UP[(flags & 3) % 3],
                          fps=FPS[(flags >> 3) & 3])


def test_a_huge_frame_count_is_refused_before_allocating():
    # 300 bytes saying "Frames: 999999999": the arrays (56 GB) were allocated before reading.
    data = (REGRESSIONS / "bvh" / "oom_frames_header_999999999").read_bytes()
    with pytest.raises(mmrl.BVHError, match=r"truncated MOTION data: 'Frames: 999999999' \(line 17\)") as info:
        parse_fuzz_bvh(data)
    assert info.value.line == data.count(b"\n") + 1  # the end of the file, as any truncation


def test_an_implausible_frame_time_is_refused():
    # Frame Time 283033333 s resampled to 30 fps asked for 8.5e9 frames (an int overflow).
    data = (REGRESSIONS / "bvh" / "ubsan_resample_frame_time_283033333").read_bytes()
    with pytest.raises(mmrl.BVHError, match="Frame Time 283033344.000000 s is implausible") as info:
        parse_fuzz_bvh(data)
    text = data[1:].decode("latin-1")
    assert info.value.line == 1 + text.split("\n").index("Frame Time: 283033333")
    # The rule's edge: 10 s per frame still parses (and resamples), 10.5 s does not.
    assert mmrl.parse_bvh(text.replace("283033333", "10"), fps=1.0).num_frames == 11
    with pytest.raises(mmrl.BVHError, match="implausible"):
        mmrl.parse_bvh(text.replace("283033333", "10.5"))


@pytest.mark.parametrize("path", inputs("bvh"), ids=lambda p: p.name)
def test_bvh_inputs_are_refused(path):
    with pytest.raises(mmrl.BVHError):
        parse_fuzz_bvh(path.read_bytes())


@pytest.mark.parametrize("path", inputs("checkpoint"), ids=lambda p: p.name)
def test_checkpoint_inputs_are_refused(tmp_path, path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(path.read_bytes())
    with pytest.raises(CheckpointError, match="bad.pt"):
        load_policy(bad)


@pytest.mark.parametrize("path", inputs("database_npz"), ids=lambda p: p.name)
def test_database_inputs_are_refused(tmp_path, path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(path.read_bytes())
    with pytest.raises(mmrl.DatabaseFileError, match="bad.npz"):
        mmrl.Database.load(bad)


def test_a_record_larger_than_the_file_is_refused_before_torch_reads_it(tmp_path, monkeypatch):
    # The fuzzer's input declared a 4 GB record in a 5.7 kB file; torch allocated it (4.4 GB)
    # before failing. Here: a genuine torch file whose central directory says one record holds
    # 2 GB. torch.load must not even be called.
    import struct

    import torch

    good = tmp_path / "good.pt"
    torch.save({"w": torch.zeros(3)}, good)
    data = bytearray(good.read_bytes())
    entry = data.index(b"PK\x01\x02")  # the first central directory entry
    data[entry + 24:entry + 28] = struct.pack("<I", 2**31 - 1)  # its uncompressed size
    bad = tmp_path / "bad.pt"
    bad.write_bytes(bytes(data))
    monkeypatch.setattr(torch, "load", lambda *a, **k: pytest.fail("torch.load was called"))
    with pytest.raises(CheckpointError, match=r"bad.pt: corrupt: its record '.*' declares 2147483647 bytes "
                                              rf"in a file of {len(data)} bytes"):
        load_policy(bad)


def test_a_compressed_record_is_refused(tmp_path):
    # torch.save stores records as they are; a deflated one is not its file.
    import zipfile

    import torch

    good = tmp_path / "good.pt"
    torch.save({"w": torch.zeros(3)}, good)
    bad = tmp_path / "bad.pt"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(bad, "w", zipfile.ZIP_DEFLATED) as dst:
        for record in src.infolist():
            dst.writestr(record.filename, src.read(record.filename))
    with pytest.raises(CheckpointError, match="bad.pt: corrupt: its record '.*' is compressed"):
        load_policy(bad)
    assert torch.load(good, weights_only=True)["w"].shape == (3,)  # the original loads
