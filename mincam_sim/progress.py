"""Progress bars for long loops (tqdm), silent when not asked for."""

from __future__ import annotations

from collections.abc import Iterable
from typing import TypeVar

from tqdm.auto import tqdm

T = TypeVar("T")


def progress(items: Iterable[T], desc: str = "", disable: bool = False, total: int | None = None) -> Iterable[T]:
    """Wrap ``items`` in a progress bar on stderr unless ``disable``."""
    if disable:
        return items
    return tqdm(items, desc=desc, total=total, dynamic_ncols=True, leave=False)
