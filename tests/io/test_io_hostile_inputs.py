"""Hostile inputs through ``posekit ...`` (``main(argv)``): each is one line on stderr, exit 1, no
traceback, nothing allocated from an untrusted size. These are the inputs that ended in
``posekit: internal error`` before the shared reading layer (posekit.io)."""

import io
import json
import os
import struct
import zipfile
import zlib

import numpy as np
import pytest

from posekit.cli.main import main
from posekit.errors import InputFileError
from posekit.io import get_limits, load_npy, read_text, set_limits

GAUGE = "demo-5"


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def one_line(rc, err, *needles, code=1):
    assert rc == code, err
    assert "Traceback" not in err and "internal error" not in err, err
    assert err.startswith("posekit: error: ") and err.count("\n") == 1, err
    assert len(err) < 400, err
    for needle in needles:
        assert needle in err, f"{needle!r} not in {err!r}"


def estimate(capsys, path):
    return run(capsys, "profiler", "estimate", path, "--gauge", GAUGE)


# --------------------------------------------------------------------------- profile files

def test_csv_cell_over_the_csv_field_limit(tmp_path, capsys):
    p = tmp_path / "p.csv"
    p.write_text("x,z\n" + "1" * 131_073 + ",2\n")
    rc, out, err = estimate(capsys, p)
    one_line(rc, err, "p.csv: line", "field larger than field limit", "expected a profile CSV")


def _npy_header(shape, descr="<f8", version=b"\x01\x00", header=None):
    text = header if header is not None else f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}"
    text = text.encode("latin1")
    pad = 64 - (10 + len(text) + 1) % 64
    body = text + b" " * pad + b"\n"
    return b"\x93NUMPY" + version + struct.pack("<H", len(body)) + body


def test_malformed_npy_header(tmp_path, capsys):
    p = tmp_path / "p.npy"
    p.write_bytes(_npy_header(None, header="{'descr': '<f8', 'fortran_order': False, 'shape': (10, 2"))
    rc, out, err = estimate(capsys, p)
    one_line(rc, err, "p.npy: malformed .npy header", "expected a NumPy .npy array")


def test_npy_header_claiming_1e10_by_2(tmp_path, capsys):
    p = tmp_path / "p.npy"
    p.write_bytes(_npy_header((10_000_000_000, 2)))
    assert p.stat().st_size <= 144
    rc, out, err = estimate(capsys, p)
    one_line(rc, err, "p.npy: the array of shape (10000000000, 2) (float64) would take 149 GiB",
             "above the 1 GiB limit (raise it with --max-input-mb)")


def test_npz_named_npy_and_npy_named_npz(tmp_path, capsys):
    npz = tmp_path / "batch.npy"
    np.savez(tmp_path / "b.npz", profiles=np.zeros((1, 10, 2)))
    (tmp_path / "b.npz").rename(npz)
    rc, out, err = estimate(capsys, npz)
    one_line(rc, err, "batch.npy: the contents are a .npz (zip archive), not a .npy array")
    npy = tmp_path / "one.npz"
    np.save(tmp_path / "o.npy", np.zeros((10, 2)))
    (tmp_path / "o.npy").rename(npy)
    rc, out, err = estimate(capsys, npy)
    one_line(rc, err, "one.npz: the contents are a .npy (NumPy array), not a .npz archive")


def _zip_member(path, data: bytes, *, method=zipfile.ZIP_STORED, flag_bits=0, name="profiles.npy"):
    with zipfile.ZipFile(path, "w", compression=method) as zf:
        zf.writestr(name, data)
    if flag_bits:  # set the flag in the local and central headers
        raw = bytearray(path.read_bytes())
        for sig, off in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):
            i = raw.find(sig)
            raw[i + off:i + off + 2] = struct.pack("<H", struct.unpack("<H", raw[i + off:i + off + 2])[0] | flag_bits)
        path.write_bytes(bytes(raw))


def test_npz_member_that_is_not_npy_data(tmp_path, capsys):
    p = tmp_path / "p.npz"
    _zip_member(p, b"hello, not numpy")
    rc, out, err = estimate(capsys, p)
    one_line(rc, err, "p.npz: member 'profiles.npy' is not NumPy .npy data")


def test_npz_encrypted_and_unsupported_compression(tmp_path, capsys):
    buf = io.BytesIO()
    np.save(buf, np.zeros((1, 10, 2)))
    enc = tmp_path / "enc.npz"
    _zip_member(enc, buf.getvalue(), flag_bits=0x1)
    rc, out, err = estimate(capsys, enc)
    one_line(rc, err, "enc.npz: member 'profiles.npy' is encrypted; expected a plain .npz archive")
    bz = tmp_path / "bz.npz"
    _zip_member(bz, buf.getvalue(), method=zipfile.ZIP_BZIP2)
    rc, out, err = estimate(capsys, bz)
    one_line(rc, err, "bz.npz: member 'profiles.npy' uses compression method 12; expected stored or deflate")


