#!/usr/bin/env python3
"""Writes the seed corpora in fuzz/corpus/<target>/ (run from anywhere).

Frames are built here from docs/wire-format.md (postcard by hand,
binascii.crc32, textbook COBS), independently of the Rust code, and the
encoder is first checked against the golden frames of core/tests/wire.rs.
Re-running it rewrites the same files; it removes nothing else.
"""

import binascii
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))
VERSION = 2


def varint(n):
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def f32(x):
    return struct.pack("<f", x)


def levels(ls):
    return varint(len(ls)) + b"".join(f32(x) for x in ls)


def cobs(data):
    out = bytearray()
    block = bytearray()
    for b in data:
        if b == 0:
            out += bytes([len(block) + 1]) + block
            block = bytearray()
        else:
            block.append(b)
            if len(block) == 254:
                out += b"\xff" + block
                block = bytearray()
    out += bytes([len(block) + 1]) + block
    return bytes(out)


def frame(payload, version=VERSION, crc_xor=0):
    body = bytes([version]) + payload
    crc = (binascii.crc32(body) ^ crc_xor) & 0xFFFFFFFF
    return cobs(body + struct.pack("<I", crc)) + b"\x00"


# Postcard payloads of each message kind (variant index first).
def hello(protocol, fw, seq=0):
    return varint(0) + bytes([protocol]) + bytes(fw) + varint(seq)


def capabilities(protocol, max_slice_samples, sample_types, display_points):
    return varint(1) + bytes([protocol]) + varint(max_slice_samples) + bytes([sample_types]) + varint(display_points)


def begin_volume(seq, dims, sample_type, spacing, lv, axes, every):
    return (varint(2) + varint(seq) + b"".join(varint(d) for d in dims) + varint(sample_type)
            + b"".join(f32(s) for s in spacing) + levels(lv) + bytes([axes, every]))


def slice_data(seq, slc, offset, data):
    return varint(3) + varint(seq) + varint(slc) + varint(offset) + varint(len(data)) + bytes(data)


def end_volume(seq):
    return varint(4) + varint(seq)


def set_levels(seq, lv):
    return varint(5) + varint(seq) + levels(lv)


def set_view(seq, yaw, pitch, roll, fov, spin):
    return varint(6) + varint(seq) + b"".join(f32(x) for x in (yaw, pitch, roll, fov, spin))


def set_beam(seq, lit_step, dwell_us, settle_us):
    return varint(7) + varint(seq) + varint(lit_step) + varint(dwell_us) + varint(settle_us)


def ack(seq):
    return varint(8) + varint(seq)


def nack(seq, code):
    return varint(9) + varint(seq) + varint(code)


def status(seq, state, slices, points, refresh):
    return varint(10) + varint(seq) + varint(state) + varint(slices) + varint(points) + varint(refresh)


# (name, payload, golden frame from core/tests/wire.rs)
GOLDEN = [
    ("hello", hello(1, [0, 3, 2], 300), "02020201090302ac02f8e2d61100"),
    ("capabilities", capabilities(1, 65536, 0x0F, 4000), "0e0201018080040fa01f3ef245aa00"),
    ("begin_volume", begin_volume(1, [64, 64, 300], 2, [1.0, 1.0, 2.5], [100.0, 1000.0], 0b101, 4),
     "090202014040ac02020103803f0103803f01042040020103c84201097a440504c670e99200"),
    ("slice_data", slice_data(2, 17, 300, [0, 1, 2, 0xFF, 0]), "0802030211ac0205040102ff05de84eea300"),
    ("end_volume", end_volume(130), "09020482011475f6f200"),
    ("set_levels", set_levels(3, [0.5]), "05020503010101063f9081ad7800"),
    ("set_view", set_view(4, 30.0, -15.0, 0.0, 0.0, 10.0),
     "040206040103f041010370c101010101010101010107204130fe9cfc00"),
    ("set_beam", set_beam(5, 64, 2, 20), "0b020705400214b517822100"),
    ("ack", ack(7), "08020807d71278aa00"),
    ("nack", nack(8, 6), "0902090806250326a500"),
    ("status", status(9, 2, 300, 4000, 5000), "0f020a0902ac02a01f882742e0dee200"),
]

for name, payload, want in GOLDEN:
    got = frame(payload).hex()
    assert got == want, f"{name}: encoder gives {got}, golden is {want}"

G = {name: frame(payload) for name, payload, _ in GOLDEN}
ACK, END = G["ack"], G["end_volume"]


def pattern(n, start=1):
    """n bytes with zeros every 37 bytes and runs of non-zero in between."""
    return bytes((start + i) % 256 if i % 37 else 0 for i in range(n))


