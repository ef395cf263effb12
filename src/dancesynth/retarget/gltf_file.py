"""Opening a user's glTF, GLB or VRM file safely.

``open_gltf`` checks a GLB container against its own lengths and the JSON's asset version before
pygltflib parses it; ``buffer_bytes`` and ``read_uri`` bring the bytes a file refers to (the
.glb's binary chunk, base64 data: URIs, files next to a .gltf); ``GltfReader`` turns accessors
into arrays (every component type, strides, sparse substitutions, normalized integers) and
finds images' bytes. Everything a broken file can get wrong becomes one ``InputError`` line,
never a traceback.
"""

from __future__ import annotations

import base64
import binascii
import json
import struct
import urllib.parse
import warnings
from pathlib import Path

import numpy as np

from ..errors import InputError

_GLB_MAGIC, _JSON_CHUNK, _BIN_CHUNK = b"glTF", 0x4E4F534A, 0x004E4942
_COMPONENT = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def invalid_file(path: Path, exc: Exception) -> InputError:
    """An exception met while reading ``path``'s JSON fields, as one ``InputError`` line."""
    detail = (str(exc).splitlines() or [""])[0][:120]
    return InputError(f"{path.name} is not a valid glTF file ({type(exc).__name__}{': ' + detail if detail else ''})")


def open_gltf(path):
    """``path`` parsed as a ``pygltflib.GLTF2`` (a .glb's binary chunk attached), or ``InputError``."""
    import pygltflib

    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    blob = None
    if data[:4] == _GLB_MAGIC:
        text, blob = _split_glb(data, path.name)
    else:
        try:
            text = data.decode("utf-8-sig")
            raw = json.loads(text)
        except (UnicodeDecodeError, ValueError):
            raise InputError(f"{path.name} is not a glTF file: expected a .glb or .vrm (binary glTF) or a .gltf "
                             "(JSON)") from None
        _check_gltf_json(raw, path.name)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gltf = pygltflib.GLTF2.gltf_from_json(text)
    except Exception as exc:  # pygltflib meets a field it cannot read
        raise invalid_file(path, exc) from None
    if blob is not None:
        gltf.set_binary_blob(blob)
    return gltf


def _split_glb(data: bytes, name: str) -> tuple[str, bytes | None]:
    """The JSON text and binary chunk of a GLB container, checked against its own lengths."""
    if len(data) < 20:
        raise InputError(f"{name} is truncated: a binary glTF is at least 20 bytes, this one {len(data)}")
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise InputError(f"{name} is binary glTF version {version}; only glTF 2.0 is supported")
    if length > len(data):
        raise InputError(f"{name} is truncated: its header says {length} bytes, the file has {len(data)}")
    chunks, at = [], 12
    while at + 8 <= length:
        size, kind = struct.unpack_from("<II", data, at)
        if at + 8 + size > length:
            raise InputError(f"{name} is truncated or corrupt: a chunk runs past the end of the file")
        chunks.append((kind, data[at + 8:at + 8 + size]))
        at += 8 + size
    if not chunks or chunks[0][0] != _JSON_CHUNK:
        raise InputError(f"{name} is corrupt: a binary glTF starts with a JSON chunk")
    try:
        text = chunks[0][1].decode("utf-8")
        raw = json.loads(text)
    except (UnicodeDecodeError, ValueError):
        raise InputError(f"{name} is corrupt: its JSON chunk does not parse") from None
    _check_gltf_json(raw, name)
    blob = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == _BIN_CHUNK else None
    return text, blob


def _check_gltf_json(raw, name: str) -> None:
    asset = raw.get("asset") if isinstance(raw, dict) else None
    if not isinstance(asset, dict) or not str(asset.get("version", "")).startswith("2."):
        raise InputError(f"{name} is not a glTF 2.0 file (JSON without an asset version 2.x)")


def buffer_bytes(gltf, path) -> list[bytes]:
    """The bytes of each of ``gltf``'s buffers: the .glb's binary chunk, a data: URI, or a file next to
    ``path``; each cut to its declared length."""
    name, folder = Path(path).name, Path(path).parent
    out = []
    for i, buf in enumerate(gltf.buffers or []):
        if buf.uri is None:
            data = gltf.binary_blob() if i == 0 else None
            if data is None:
                raise InputError(f"{name} is corrupt: buffer {i} has no data")
        else:
            data = read_uri(buf.uri, folder, name)
        if len(data) < (buf.byteLength or 0):
            raise InputError(f"{name} is truncated: buffer {i} holds {len(data)} of its {buf.byteLength} bytes")
        out.append(bytes(data[:buf.byteLength]))
    return out


