"""Typed containers that compiled code takes as one argument.

A container is a frozen dataclass of numpy arrays and scalars: Python code reads and writes its
arrays by name, and :func:`to_struct` hands the same memory to numba-compiled code as a numba
``StructRef`` whose fields have the dataclass's names (one unboxing per call, whatever the number
of arrays, where a tuple of arrays would unbox each). The dataclass is the one list of fields;
each container module registers its struct type and a cached constructor with
:func:`register_struct`'s three lines (numba caches a constructor only when it is defined in a
file, so it cannot be made here)::

    @structref.register
    class _StageQpType(StructType): ...
    class _StageQpStruct(structref.StructRefProxy): ...
    register_struct(StageQp, _StageQpType, _StageQpStruct)

    @njit(cache=True)
    def _build_stage_qp(values):
        return _StageQpStruct(*values)

Arrays are stored C-contiguous as given (the dataclass's arrays *are* the struct's memory: a
write on either side is seen on the other); a scalar field is copied into the struct, so one
that compiled code must see change is written through a compiled setter.
"""

from __future__ import annotations

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


def register_struct(container_class, struct_type, proxy_class) -> None:
    """Make ``proxy_class`` the Python handle of ``struct_type`` with the fields of
    ``container_class`` (a dataclass)."""
    structref.define_proxy(proxy_class, struct_type, field_names(container_class))


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
