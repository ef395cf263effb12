"""Opening a user's glTF, GLB or VRM file safely: a downloaded model is hostile input.

``open_gltf`` checks a GLB container against its own lengths, the JSON (strict: no NaN or
Infinity; nesting at most ``MAX_JSON_DEPTH`` deep), its asset version and every URI it holds
before pygltflib parses it; ``buffer_bytes`` and ``read_uri`` bring the bytes a file refers to
(the .glb's binary chunk, base64 data: URIs, files in the model's own folder); ``GltfReader``
turns accessors into arrays (every component type, strides, sparse substitutions, normalized
integers) and finds images' bytes. Everything a broken file can get wrong becomes one
``InputError`` line, never a traceback.

What a model may make us read: a URI is a ``data:`` URI or a relative path to a regular file
inside the model's folder (resolved, symlinks followed: none may lead out); absolute paths,
``../`` out of the folder (percent-encoded too), other schemes, devices and pipes are refused
when the model is opened, before anything is read. Sizes are bounded: the model file and the
files it refers to together by ``MAX_MODEL_BYTES``, an image by ``MAX_IMAGE_BYTES``, an
accessor by ``MAX_ACCESSOR_COUNT`` elements.
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
from ..io.files import inside_folder, read_user_file

_GLB_MAGIC, _JSON_CHUNK, _BIN_CHUNK = b"glTF", 0x4E4F534A, 0x004E4942
_COMPONENT = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
MAX_MODEL_BYTES = 512 * 2**20     # a model and the files it refers to, together (avatars are 5-100 MB)
MAX_IMAGE_BYTES = 64 * 2**20      # one encoded texture
MAX_ACCESSOR_COUNT = 4_000_000    # elements of one accessor (an avatar has 10^4-10^5 vertices)
MAX_JSON_DEPTH = 64               # glTF nests about 8 deep; far deeper is an attack on the parsers


def invalid_file(path: Path, exc: Exception) -> InputError:
    """An exception met while reading ``path``'s JSON fields, as one ``InputError`` line."""
    detail = (str(exc).splitlines() or [""])[0][:120]
    return InputError(f"{path.name} is not a valid glTF file ({type(exc).__name__}{': ' + detail if detail else ''})")


