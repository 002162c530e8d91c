"""One mechanism for every TOML file of mincam_sim: a section is a dataclass (pure Python/numpy).

A section's fields carry their default, the comment that documents them and the check of their value
(:func:`setting`); a dataclass with plain fields (the reproduce set-up and experiment parameters) gets its checks
from the type of each default and its comments from the numpydoc ``Attributes`` of its docstring. From the same
dataclasses:

* :func:`read_section` turns a TOML table into an instance: unknown keys are refused with the closest allowed
  key as a hint, every value is type-checked, and each problem is one
  :class:`~mincam_sim.errors.ConfigError` line naming ``[section] key`` and the fix;
* :meth:`Schema.tables` checks a document's top level (unknown sections, a table where an array of tables
  belongs, ...) and hands each section its table;
* :meth:`Schema.example` writes the documented example file, every key with its default and its comment.

So the defaults, the checks and the documentation cannot drift apart: ``mincam-sim config-example`` (render,
``--world``, ``--reproduce``, ``--study``) prints what :meth:`Schema.example` writes.
"""

from __future__ import annotations

import dataclasses
import difflib
import textwrap
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import Any

import numpy as np

from mincam_sim.configuration.toml_files import read_document
from mincam_sim.errors import ConfigError, IgnoredSettingWarning

MAX_INT = 2**63 - 1
EXAMPLE_WIDTH = 116  # characters per line of a generated example
VALUE_COLUMN = 27  # where a key's comment starts in a generated example (when the key = value fits)


# ------------------------------------------------------------------------------------------------ messages
def describe(value: Any) -> str:
    """Short repr of a config value for messages (with its TOML type)."""
    kind = {bool: "boolean", int: "integer", float: "number", str: "string", list: "array", dict: "table",
            tuple: "array"}.get(type(value), type(value).__name__)
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{text} ({kind})"


def where(section: str, key: str) -> str:
    """``[section] key`` (``section`` may already be bracketed: ``[[mixel]] #2``)."""
    return f"{section} {key}" if section.startswith("[") else f"[{section}] {key}"


def bracket(section: str) -> str:
    return section if section.startswith("[") else f"[{section}]"


def closest(name: str, allowed: Iterable[str]) -> str | None:
    """The allowed name closest to a misspelt ``name`` (None when nothing is close)."""
    found = difflib.get_close_matches(str(name), list(allowed), n=1, cutoff=0.6)
    return found[0] if found else None


def refuse_unknown(section: str, given: Iterable[Any], allowed: Sequence[str], what: str = "key") -> None:
    """Raise a ConfigError naming the unknown names of ``given`` (with a close-match hint) and the allowed ones."""
    unknown = sorted(str(k) for k in given if k not in allowed)
    if not unknown:
        return
    hints = [f"{u} (did you mean {hint}?)" if (hint := closest(u, allowed)) else u for u in unknown]
    plural = "s" if len(unknown) > 1 else ""
    raise ConfigError(f"{bracket(section)}: unknown {what}{plural} {', '.join(hints)}; allowed {what}s are "
                      f"{', '.join(sorted(allowed))}")


def warn_ignored(section: str, given: dict, keys: Sequence[str], why: str, cls: type | None = None) -> None:
    """One :class:`~mincam_sim.errors.IgnoredSettingWarning` line naming the ``keys`` that ``given`` sets (to other
    than their default in the section dataclass ``cls``, when given: a default written out changes nothing) and
    ``why`` they are ignored."""
    default = defaults(cls) if cls is not None else {}
    named = [k for k in keys if k in given and (k not in default or plain(given[k]) != default[k])]
    if named:
        verb = "is" if len(named) == 1 else "are"
        warnings.warn(f"{where(section, ', '.join(named))} {verb} ignored: {why}", IgnoredSettingWarning,
                      stacklevel=3)


# ------------------------------------------------------------------------------------------------ values
def table(where_: str, value: Any) -> dict:
    """``value`` if it is a TOML table with string keys."""
    if not isinstance(value, dict):
        raise ConfigError(f"{where_} must be a table (a [section] with key = value lines), got {describe(value)}")
    bad = [k for k in value if not isinstance(k, str)]
    if bad:
        raise ConfigError(f"{where_}: keys must be strings, got {bad[0]!r}")
    return value