# Single frames that must be rejected (delimiter included).
BAD = {
    "bad_version": frame(ack(7), version=1),
    "bad_crc": frame(ack(7), crc_xor=1),
    "nine_levels": frame(set_levels(3, [1.0] * 9)),
    "unknown_variant": frame(varint(11) + varint(3)),
    "trailing_byte": frame(ack(7) + b"\x01"),
    "cut_in_block": G["ack"][:5] + b"\x00",
    "cut_on_boundary": G["set_view"][:12] + b"\x00",
    "truncated": bytes([0x03, 0x01, 0x08, 0x00]),
    "slice_len_past_end": frame(varint(3) + varint(1) + varint(0) + varint(0) + varint(200) + b"\x01\x02"),
    "overlong_varint_seq": frame(varint(8) + b"\x87\x00"),  # Ack { seq: 7 }, varint 2 bytes long
}

# Large frames: a SliceData with a 254-byte non-zero run (COBS 0xFF blocks),
# the largest frame of the protocol (MAX_CHUNK = 1024 bytes, largest
# varints), one over 64 bytes and one over 1200 bytes.
BIG = {
    "run_of_254": frame(slice_data(1, 2, 3, bytes(range(1, 255)) * 2)),
    "max_chunk": frame(slice_data(0xFFFF, 0xFFFF, 0xFFFFFFFF, pattern(1024))),
    "over_64": frame(slice_data(2, 3, 4096, pattern(100))),
    "over_1200": frame(slice_data(2, 3, 8192, pattern(1250))),
}

ALL_GOLDEN = b"".join(G[name] for name, _, _ in GOLDEN)

STREAMS = {
    "all_golden_back_to_back": ALL_GOLDEN,
    "flush_then_frames": b"\x00" + ACK + END,
    "garbage_then_frames": b"\x00\x00noise\x00" + ACK + b"\x00\x00\x00more junk\x00" + END,
    "junk_without_delimiter_then_frames": b"junk" + ACK + END,
    "bad_frames_then_good": b"".join(BAD.values()) + ACK,
    "over_64_then_ack": BIG["over_64"] + ACK + BIG["over_64"] + ACK,
    "over_1200_then_ack": BIG["over_1200"] + ACK,
    "partial_tail": ACK + G["begin_volume"][:20],
}


