"""Atomic output files and provenance hashes (holoprobe.io._atomic)."""

import hashlib
import os
import time
from pathlib import Path

import pytest

from holoprobe.errors import InputError
from holoprobe.io import atomic_write, file_sha256


def test_failed_write_leaves_no_file_and_no_temporary(tmp_path):
    target = tmp_path / "out.h5"
    with pytest.raises(RuntimeError), atomic_write(target) as tmp:
        tmp.write_bytes(b"partial")
        raise RuntimeError("writer crashed")
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_failed_overwrite_keeps_the_previous_file_intact(tmp_path):
    target = tmp_path / "out.json"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_write(target, overwrite=True) as tmp:
        tmp.write_text("new but incomplete")
        raise RuntimeError("writer crashed")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_successful_write_replaces_and_temporary_is_gone(tmp_path):
    target = tmp_path / "sub" / "out.txt"
    with atomic_write(target) as tmp:
        assert tmp.parent == target.parent and tmp.suffix == ".txt"
        tmp.write_text("done")
    assert target.read_text() == "done"
    assert [p.name for p in target.parent.iterdir()] == ["out.txt"]


def test_existing_output_is_refused_without_overwrite(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("keep")
    with pytest.raises(InputError, match="overwrite=True") as err, atomic_write(target):
        pass
    assert err.value.file == str(target)
    assert target.read_text() == "keep"


def test_an_input_file_is_never_overwritten_even_with_overwrite(tmp_path):
    source = tmp_path / "ScanData.mat"
    source.write_text("measurement")
    with pytest.raises(InputError, match="input"), \
            atomic_write(source, overwrite=True, protect=[source]):
        pass
    assert source.read_text() == "measurement"


def test_sha256_matches_the_nist_test_vector_for_abc(tmp_path):
    p = tmp_path / "abc.bin"
    p.write_bytes(b"abc")
    assert file_sha256(p, chunk_bytes=2) == (
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad")
    big = tmp_path / "big.bin"
    big.write_bytes(bytes(range(256)) * 5000)
    assert file_sha256(big) == hashlib.sha256(big.read_bytes()).hexdigest()
    with pytest.raises(InputError, match="no such file"):
        file_sha256(tmp_path / "missing.bin")


def test_a_digest_is_kept_until_the_file_changes_and_can_be_computed_ahead_on_a_thread(
        tmp_path, monkeypatch):
    import holoprobe.io._atomic as atomic
    from holoprobe.io import warm_sha256
    from holoprobe.signal import Threads

    p = tmp_path / "scan.h5"
    p.write_bytes(b"first content")
    with Threads(1) as threads:  # as workflow.characterize does; a missing file: no error
        threads.submit(warm_sha256, [p, tmp_path / "missing.h5"])
    opened = []
    real_open = Path.open

    def counting_open(self, *a, **k):
        opened.append(self)
        return real_open(self, *a, **k)

    monkeypatch.setattr(Path, "open", counting_open)
    assert file_sha256(p) == hashlib.sha256(b"first content").hexdigest()
    assert opened == []  # the background thread's digest, not read again
    p.write_bytes(b"changed content, another size")
    os.utime(p, ns=(1, 10**18))  # and another modification time
    opened.clear()
    assert file_sha256(p) == hashlib.sha256(b"changed content, another size").hexdigest()
    assert opened == [p]
    assert len(atomic._SHA_DIGESTS) >= 2


def test_a_same_size_rewrite_with_its_modification_time_set_back_gets_a_new_digest(tmp_path):
    """Review A (session 12): the digest cache was keyed on (path, inode, size, mtime):
    a file rewritten in place with the same size and its mtime restored (cp -p,
    rsync -t) kept the stale digest (fails on the old code)."""
    p = tmp_path / "scan.h5"
    p.write_bytes(b"A" * 1000)
    st = os.stat(p)
    assert file_sha256(p) == hashlib.sha256(b"A" * 1000).hexdigest()
    time.sleep(0.03)  # past a coarse (kernel-tick) ctime granularity
    with p.open("r+b") as fh:  # in place: same inode, same size
        fh.write(b"B" * 1000)
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert os.stat(p).st_mtime_ns == st.st_mtime_ns and os.stat(p).st_ino == st.st_ino
    assert file_sha256(p) == hashlib.sha256(b"B" * 1000).hexdigest()