def test_small_npz_that_inflates_to_gigabytes(tmp_path, capsys):
    """2.5 MB of deflate that would decode to 2.56 GB: refused from the member's header."""
    p = tmp_path / "bomb.npz"
    shape = (100_000, 1_600, 2)  # 2.56 GB of float64
    header = _npy_header(shape)
    comp = zlib.compressobj(9, zlib.DEFLATED, -15)
    chunk = bytes(2**20)
    parts = [comp.compress(header)]
    for _ in range(40):  # 40 MiB of zeros is enough to look real; the header decides
        parts.append(comp.compress(chunk))
    parts.append(comp.flush())
    with zipfile.ZipFile(p, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("profiles.npy", header + bytes(40 * 2**20))
    assert p.stat().st_size < 3e6
    rc, out, err = estimate(capsys, p)
    one_line(rc, err, "bomb.npz: member 'profiles.npy': the array of shape (100000, 1600, 2) (float64) would take "
                      "2.38 GiB", "above the 1 GiB limit")


def test_array_limit_is_raised_by_the_flag(tmp_path, capsys):
    p = tmp_path / "p.npy"
    np.save(p, np.zeros((200_000, 2)))  # 3.05 MiB
    previous = set_limits(array_bytes=2**20)
    try:
        rc, out, err = estimate(capsys, p)
        one_line(rc, err, "above the 1 MiB limit")
        rc, out, err = run(capsys, "profiler", "estimate", p, "--gauge", GAUGE, "--max-input-mb", "8")
        assert "above the" not in err
    finally:
        set_limits(**vars(previous))
    assert get_limits().array_bytes == 2**30


def test_unreadable_profile_csv(tmp_path, capsys, monkeypatch):
    p = tmp_path / "p.csv"
    p.write_text("x,z\n1,2\n")
    real = os.access
    monkeypatch.setattr(os, "access", lambda path, mode, **kw: False if str(path) == str(p) else real(path, mode))
    rc, out, err = estimate(capsys, p)  # as root chmod 000 is still readable: simulate the denial
    one_line(rc, err, "p.csv: permission denied (not readable)")


# --------------------------------------------------------------------------- text encodings, YAML, JSON

def test_gauge_yaml_in_latin1_and_utf16(tmp_path, capsys):
    from posekit.profiler.gauge.model import bundled_gauge_path

    text = bundled_gauge_path(GAUGE).read_text().replace("name: demo-5", "name: jauge-à-5")
    latin = tmp_path / "latin.yaml"
    latin.write_bytes(text.encode("latin-1"))
    rc, out, err = run(capsys, "profiler", "simulate", "--gauge", latin, "--count", "1", "--out", tmp_path / "o1")
    one_line(rc, err, "latin.yaml: line 4: byte 0xe0 is not UTF-8; expected a gauge YAML file in UTF-8")
    utf16 = tmp_path / "utf16.yaml"
    utf16.write_bytes(text.encode("utf-16"))
    rc, out, err = run(capsys, "profiler", "simulate", "--gauge", utf16, "--count", "1", "--out", tmp_path / "o2")
    one_line(rc, err, "utf16.yaml: UTF-16 (little-endian) text; expected a gauge YAML file in UTF-8")
    bom = tmp_path / "bom.yaml"
    bom.write_bytes(b"\xef\xbb\xbf" + text.encode("utf-8"))
    rc, out, err = run(capsys, "profiler", "simulate", "--gauge", bom, "--count", "1", "--out", tmp_path / "o3")
    assert rc == 0, err


DEEP_YAML = "a: " + "[" * 5000 + "]" * 5000 + "\n"
DEEP_JSON = "[" * 100_000 + "]" * 100_000


def test_deep_nesting_in_gauge_yaml_seam_config_and_calibration_json(tmp_path, capsys):
    g = tmp_path / "deep.yaml"
    g.write_text(DEEP_YAML)
    rc, out, err = run(capsys, "profiler", "simulate", "--gauge", g, "--count", "1", "--out", tmp_path / "o")
    one_line(rc, err, "deep.yaml: nested more than 64 levels deep")
    rc, out, err = run(capsys, "seam", "simulate", "--config", g, "--out", tmp_path / "s")
    one_line(rc, err, "deep.yaml: nested more than 64 levels deep")
    j = tmp_path / "cal.json"
    j.write_text(DEEP_JSON)
    rc, out, err = run(capsys, "ceiling", "track", tmp_path, "--calibration", j, "--out", tmp_path / "t.csv")
    one_line(rc, err, "cal.json: nested more than 64 levels deep")


def test_calibration_json_with_a_4300_digit_integer(tmp_path, capsys):
    j = tmp_path / "cal.json"
    j.write_text(json.dumps({"H_image_world": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                             "H_world_image": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "rms_px": 0, "rms_world": 0})
                 .replace('"rms_px": 0', '"rms_px": ' + "9" * 4300))
    rc, out, err = run(capsys, "ceiling", "track", tmp_path, "--calibration", j, "--out", tmp_path / "t.csv")
    one_line(rc, err, "cal.json: line 1: a number of 4300 digits", "expected at most 30 digits")


def test_messages_stay_one_line_with_newlines_and_megabytes_in_the_input(tmp_path, capsys):
    p = tmp_path / "p.csv"
    p.write_text("x,z\n" + "1,\"abc\ndef" + "y" * 2_000_000 + "\"\n")
    rc, out, err = estimate(capsys, p)
    one_line(rc, err, "p.csv: line")


# --------------------------------------------------------------------------- images

def _png_header(width, height) -> bytes:
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    chunk = b"IHDR" + ihdr
    return (b"\x89PNG\r\n\x1a\n" + struct.pack(">I", len(ihdr)) + chunk
            + struct.pack(">I", zlib.crc32(chunk) & 0xFFFFFFFF))


def test_png_header_claiming_65535_squared(tmp_path, capsys):
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / "0001.png").write_bytes(_png_header(65535, 65535) + b"\x00" * 64)
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"H_image_world": np.eye(3).tolist(), "H_world_image": np.eye(3).tolist(),
                               "rms_px": 0.1, "rms_world": 0.1}))
    rc, out, err = run(capsys, "ceiling", "track", folder, "--calibration", cal, "--out", tmp_path / "t.csv")
    one_line(rc, err, "0001.png: 65535 x 65535 pixels, above the 100 MP image limit")