def is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def number(section: str, key: str, value: Any, *, minimum: float | None = None, positive: bool = False,
           maximum: float | None = None) -> float:
    """A finite real number (not a boolean, not a string); ``positive``: > 0; ``minimum``/``maximum``: bounds."""
    if not is_number(value) or (isinstance(value, float) and not np.isfinite(value)):
        bound = " > 0" if positive else (f" >= {minimum:g}" if minimum is not None else "")
        raise ConfigError(f"{where(section, key)} must be a number{bound} (no quotes, no units), got "
                          f"{describe(value)}")
    if positive and not value > 0:
        raise ConfigError(f"{where(section, key)} must be a number > 0, got {value!r}")
    if minimum is not None and not value >= minimum:
        raise ConfigError(f"{where(section, key)} must be a number >= {minimum:g}, got {value!r}")
    if maximum is not None and not value <= maximum:
        raise ConfigError(f"{where(section, key)} must be a number <= {maximum:g}, got {value!r}")
    return float(value)


def integer(section: str, key: str, value: Any, *, minimum: int = 1, maximum: int = MAX_INT) -> int:
    """An integer in [minimum, maximum]; booleans and fractional numbers are refused, not converted."""
    bound = "> 0" if minimum == 1 else f">= {minimum}"
    if isinstance(value, bool) or not isinstance(value, int):
        hint = " (a whole number, no decimal point)" if isinstance(value, float) else ""
        raise ConfigError(f"{where(section, key)} must be an integer {bound}{hint}, got {describe(value)}")
    if value < minimum:
        raise ConfigError(f"{where(section, key)} must be an integer {bound}, got {value!r}")
    if value > maximum:
        raise ConfigError(f"{where(section, key)} must be at most {maximum}, got {value!r}")
    return int(value)


def string(section: str, key: str, value: Any) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{where(section, key)} must be a string (in quotes), got {describe(value)}")
    return value


def boolean(section: str, key: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"{where(section, key)} must be true or false, got {describe(value)}")
    return value


def choice(section: str, key: str, value: Any, choices: Sequence[str]) -> str:
    if not isinstance(value, str) or value not in choices:
        hint = closest(value, choices) if isinstance(value, str) else None
        extra = f" (did you mean {hint!r}?)" if hint else ""
        raise ConfigError(f"{where(section, key)} = {value!r} is not one of {', '.join(map(repr, choices))}{extra}")
    return value


def vector(section: str, key: str, value: Any, n: int) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or len(value) != n or not all(
        is_number(v) and np.isfinite(v) for v in value
    ):
        raise ConfigError(f"{where(section, key)} must be a list of {n} finite numbers, got {describe(value)}")
    return tuple(float(v) for v in value)


def int_pair(section: str, key: str, value: Any, maximum: int) -> tuple[int, int]:
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ConfigError(f"{where(section, key)} must be a list of two integers, got {describe(value)}")
    return tuple(integer(section, f"{key}[{i}]", v, maximum=maximum) for i, v in enumerate(value))  # type: ignore


def path(section: str, key: str, value: Any, base: Path) -> Path:
    """A path string resolved against ``base`` (the config file's directory) unless absolute."""
    text = string(section, key, value)
    if "\x00" in text:
        raise ConfigError(f"{where(section, key)} contains a NUL character; give a plain file path")
    p = Path(text).expanduser()
    return p if p.is_absolute() else base / p


# ------------------------------------------------------------------------------------------------ checks
Check = Callable[[str, str, Any], Any]


@dataclass(frozen=True)
class Number:
    """A finite number [unit in the key's name]: ``positive`` (> 0), or ``minimum`` / ``maximum`` bounds."""

    minimum: float | None = None
    positive: bool = False
    maximum: float | None = None

    def __call__(self, section: str, key: str, value: Any) -> float:
        return number(section, key, value, minimum=self.minimum, positive=self.positive, maximum=self.maximum)


