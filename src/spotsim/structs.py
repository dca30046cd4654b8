"""Structures shared by Python and compiled code, with named fields: numba structrefs.

A structure's fields are those of a NamedTuple class (one place names and documents them).
Compiled code reads and writes them by name (`d.t += h`, `d.contacts = ...`) and passes the
structure as one pointer: a call costs what a call of two pointers costs, where a NamedTuple
of a hundred arrays is passed as its members and each array's reference count is raised on
entry. From Python, `view(s)` gives every field at once (arrays live, numbers copied) and
`assign(s, fields)` writes them.

    @structref.register
    class DataType(StructType): ...
    class Data(StructProxy): ...
    register(DataType, DataFields, Data)
    d = new_struct(DataFields(...))
"""

from __future__ import annotations

from functools import lru_cache

from numba import types
from numba.experimental import structref
from numba.extending import overload

from .jit import njit

#: Each registered structure's type class -> its fields' NamedTuple class, and back.
_FIELDS: dict = {}
_TYPES: dict = {}


class StructType(types.StructRef):
    """Base of the structures' numba types (subclass it at module level: the cache finds the
    types by their module and name)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(t)) for name, t in fields)


class StructProxy(structref.StructRefProxy):
    """A structure as Python sees it: its fields as attributes (arrays live, numbers copied).
    Setting a field writes it into the structure (`assign`), where compiled code and `copy`
    read it, not into an attribute of this proxy alone."""

    def __getattr__(self, name):
        fields = _FIELDS[type(self._type)]
        if name in fields._fields:
            return getattr(view(self), name)
        raise AttributeError(f"{type(self).__name__} has no field {name!r}")

    def __setattr__(self, name, value):
        if name not in structref.StructRefProxy.__slots__ and name in _FIELDS[type(self._type)]._fields:
            self.assign(**{name: value})
        else:  # the proxy's own (numba's boxing sets _type and _meminfo)
            super().__setattr__(name, value)

    def view(self):
        """Every field at once, as the fields' NamedTuple: arrays live, numbers copied."""
        return view(self)

    def assign(self, **changes) -> None:
        """Write the named fields (arrays replaced by those given)."""
        assign(self, view(self)._replace(**changes))


def register(type_class, fields_class, proxy_class) -> None:
    """Make `type_class` (a StructType subclass) the numba type of structures with the fields
    of `fields_class`, seen from Python as `proxy_class`."""
    _FIELDS[type_class] = fields_class
    _TYPES[fields_class] = type_class
    structref.define_boxing(type_class, proxy_class)


# The generic accessors: their code is written out from each structure's field names.
def _fields_of(s):
    pass


def _write_fields(s, f):
    pass


def _make(f):
    pass


@lru_cache(maxsize=None)
def _code(fields_class, what: str):
    names = fields_class._fields
    if what == "view":
        source = f"def impl(s):\n    return F({', '.join('s.' + n for n in names)})\n"
    elif what == "write":
        source = "def impl(s, f):\n" + "".join(f"    s.{n} = f.{n}\n" for n in names)
    else:
        source = "def impl(f):\n    s = new(struct_type)\n" + "".join(f"    s.{n} = f.{n}\n" for n in names) + \
            "    return s\n"
    return source


def _compile(fields_class, what: str, **names):
    scope = {"F": fields_class, "new": structref.new, **names}
    exec(_code(fields_class, what), scope)
    return scope["impl"]


@overload(_fields_of)
def _fields_of_impl(s):
    return _compile(_FIELDS[type(s)], "view")


@overload(_write_fields)
def _write_fields_impl(s, f):
    return _compile(_FIELDS[type(s)], "write")


@overload(_make)
def _make_impl(f):
    cls = f.instance_class
    return _compile(cls, "make", struct_type=_TYPES[cls](list(zip(cls._fields, f.types))))


@njit
def view(s):
    """Every field of the structure s, as its fields' NamedTuple."""
    return _fields_of(s)


@njit
def assign(s, f):
    """Write every field of the structure s from f, its fields' NamedTuple."""
    _write_fields(s, f)


@njit
def new_struct(f):
    """A structure holding the fields f (a registered fields' NamedTuple), arrays shared."""
    return _make(f)
