#!/usr/bin/env python3
"""Writes the seed corpus of the fuzz targets into tests/fuzz/corpus/<target>/seed_*.

The seeds are small valid inputs (plus a few deliberately bad ones) that show libFuzzer each
format's structure: PLY in all three encodings and SH degrees, .splat, cameras.json,
trajectory files and specs, command-line values, and the server's protobuf requests (encoded
with `protoc --encode` from proto/catgs/v1/catgs.proto), and the compressed scene formats
(.spz, compressed PLY, SOG, .glb) as splat-transform writes them. Crash reproducers found by
fuzzing are kept beside them as crash_* files and are never overwritten by this script.

Usage: python3 tests/fuzz/make_seed_corpus.py   (from anywhere; needs protoc for the requests,
and tests/oracle/install-deps.sh's splat-transform for the compressed formats: without it
their seeds are left as they are)
"""

import gzip
import io
import json
import math
import os
import random
import shutil
import struct
import subprocess
import sys
import tempfile
import zipfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
CORPUS = os.path.join(HERE, "corpus")


def put(target, name, data):
    folder = os.path.join(CORPUS, target)
    os.makedirs(folder, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    with open(os.path.join(folder, "seed_" + name), "wb") as f:
        f.write(data)


def clear_seeds(keep=()):
    if not os.path.isdir(CORPUS):
        return
    for target in os.listdir(CORPUS):
        if target in keep:
            continue
        folder = os.path.join(CORPUS, target)
        for name in os.listdir(folder):
            if name.startswith("seed_"):
                os.remove(os.path.join(folder, name))


# ---------------------------------------------------------------------------------------
# PLY

BASE = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
TAIL = ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
REST = {0: 0, 1: 9, 2: 24, 3: 45}


def names(degree):
    return BASE + ["f_rest_%d" % j for j in range(REST[degree])] + TAIL


def record(i, degree):
    values = {"x": i + 0.25, "y": -2.0 * i - 0.5, "z": 0.125 * i, "nx": 0, "ny": 0, "nz": 0}
    for c in range(3):
        values["f_dc_%d" % c] = 0.5 * c - i
    for j in range(REST[degree]):
        values["f_rest_%d" % j] = 0.01 * j
    values.update({"opacity": 0.25 * i + 1, "scale_0": -1.0, "scale_1": -1.5, "scale_2": -2.0,
                   "rot_0": 1.0 + i, "rot_1": 0.5, "rot_2": -0.25, "rot_3": 0.125 * i})
    return values


PACK = {"float": "f", "double": "d", "uchar": "B", "char": "b", "short": "h", "ushort": "H",
        "int": "i", "uint": "I"}


def ply(fmt, degree=0, records=2, types=None, before="", before_data=b"", after="", newline="\n"):
    props = names(degree)
    types = types or {}
    header = ["ply", "format %s 1.0" % fmt, "comment seed"]
    header += [line for line in before.split("\n") if line]
    header.append("element vertex %d" % records)
    header += ["property %s %s" % (types.get(p, "float"), p) for p in props]
    header += [line for line in after.split("\n") if line]
    header.append("end_header")
    out = (newline.join(header) + newline).encode() + before_data
    endian = "<" if fmt == "binary_little_endian" else ">"
    for i in range(records):
        values = record(i, degree)
        if fmt == "ascii":
            out += (" ".join(repr(float(values[p])) if types.get(p, "float") in ("float", "double")
                             else str(int(values[p])) for p in props) + newline).encode()
        else:
            for p in props:
                t = types.get(p, "float")
                v = values[p] if t in ("float", "double") else int(values[p])
                out += struct.pack(endian + PACK[t], v)
    return out


def ply_seeds():
    t = "fuzz_ply"
    put(t, "le_deg0.ply", ply("binary_little_endian"))
    put(t, "be_deg0.ply", ply("binary_big_endian"))
    put(t, "ascii_deg0.ply", ply("ascii"))
    put(t, "ascii_crlf.ply", ply("ascii", newline="\r\n"))
    put(t, "le_deg1.ply", ply("binary_little_endian", degree=1, records=1))
    put(t, "ascii_deg1.ply", ply("ascii", degree=1, records=1))
    put(t, "be_double.ply", ply("binary_big_endian", records=1,
                                types={"x": "double", "y": "double", "z": "double", "opacity": "double",
                                       "scale_0": "double", "rot_0": "double", "rot_1": "double"}))
    put(t, "le_int_types.ply", ply("binary_little_endian", records=1,
                                   types={"nx": "uchar", "ny": "short", "nz": "uint", "f_dc_0": "char",
                                          "rot_3": "int"}))
    # An element with a list property before the vertex, and one after it.
    face = struct.pack("<BIII", 3, 0, 1, 2)
    put(t, "le_face_before.ply", ply("binary_little_endian", records=1,
                                     before="element face 1\nproperty list uchar uint vertex_indices",
                                     before_data=face, after="element extra 0\nproperty float w"))
    put(t, "ascii_face_before.ply", ply("ascii", records=1,
                                        before="element face 1\nproperty list uchar int vertex_indices",
                                        before_data=b"3 0 1 2\n"))
    # Bad values the readers must name: NaN, a zero quaternion, a transparent record.
    bad = ply("ascii", records=1).replace(b"0.25 -0.5", b"nan -0.5")
    put(t, "ascii_nan.ply", bad)
    put(t, "ascii_zero_quaternion.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\n" +
        b"".join(b"property float %s\n" % p.encode() for p in names(0)) +
        b"end_header\n0 0 0 0 0 0 0 0 0 5 0 0 0 0 0 0 0\n")


# ---------------------------------------------------------------------------------------
# .splat

def splat(position, scale, rgba, quaternion):
    return struct.pack("<3f3f4B4B", *position, *scale, *rgba, *quaternion)


def splat_seeds():
    t = "fuzz_splat"
    a = splat((0, 0, 0), (0.1, 0.1, 0.1), (200, 100, 50, 255), (255, 128, 128, 128))
    b = splat((1.5, -2, 3.25), (0.5, 0.02, 1), (0, 255, 128, 128), (200, 60, 128, 140))
    transparent = splat((0, 0, 0), (1, 1, 1), (128, 128, 128, 0), (255, 128, 128, 128))
    nan = struct.pack("<3f", math.nan, 0, 0) + a[12:]
    zero_q = a[:28] + bytes([128, 128, 128, 128])
    put(t, "one.splat", a)
    put(t, "two.splat", a + b)
    put(t, "transparent.splat", a + transparent)
    put(t, "nan.splat", a + nan)
    put(t, "zero_quaternion.splat", zero_q + a)
    put(t, "trailing.splat", a + b"\x00\x01\x02")


# ---------------------------------------------------------------------------------------
# Cameras and trajectories

CAMERAS_JSON = """[
 {"id": 0, "img_name": "00001", "width": 64, "height": 48,
  "position": [1.0, 2.0, 3.0],
  "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 55.5, "fy": 55.5},
 {"id": 1, "img_name": "00002.png", "width": 32, "height": 32,
  "position": [-4.5, 0.25, 1e6],
  "rotation": [[0, -1, 0], [1, 0, 0], [0, 0, 1]], "fx": 30, "fy": 31.5}
]
"""


def camera_seeds():
    t = "fuzz_cameras_json"
    put(t, "two.json", CAMERAS_JSON)
    put(t, "one_min.json", '[{"img_name":"a","width":1,"height":1,"position":[0,0,0],'
                           '"rotation":[[0,0,1],[0,1,0],[-1,0,0]],"fx":1,"fy":1}]')
    put(t, "not_rotation.json", '[{"img_name":"a","width":8,"height":8,"position":[0,0,0],'
                                '"rotation":[[2,0,0],[0,1,0],[0,0,1]],"fx":1,"fy":1}]')
    put(t, "empty.json", "[]")

    t = "fuzz_trajectory_file"
    put(t, "pose_lines.txt", "# timestamp px py pz qw qx qy qz\n"
                             "0 0 0 10 1 0 0 0\n"
                             "0.033 0.5 -0.25 10 0.9 0.1 -0.2 0.3  # unnormalised\n\n")
    put(t, "full_lines.txt", "0 1 2 3 1 0 0 0 50 50 32 24 64 48\n"
                             "1.5 1e6 4e6 120 0 1 0 0 500.5 500.5 320 240 640 480\n")
    put(t, "crlf_tabs.txt", "0\t1\t2\t3\t1\t0\t0\t0\r\n1 1 2 3 0.7071 0.7071 0 0\r\n")


def spec_seeds():
    t = "fuzz_trajectory_spec"
    for name, spec in [
        ("orbit", "builtin:orbit?frames=20"),
        ("survey", "builtin:survey?speed=8&fps=0.1&altitude=80&pitch=-45&frames=30&up=z&seed=1"),
        ("flythrough", "builtin:flythrough?frames=32&fps=0.5&seed=7&speed=20"),
        ("hover", "builtin:hover?frames=10&up=y"),
        ("orbit_up_minus_y", "builtin:orbit?frames=5&pitch=-90&up=-y&altitude=2"),
        ("survey_nadir", "builtin:survey?pitch=-90&frames=8&fps=1e3&speed=2.5e1"),
    ]:
        put(t, name, spec)

    t = "fuzz_builtin_spec"
    for name, spec in [
        ("city", "builtin:city"),
        ("city_params", "builtin:city?gaussians=2000000&seed=1"),
        ("city_exponent", "builtin:city?gaussians=2e6&seed=3"),
        ("city_too_small", "builtin:city?gaussians=10"),
        ("orbit", "builtin:orbit?speed=8.5&x=1"),
        ("duplicate", "builtin:city?seed=1&seed=2"),
    ]:
        put(t, name, spec)

    t = "fuzz_bench_sweep"
    for name, text in [
        ("two", "base: --culling opacity-aware; split: --split 256 --cache speculative --window 4"),
        ("file_lines", "# a sweep file\nexact: --culling exact\nauto: --split auto --split-tail 0.001\n"),
        ("bad_flag", "x: --window 99"),
    ]:
        put(t, name, text)

    t = "fuzz_render_flags"
    for name, text in [("grey", "0.5,0.5,0.5"), ("black", "0,0,0"), ("bad", "1,2"), ("exp", "1e-3,+0.25,1.0")]:
        put(t, name, text)

    t = "fuzz_token_file"
    for name, text in [("token", "s3cr3t-token\n"), ("crlf", "abc def \r\nsecond line\n"), ("empty_line", "\nx\n")]:
        put(t, name, text)

    t = "fuzz_cli_values"
    for name, text in [
        ("grid", "3x3"),
        ("up", "-y"),
        ("culling", "opacity-aware"),
        ("cache", "speculative"),
        ("precision", "double"),
        ("sweep_fixed", "--split 64 --cache speculative --window 8 --culling exact --guard-px 2 --guard-m 0.5 "
                        "--resort off"),
        ("sweep_auto", "--split auto --split-tail 0.01 --window adaptive --window-start 2 --cache off"),
        ("sweep_quoted", "--culling \"bbox3sigma\" --split=256"),
    ]:
        put(t, name, text)


# ---------------------------------------------------------------------------------------
# Server requests (protobuf), encoded from text format by protoc.

CONFIG = """scene_id: "city" width: 320 height: 240 horizontal_fov_degrees: 70
encoding { encoding: ENCODING_JPEG jpeg_quality: 90 jpeg_subsampling: CHROMA_SUBSAMPLING_444 }
background { r: 0.1 g: 0.2 b: 0.3 }
pipeline { cache: CACHE_MODE_SPECULATIVE window_start: 4 split: SPLIT_MODE_FIXED split_k: 256
           culling: CULLING_OPACITY_AWARE near_plane: 0.3 }
max_unacked_frames: 2 client_name: "seed" """
CONFIG_INTRINSICS = """scene_id: "a.b-c_d" width: 64 height: 48
intrinsics { fx: 50 fy: 51 cx: 32 cy: 24 }
encoding { encoding: ENCODING_RAW_RGB8 }
pipeline { fixed_window: 8 split: SPLIT_MODE_AUTO culling: CULLING_EXACT cache: CACHE_MODE_OFF }"""
POSE = "pose { position { x: 1 y: 2 z: 80 } orientation { w: 0.9 x: 0.1 y: -0.2 z: 0.3 } }"
FRAME = """sequence: 1 %s client_timestamp_us: 33333
linear_velocity { x: 1 y: 0 z: 0 } angular_speed: 0.5 last_received_sequence: 0
flight_plan { %s client_timestamp_us: 66666 }
flight_plan { pose { position { x: 1.5 y: 2 z: 80 } orientation { w: 1 } } client_timestamp_us: 99999 }""" % (POSE, POSE)
FRAME_MIN = "sequence: 7 pose { position { x: 0 y: 0 z: 0 } orientation { w: 1 } }"


def encode(message, text):
    proto_dir = os.path.join(ROOT, "proto")
    return subprocess.run(["protoc", "--encode=catgs.v1." + message, "-I", proto_dir, "catgs/v1/catgs.proto"],
                          input=text.encode(), capture_output=True, check=True).stdout


def request_seeds():
    if not shutil.which("protoc"):
        print("make_seed_corpus: protoc not found; request seeds not written", file=sys.stderr)
        return
    t = "fuzz_render_request"
    put(t, "fov_jpeg", encode("RenderRequest", "config { %s } frame { %s }" % (CONFIG, FRAME)))
    put(t, "intrinsics_raw", encode("RenderRequest", "config { %s } frame { %s }" % (CONFIG_INTRINSICS, FRAME_MIN)))
    put(t, "no_pose", encode("RenderRequest", "config { %s } frame { sequence: 1 }" % CONFIG_INTRINSICS))
    put(t, "too_wide", encode("RenderRequest", 'config { scene_id: "x" width: 8000 height: 10 } frame { %s }' % POSE))

    t = "fuzz_stream_request"
    put(t, "open", encode("StreamRequest", "open { %s }" % CONFIG))
    put(t, "open_intrinsics", encode("StreamRequest", "open { %s }" % CONFIG_INTRINSICS))
    put(t, "frame", encode("StreamRequest", "frame { %s }" % FRAME))
    put(t, "frame_min", encode("StreamRequest", "frame { %s }" % FRAME_MIN))
    put(t, "empty", b"")

    t = "fuzz_load_scene_request"
    for name, text in [
        ("ply", 'scene_id: "tiny" source: "tiny.ply"'),
        ("splat_derived_id", 'source: "tiny.splat"'),
        ("sub", 'source: "sub/tiny.ply" drop_invalid: true'),
        ("bad_drop", 'source: "bad.ply" drop_invalid: true'),
        ("bad", 'scene_id: "b" source: "bad.ply"'),
        ("link", 'source: "link.ply"'),
        ("dotdot", 'source: "../catgs-fuzz-scene-root/tiny.ply"'),
        ("up_link", 'source: "up/catgs-fuzz-scene-root/tiny.ply"'),
        ("slash_link", 'source: "slash/tmp/catgs-fuzz-scene-root/bad.ply"'),
        ("escape", 'source: "slash/etc/hostname"'),
        ("absolute", 'source: "/tmp/catgs-fuzz-scene-root/tiny.ply"'),
        ("builtin", 'scene_id: "c" source: "builtin:city?gaussians=10000&seed=2"'),
        ("bad_id", 'scene_id: "a b" source: "tiny.ply"'),
    ]:
        put(t, name, encode("LoadSceneRequest", text))


# ---------------------------------------------------------------------------------------
# The compressed scene formats: what splat-transform writes from small random graphdeco PLYs.
#
# Each fuzz execution decodes its whole input, with coverage and ASan on every byte, so the
# seeds are as small as the formats allow: 3 Gaussians per SH degree 0..3 (and one 257-Gaussian
# compressed PLY, whose second chunk holds one). SOG's meta.json holds three or four codebooks
# of 256 numbers whatever the count, ~18 characters each as splat-transform writes them: they are
# rounded to 4 significant digits, which keeps every value finite and every index in range
# but makes the JSON, which each execution parses twice, a third as long.

SPLAT_TRANSFORM = os.path.join(ROOT, "tests", "oracle", "node_modules", ".bin", "splat-transform")
ORACLE_TARGETS = ("fuzz_spz", "fuzz_compressed_ply", "fuzz_sog", "fuzz_glb")
SEED_COUNT = 3
TWO_CHUNK_COUNT = 257  # compressed PLY chunks hold 256 Gaussians
CODEBOOK_DIGITS = 4
ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # a fixed date: the seeds do not change when regenerated


def random_ply(path, degree, count):
    """A binary graphdeco PLY of `count` random Gaussians (seeded by degree and count)."""
    rng = random.Random(degree * 1000 + count)
    rest = 3 * ((degree + 1) ** 2 - 1)
    fields = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"] + ["f_rest_%d" % i for i in range(rest)] + \
        ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    with open(path, "wb") as f:
        f.write(("ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % count).encode())
        f.write("".join("property float %s\n" % n for n in fields).encode() + b"end_header\n")
        for _ in range(count):
            q = [rng.gauss(0, 1) for _ in range(4)]
            n = math.sqrt(sum(c * c for c in q))
            row = [rng.uniform(-5, 5), rng.uniform(-3, 3), rng.uniform(1, 9)] + \
                [rng.uniform(-1.5, 1.5) for _ in range(3)] + [rng.uniform(-0.4, 0.4) for _ in range(rest)] + \
                [rng.uniform(-3, 5)] + [rng.uniform(-5, -1) for _ in range(3)] + [c / n for c in q]
            f.write(struct.pack("<%df" % len(row), *row))


def splat_transform(*args):
    # -g cpu: SOG's SH palette is clustered on the GPU otherwise, which CI does not have.
    subprocess.run([SPLAT_TRANSFORM, "-q", "-w", "-g", "cpu", *args], check=True)


def read_bytes(path):
    with open(path, "rb") as f:
        return f.read()


def spz_version_2(raw):
    """Version 3's inflated payload re-encoded as version 2 (splat-transform writes only 3
    and 4): the smallest-three rotations become version 2's (x, y, z) bytes, w >= 0."""
    _, _, n, _, _, _, _ = struct.unpack("<IIIBBBB", raw[:16])
    rot = 16 + n * (9 + 1 + 3 + 3)
    v2 = bytearray(raw[:rot])
    struct.pack_into("<I", v2, 4, 2)
    for i in range(n):
        bits = struct.unpack("<I", raw[rot + 4 * i:rot + 4 * i + 4])[0]
        largest, q, norm2 = bits >> 30, [0.0] * 4, 0.0
        for c in (3, 2, 1, 0):
            if c == largest:
                continue
            mag = math.sqrt(0.5) * (bits & 511) / 511
            q[c] = -mag if (bits >> 9) & 1 else mag
            norm2 += q[c] * q[c]
            bits >>= 10
        q[largest] = math.sqrt(max(0.0, 1 - norm2))
        sign = -1.0 if q[3] < 0 else 1.0
        v2 += bytes(min(255, max(0, round(127.5 * (1 + sign * c)))) for c in q[:3])
    return bytes(v2 + raw[rot + 4 * n:])


def short_numbers(value):
    """meta.json with every float rounded to CODEBOOK_DIGITS significant digits."""
    if isinstance(value, float):
        return float("%.*g" % (CODEBOOK_DIGITS, value))
    if isinstance(value, list):
        return [short_numbers(v) for v in value]
    if isinstance(value, dict):
        return {k: short_numbers(v) for k, v in value.items()}
    return value


def short_meta(text):
    return json.dumps(short_numbers(json.loads(text)), separators=(",", ":")).encode()


def short_sog(path):
    """The .sog at `path` with its meta.json shortened, its entries stored in the same order."""
    with zipfile.ZipFile(path) as archive:
        entries = [(info.filename, archive.read(info)) for info in archive.infolist()]
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as archive:
        for name, data in entries:
            archive.writestr(zipfile.ZipInfo(name, ZIP_DATE), short_meta(data) if name == "meta.json" else data)
    return out.getvalue()


def oracle_seeds():
    work = tempfile.mkdtemp(prefix="catgs-seeds-")
    try:
        for degree in range(4):
            ply_in = os.path.join(work, "in%d.ply" % degree)
            random_ply(ply_in, degree, SEED_COUNT)
            name = "sh%d_n%d" % (degree, SEED_COUNT)
            out = os.path.join(work, name)
            # .spz as the file (versions 3 and 4), and its inflated payload (fuzz_spz gzips every
            # input and wraps it in ZSTD streams too, so that mutations reach the SPZ header and
            # blocks), in versions 3 and 2.
            splat_transform(ply_in, "--spz-version", "3", out + ".spz")
            raw = gzip.decompress(read_bytes(out + ".spz"))
            put("fuzz_spz", name + ".spz", read_bytes(out + ".spz"))
            splat_transform(ply_in, out + "_v4.spz")
            put("fuzz_spz", name + "_v4.spz", read_bytes(out + "_v4.spz"))
            put("fuzz_spz", name + ".spz.raw", raw)
            put("fuzz_spz", name + "_v2.spz.raw", spz_version_2(raw))
            splat_transform(ply_in, out + ".compressed.ply")
            put("fuzz_compressed_ply", name + ".compressed.ply", read_bytes(out + ".compressed.ply"))
            splat_transform(ply_in, out + ".glb")
            put("fuzz_glb", name + ".glb", read_bytes(out + ".glb"))
            # (splat-transform clusters the SH palette from random starts: the .sog files with SH
            # differ, equally valid, each time they are made.)
            splat_transform(ply_in, out + ".sog")
            put("fuzz_sog", name + ".sog", short_sog(out + ".sog"))
            if degree in (0, 3):  # the unbundled form, without and with the SH palette
                os.makedirs(out + "_meta")
                splat_transform(ply_in, os.path.join(out + "_meta", "meta.json"))
                put("fuzz_sog", name + "_meta.json", short_meta(read_bytes(os.path.join(out + "_meta", "meta.json"))))
        ply_in = os.path.join(work, "chunks.ply")
        random_ply(ply_in, 0, TWO_CHUNK_COUNT)
        out = os.path.join(work, "chunks.compressed.ply")
        splat_transform(ply_in, out)
        put("fuzz_compressed_ply", "sh0_n%d.compressed.ply" % TWO_CHUNK_COUNT, read_bytes(out))
    finally:
        shutil.rmtree(work)


def main():
    oracle = os.access(SPLAT_TRANSFORM, os.X_OK)
    if not oracle:
        print("make_seed_corpus: %s not found (tests/oracle/install-deps.sh): the seeds of %s are kept"
              % (SPLAT_TRANSFORM, ", ".join(ORACLE_TARGETS)), file=sys.stderr)
    clear_seeds(keep=() if oracle else ORACLE_TARGETS)
    if oracle:
        oracle_seeds()
    ply_seeds()
    splat_seeds()
    camera_seeds()
    spec_seeds()
    request_seeds()


if __name__ == "__main__":
    main()