@dataclass(frozen=True)
class Integer:
    """An integer in [minimum, maximum] (a float, even 2.0, is refused)."""

    minimum: int = 1
    maximum: int = MAX_INT

    def __call__(self, section: str, key: str, value: Any) -> int:
        return integer(section, key, value, minimum=self.minimum, maximum=self.maximum)


@dataclass(frozen=True)
class Text:
    """A string; ``nonempty`` refuses "" and blanks."""

    nonempty: bool = False

    def __call__(self, section: str, key: str, value: Any) -> str:
        text = string(section, key, value)
        if self.nonempty and not text.strip():
            raise ConfigError(f"{where(section, key)} must not be empty")
        return text


@dataclass(frozen=True)
class Choice:
    """One of ``choices`` (strings)."""

    choices: tuple[str, ...]

    def __call__(self, section: str, key: str, value: Any) -> str:
        return choice(section, key, value, self.choices)


@dataclass(frozen=True)
class Vector:
    """A list of ``n`` finite numbers (a tuple of floats)."""

    n: int

    def __call__(self, section: str, key: str, value: Any) -> tuple[float, ...]:
        return vector(section, key, value, self.n)


@dataclass(frozen=True)
class IntPair:
    """Two integers in [1, maximum]."""

    maximum: int = MAX_INT

    def __call__(self, section: str, key: str, value: Any) -> tuple[int, int]:
        return int_pair(section, key, value, self.maximum)


@dataclass(frozen=True)
class Flag:
    """true or false."""

    def __call__(self, section: str, key: str, value: Any) -> bool:
        return boolean(section, key, value)


@dataclass(frozen=True)
class Like:
    """Checked like a default of this type (bool, int >= 0, float, str, or a non-empty list of them)."""

    default: Any

    def __call__(self, section: str, key: str, value: Any) -> Any:
        return typed_value(section, key, value, self.default)


def typed_value(section: str, key: str, value: Any, default: Any) -> Any:
    """``value`` checked against the type of ``default`` (bool, int, float, str, or a tuple of them: a list,
    non-empty unless the default is empty)."""
    if isinstance(default, bool):
        return boolean(section, key, value)
    if isinstance(default, int):
        return integer(section, key, value, minimum=0)
    if isinstance(default, float):
        return number(section, key, value)
    if isinstance(default, str):
        return string(section, key, value)
    if isinstance(default, tuple | list):
        if not isinstance(value, list | tuple) or (len(value) == 0 and len(default) > 0):
            raise ConfigError(f"{where(section, key)} must be a non-empty list like {list(default)}, got "
                              f"{describe(value)}")
        item = default[0] if default else 0.0
        return tuple(typed_value(section, f"{key}[{i}]", v, item) for i, v in enumerate(value))
    raise ConfigError(f"{where(section, key)} cannot be set from a config file")


def setting(default: Any, comment: str, check: Check | None = None, *, example: Any = None,
            shown: bool | None = None) -> Any:
    """A field of a config section: its default, its documentation and the check of a given value.

    Parameters
    ----------
    default : Any
        The value when the key is left out (lists are given as tuples; ``None``: optional, or required and
        checked by the section's user, with ``example`` shown in the documented file).
    comment : str
        What the key means, with its unit; ``"\\n"`` starts a new comment line in the example.
    check : callable, optional
        ``check(section, key, value) -> value`` (:class:`Number`, :class:`Integer`, :class:`Choice` ...),
        raising :class:`~mincam_sim.errors.ConfigError`; default: like the default's type (:class:`Like`).
    example : Any, optional
        The value the documented file shows instead of the default (for keys without one).
    shown : bool, optional
        Whether the documented file sets the key (True) or shows it commented out (False). Default: a key
        with a default is set to it; a key whose default is None is shown commented out with its ``example``.
    """
    return dataclasses.field(default=default, metadata={"comment": comment, "check": check, "example": example,
                                                        "shown": shown})


def _fields(cls: type) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if f.init]


def field_check(f: dataclasses.Field) -> Check:
    check = f.metadata.get("check")
    if check is not None:
        return check
    return Like(f.default if f.default is not dataclasses.MISSING else f.default_factory())  # type: ignore[misc]


