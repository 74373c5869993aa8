"""Write the seed corpus of every target into ``fuzz/corpus/<target>/`` (run once; the files are committed).

Seeds are tiny on purpose: valid inputs of each format plus a few broken ones, so that the
fuzzer starts next to every branch of the parser. ``python fuzz/seeds.py`` rewrites them.
"""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

CORPUS = Path(__file__).resolve().parent / "corpus"


def _png(arr: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", arr)
    assert ok
    return buf.tobytes()


def _images() -> dict[str, bytes]:
    rng = np.random.default_rng(16)
    g8 = rng.integers(0, 256, (4, 5), np.uint8)
    out = {
        "gray8.png": _png(g8),
        "gray16.png": _png(rng.integers(0, 65536, (3, 4), np.uint16)),
        "rgb8.png": _png(rng.integers(0, 256, (4, 4, 3), np.uint8)),
        "rgba8.png": _png(rng.integers(0, 256, (3, 3, 4), np.uint8)),
        "rgb16.png": _png(rng.integers(0, 65536, (2, 3, 3), np.uint16)),
    }
    buf = io.BytesIO()
    Image.fromarray(np.repeat(g8[..., None], 3, axis=2)).save(buf, "PNG", optimize=False)
    b = io.BytesIO()
    Image.fromarray(rng.integers(0, 256, (8, 8, 3), np.uint8)).save(b, "JPEG", quality=50)
    out["rgb.jpg"] = b.getvalue()
    b = io.BytesIO()
    Image.fromarray(g8).save(b, "JPEG", quality=50)
    out["gray.jpg"] = b.getvalue()
    for name, arr in {"gray8.tif": g8, "rgb8.tif": rng.integers(0, 256, (2, 2, 3), np.uint8)}.items():
        b = io.BytesIO()
        Image.fromarray(arr).save(b, "TIFF")
        out[name] = b.getvalue()
    b = io.BytesIO()
    Image.fromarray(rng.random((2, 3), np.float32), mode="F").save(b, "TIFF")
    out["float32.tif"] = b.getvalue()
    # broken ones: truncated PNG/JPEG, a header of a huge image, a bad CRC
    out["truncated.png"] = out["rgb8.png"][:40]
    out["truncated.jpg"] = out["rgb.jpg"][: len(out["rgb.jpg"]) // 2]
    big = bytearray(out["gray8.png"])
    big[16:24] = struct.pack(">II", 100000, 100000)
    out["huge_header.png"] = bytes(big)
    bad = bytearray(out["gray8.png"])
    bad[-20] ^= 0xFF
    out["bad_crc.png"] = bytes(bad)
    out["empty"] = b""
    return out


def _labels() -> dict[str, bytes]:
    lab = np.array([[0, 0, 1, 1], [0, 2, 2, 1], [3, 3, 2, 1]], np.uint8) * 85
    rgb = np.stack([lab, 255 - lab, lab // 2], axis=2)
    many = (np.arange(20, dtype=np.uint8) * 12).reshape(4, 5)
    return {"gray4.png": _png(lab), "rgb4.png": _png(rgb), "one.png": _png(np.zeros((2, 2), np.uint8)),
            "too_many.png": _png(many), "rgba.png": _png(np.dstack([rgb, np.full((3, 4), 255, np.uint8)]))}  # fmt: skip


def _masks() -> dict[str, bytes]:
    m = np.zeros((4, 4), np.uint8)
    m[1:3, 1:3] = 255
    rgba = np.dstack([np.full((4, 4, 3), 200, np.uint8), 255 - m])
    arrays = {
        "array_bool.bin": bytes([1, 0, 3, 3, 0]) + bytes([0, 1] * 8),
        "array_float.bin": bytes([1, 8, 1, 1, 0]) + np.array([0, 1, 0.5, np.nan], np.float64).tobytes(),
        "array_u16_3ch.bin": bytes([1, 2, 1, 1, 1]) + np.array([0, 65535], np.uint16).tobytes(),
        "labels_u8.bin": bytes([2, 1, 2, 2, 0]) + bytes([0, 10, 20, 30, 40, 50, 60, 70, 80]),
        "labels_f32.bin": bytes([2, 7, 1, 1, 3]) + np.array([0, 0.5, 1, 0.25, 0.75, 1], np.float32).tobytes(),
    }
    return {"file_gray.png": b"\0" + _png(m), "file_alpha.png": b"\3" + _png(rgba), **arrays}


def _skeletons() -> dict[str, bytes]:
    sk = {"format": "phloem.skeleton", "version": 1, "shape": [32, 48], "branches": [
        {"points": [[1, 2], [10, 12], [20, 5]], "thickness": [2, 1.5, 1]},
        {"points": [[10, 12], [15, 30]], "thickness": 1, "parent": [0, 1]}]}  # fmt: skip
    return {
        "two_branches.json": json.dumps(sk).encode(),
        "no_shape.json": json.dumps({"branches": [{"points": [[0, 0], [3, 4]]}]}).encode(),
        "bad_parent.json": json.dumps({"branches": [{"points": [[0, 0], [1, 1]], "parent": [0, "x"]}]}).encode(),
        "not_object.json": b"[1, 2, 3]",
        "nan.json": b'{"branches": [{"points": [[0, NaN], [1, 1]]}]}',
        "bad_json.json": b'{"branches": [',
    }


def _guides() -> dict[str, bytes]:
    return {"line.json": b"[[0, 0], [10, 5], [20, 20]]", "one_point.json": b"[[1, 2]]",
            "floats.json": b"[[0.5, 1e3], [-2.25, 3]]", "bad.json": b"[[0, 0], [1"}  # fmt: skip


def _trunk_models() -> dict[str, bytes]:
    d = 2
    good = {"format": "phloem.trees.TrunkClassifier", "version": 1, "coef": [0.1] * (1 + d + d * (d + 1) // 2),
            "mean": [0.0] * d, "scale": [1.0] * d, "alpha_threshold": 0.5}  # fmt: skip
    return {
        "model.json": json.dumps(good).encode(),
        "wrong_sizes.json": json.dumps({**good, "coef": [0.1]}).encode(),
        "other_format.json": b'{"format": "x"}',
    }


def _strokes() -> dict[str, bytes]:
    good = {"format": "phloem.strokes", "version": 1, "source_shape": [32, 48], "target_size": [40, 40], "pairs": [
        {"source": [[1, 2], [10, 12], [20, 5]], "target": [[5, 5], [30, 30]], "controls": [[0, 0], [0.4, 0.5], [1, 1]]},
        {"source": [[10, 12], [15, 30]], "target": [[30, 30], [35, 10]]}]}  # fmt: skip
    bad_controls = {"source": [[0, 0], [1, 1]], "target": [[0, 0], [2, 2]], "controls": [[0, 0], [0.5, 1], [1, 1]]}
    return {
        "two_pairs.json": json.dumps(good).encode(),
        "no_shapes.json": json.dumps({"pairs": [{"source": [[0, 0], [3, 4]], "target": [[1, 1], [2, 9]]}]}).encode(),
        "bad_controls.json": json.dumps({"pairs": [bad_controls]}).encode(),
        "zero_length.json": b'{"pairs": [{"source": [[1, 1], [1, 1]], "target": [[0, 0], [1, 1]]}]}',
        "nan.json": b'{"pairs": [{"source": [[0, NaN], [1, 1]], "target": [[0, 0], [1, 1]]}]}',
        "bad_json.json": b'{"pairs": [',
    }


def _svgs() -> dict[str, bytes]:
    ns = b'xmlns="http://www.w3.org/2000/svg" xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"'
    return {
        "layers.svg": b"<svg " + ns + b' width="20mm" height="10mm" viewBox="0 0 200 100">'
        b'<g inkscape:label="source" transform="translate(5 5) rotate(30)"><path d="M0 0C10 0 20 10 30 10s20 5 30 0"/>'
        b'<path d="m5 5 a10 5 30 1 0 20 0z"/></g>'
        b'<g inkscape:label="target"><polyline points="0,0 10,10 20,0"/><line x1="1" y1="2" x2="3" y2="4"/>'
        b'<path d="M0 0Q10 20 20 0T40 0H50V9"/></g></svg>',
        "compact_arc.svg": b"<svg " + ns + b'><path d="M0 0a5 5 0 1110 10l-1-1"/></svg>',
        "bad_path.svg": b"<svg " + ns + b'><path d="M0 0 C 1"/></svg>',
        "not_xml.svg": b"<svg",
    }


def main() -> None:
    for target, files in {"image": _images(), "label_map": _labels(), "mask": _masks(),
                          "skeleton": _skeletons(), "guide": _guides(), "trunk_model": _trunk_models(),
                          "strokes": _strokes(), "svg": _svgs()}.items():  # fmt: skip
        d = CORPUS / target
        d.mkdir(parents=True, exist_ok=True)
        for name, data in files.items():
            (d / name).write_bytes(data)


if __name__ == "__main__":
    main()
