"""PyTorch state dicts in the legacy (non-zip) ``torch.save`` format, read with numpy alone.

The legacy file is a run of pickles followed by raw storage bytes: a magic number, the protocol
version (1001), a system-info dict (byte order, type sizes), the state dict itself (an
``OrderedDict`` of tensors, each a ``torch._utils._rebuild_tensor_v2`` call on a storage named by a
persistent id), the list of storage keys, then per key (in that order) an 8-byte little-endian element
count and the elements.

Nothing in the file is executed: the file's sha256 is checked before any byte is unpickled, and the
unpickler (:class:`TensorUnpickler`) admits only the names a tensor rebuild needs, each mapped to a
local function that builds a plain description; every other global is refused by name.
"""

from __future__ import annotations

import collections
import hashlib
import io
import pickle
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: ``torch.serialization.MAGIC_NUMBER``: the first pickle of a legacy file.
MAGIC_NUMBER = 0x1950A86A20F9469CFC6C
#: ``torch.serialization.PROTOCOL_VERSION``: the second pickle.
PROTOCOL_VERSION = 1001
#: Storage class name -> numpy element type (little-endian).
STORAGE_DTYPES = {
    "FloatStorage": "<f4", "DoubleStorage": "<f8", "HalfStorage": "<f2", "LongStorage": "<i8",
    "IntStorage": "<i4", "ShortStorage": "<i2", "CharStorage": "i1", "ByteStorage": "u1", "BoolStorage": "?",
}


class UnsafePickleError(ValueError):
    """A pickle asked for a global that a tensor rebuild does not need."""


@dataclass(frozen=True)
class _StorageType:
    name: str


@dataclass(frozen=True)
class _StorageRef:
    key: str
    dtype: str
    count: int


@dataclass(frozen=True)
class _TensorRef:
    storage: _StorageRef
    offset: int
    shape: tuple[int, ...]
    strides: tuple[int, ...]


def _rebuild_tensor(storage: _StorageRef, offset: int, shape: tuple[int, ...], strides: tuple[int, ...],
                    *_ignored: object) -> _TensorRef:
    """Stands in for ``torch._utils._rebuild_tensor_v2``: records where the tensor's elements are."""
    if not isinstance(storage, _StorageRef):
        raise UnsafePickleError(f"tensor rebuild got {type(storage).__name__} instead of a storage")
    return _TensorRef(storage, int(offset), tuple(int(n) for n in shape), tuple(int(n) for n in strides))


def _ordered_dict(*args: object) -> collections.OrderedDict:
    """``collections.OrderedDict`` (the state dict and each tensor's backward-hooks dict)."""
    return collections.OrderedDict(*args)


_ALLOWED = {("torch._utils", "_rebuild_tensor_v2"): _rebuild_tensor,
            ("collections", "OrderedDict"): _ordered_dict}
_ALLOWED.update({("torch", name): _StorageType(name) for name in STORAGE_DTYPES})


class TensorUnpickler(pickle.Unpickler):
    """An unpickler that rebuilds tensor descriptions and refuses every other global.

    Args:
        file: binary stream positioned at a pickle.
        source: the file's name, for messages.
    """

    def __init__(self, file: io.BufferedIOBase, source: str):
        super().__init__(file)
        self.source = source

    def find_class(self, module: str, name: str) -> object:
        """The local stand-in for ``module.name``; anything outside tensor rebuilds is refused."""
        try:
            return _ALLOWED[(module, name)]
        except KeyError:
            raise UnsafePickleError(f"{self.source}: the pickle asks for {module}.{name}, which is not part of a "
                                    f"tensor state dict; refused (nothing was executed)") from None

    def persistent_load(self, pid: object) -> _StorageRef:
        """A storage reference ``('storage', storage type, key, location, element count[, view])``."""
        if (not isinstance(pid, tuple) or len(pid) < 5 or pid[0] != "storage"
                or not isinstance(pid[1], _StorageType)):
            raise UnsafePickleError(f"{self.source}: unexpected persistent id {str(pid)[:80]} (expected a storage)")
        return _StorageRef(str(pid[2]), STORAGE_DTYPES[pid[1].name], int(pid[4]))


