"""A ``state_dict`` saved by ``torch.save`` read as numpy arrays, without unpickling anything and without torch.

``torch.save`` writes a zip archive: ``<prefix>/data.pkl`` (a pickle of the dict, whose tensors point at
storages by persistent id) and ``<prefix>/data/<key>`` (each storage's raw bytes). :func:`read_state_dict` walks
the pickle's opcodes with :func:`pickletools.genops`, which only decodes them, and interprets the few that a
dict of tensors uses on a stack of plain values: a ``GLOBAL`` becomes its name, never an object; a call is
allowed for three names only (an ``OrderedDict``, ``torch._utils._rebuild_tensor_v2`` and the storage types),
and each is carried out here, on numpy arrays. Any other opcode or name is refused with a ``ValueError``, so a
crafted file (a ``__reduce__`` that runs code) runs nothing: no unpickler resolves a global, none is imported.
"""

from __future__ import annotations

import dataclasses
import io
import pickletools
import zipfile
from collections.abc import Mapping
from typing import Any

import numpy as np

#: Storage types of ``torch.save``'s persistent ids, and their numpy dtypes (little-endian).
STORAGE_DTYPES = {
    "FloatStorage": "<f4",
    "DoubleStorage": "<f8",
    "HalfStorage": "<f2",
    "LongStorage": "<i8",
    "IntStorage": "<i4",
    "ShortStorage": "<i2",
    "CharStorage": "<i1",
    "ByteStorage": "<u1",
    "BoolStorage": "?",
}
_ORDERED_DICT = ("collections", "OrderedDict")
_REBUILD_TENSOR = ("torch._utils", "_rebuild_tensor_v2")
_MEMO_PUT = ("BINPUT", "LONG_BINPUT", "PUT")
_MEMO_GET = ("BINGET", "LONG_BINGET", "GET")
_PUSH_ARG = (
    "BINUNICODE", "SHORT_BINUNICODE", "BINUNICODE8", "UNICODE", "BININT", "BININT1", "BININT2", "LONG1",
    "BINFLOAT", "SHORT_BINBYTES", "BINBYTES",
)  # fmt: skip


@dataclasses.dataclass(frozen=True)
class _Global:
    module: str
    name: str


@dataclasses.dataclass(frozen=True)
class _Storage:
    dtype: str
    key: str
    numel: int


class _Mark:
    pass


_MARK = _Mark()


def _refuse(where: str, what: str) -> ValueError:
    return ValueError(
        f"{where}: {what}; only a state_dict of tensors is read (nothing is unpickled), so the file is refused"
    )


def read_state_dict(data: bytes, where: str = "the checkpoint") -> dict[str, np.ndarray]:
    """The tensors of a ``torch.save`` zip holding a ``state_dict``, as numpy arrays (name -> array).

    Args:
        data: The bytes of the zip file (e.g. an SB3 zip's ``policy.pth``).
        where: The file's name, for messages.

    Raises:
        ValueError: For anything but a (possibly ordered) dict of tensors: other objects, calls, opcodes.
    """
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile:
        raise _refuse(where, "it is not a torch.save zip archive (a legacy or pickle-only file)") from None
    pickles = [n for n in archive.namelist() if n.endswith("/data.pkl") and n.count("/") == 1]
    if len(pickles) != 1:
        raise _refuse(where, "it holds no single <prefix>/data.pkl")
    prefix = pickles[0][: -len("data.pkl")]
    big = prefix + "byteorder" in archive.namelist() and archive.read(prefix + "byteorder").strip() == b"big"
    storages: dict[str, np.ndarray] = {}

    def storage(s: _Storage) -> np.ndarray:
        if s.key not in storages:
            name = f"{prefix}data/{s.key}"
            if name not in archive.namelist():
                raise _refuse(where, f"storage {s.key!r} is missing")
            dtype = np.dtype(s.dtype).newbyteorder(">") if big and s.dtype != "?" else np.dtype(s.dtype)
            flat = np.frombuffer(archive.read(name), dtype=dtype)
            if flat.size < s.numel:
                raise _refuse(where, f"storage {s.key!r} holds {flat.size} values, {s.numel} expected")
            storages[s.key] = flat
        return storages[s.key]

    result = _interpret(archive.read(pickles[0]), where, storage)
    if not isinstance(result, dict) or not all(isinstance(v, np.ndarray) for v in result.values()):
        raise _refuse(where, "it is not a dict of tensors")
    return {str(k): v for k, v in result.items()}