def defaults(cls: type) -> dict[str, Any]:
    """The section's keys and defaults as TOML values (tuples as lists)."""
    instance = cls()
    return {f.name: plain(getattr(instance, f.name)) for f in _fields(cls)}


def plain(value: Any) -> Any:
    """``value`` with tuples turned into lists (recursively): what TOML would give back."""
    if isinstance(value, tuple | list):
        return [plain(v) for v in value]
    return value


def read_section(section: str, given: Any, cls: type, base: Any = None) -> Any:
    """An instance of the section dataclass ``cls`` from a TOML table (``base``: a defaults instance to update).

    Every key must be a field (else the closest one is suggested), every value passes its field's check; the
    dataclass's own ``__post_init__`` then checks its ranges and its ``ValueError`` comes back as a
    :class:`~mincam_sim.errors.ConfigError` naming the section.
    """
    given = table(bracket(section), given)
    fields = {f.name: f for f in _fields(cls)}
    refuse_unknown(section, given, list(fields))
    values = {key: field_check(fields[key])(section, key, value) for key, value in given.items()}
    try:
        return dataclasses.replace(base, **values) if base is not None else cls(**values)
    except ValueError as err:
        raise ConfigError(f"{bracket(section)}: {err}") from None


def dataclass_from_section(section: str, table_: Any, defaults_: Any) -> Any:
    """A copy of the dataclass instance ``defaults_`` with the keys of a TOML ``[section]`` table applied
    (:func:`mincam_sim.configuration.schema.read_section` with the instance as the base)."""
    return read_section(section, table_, type(defaults_), defaults_)


# ------------------------------------------------------------------------------------------------ documents
@dataclass(frozen=True)
class Part:
    """One section of a file kind: ``[name]`` (a dataclass ``cls``), ``[[name]]`` tables (``array``), or a
    free table whose keys the file's reader checks itself (``cls`` None).

    ``name`` may be dotted (``world.object``: the ``object`` key of ``[world]``). ``intro`` is comment text
    printed above the section in the example; ``commented`` shows the whole section commented out there;
    ``example`` is the text of a free table's example body (its keys are examples, not defaults).
    """

    name: str
    cls: type | None = None
    array: bool = False
    intro: str = ""
    commented: bool = False
    example: str = ""

    @property
    def header(self) -> str:
        return f"[[{self.name}]]" if self.array else f"[{self.name}]"


@dataclass(frozen=True)
class Schema:
    """A file kind: its title (the example's first comment lines) and its sections."""

    title: str
    parts: tuple[Part, ...]

    def part(self, name: str) -> Part:
        return next(p for p in self.parts if p.name == name)

    def _allowed_top(self) -> list[str]:
        return list(dict.fromkeys(p.name.split(".")[0] for p in self.parts))

    def tables(self, raw: Any) -> dict[str, Any]:
        """Each part's table (``{}`` / ``[]`` when absent) from a parsed document, after refusing unknown
        sections, sections that are no table, and a ``[name]`` table where ``[[name]]`` tables belong."""
        if not isinstance(raw, dict):
            raise ConfigError(f"a TOML document is a table of sections, got {describe(raw)}")
        bad = [k for k in raw if not isinstance(k, str)]
        if bad:
            raise ConfigError(f"section names must be strings, got {bad[0]!r}")
        top = self._allowed_top()
        unknown = [k for k in raw if k not in top]
        if unknown:
            hints = [f"[{u}] (did you mean {self.part_named(h).header}?)" if (h := closest(u, top)) else f"[{u}]"
                     for u in sorted(unknown)]
            raise ConfigError(f"unknown section{'s' if len(unknown) > 1 else ''} {', '.join(hints)}; allowed "
                              f"sections are {', '.join(self.part_named(t).header for t in top)}")
        out: dict[str, Any] = {}
        for part in self.parts:
            head, _, sub = part.name.partition(".")
            value: Any = raw.get(head)
            if sub:
                value = value.get(sub) if isinstance(value, dict) else None
            if value is None:
                out[part.name] = [] if part.array else {}
            elif part.array:
                out[part.name] = array_of_tables(part.name, value)
            else:
                out[part.name] = table(part.header, value)
        return out

    def part_named(self, top: str) -> Part:
        return next(p for p in self.parts if p.name.split(".")[0] == top)

    def subparts(self, name: str) -> list[str]:
        """The dotted parts under ``[name]`` (``object`` for ``world.object``): keys the section's table holds
        besides its own fields."""
        return [p.name.split(".", 1)[1] for p in self.parts if p.name.startswith(name + ".")]

    def read(self, name: str, given: dict, base: Any = None) -> Any:
        """:func:`mincam_sim.configuration.schema.read_section` of part ``name`` (its sub-parts' keys set aside)."""
        part = self.part(name)
        subs = self.subparts(name)
        own = {k: v for k, v in table(part.header, given).items() if k not in subs}
        return read_section(name, own, part.cls, base)

    def example(self, notes: dict[str, dict[str, str]] | None = None, commented_keys: bool = False) -> str:
        """The documented file: the title, then every section with every key, its default and its comment.

        ``notes[section][key]`` is appended to a key's comment; ``commented_keys`` writes every key commented
        out (a file whose keys are all optional and would override other defaults if set).
        """
        lines = [*(_comment(t) for t in self.title.splitlines())]
        for part in self.parts:
            lines.append("")
            lines += [_comment(t) for t in part.intro.splitlines()]
            lines.append(f"# {part.header}" if part.commented else part.header)
            if part.cls is not None:
                lines += example_lines(part.cls, (notes or {}).get(part.name, {}), commented_keys or part.commented)
            lines += [_comment_out(b) for b in part.example.splitlines()] if part.commented else \
                part.example.splitlines()
        return "\n".join(lines).strip("\n") + "\n"


