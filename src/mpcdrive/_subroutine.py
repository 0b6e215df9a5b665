"""Compiled helpers that are compiled only inside the compiled functions that call them.

numba compiles a ``@njit`` function called from another compiled function as a function of its
own: it optimizes that function's whole module (its callees linked in) and emits machine code for
it, and then optimizes and emits the same code again inside every caller, at every level of the
call tree. The controller's step is such a tree (step -> assembly -> linearization -> Jacobians
-> model terms; step -> solver -> active set -> Cholesky), so most of a first compile was spent
on machine code that no one calls.

:func:`subroutine` marks a function that compiled code calls. In compiled code it is typed and
lowered once per argument types, like a ``@njit`` function (constant arguments are typed as
literals, so a call with constant sizes gets its own specialized copy, as before); its code is
linked into the caller and optimized and emitted only with the compiled function that Python
calls (``@njit(cache=True)``, whose on-disk cache therefore holds it too). Called from Python, a
subroutine runs through a ``@njit(cache=True)`` copy of itself, compiled on the first such call.

A subroutine *borrows* its arguments where it can: it is lowered without numba's reference
counting (NRT), so it neither counts its array arguments up on entry nor down on exit. Those
counts are atomic operations, about 10-20 ns for each array argument of each call (measured on
the planner's road check, one array: 18 ns a call), and the planner's and controller's inner
loops call small helpers with arrays thousands of times per step. A caller holds every array it
passes for the whole call, so borrowing is safe for a function that makes no counted value (an
array, a struct), stores none and hands none back (:func:`_borrows_safely`, read from its typed
code between typing and lowering, in the one compile); any other keeps its counts, as numba
lowers it. The arithmetic is the same either way.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import llvmlite.binding as ll
from numba import njit, types
from numba.core import compiler, ir
from numba.core.compiler_machinery import FunctionPass, LoweringPass, register_pass
from numba.core.compiler_lock import global_compiler_lock
from numba.core.errors import NumbaError
from numba.core.cpu import CPUTargetOptions
from numba.core.registry import cpu_target
from numba.core.typing.templates import AbstractTemplate
from numba.core.typed_passes import AnnotateTypes
from numba.core.untyped_passes import IRProcessing
from numba.extending import lower_builtin, typeof_impl


@register_pass(mutates_CFG=True, analysis_only=False)
class _ConstantArguments(FunctionPass):
    """An argument typed as an integer or boolean literal becomes that constant in the function
    body, before numba's dead-branch pruning: a branch on it (``if kind == KIND_DYNAMIC:``) is
    then decided at compile time and the code of the branch not taken is never typed, lowered or
    optimized. (numba itself prunes such branches only for ``None`` arguments.)"""

    _name = "mpcdrive_constant_arguments"

    def __init__(self) -> None:
        FunctionPass.__init__(self)

    def run_pass(self, state: Any) -> bool:
        constants = {
            i: t.literal_value
            for i, t in enumerate(state.args)
            if isinstance(t, (types.IntegerLiteral, types.BooleanLiteral))
        }
        changed = False
        for block in state.func_ir.blocks.values():
            for stmt in block.body:
                if isinstance(stmt, ir.Assign) and isinstance(stmt.value, ir.Arg) and stmt.value.index in constants:
                    stmt.value = ir.Const(constants[stmt.value.index], stmt.value.loc)
                    changed = True
        return changed


#: the compile result's metadata key saying the function was lowered borrowing its arguments
_BORROWS = "mpcdrive_borrows"


@register_pass(mutates_CFG=False, analysis_only=True)
class _Borrow(LoweringPass):
    """After typing, before lowering: a function that may borrow its arguments
    (:func:`_borrows_safely`) is lowered without reference counting (the module docstring).
    Its IR stays as it is (an analysis, for numba's pass manager); the lowering's context
    and flags change."""

    _name = "mpcdrive_borrow"

    def __init__(self) -> None:
        LoweringPass.__init__(self)

    def run_pass(self, state: Any) -> bool:
        if _borrows_safely(state.return_type, state.typemap, state.func_ir.blocks):
            context = state.targetctx.subtarget(enable_nrt=False)
            context.__dict__.pop("nrt", None)  # its NRT context is made anew, disabled
            state.targetctx = context
            state.flags.nrt = False
            state.metadata[_BORROWS] = True
        return False


class _Pipeline(compiler.CompilerBase):
    """numba's nopython pipeline with :class:`_ConstantArguments` after the IR is built and, where
    ``borrow``, :class:`_Borrow` before lowering."""

    borrow = True

    def define_pipelines(self) -> list:
        pm = compiler.DefaultPassBuilder.define_nopython_pipeline(self.state)
        pm.add_pass_after(_ConstantArguments, IRProcessing)
        if self.borrow:
            pm.add_pass_after(_Borrow, AnnotateTypes)
        pm.finalize()
        return [pm]


class _CountingPipeline(_Pipeline):
    """:class:`_Pipeline` lowering with the counts, as numba does."""

    borrow = False


class _Unfinalized:
    """Stands in for a subroutine's numba code library where a caller links it: hands over the
    library's code (optimized function by function, as numba does before linking) without
    finalizing the library, which numba would otherwise do first (optimize its whole module and
    emit machine code for it). The caller's own finalization optimizes and emits it."""

    def __init__(self, library: Any) -> None:
        self._library = library
        self._module: Any = None

    @property
    def _reload_init(self) -> set:
        found = set(self._library._reload_init)
        for dep in self._library._linking_libraries:
            found.update(dep._reload_init)
        return found

    def _ensure_finalized(self) -> None:
        """Nothing: linked unfinalized on purpose."""

    def _get_module_for_linking(self) -> Any:
        """The library's module with what it links in; its definitions made ``linkonce_odr`` (as
        numba does for shared code), so a function linked in along two paths is kept once."""
        if self._module is None:
            mod = self._library._final_module.clone()
            for dep in self._library._linking_libraries:
                mod.link_in(dep._get_module_for_linking(), preserve=True)
            for fn in mod.functions:
                if not fn.is_declaration and fn.linkage == ll.Linkage.external:
                    fn.linkage = "linkonce_odr"
            self._module = mod
        return self._module


class Subroutine:
    """A function compiled inside its compiled callers (see the module docstring); ``py_func``
    is the Python function. Made by :func:`subroutine`."""

    def __init__(self, py_func: Callable[..., Any], options: dict[str, Any]) -> None:
        self.py_func = py_func
        self.__name__ = py_func.__name__
        self.__qualname__ = py_func.__qualname__
        self.__module__ = py_func.__module__
        self.__doc__ = py_func.__doc__
        self._options = options
        self._compiled: dict[tuple, Any] = {}
        self._links: dict[tuple, _Unfinalized] = {}
        self._python_entry: Any = None
        sub = self

        class _Template(AbstractTemplate):
            key = sub
            prefer_literal = True  # constant arguments specialize, as for a @njit callee

            def generic(self, args, kws):
                if kws:
                    return None
                return sub._compile(tuple(args)).signature

        self._numba_type = types.Function(_Template)

        @lower_builtin(self, types.VarArg(types.Any))
        def _call(context, builder, sig, args):
            args_key = tuple(sig.args)
            cres = sub._compiled[args_key]
            context.active_code_library.add_linking_library(sub._links[args_key])
            return context.call_internal(builder, cres.fndesc, sig, args)

    def _compile(self, args: tuple) -> Any:
        """Type and lower the function for ``args`` (numba types) into a library of its own that
        is linked into callers and never finalized by itself."""
        cres = self._compiled.get(args)
        if cres is not None:
            return cres
        with global_compiler_lock:
            cres = self._compiled.get(args)
            if cres is None:
                cres, library = self._lower(args)
                self._compiled[args] = cres
                self._links[args] = _Unfinalized(library)
        return cres

    @property
    def borrows(self) -> dict[tuple, bool]:
        """Per argument types compiled: whether the function was lowered borrowing its arguments."""
        return {args: bool(cres.metadata.get(_BORROWS, False)) for args, cres in self._compiled.items()}

    def _lower(self, args: tuple) -> tuple[Any, Any]:
        """Type and lower for ``args`` (numba's pipeline, with :class:`_ConstantArguments`),
        borrowing where :class:`_Borrow` finds it safe; where numba's lowering finds it needs
        the counts after all, again with them."""
        if "_nrt" not in self._options:  # the caller's choice, else borrowing where safe
            try:
                return self._lower_with(args, _Pipeline)
            except NumbaError:
                pass  # lowered again with the counts: a real error is raised there
        return self._lower_with(args, _CountingPipeline)

    def _lower_with(self, args: tuple, pipeline: type) -> tuple[Any, Any]:
        flags = CPUTargetOptions.parse_as_flags(compiler.Flags(), {"nopython": True, **self._options})
        flags.no_compile = True
        flags.no_cpython_wrapper = True
        flags.no_cfunc_wrapper = True
        context = cpu_target.target_context
        library = context.codegen().create_library(self.__qualname__)
        cres = compiler.compile_extra(
            cpu_target.typing_context,
            context,
            self.py_func,
            args,
            None,
            flags,
            {},
            library=library,
            pipeline_class=pipeline,
        )
        return cres, library

    def __call__(self, *args: Any) -> Any:
        entry = self._python_entry
        if entry is None:
            entry = self._python_entry = njit(cache=True, **self._options)(self.py_func)
        return entry(*args)

    def __repr__(self) -> str:
        return f"<subroutine {self.__module__}.{self.__qualname__}>"


def _counted(ty: Any) -> bool:
    """Whether values of numba type ``ty`` carry a reference count (an array, a struct...)."""
    return bool(cpu_target.target_context.data_model_manager[ty].contains_nrt_meminfo())


#: the expressions whose counted result borrows from a value the function already holds: an
#: attribute or an element of an array, a view of it (not a struct's field: numba counts that up
#: as it reads it)
_BORROWING_OPS = frozenset({"getattr", "getitem", "static_getitem"})


def _borrows_safely(return_type: Any, typemap: dict, blocks: dict) -> bool:
    """Whether a typed function (its return type, the types of its variables, its IR blocks)
    may run without reference counting: it returns no counted value, stores none (in a struct's
    field or a container), and every counted value it names is an argument, a copy of one, or
    borrowed from one (:data:`_BORROWING_OPS`). Anything else (an allocation, a value a call
    hands back, an iterator) makes it keep the counts."""
    if _counted(return_type):
        return False
    for block in blocks.values():
        for stmt in block.body:
            if isinstance(stmt, (ir.SetAttr, ir.SetItem, ir.StaticSetItem)) and _counted(typemap[stmt.value.name]):
                return False  # stores a counted value where it outlives the call
            if not isinstance(stmt, ir.Assign) or not _counted(typemap[stmt.target.name]):
                continue
            value = stmt.value
            if isinstance(value, (ir.Arg, ir.Var)):
                continue
            if isinstance(value, ir.Expr) and value.op in _BORROWING_OPS:
                if value.op == "getattr" and isinstance(typemap[value.value.name], types.StructRef):
                    return False  # numba counts a struct's field up as it reads it
                continue
            return False
    return True


@typeof_impl.register(Subroutine)
def _typeof_subroutine(val: Subroutine, c: Any) -> Any:
    return val._numba_type


def subroutine(py_func: Callable[..., Any] | None = None, **options: Any) -> Any:
    """Decorator: ``@subroutine`` or ``@subroutine(fastmath=...)`` (numba's ``njit`` options)
    for a function that compiled code calls; see the module docstring."""
    if py_func is None:
        return lambda f: Subroutine(f, options)
    return Subroutine(py_func, options)