def read_uri(uri: str, folder: Path, name: str) -> bytes:
    """The bytes a glTF URI points at: a base64 data: URI or a file relative to the model's folder."""
    if uri.startswith("data:"):
        try:
            return base64.b64decode(uri.partition(",")[2], validate=True)
        except (binascii.Error, ValueError):
            raise InputError(f"{name} is corrupt: a data: URI is not valid base64") from None
    file = folder / urllib.parse.unquote(uri)
    try:
        return file.read_bytes()
    except OSError as exc:
        raise InputError(f"{name} refers to {uri}, which cannot be read: {exc.strerror or exc}; keep the "
                         "files a .gltf names next to it") from None


class GltfReader:
    """A model's accessors as arrays and its images as bytes, its buffers read once."""

    def __init__(self, gltf, path: Path):
        self.gltf, self.path = gltf, path
        self._buffers = None

    def corrupt(self, detail: str) -> InputError:
        return InputError(f"{self.path.name} is corrupt: {detail}")

    def check_index(self, items, i, kind: str, what: str) -> int:
        if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < len(items or []):
            raise self.corrupt(f"{what} refers to {kind} {i!r}, which does not exist")
        return i

    @property
    def buffers(self) -> list[bytes]:
        if self._buffers is None:
            self._buffers = buffer_bytes(self.gltf, self.path)
        return self._buffers

    def accessor(self, i, what: str, types: tuple[str, ...], *, integer=False, as_float=False,
                 count: int | None = None) -> np.ndarray:
        """Accessor ``i`` as a (count, components) array, sparse values substituted. ``integer``: it must
        hold integers (indices, joints); ``as_float``: integers become floats as a normalized accessor's
        do (the glTF spec allows only normalized ones there); ``count``: the count it must have."""
        acc = self.gltf.accessors[self.check_index(self.gltf.accessors, i, "accessor", what)]
        dtype = _COMPONENT.get(acc.componentType)
        if acc.type not in types or dtype is None:
            raise self.corrupt(f"{what} is a {acc.type} accessor of component type {acc.componentType}; "
                               f"expected {' or '.join(types)}")
        n = acc.count
        if isinstance(n, bool) or not isinstance(n, int) or n < 0 or (count is not None and n != count):
            raise self.corrupt(f"{what} has {n!r} elements" + (f", not {count}" if count is not None else ""))
        width = _WIDTH[acc.type]
        out = np.zeros((n, width), dtype) if acc.bufferView is None else \
            self._view(acc.bufferView, acc.byteOffset or 0, n, width, dtype, what)
        if acc.sparse is not None and acc.sparse.count:
            sparse = acc.sparse
            at = self._view(sparse.indices.bufferView, sparse.indices.byteOffset or 0, sparse.count, 1,
                            _COMPONENT.get(sparse.indices.componentType, "<f4"), f"{what}'s sparse indices").ravel()
            if at.dtype.kind != "u" or at.max() >= n:
                raise self.corrupt(f"{what}'s sparse indices are not indices of its {n} elements")
            out = out.copy()
            out[at] = self._view(sparse.values.bufferView, sparse.values.byteOffset or 0, sparse.count, width,
                                 dtype, f"{what}'s sparse values")
        if integer and out.dtype.kind == "f":
            raise self.corrupt(f"{what} holds floats where integers belong")
        if out.dtype.kind != "f" and not integer and (acc.normalized or as_float):
            out = np.maximum(out / np.float32(np.iinfo(out.dtype).max), -1.0).astype(np.float32)
        return out

    def _view(self, v, offset: int, count: int, width: int, dtype: str, what: str) -> np.ndarray:
        """``count`` elements of ``width`` components read from bufferView ``v`` at ``offset``, its stride
        honoured (a read-only view of the buffer)."""
        view = self.gltf.bufferViews[self.check_index(self.gltf.bufferViews, v, "bufferView", what)]
        data = self.buffers[self.check_index(self.buffers, view.buffer, "buffer", f"bufferView {v}")]
        item = np.dtype(dtype).itemsize
        stride = view.byteStride or width * item
        start, end = (view.byteOffset or 0), (view.byteOffset or 0) + (view.byteLength or 0)
        need = start + offset + (stride * (count - 1) + width * item if count else 0)
        if offset < 0 or stride < width * item or need > end or end > len(data):
            raise self.corrupt(f"{what} runs past the end of bufferView {v} or its buffer")
        return np.ndarray((count, width), dtype, data, start + offset, (stride, item))

    def image_bytes(self, i: int) -> bytes | None:
        """Image ``i``'s encoded bytes, from its bufferView or its URI; None when it names neither."""
        image = self.gltf.images[i]
        if image.bufferView is not None:
            view = self.gltf.bufferViews[image.bufferView]
            start = view.byteOffset or 0
            return self.buffers[view.buffer][start:start + view.byteLength]
        if image.uri:
            return read_uri(image.uri, self.path.parent, self.path.name)
        return None
