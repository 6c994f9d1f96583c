"""FileCache: a value made from files is shared while they are unchanged, and made again when one changes."""

import os

import pytest

from agri_training.core.filecache import FileCache


def test_a_value_is_kept_while_its_files_are_unchanged(tmp_path):
    weights = tmp_path / "w.bin"
    weights.write_bytes(b"v1")
    cache: FileCache[bytes] = FileCache(size=2)
    made = []

    def make():
        made.append(1)
        return weights.read_bytes()

    assert cache.get([weights, None], "spaces", make) == b"v1"
    assert cache.get([weights, None], "spaces", make) == b"v1" and len(made) == 1  # shared
    assert cache.get([weights, None], "other spaces", make) == b"v1" and len(made) == 2
    weights.write_bytes(b"v2 longer")
    os.utime(weights, ns=(1, 1))
    assert cache.get([weights, None], "spaces", make) == b"v2 longer" and len(made) == 3  # the file changed
    with pytest.raises(ValueError):
        cache.get([tmp_path / "x"], None, lambda: (_ for _ in ()).throw(ValueError("refused")))
    assert cache.get([tmp_path / "x"], None, lambda: b"made") == b"made"  # a refusal was not kept
