"""Every TOML file of mincam_sim is read here, and only here (pure Python).

:func:`read_document` takes what a user hands over -- a ``.toml`` path, TOML text or an already-parsed dict -- and
gives the parsed document, the directory its relative paths resolve against and the file (if any);
:func:`read_toml_file` reads one file (``--config`` of the design command, a study's render target). Every problem
(a missing file, a directory, text that is not UTF-8, invalid TOML) is one :class:`~mincam_sim.errors.ConfigError`
line naming the file; the checks of the values are :mod:`mincam_sim.configuration.schema`'s.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from mincam_sim.errors import ConfigError

__all__ = ["parse_toml", "read_document", "read_toml_file"]


def parse_toml(text: str, label: str = "config") -> dict:
    """The document of TOML ``text``; ``label`` names it in the error (``"config file a.toml"``)."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{label} is not valid TOML: {err}") from None


def _file_text(file: Path, kind: str) -> str:
    if not file.exists():
        raise ConfigError(f"{kind} file {file} does not exist")
    if file.is_dir():
        raise ConfigError(f"{kind} file {file} is a directory; give a .toml file")
    try:
        return file.read_bytes().decode("utf-8-sig")  # a byte-order mark (Windows editors) is dropped
    except UnicodeDecodeError:
        raise ConfigError(f"{kind} file {file} is not UTF-8 text; give a TOML file") from None
    except OSError as err:
        raise ConfigError(f"cannot read {kind} file {file}: {err.strerror or err}") from None


def read_toml_file(path: str | Path, kind: str = "config") -> dict:
    """The parsed TOML file ``path``; ``kind`` names it in messages (``"--config"``, ``"render config"``)."""
    file = Path(path)
    return parse_toml(_file_text(file, kind), f"{kind} file {file}")


def _is_file_name(source: Any) -> bool:
    return isinstance(source, Path) or (isinstance(source, str) and "\n" not in source and "=" not in source
                                        and (source.endswith(".toml") or Path(source).is_file()))


def read_document(source: Any, base_dir: str | Path | None, kind: str = "config") -> tuple[dict, Path, Path | None]:
    """(parsed document, base directory, file or None) from a ``.toml`` path, TOML text or a parsed dict.

    ``kind`` names the document in messages (``"config"``, ``"study"``). Relative paths in the document
    resolve against ``base_dir``, default: the file's directory (the working directory for text and dicts).
    """
    if isinstance(source, dict):
        return source, Path(base_dir or "."), None
    if _is_file_name(source):
        file = Path(source)
        text = _file_text(file, kind)
        return parse_toml(text, f"{kind} file {file}"), file.parent if base_dir is None else Path(base_dir), file
    if isinstance(source, str):
        return parse_toml(source.removeprefix("\ufeff"), kind), Path(base_dir or "."), None
    raise ConfigError(f"a {kind} is a TOML file path, TOML text or a dict, got {type(source).__name__}")
