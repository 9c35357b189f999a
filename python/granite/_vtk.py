"""Reads the VTK XML frames granite writes (vtk/*.vtu, *.vtp) into numpy arrays: appended raw
binary (zlib-compressed or not, UInt32 or UInt64 block headers) and ascii."""

import re
import xml.etree.ElementTree as ElementTree
import zlib

import numpy as np

_TYPES = {
    "Int8": "i1", "UInt8": "u1", "Int16": "i2", "UInt16": "u2", "Int32": "i4", "UInt32": "u4",
    "Int64": "i8", "UInt64": "u8", "Float32": "f4", "Float64": "f8",
}
_MARK = b"<AppendedData encoding=\"raw\">"


def read_frame(path):
    """Every data array of a VTK XML file as {name: array}: point positions as "position"
    (n, 3), arrays of several components as (n, components), single ones as (n,). Arrays of the
    cells' layout (connectivity, offsets, types) are left out."""
    raw = open(path, "rb").read()
    start = raw.find(_MARK)
    if start >= 0:
        # The appended block starts after "_" and is binary: parse the XML without it.
        underscore = raw.index(b"_", start + len(_MARK))
        appended = raw[underscore + 1:]
        end = raw.rfind(b"</AppendedData>")
        xml = raw[:start] + b"<AppendedData/>" + raw[end + len(b"</AppendedData>"):]
    else:
        appended, xml = b"", raw
    root = ElementTree.fromstring(xml)
    byte_order = "<" if root.get("byte_order", "LittleEndian") == "LittleEndian" else ">"
    header = np.dtype(byte_order + ("u8" if root.get("header_type") == "UInt64" else "u4"))
    compressed = root.get("compressor") is not None
    arrays = {}
    for parent in root.iter():
        for array in parent.findall("DataArray"):
            name = array.get("Name")
            if parent.tag == "Points":
                name = "position"
            if parent.tag in ("Cells", "Verts", "Lines", "Polys", "Strips") or name is None:
                continue
            dtype = np.dtype(byte_order + _TYPES[array.get("type")])
            if array.get("format") == "appended":
                values = _appended(appended, int(array.get("offset")), dtype, header, compressed)
            elif array.get("format") == "ascii":
                values = np.array((array.text or "").split(), dtype=dtype)
            else:
                raise ValueError(f"{path}: DataArray {name}: format {array.get('format')!r} is not read here")
            components = int(array.get("NumberOfComponents", "1"))
            arrays[name] = values.reshape(-1, components) if components > 1 else values
    return arrays


def _appended(data, offset, dtype, header, compressed):
    size = header.itemsize
    if not compressed:
        length = int(np.frombuffer(data, header, 1, offset)[0])
        return np.frombuffer(data, dtype, length // dtype.itemsize, offset + size).copy()
    blocks, block_size, last_size = (int(v) for v in np.frombuffer(data, header, 3, offset))
    if blocks == 0:
        return np.empty(0, dtype)
    sizes = np.frombuffer(data, header, blocks, offset + 3 * size).astype(np.int64)
    at = offset + (3 + blocks) * size
    parts = []
    for k, compressed_size in enumerate(sizes):
        block = zlib.decompress(data[at:at + compressed_size])
        expected = last_size if (k == blocks - 1 and last_size) else block_size
        if len(block) != expected:
            raise ValueError(f"a compressed block of {len(block)} bytes where {expected} were announced")
        parts.append(block)
        at += compressed_size
    return np.frombuffer(b"".join(parts), dtype).copy()


def frame_files(vtk_dir, collection):
    """The frames of one collection (`points`, `contacts`) in order, from their file names."""
    pattern = re.compile(re.escape(collection) + r"_(\d+)\.vt[up]$")
    found = []
    if vtk_dir.is_dir():
        for path in vtk_dir.iterdir():
            match = pattern.match(path.name)
            if match:
                found.append((int(match.group(1)), path))
    return [path for _, path in sorted(found)]