def sha256_of(path: Path) -> str:
    """Hex sha256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def check_sha256(path: Path, expected: str) -> None:
    """Raises ValueError naming ``path``, the expected and the actual hash when they differ."""
    actual = sha256_of(path)
    if actual != expected:
        raise ValueError(f"{path}: sha256 {actual} differs from the expected {expected}; the file is not the "
                         f"one this code was written for (refused before reading it)")


def load_state_dict(path: str | Path, sha256: str) -> dict[str, np.ndarray]:
    """Reads a legacy ``torch.save`` state dict into numpy arrays, without PyTorch and without running code.

    Args:
        path: the ``.pth`` file.
        sha256: its expected hex sha256, checked before anything is unpickled.

    Returns:
        Tensor name -> array (its shape, strides and storage offset applied; a copy, C-contiguous).

    Raises:
        ValueError: wrong hash, not a legacy state dict, truncated file, or (:class:`UnsafePickleError`) a
            pickle that asks for anything but tensors.
    """
    path = Path(path)
    check_sha256(path, sha256)
    data = path.read_bytes()
    if data[:2] == b"PK":
        raise ValueError(f"{path}: a zip-format torch file; only the legacy (non-zip) format is read")
    stream = io.BytesIO(data)
    source = str(path)
    try:
        header = [TensorUnpickler(stream, source).load() for _ in range(3)]
        if header[0] != MAGIC_NUMBER or header[1] != PROTOCOL_VERSION:
            raise ValueError(f"{path}: not a legacy torch file (magic {header[0]!r}, protocol {header[1]!r})")
        if not isinstance(header[2], dict) or header[2].get("little_endian") is not True:
            raise ValueError(f"{path}: only little-endian torch files are read (system info {header[2]!r})")
        tensors = TensorUnpickler(stream, source).load()
        keys = TensorUnpickler(stream, source).load()
    except (pickle.UnpicklingError, EOFError, struct.error) as error:
        raise ValueError(f"{path}: corrupt torch pickle ({error})") from error
    if not isinstance(tensors, dict) or not all(isinstance(v, _TensorRef) for v in tensors.values()):
        raise ValueError(f"{path}: the state-dict pickle holds something other than a dict of tensors")
    storages = _read_storages(data, stream.tell(), keys, tensors.values(), path)
    return {str(name): _tensor_array(ref, storages[ref.storage.key], name, path) for name, ref in tensors.items()}


def _read_storages(data: bytes, position: int, keys: object, refs: object, path: Path) -> dict[str, np.ndarray]:
    """The storages after the pickles: per key an int64 element count, then the elements."""
    if not isinstance(keys, list) or not all(isinstance(key, str) for key in keys):
        raise ValueError(f"{path}: the storage-key pickle is not a list of strings")
    dtypes = {ref.storage.key: ref.storage.dtype for ref in refs}
    storages = {}
    for key in keys:
        if key not in dtypes:
            raise ValueError(f"{path}: storage {key} is not used by any tensor")
        dtype = np.dtype(dtypes[key])
        if position + 8 > len(data):
            raise ValueError(f"{path}: file ends before storage {key}")
        (count,) = struct.unpack_from("<q", data, position)
        end = position + 8 + count * dtype.itemsize
        if count < 0 or end > len(data):
            raise ValueError(f"{path}: storage {key} claims {count} elements past the end of the file")
        storages[key] = np.frombuffer(data, dtype, count, position + 8)
        position = end
    missing = set(dtypes) - set(storages)
    if missing:
        raise ValueError(f"{path}: storages {sorted(missing)[:5]} used by tensors are not in the file")
    if position != len(data):
        raise ValueError(f"{path}: {len(data) - position} bytes after the last storage")
    return storages


def _tensor_array(ref: _TensorRef, storage: np.ndarray, name: object, path: Path) -> np.ndarray:
    """The tensor's elements: ``storage[offset + sum(index * strides)]`` for every index of ``shape``."""
    if len(ref.shape) != len(ref.strides) or min(ref.shape + ref.strides, default=0) < 0:
        raise ValueError(f"{path}: tensor {name}: bad shape {ref.shape} / strides {ref.strides}")
    last = ref.offset + sum((n - 1) * s for n, s in zip(ref.shape, ref.strides)) if all(ref.shape) else ref.offset - 1
    if ref.offset < 0 or last >= storage.size:
        raise ValueError(f"{path}: tensor {name} reads past its storage ({storage.size} elements)")
    itemsize = storage.dtype.itemsize
    view = np.lib.stride_tricks.as_strided(storage[ref.offset:], ref.shape, [s * itemsize for s in ref.strides],
                                           writeable=False)
    return np.array(view, order="C")
