"""phloem._json.read_json: every bad JSON file is one line naming the argument and the file."""

from __future__ import annotations

import pytest

from phloem._json import MAX_DEPTH, parse_json, read_json


def _read(tmp_path, content: bytes, **kw):
    p = tmp_path / "f.json"
    p.write_bytes(content)
    return read_json(p, "skeleton", **kw)


def test_reads_json_with_or_without_a_bom(tmp_path):
    assert _read(tmp_path, b'{"a": [1, 2.5, "[[[{"]}') == {"a": [1, 2.5, "[[[{"]}
    assert _read(tmp_path, b"\xef\xbb\xbf[true]") == [True]
    assert _read(tmp_path, b'["NaN", "x\\"[[["]') == ["NaN", 'x"[[[']


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"[" * 100_000, r"f.json line 1 column 65: nested more than 64 levels deep$"),
        (b"[\n" + b"{" * 70, r"f.json line 2 column 64: nested more than 64 levels deep$"),
        (b"\x89PNG\r\n\x1a\n", r"f.json is not a JSON file \(binary data at byte 0\)$"),
        (b'["caf\xc3\xa9", "\xe9"]', r"f.json is not a JSON file \(binary data at byte 11\)$"),
        (b"[1]\x00", r"f.json is not a JSON file \(binary data at byte 3\)$"),
        (b"", r"f.json line 1 column 1: Expecting value$"),
        (b'{"a":\n  [1, 2,]}', r"f.json line 2 column 9: Expecting value$"),
        (b"[1, NaN]", r"f.json line 1 column 5: NaN is not a JSON number$"),
        (b"[-Infinity]", r"f.json line 1 column 2: -Infinity is not a JSON number$"),
        (b"[1e400]", r"f.json 1e400 is too large for a number$"),
        (b"[" + b"9" * 5000 + b"]", r"f.json holds an integer with too many digits$"),
    ],
)
def test_bad_files_give_one_line(tmp_path, content, message):
    with pytest.raises(ValueError, match=r"^skeleton: .*" + message) as info:
        _read(tmp_path, content)
    assert "\n" not in str(info.value)


def test_depth_limit_is_exact_and_strings_do_not_count():
    deep = parse_json("[" * MAX_DEPTH + "]" * MAX_DEPTH, "x", "")
    for _ in range(MAX_DEPTH - 1):
        deep = deep[0]
    assert deep == []
    with pytest.raises(ValueError, match=r"^x: line 1 column 65: nested"):
        parse_json("[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1), "x", "")
    assert parse_json('["' + "[" * 1000 + '"]', "x", "") == ["[" * 1000]


def test_size_folder_missing_and_error_class(tmp_path):
    with pytest.raises(ValueError, match=r"^skeleton: .*f.json is 21 bytes, larger than the limit of 10"):
        _read(tmp_path, b"[1, 2, 3, 4, 5, 6, 7]", max_bytes=10)
    with pytest.raises(ValueError, match=r"^g: .* is a folder, not a JSON file$"):
        read_json(tmp_path, "g")
    with pytest.raises(ValueError, match=r"^g: .*nope.json does not exist$"):
        read_json(tmp_path / "nope.json", "g")

    class Mine(ValueError):
        pass

    with pytest.raises(Mine):
        read_json(tmp_path / "nope.json", "g", error=Mine)
