import json

import pytest

from physics.errors import InputError
from physics.io.fileio import atomic_path, write_json, write_text


def test_atomic_write_replaces_only_on_success(tmp_path):
    target = tmp_path / "out.txt"
    write_text(target, "first")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half-written")
            raise RuntimeError("crash halfway")
    assert target.read_text() == "first"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]  # no temporary left behind


def test_refuses_to_overwrite_inputs_and_existing(tmp_path):
    src = tmp_path / "in.csv"
    src.write_text("data")
    with pytest.raises(InputError, match="input file"):
        write_text(src, "x", protect=(src,))
    with pytest.raises(InputError, match="already exists"):
        write_text(src, "x", overwrite=False)
    assert src.read_text() == "data"


def test_write_json_rejects_nan(tmp_path):
    with pytest.raises(ValueError):
        write_json(tmp_path / "a.json", {"x": float("nan")})
    write_json(tmp_path / "b.json", {"x": 1.5})
    assert json.loads((tmp_path / "b.json").read_text()) == {"x": 1.5}
