"""Bytes of RGL tensor_file (.bsdf) files written from the format description, for the reader's
tests and the fuzzer."""

import struct

import numpy as np

_CODES = {np.dtype("uint8"): 1, np.dtype("uint32"): 5, np.dtype("float32"): 10}


def tensor_file(fields, align=8):
    """Bytes of a tensor_file holding ``fields`` (name -> array), written from the format
    description, and ``{name: (entry, dtype byte, offset byte, data offset)}``."""
    head = bytearray(b"tensor_file\x00" + bytes([1, 0]) + struct.pack("<I", len(fields)))
    where, arrays = {}, {}
    for name, a in fields.items():
        a = np.ascontiguousarray(a)
        entry = len(head)
        raw = name.encode()
        head += struct.pack("<H", len(raw)) + raw + struct.pack("<H", a.ndim)
        where[name] = [entry, len(head), len(head) + 1]
        head += struct.pack("<BQ", _CODES[a.dtype], 0) + struct.pack(f"<{a.ndim}Q", *a.shape)
        arrays[name] = a
    body = bytearray(head)
    for name, a in arrays.items():
        body += bytes(-len(body) % align)
        struct.pack_into("<Q", body, where[name][2], len(body))
        where[name].append(len(body))
        body += a.astype(a.dtype.newbyteorder("<")).tobytes()
    return bytes(body), {k: tuple(v) for k, v in where.items()}


def small_material():
    """A valid material with 3 incident angles and 4 x 4 samples per angle."""
    f32 = np.float32
    return {
        "version": np.array([1, 0], dtype=np.uint32),
        "description": np.frombuffer("Test swatch (µ)".encode(), dtype=np.uint8),
        "phi_i": np.zeros(1, f32),
        "theta_i": np.array([0.0, 0.7, 1.5707964], f32),
        "sigma": np.full((2, 8), 0.8, f32),
        "ndf": np.full((2, 8), 0.3, f32),
        "vndf": np.ones((1, 3, 8, 8), f32),
        "luminance": np.ones((1, 3, 4, 4), f32),
        "rgb": np.full((1, 3, 3, 4, 4), 0.5, f32),
        "jacobian": np.ones(1, np.uint8),
    }