def test_valid_png_above_the_pixel_limit(tmp_path, capsys):
    """A real, valid PNG larger than the limit (the limit lowered so the test stays small)."""
    import cv2

    folder = tmp_path / "frames"
    folder.mkdir()
    cv2.imwrite(str(folder / "0001.png"), np.zeros((300, 400, 3), np.uint8))
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"H_image_world": np.eye(3).tolist(), "H_world_image": np.eye(3).tolist(),
                               "rms_px": 0.1, "rms_world": 0.1}))
    rc, out, err = run(capsys, "ceiling", "track", folder, "--calibration", cal, "--out", tmp_path / "t.csv",
                       "--max-image-mp", "0.1")
    one_line(rc, err, "0001.png: 400 x 300 pixels, above the 0.1 MP image limit")


def test_unreadable_image_folder(tmp_path, capsys, monkeypatch):
    from pathlib import Path

    folder = tmp_path / "frames"
    folder.mkdir()
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"H_image_world": np.eye(3).tolist(), "H_world_image": np.eye(3).tolist(),
                               "rms_px": 0.1, "rms_world": 0.1}))
    real = Path.iterdir

    def denied(self):
        if self == folder:
            raise PermissionError(13, "Permission denied")
        return real(self)

    monkeypatch.setattr(Path, "iterdir", denied)
    rc, out, err = run(capsys, "ceiling", "track", folder, "--calibration", cal, "--out", tmp_path / "t.csv")
    one_line(rc, err, "frames: permission denied (cannot list the folder)")


# --------------------------------------------------------------------------- the readers directly

def test_read_text_rules(tmp_path):
    p = tmp_path / "a.txt"
    p.write_bytes(b"\xef\xbb\xbfhello")
    assert read_text(p, expected="text") == "hello"
    p.write_bytes(b"abc\x00def")
    with pytest.raises(InputFileError, match=r"a\.txt: binary data \(NUL bytes\); expected text \(UTF-8 text\)"):
        read_text(p, expected="text")
    np.save(tmp_path / "x.npy", np.zeros(3))
    with pytest.raises(InputFileError, match=r"x\.npy: the contents are a \.npy \(NumPy array\), not text"):
        read_text(tmp_path / "x.npy", expected="a CSV file")


def test_load_npy_round_trip_and_fortran_order(tmp_path):
    a = np.arange(12.0).reshape(3, 4)
    for arr in (a, np.asfortranarray(a), a.astype(np.float32)):
        np.save(tmp_path / "a.npy", arr)
        b = load_npy(tmp_path / "a.npy")
        np.testing.assert_array_equal(b, arr)
        assert b.flags.writeable
    np.save(tmp_path / "o.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(InputFileError, match=r"o\.npy: holds Python objects \(dtype object\)"):
        load_npy(tmp_path / "o.npy")
    raw = (tmp_path / "a.npy").read_bytes()
    (tmp_path / "t.npy").write_bytes(raw[:-5])
    with pytest.raises(InputFileError, match=r"t\.npy: truncated: shape \(3, 4\) needs 48 bytes of data, found 43"):
        load_npy(tmp_path / "t.npy")