def array_of_tables(name: str, value: Any) -> list[dict]:
    """The ``[[name]]`` tables of a document (a single ``[name]`` table or another value is refused)."""
    if isinstance(value, dict):
        raise ConfigError(f"[[{name}]] entries are an array of tables (double brackets, one [[{name}]] per "
                          f"entry), not a single [{name}] table")
    if not isinstance(value, list):
        raise ConfigError(f"[[{name}]] must be an array of tables (double brackets), got {describe(value)}")
    return [table(f"[[{name}]] #{i + 1}", t) for i, t in enumerate(value)]


def read_sections(source: str | Path | dict, allowed: Sequence[str]) -> dict[str, dict]:
    """A TOML document (file path, text or dict) whose top level holds only the tables ``allowed``."""
    raw, _, _ = read_document(source, None)
    schema = Schema("", tuple(Part(name) for name in allowed))
    tables = schema.tables(raw)
    return {name: tables[name] for name in raw}


# ------------------------------------------------------------------------------------------------ writing
def toml_value(value: Any) -> str:
    """``value`` as TOML (floats exactly, small ones in engineering notation: 550e-9)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, float):
        text = repr(value)
        if "e" in text and np.isfinite(value):
            exp = int(Decimal(text).adjusted())
            exp3 = exp - exp % 3
            mantissa = Decimal(text).scaleb(-exp3).normalize()
            candidate = f"{mantissa:f}e{exp3}"
            if float(candidate) == value:
                return candidate
        return text
    if isinstance(value, int):
        return str(value)
    if isinstance(value, tuple | list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"no TOML form for {value!r}")


_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def _toml_string(text: str) -> str:
    """A TOML basic string: quotes, backslashes and control characters escaped."""
    out = [_ESCAPES.get(ch) or (f"\\u{ord(ch):04x}" if ord(ch) < 0x20 or ord(ch) == 0x7F else ch) for ch in text]
    return '"' + "".join(out) + '"'


def inline_table(cls: type, **values: Any) -> str:
    """A TOML inline table of the section ``cls``: every field's default, or its value in ``values``."""
    return toml_value({k: values.get(k, v) for k, v in defaults(cls).items()})


def field_comment(cls: type, f: dataclasses.Field) -> str:
    """A field's comment: its ``setting`` comment, else its entry in the class's numpydoc Attributes."""
    comment = f.metadata.get("comment")
    if comment is not None:
        return comment
    return attribute_docs(cls).get(f.name, "")