def write(target, name, data):
    d = os.path.join(HERE, "corpus", target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


# frame_decoder: byte streams.
for name, data in G.items():
    write("frame_decoder", "golden_" + name, data)
for name, data in {**BAD, **BIG, **STREAMS}.items():
    write("frame_decoder", name, data)

# decode_frame: one frame, without its delimiter.
for name, data in {**{"golden_" + k: v for k, v in G.items()}, **BAD, **BIG}.items():
    write("decode_frame", name, data[:-1])

# message_roundtrip: input for `arbitrary` (fuzz_targets/message_roundtrip.rs):
# the variant is picked by a little-endian u32 x as (x * 11) >> 32, then the
# fields. One seed per variant, with the golden payload bytes as the fields.
for i, (name, payload, _) in enumerate(GOLDEN):
    x = -(-(i << 32) // 11)  # ceil(i * 2^32 / 11): the smallest x picking variant i
    write("message_roundtrip", "variant_" + name, struct.pack("<I", x) + payload[1:] + pattern(16))
write("message_roundtrip", "variant_slice_data_1024",
      struct.pack("<I", -(-(3 << 32) // 11)) + b"\x02\x00\x11\x00\x2c\x01\x00\x00" + pattern(1024))

# engine: one configuration byte (chunk size 1 + c % 64, clock step
# (c >> 6) * 2 s per chunk), then the bytes on the line
# (fuzz_targets/engine.rs).
def volume_stream(seq, dims, chunk=1024, every=1, skip=None, dup=None):
    nx, ny, nz = dims
    out = b"\x00" + frame(hello(2, [0, 0, 0], seq))
    out += frame(begin_volume(seq, dims, 0, [1.0, 1.0, 1.0], [40.5, 90.0], 0b111, every))
    seq += 1
    for z in range(nz):
        data = bytes(((i * 29 + z * 53) % 150) for i in range(nx * ny))
        for off in range(0, len(data), chunk):
            if (z, off) == skip:
                continue
            f = frame(slice_data(seq & 0xFFFF, z, off, data[off:off + chunk]))
            out += f + (f if (z, off) == dup else b"")
            seq += 1
    return out + frame(end_volume(seq & 0xFFFF))


ENGINE = {
    "volume_whole_chunks": (0x3F, volume_stream(1, (6, 5, 3))),
    "volume_small_chunks_every2": (0x07, volume_stream(100, (8, 6, 4), chunk=7, every=2)),
    "volume_byte_by_byte": (0x00, volume_stream(65530, (4, 4, 2))),
    "volume_missing_chunk": (0x10, volume_stream(5, (8, 6, 3), chunk=16, skip=(1, 16))),
    "volume_retransmitted_chunk": (0x10, volume_stream(5, (8, 6, 3), chunk=16, dup=(1, 0))),
    "volume_times_out": (0x7F, volume_stream(1, (6, 5, 3), chunk=10)),
    "settings_then_volume": (0x20, b"\x00" + frame(hello(2, [0, 0, 0], 1)) + frame(set_levels(1, [70.0]))
                             + frame(set_view(2, 45.0, 10.0, 5.0, 40.0, 30.0)) + frame(set_beam(3, 8, 3, 4))
                             + volume_stream(4, (6, 6, 3))),
    "garbage_then_volume": (0x05, bytes(range(1, 200)) + b"\x00" + volume_stream(9, (5, 5, 2))),
    "all_golden": (0x30, ALL_GOLDEN),
}
for name, (cfg, data) in ENGINE.items():
    write("engine", name, bytes([cfg]) + data)


# The volume readers: a byte picking the format (readers.rs: 0 NRRD, 1
# NIfTI-1 .nii, 2 MRC, 3 cube, 4 VTK, 5 NIfTI-1 .hdr), then a small file of
# that format, written here from the formats' own descriptions.
import gzip as _gzip

DATA = bytes(range(24))
NRRD = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 3 2\nspacings: 1 1 2\nencoding: raw\n\n" + DATA


def nifti(magic=b"n+1\0", datatype=2, bitpix=8, dims=(4, 3, 2), data=DATA):
    h = bytearray(348)
    struct.pack_into("<i", h, 0, 348)
    struct.pack_into("<8h", h, 40, 3, *dims, 1, 1, 1, 1)
    struct.pack_into("<hh", h, 70, datatype, bitpix)
    struct.pack_into("<8f", h, 76, 1.0, 1.0, 1.0, 2.0, 1.0, 1.0, 1.0, 1.0)
    struct.pack_into("<ff", h, 108, 352.0, 1.0)
    h[344:348] = magic
    return bytes(h) + b"\0\0\0\0" + data


def mrc(dims=(4, 3, 2), data=DATA):
    h = bytearray(1024)
    struct.pack_into("<4i", h, 0, *dims, 0)
    struct.pack_into("<3i", h, 28, *dims)
    struct.pack_into("<3f", h, 40, float(dims[0]), float(dims[1]), float(dims[2]))
    struct.pack_into("<3f", h, 52, 90.0, 90.0, 90.0)
    struct.pack_into("<3i", h, 64, 1, 2, 3)
    h[208:212] = b"MAP "
    h[212:216] = b"\x44\x44\x00\x00"
    return bytes(h) + data


CUBE = (b"a cube\nof two by two by two\n 1 0.0 0.0 0.0\n 2 1.0 0.0 0.0\n 2 0.0 1.0 0.0\n 2 0.0 0.0 1.0\n"
        b" 1 1.0 0.0 0.0 0.0\n 1.0 2.0 3.0 4.0 5.0\n 6.0 7.0 8.0\n")
VTK_HEAD = (b"# vtk DataFile Version 3.0\nseed\n%s\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2 2\n"
            b"ORIGIN 0 0 0\nSPACING 1 1 1\nPOINT_DATA 8\nSCALARS s float 1\nLOOKUP_TABLE default\n")
VTK_ASCII = VTK_HEAD % b"ASCII" + b"1 2 3 4 5 6 7 8\n"
VTK_BINARY = VTK_HEAD % b"BINARY" + struct.pack(">8f", *range(1, 9)) + b"\n"

READERS = {
    "nrrd_raw": (0, NRRD),
    "nrrd_gzip": (0, NRRD.replace(b"encoding: raw", b"encoding: gzip").replace(DATA, _gzip.compress(DATA, mtime=0))),
    "nrrd_ascii": (0, NRRD.replace(b"encoding: raw", b"encoding: ascii").replace(DATA, b" ".join(b"%d" % b for b in DATA))),
    "nifti": (1, nifti()),
    "nifti_f32": (1, nifti(datatype=16, bitpix=32, dims=(2, 2, 2), data=struct.pack("<8f", *range(8)))),
    "nifti_gz": (1, _gzip.compress(nifti(), mtime=0)),
    "mrc": (2, mrc()),
    "mrc_gz": (2, _gzip.compress(mrc(), mtime=0)),
    "cube": (3, CUBE),
    "cube_gz": (3, _gzip.compress(CUBE, mtime=0)),
    "vtk_ascii": (4, VTK_ASCII),
    "vtk_binary": (4, VTK_BINARY),
    "vtk_gz": (4, _gzip.compress(VTK_BINARY, mtime=0)),
    "nifti_pair_header": (5, nifti(magic=b"ni1\0")[:348]),
}
for name, (pick, data) in READERS.items():
    write("readers", name, bytes([pick]) + data)