def open_gltf(path):
    """``path`` parsed as a ``pygltflib.GLTF2`` (a .glb's binary chunk attached), or ``InputError``."""
    import pygltflib

    path = Path(path)
    data = read_user_file(path, limit=MAX_MODEL_BYTES, what=str(path))
    blob = None
    if data[:4] == _GLB_MAGIC:
        text, raw, blob = _split_glb(data, path.name)
    else:
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError:
            raise InputError(f"{path.name} is not a glTF file: expected a .glb or .vrm (binary glTF) or a .gltf "
                             "(JSON)") from None
        raw = _parse_json(text, path.name, f"{path.name} is not a glTF file: expected a .glb or .vrm (binary glTF) "
                                           "or a .gltf (JSON)")
    _check_gltf_json(raw, path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gltf = pygltflib.GLTF2.gltf_from_json(text)
    except Exception as exc:  # pygltflib meets a field it cannot read
        raise invalid_file(path, exc) from None
    if blob is not None:
        gltf.set_binary_blob(blob)
    # pygltflib writes a file back only with these of the right type ("extensions": null is valid JSON).
    gltf.extensions = gltf.extensions if isinstance(gltf.extensions, dict) else {}
    gltf.extensionsUsed = gltf.extensionsUsed if isinstance(gltf.extensionsUsed, list) else []
    gltf.extensionsRequired = gltf.extensionsRequired if isinstance(gltf.extensionsRequired, list) else []
    return gltf


def _split_glb(data: bytes, name: str) -> tuple[str, object, bytes | None]:
    """The JSON text, its parse and the binary chunk of a GLB container, checked against its own lengths."""
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
    except UnicodeDecodeError:
        raise InputError(f"{name} is corrupt: its JSON chunk is not UTF-8") from None
    raw = _parse_json(text, name, f"{name} is corrupt: its JSON chunk does not parse")
    blob = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == _BIN_CHUNK else None
    return text, raw, blob


def _parse_json(text: str, name: str, failure: str):
    """Strict JSON (NaN and Infinity are not JSON, and no writer can put them back) nested at most
    ``MAX_JSON_DEPTH`` deep."""
    def no_constant(word):
        raise InputError(f"{name} is corrupt: its JSON holds {word}, which JSON does not allow")

    deep = InputError(f"{name} is corrupt: its JSON nests more than {MAX_JSON_DEPTH} levels deep")
    try:
        raw = json.loads(text, parse_constant=no_constant)
    except RecursionError:
        raise deep from None
    except ValueError:
        raise InputError(failure) from None
    todo, depth = [raw], 0
    while todo:   # breadth first, one level at a time
        depth += 1
        if depth > MAX_JSON_DEPTH:
            raise deep
        todo = [v for x in todo for v in (x.values() if isinstance(x, dict) else x) if isinstance(v, (dict, list))]
    return raw


def _check_gltf_json(raw, path: Path) -> None:
    """A glTF 2.0 asset whose every buffer and image URI may be read (``resolve_uri``)."""
    name = path.name
    asset = raw.get("asset") if isinstance(raw, dict) else None
    if not isinstance(asset, dict) or not str(asset.get("version", "")).startswith("2."):
        raise InputError(f"{name} is not a glTF 2.0 file (JSON without an asset version 2.x)")
    views = raw.get("bufferViews")
    for i, view in enumerate(views if isinstance(views, list) else [] if views is None else [None]):
        # buffer and byteLength are required, byteOffset optional: each a whole number >= 0
        fields = [view.get("buffer"), view.get("byteLength"), view.get("byteOffset", 0)] \
            if isinstance(view, dict) else [None]
        if not all(type(v) is int and v >= 0 for v in fields):
            raise InputError(f"{name} is corrupt: bufferView {i} is not a buffer, byte length and offset")
    for kind in ("buffers", "images"):
        items = raw.get(kind)
        if items is None:
            continue
        if not isinstance(items, list):
            raise InputError(f"{name} is corrupt: its {kind} are not a list")
        for item in items:
            uri = item.get("uri") if isinstance(item, dict) else None
            if uri is None:
                continue
            if not isinstance(uri, str):
                raise InputError(f"{name} is corrupt: a URI of its {kind} is not text")
            resolve_uri(uri, path.parent, name)


def resolve_uri(uri: str, folder: Path, name: str) -> Path | None:
    """The file a glTF URI names, inside ``folder``; None for a ``data:`` URI. Anything else is refused:
    a model must not make us read (and copy into a dance the user shares) files outside its folder."""
    if uri.startswith("data:"):
        return None
    shown = repr(uri[:80])
    refuse = (f"{name} refers to {shown}, {{}}; a model may refer only to files in its own folder or to "
              "data: URIs")
    try:
        parts = urllib.parse.urlsplit(uri)
    except ValueError:   # e.g. a malformed IPv6 host
        raise InputError(refuse.format("which is not a valid URI")) from None
    relative = urllib.parse.unquote(parts.path).replace("\\", "/")   # Windows tools write backslashes
    if parts.scheme or parts.netloc:
        raise InputError(refuse.format(f"a {parts.scheme or 'network'} address"))
    if "\0" in relative or relative.startswith("/") or not relative.strip():
        raise InputError(refuse.format("which is not a relative path"))
    target = inside_folder(folder, relative)
    if target is None:
        raise InputError(refuse.format("which lies outside the model's folder"))
    return target


def buffer_bytes(gltf, path) -> list[bytes]:
    """The bytes of each of ``gltf``'s buffers: the .glb's binary chunk, a data: URI, or a file in
    ``path``'s folder; each cut to its declared length, all together at most ``MAX_MODEL_BYTES``."""
    name, folder = Path(path).name, Path(path).parent
    out, total = [], 0
    for i, buf in enumerate(gltf.buffers or []):
        size = buf.byteLength
        if isinstance(size, bool) or not isinstance(size, int) or not 0 <= size <= MAX_MODEL_BYTES - total:
            raise InputError(f"{name} is corrupt or too large: buffer {i} declares {size!r} bytes (a model and "
                             f"its buffers may hold {MAX_MODEL_BYTES / 2**20:g} MB)")
        total += size
        if buf.uri is None:
            data = gltf.binary_blob() if i == 0 else None
            if data is None:
                raise InputError(f"{name} is corrupt: buffer {i} has no data")
        else:
            data = read_uri(buf.uri, folder, name, limit=size, exact=True)
        if len(data) < size:
            raise InputError(f"{name} is truncated: buffer {i} holds {len(data)} of its {size} bytes")
        out.append(bytes(data[:size]))
    return out


def read_uri(uri: str, folder: Path, name: str, *, limit: int = MAX_IMAGE_BYTES, exact: bool = False) -> bytes:
    """The bytes a glTF URI points at (``resolve_uri``): a base64 data: URI or a file in the model's
    folder, at most ``limit`` bytes (``exact``: only its first ``limit`` bytes, which it must have)."""
    file = resolve_uri(uri, folder, name)
    if file is None:
        payload = uri.partition(",")[2]
        if len(payload) > 4 * (limit // 3 + 1) + 4 and not exact:
            raise InputError(f"{name} is too large: a data: URI holds over {limit / 2**20:g} MB")
        try:
            return base64.b64decode(payload, validate=True)
        except (binascii.Error, ValueError):
            raise InputError(f"{name} is corrupt: a data: URI is not valid base64") from None
    if not file.exists():
        raise InputError(f"{name} refers to {uri[:80]!r}, which does not exist; keep the files a .gltf names "
                         "next to it")
    return read_user_file(file, limit=limit, what=f"{uri[:80]!r} (named by {name})", prefix=limit if exact else None)


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
        if isinstance(n, int) and n > MAX_ACCESSOR_COUNT:
            raise self.corrupt(f"{what} has {n} elements; at most {MAX_ACCESSOR_COUNT} are read")
        if isinstance(n, bool) or not isinstance(n, int) or n < 0 or (count is not None and n != count):
            raise self.corrupt(f"{what} has {n!r} elements" + (f", not {count}" if count is not None else ""))
        width = _WIDTH[acc.type]
        out = np.zeros((n, width), dtype) if acc.bufferView is None else \
            self._view(acc.bufferView, acc.byteOffset or 0, n, width, dtype, what)
        if acc.sparse is not None and acc.sparse.count:
            sparse = acc.sparse
            if isinstance(sparse.count, bool) or not isinstance(sparse.count, int) or not 0 < sparse.count <= n:
                raise self.corrupt(f"{what} has {sparse.count!r} sparse elements for its {n}")
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
            v = self.check_index(self.gltf.bufferViews, image.bufferView, "bufferView", f"image {i}")
            view = self.gltf.bufferViews[v]
            data = self.buffers[self.check_index(self.buffers, view.buffer, "buffer", f"bufferView {v}")]
            start, size = view.byteOffset or 0, view.byteLength or 0
            if not (isinstance(start, int) and isinstance(size, int) and 0 <= start and 0 <= size <= MAX_IMAGE_BYTES):
                raise self.corrupt(f"image {i}'s bufferView {v} has a bad offset or length")
            return data[start:start + size]
        if image.uri:
            return read_uri(image.uri, self.path.parent, self.path.name)
        return None