def example_lines(cls: type, notes: dict[str, str] | None = None, commented_keys: bool = False) -> list[str]:
    """``key = value  # comment`` lines of every field of ``cls``.

    A field with a default of None is optional: shown commented out with its ``example`` (or left out of the
    file with no example); a field with an ``example`` and a None default is shown set to the example when
    its ``shown`` is True. Long comments continue on the next lines, aligned; fields documented together
    (numpydoc ``a, b : float``) share one comment, written above them.
    """
    instance = cls()
    notes = notes or {}
    entries = []
    for f in _fields(cls):
        value = getattr(instance, f.name)
        example = f.metadata.get("example")
        shown = f.metadata.get("shown")
        if value is None:
            if example is None:
                continue
            value = example
            shown = bool(shown)
        elif shown is None:
            shown = True
        entries.append((f.name, toml_value(value), field_comment(cls, f), notes.get(f.name, ""),
                        not shown or commented_keys))
    out: list[str] = []
    i = 0
    while i < len(entries):
        j = i
        while entries[i][2] and j + 1 < len(entries) and entries[j + 1][2] == entries[i][2]:
            j += 1  # keys documented together (numpydoc "a, b : float"): the comment once, above them
        if j > i:
            out += [f"# {p}" for p in _wrap(entries[i][2], EXAMPLE_WIDTH - 2)]
            for key, value, _, note, commented in entries[i:j + 1]:
                out += _key_lines(key, value, note, commented)
        else:
            key, value, comment, note, commented = entries[i]
            out += _key_lines(key, value, " ".join(t for t in (comment, note) if t), commented)
        i = j + 1
    return out


def _wrap(text: str, width: int) -> list[str]:
    """``text`` wrapped to ``width`` columns; ``"\\n"`` starts a new line."""
    pieces = []
    for paragraph in text.split("\n"):
        pieces += textwrap.wrap(paragraph, width, break_long_words=False, break_on_hyphens=False) or [""]
    return pieces


def _key_lines(key: str, value: str, comment: str, commented: bool) -> list[str]:
    """``key = value  # comment`` (continued on aligned lines); the comment goes above a long key = value."""
    head = f"{'# ' if commented else ''}{key} = {value}"
    if not comment:
        return [head]
    above = len(head) + 1 > VALUE_COLUMN + 8
    column = 0 if above else max(VALUE_COLUMN, len(head) + 1)
    pieces = _wrap(comment, EXAMPLE_WIDTH - column - 2)
    if above:
        return [f"# {p}".rstrip() for p in pieces] + [head]
    lead = "#" if commented else ""
    lines = [f"{head:<{column}}# {pieces[0]}"] + [f"{lead:<{column}}# {p}" for p in pieces[1:]]
    return [line.rstrip() for line in lines]


def _comment(text: str) -> str:
    return f"# {text}".rstrip() if text else "#"


def _comment_out(line: str) -> str:
    if not line:
        return line
    return line if line.startswith("#") else f"# {line}"


def attribute_docs(cls: type) -> dict[str, str]:
    """``name -> description`` from a numpydoc ``Attributes`` section (names may be grouped: ``a, b : float``)."""
    doc = cls.__doc__ or ""
    out: dict[str, str] = {}
    lines = doc.splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.strip() == "Attributes")
    except StopIteration:
        return out
    current: list[str] = []
    indent = None
    for line in lines[start + 2:]:
        stripped = line.strip()
        if not stripped:
            continue
        this_indent = len(line) - len(line.lstrip())
        if indent is None:
            indent = this_indent
        if this_indent == indent and (" : " in stripped or stripped.endswith(":")):
            current = [n.strip() for n in stripped.split(" : ")[0].rstrip(":").split(",")]
            for n in current:
                out.setdefault(n, "")
        elif this_indent > indent and current:
            for n in current:
                out[n] = (out[n] + " " + stripped).strip()
        else:
            break
    return {k: _plain_rst(v) for k, v in out.items()}


def _plain_rst(text: str) -> str:
    """Docstring markup made plain for a TOML comment (``x`` -> x, :data:`~a.b.C` -> C)."""
    import re

    text = re.sub(r":\w+:`~?([^`]+)`", lambda m: m.group(1).rsplit(".", 1)[-1], text)
    return text.replace("``", "")