def _interpret(pickle_bytes: bytes, where: str, storage: Any) -> Any:
    """Interpret the opcodes of a state_dict's pickle on plain values (module docstring)."""
    stack: list[Any] = []
    memo: dict[int, Any] = {}

    def pop_mark() -> list[Any]:
        for k in range(len(stack) - 1, -1, -1):
            if stack[k] is _MARK:
                items = stack[k + 1 :]
                del stack[k:]
                return items
        raise _refuse(where, "a MARK is missing")

    try:
        ops = list(pickletools.genops(pickle_bytes))
    except Exception as exc:  # a truncated or malformed pickle
        raise _refuse(where, f"its pickle does not decode ({exc})") from None
    for opcode, arg, _ in ops:
        name = opcode.name
        if name in ("PROTO", "FRAME"):
            continue
        if name == "STOP":
            return stack.pop() if stack else None
        if name == "GLOBAL":
            module, _, attr = str(arg).partition(" ")
            stack.append(_Global(module, attr))
        elif name in _MEMO_PUT:
            memo[int(str(arg))] = stack[-1]
        elif name == "MEMOIZE":
            memo[len(memo)] = stack[-1]
        elif name in _MEMO_GET:
            stack.append(memo[int(str(arg))])
        elif name == "MARK":
            stack.append(_MARK)
        elif name in _PUSH_ARG:
            stack.append(arg)
        elif name == "NONE":
            stack.append(None)
        elif name in ("NEWTRUE", "NEWFALSE"):
            stack.append(name == "NEWTRUE")
        elif name == "EMPTY_TUPLE":
            stack.append(())
        elif name in ("TUPLE1", "TUPLE2", "TUPLE3"):
            n = int(name[-1])
            items = stack[-n:]
            del stack[-n:]
            stack.append(tuple(items))
        elif name == "TUPLE":
            stack.append(tuple(pop_mark()))
        elif name == "EMPTY_DICT":
            stack.append({})
        elif name == "EMPTY_LIST":
            stack.append([])
        elif name == "LIST":
            stack.append(pop_mark())
        elif name == "DICT":
            items = pop_mark()
            stack.append(dict(zip(items[::2], items[1::2], strict=True)))
        elif name == "APPEND":
            value = stack.pop()
            _container(stack[-1], list, where).append(value)
        elif name == "APPENDS":
            items = pop_mark()
            _container(stack[-1], list, where).extend(items)
        elif name == "SETITEM":
            value, key = stack.pop(), stack.pop()
            _container(stack[-1], dict, where)[_key(key, where)] = value
        elif name == "SETITEMS":
            items = pop_mark()
            target = _container(stack[-1], dict, where)
            for key, value in zip(items[::2], items[1::2], strict=True):
                target[_key(key, where)] = value
        elif name == "BINPERSID":
            stack.append(_persistent(stack.pop(), where))
        elif name == "REDUCE":
            args, func = stack.pop(), stack.pop()
            stack.append(_call(func, args, where, storage))
        elif name == "BUILD":
            state = stack.pop()  # an OrderedDict's attributes (the state_dict's _metadata): not needed
            if not isinstance(stack[-1], dict) or not isinstance(state, (dict, tuple, type(None))):
                raise _refuse(where, "it sets the state of an object that is not a dict")
        else:
            raise _refuse(where, f"its pickle uses the opcode {name}")
    raise _refuse(where, "its pickle has no STOP")


def _container(value: Any, kind: type, where: str) -> Any:
    if not isinstance(value, kind):
        raise _refuse(where, f"it adds items to a {type(value).__name__}")
    return value


def _key(key: Any, where: str) -> Any:
    if not isinstance(key, (str, int)):
        raise _refuse(where, f"it uses a {type(key).__name__} as a dict key")
    return key


def _persistent(pid: Any, where: str) -> _Storage:
    if (
        not isinstance(pid, tuple)
        or len(pid) != 5
        or pid[0] != "storage"
        or not isinstance(pid[1], _Global)
        or pid[1].module != "torch"
        or pid[1].name not in STORAGE_DTYPES
    ):
        raise _refuse(where, f"it refers to {pid!r}, not a tensor storage")
    return _Storage(STORAGE_DTYPES[pid[1].name], str(pid[2]), int(pid[4]))


def _call(func: Any, args: Any, where: str, storage: Any) -> Any:
    if not isinstance(func, _Global) or not isinstance(args, tuple):
        raise _refuse(where, f"it calls {func!r}")
    target = (func.module, func.name)
    if target == _ORDERED_DICT:
        if args not in ((), ([],)):
            raise _refuse(where, "it builds an OrderedDict from arguments")
        return {}
    if target == _REBUILD_TENSOR:
        return _rebuild_tensor(args, where, storage)
    raise _refuse(where, f"it calls {func.module}.{func.name}")


def _rebuild_tensor(args: tuple[Any, ...], where: str, storage: Any) -> np.ndarray:
    """``_rebuild_tensor_v2(storage, offset, size, stride, requires_grad, hooks[, metadata])`` on numpy."""
    if len(args) < 6 or not isinstance(args[0], _Storage):
        raise _refuse(where, "a tensor is rebuilt from unexpected arguments")
    offset, size, stride = args[1], args[2], args[3]
    ints = (offset, *size, *stride) if isinstance(size, tuple) and isinstance(stride, tuple) else (None,)
    if not all(isinstance(v, int) and v >= 0 for v in ints) or len(size) != len(stride):
        raise _refuse(where, "a tensor has a bad offset, size or stride")
    if isinstance(args[5], Mapping) and args[5]:
        raise _refuse(where, "a tensor carries backward hooks")
    flat = storage(args[0])
    count = int(np.prod(size)) if size else 1
    if count == 0:
        return np.zeros(size, dtype=flat.dtype)
    last = offset + sum((n - 1) * s for n, s in zip(size, stride, strict=True))
    if last >= flat.size:
        raise _refuse(where, "a tensor reaches past its storage")
    view = np.lib.stride_tricks.as_strided(
        flat[offset:], shape=size, strides=tuple(s * flat.itemsize for s in stride), writeable=False
    )
    return np.array(view, dtype=flat.dtype.newbyteorder("="))
