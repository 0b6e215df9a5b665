"""Typed containers that compiled code takes as one argument.

A container is a frozen dataclass of numpy arrays and scalars: Python code reads and writes its
arrays by name, and :func:`to_struct` hands the same memory to numba-compiled code as a numba
``StructRef`` whose fields have the dataclass's names (one unboxing per call, whatever the number
of arrays, where a tuple of arrays would unbox each). The dataclass is the one list of fields;
each container module defines its struct with :func:`define_struct` and a cached constructor
(numba caches a constructor only when it is defined in a file, so it cannot be made here)::

    _StageQpType, _StageQpStruct = define_struct(StageQp, __name__)

    @njit(cache=True)
    def _build_stage_qp(values):
        return _StageQpStruct(*values)

Arrays are stored C-contiguous as given (the dataclass's arrays *are* the struct's memory: a
write on either side is seen on the other); a scalar field is copied into the struct when it
is made, so a value that Python changes afterwards is kept as a one-element array (a setter on
the struct alone would be lost when the struct is made anew from the dataclass).
"""

from __future__ import annotations

import sys
from dataclasses import fields, is_dataclass
from typing import Any

import numpy as np
from numba import types
from numba.experimental import structref


class StructType(types.StructRef):
    """Base of the containers' numba types: literal scalars are typed as plain ones."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


def field_names(container_class) -> list[str]:
    """The fields of a container dataclass, in order."""
    return [f.name for f in fields(container_class)]


def define_struct(container_class, module: str):
    """The numba struct type class and Python handle (proxy) class of ``container_class`` (a
    dataclass), registered with numba and bound in ``module`` (the container's module, by its
    name) as ``_<Name>Type`` and ``_<Name>Struct``: numba's on-disk cache finds a struct type by
    its module and name."""
    name = container_class.__name__
    type_name, proxy_name = f"_{name}Type", f"_{name}Struct"
    struct_type = structref.register(type(type_name, (StructType,), {"__module__": module, "__qualname__": type_name}))
    proxy = type(proxy_name, (structref.StructRefProxy,), {"__module__": module, "__qualname__": proxy_name})
    structref.define_proxy(proxy, struct_type, field_names(container_class))
    setattr(sys.modules[module], type_name, struct_type)
    setattr(sys.modules[module], proxy_name, proxy)
    return struct_type, proxy


def struct_values(container) -> tuple[Any, ...]:
    """The values of a container's fields, in order, as the compiled constructor takes them.
    Raises ValueError for an array that is not C-contiguous float64 or int64 (numba would type
    it as another struct, and compile again)."""
    if not is_dataclass(container):
        raise TypeError(f"expected a container dataclass, got {type(container).__name__}")
    out = []
    for f in fields(container):
        v = getattr(container, f.name)
        if isinstance(v, np.ndarray):
            if v.dtype not in (np.float64, np.int64) or not v.flags.c_contiguous:
                raise ValueError(
                    f"{type(container).__name__}.{f.name}: a C-contiguous float64 or int64 array is needed, "
                    f"got {v.dtype} {'C' if v.flags.c_contiguous else 'strided'}"
                )
        out.append(v)
    return tuple(out)


def to_struct(container, build):
    """The compiled struct of ``container``, made by its module's cached constructor ``build``."""
    return build(struct_values(container))
