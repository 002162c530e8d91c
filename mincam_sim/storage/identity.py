"""Content fingerprints of everything that determines the numbers (pure numpy; never imports Mitsuba).

A run is identified by *what it computes from*, not by names: mask transmission arrays, geometry, frames,
sample budget, seed, form, library versions. :func:`fingerprint` hashes any such description:

* numpy arrays by dtype, shape and bytes (C order);
* ``dict`` / ``list`` / ``tuple`` / ``set`` / scalars / ``str`` / ``Path`` through a canonical JSON form
  (sorted keys; ``2`` and ``2.0`` hash alike, ``True`` and ``1`` do not);
* dataclasses field by field (``Pose``, ``Mixel``, ``Mincam``, ``Screen``, ``Mask`` ...), recursively; a field
  whose metadata sets :data:`OMIT_DEFAULT` is left out while it holds its default (fields added later then
  keep older identities valid);
* any object with a ``fingerprint_parts()`` method, through what that method returns.

:class:`StreamingHash` hashes frames chunk by chunk as they stream (the digest does not depend on how the
stream is cut into chunks), so a frame stack never has to be held in memory to be identified.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import importlib.metadata
import json
import math
from collections.abc import Iterable, Mapping
from pathlib import PurePath
from typing import Any

import numpy as np

from mincam_sim.masks import Mask

#: Default length of a fingerprint [hex characters] (128 bits).
FINGERPRINT_CHARS = 32

#: Keys of a Mask's ``meta`` that record provenance only (where a file was read), not content.
PROVENANCE_META_KEYS = frozenset({"source"})

#: Distributions whose versions can change the numbers.
VERSIONED_LIBRARIES = ("mincam_sim", "mitsuba", "drjit", "numpy")

#: The method's own version, part of every stored result's identity: raise it with any change to the code that
#: changes the numbers for the same inputs (a fixed bias, a new sampling), so that no store made before is reused.
#: The package version alone does not move between releases.
METHOD_VERSION = "2026-12-07"  # raster masks cut along their lines in DotProduct; ResponseMap target search floor


def array_digest(array: np.ndarray) -> str:
    """sha256 hex digest of an array's dtype, shape and C-ordered bytes."""
    arr = np.asarray(array)
    if arr.dtype.hasobject:
        raise TypeError("cannot fingerprint an object array by its bytes; convert it to a numeric dtype")
    h = hashlib.sha256()
    h.update(f"ndarray:{arr.dtype.str}:{arr.shape}:".encode())
    h.update(np.ascontiguousarray(arr).data)
    return h.hexdigest()


def _number(value: float) -> Any:
    if math.isfinite(value) and float(value).is_integer() and abs(value) < 2**53:
        return int(value)
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "Infinity" if value > 0 else "-Infinity"
    return float(value)


OMIT_DEFAULT = "identity_omit_default"  # dataclass field metadata: leave the field out while it has its default


def canonical(obj: Any) -> Any:
    """A JSON-serialisable, canonical form of ``obj`` (arrays replaced by their digest).

    Parameters
    ----------
    obj : object
        Scalars, strings, paths, arrays, mappings, sequences, sets, dataclasses, enums, or objects with a
        ``fingerprint_parts()`` method.

    Returns
    -------
    object
        Built from ``dict`` (string keys), ``list``, ``str``, ``int``, ``float``, ``bool`` and ``None`` only.

    Raises
    ------
    TypeError
        For objects it does not know how to describe (their ``repr`` would not be stable across runs).
    """
    if obj is None or isinstance(obj, bool | str):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        return _number(float(obj))
    if isinstance(obj, complex | np.complexfloating):
        return {"__complex__": [_number(obj.real), _number(obj.imag)]}
    if isinstance(obj, bytes):
        return {"__bytes__": hashlib.sha256(obj).hexdigest()}
    if isinstance(obj, PurePath):
        return obj.as_posix()
    if isinstance(obj, enum.Enum):
        return {"__enum__": f"{type(obj).__name__}.{obj.name}"}
    if isinstance(obj, np.ndarray):
        if obj.dtype.hasobject:
            return [canonical(v) for v in obj.tolist()]
        return {"__ndarray__": array_digest(obj)}
    parts = getattr(obj, "fingerprint_parts", None)
    if callable(parts) and not isinstance(obj, type):
        return {"__type__": type(obj).__name__, "parts": canonical(parts())}
    if _is_mask(obj):
        meta = {k: v for k, v in dict(obj.meta).items() if k not in PROVENANCE_META_KEYS}
        return {"__type__": "Mask", "transmission": canonical(np.asarray(obj.transmission)),
                "width_m": canonical(obj.width_m), "height_m": canonical(obj.height_m), "name": obj.name,
                "meta": canonical(meta)}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        fields = {f.name: canonical(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                  if not (f.metadata.get(OMIT_DEFAULT) and getattr(obj, f.name) == f.default)}
        return {"__type__": type(obj).__name__, **fields}
    if isinstance(obj, Mapping):
        out = {}
        for key, value in obj.items():
            if not isinstance(key, str | int | float | bool) and key is not None:
                raise TypeError(f"cannot fingerprint a mapping key of type {type(key).__name__}")
            out[key if isinstance(key, str) else json.dumps(canonical(key))] = canonical(value)
        return out
    if isinstance(obj, set | frozenset):
        items = [canonical(v) for v in obj]
        return {"__set__": sorted(items, key=lambda v: json.dumps(v, sort_keys=True))}
    if isinstance(obj, list | tuple):
        return [canonical(v) for v in obj]
    raise TypeError(
        f"cannot fingerprint an object of type {type(obj).__name__}: give it a fingerprint_parts() method or "
        "describe it with numbers, strings, arrays and dicts"
    )


def _is_mask(obj: Any) -> bool:
    return isinstance(obj, Mask)


def canonical_json(obj: Any) -> str:
    """The canonical form of ``obj`` as compact JSON text (sorted keys)."""
    return json.dumps(canonical(obj), sort_keys=True, separators=(",", ":"), allow_nan=False)


def fingerprint(obj: Any, chars: int = FINGERPRINT_CHARS) -> str:
    """Content fingerprint of ``obj``: the first ``chars`` hex characters of a sha256.

    Parameters
    ----------
    obj : object
        Anything :func:`canonical` accepts (arrays, dicts, dataclasses such as ``Mincam`` or ``Screen`` ...).
    chars : int
        Length of the returned hex string, 16 to 64.

    Returns
    -------
    str
        Equal for equal content (same array bytes, same numbers), different otherwise.
    """
    if not 16 <= chars <= 64:
        raise ValueError(f"a fingerprint has 16 to 64 hex characters, got {chars}")
    return hashlib.sha256(canonical_json(obj).encode()).hexdigest()[:chars]


def run_key(identity: Any) -> str:
    """Key of a run's identity: its :func:`~mincam_sim.storage.identity.fingerprint` (32 hex characters)."""
    return fingerprint(identity)


class StreamingHash:
    """Fingerprint of a stream of frames, fed chunk by chunk.

    The digest depends on the frames' values (as ``dtype``), their shape and their number, not on how the
    stream was cut into chunks: ``update(stack)`` equals ``update(stack[:3]); update(stack[3:])`` equals one
    ``update(frame)`` per frame.

    Parameters
    ----------
    frame_ndim : int
        Dimensions of one frame (2 for (rows, cols) images). An array with ``frame_ndim`` dimensions is one
        frame; one with ``frame_ndim + 1`` is a chunk of frames along axis 0.
    dtype : numpy dtype or None
        Frames are converted to it before hashing (default float64, the dtype the renderers compute in), so
        a float32 and a float64 copy of the same values hash alike. None hashes the given dtype's bytes.
    """

    def __init__(self, frame_ndim: int = 2, dtype: Any = np.float64) -> None:
        self.frame_ndim = int(frame_ndim)
        self.dtype = None if dtype is None else np.dtype(dtype)
        self._sha = hashlib.sha256()
        self.n_frames = 0
        self.frame_shape: tuple[int, ...] | None = None
        self.frame_dtype: str | None = None

    def update(self, frames: np.ndarray) -> StreamingHash:
        """Add one frame or a chunk of frames; return ``self``."""
        arr = np.asarray(frames)
        if arr.ndim == self.frame_ndim:
            arr = arr[None]
        if arr.ndim != self.frame_ndim + 1:
            raise ValueError(
                f"expected a frame with {self.frame_ndim} dimensions or a chunk with {self.frame_ndim + 1}, "
                f"got shape {arr.shape}"
            )
        if self.dtype is not None:
            arr = arr.astype(self.dtype, copy=False)
        if arr.dtype.hasobject:
            raise TypeError("cannot hash frames of object dtype")
        shape, dtype = tuple(arr.shape[1:]), arr.dtype.str
        if self.frame_shape is None:
            self.frame_shape, self.frame_dtype = shape, dtype
        elif shape != self.frame_shape or dtype != self.frame_dtype:
            raise ValueError(
                f"frame of shape {shape} ({dtype}) after frames of shape {self.frame_shape} ({self.frame_dtype}); "
                "all frames of a stream must have one shape"
            )
        self._sha.update(np.ascontiguousarray(arr).data)
        self.n_frames += len(arr)
        return self

    def hexdigest(self, chars: int = FINGERPRINT_CHARS) -> str:
        """Fingerprint of the frames so far (number, shape, dtype and values)."""
        summary = {"n_frames": self.n_frames, "frame_shape": list(self.frame_shape or ()),
                   "dtype": self.frame_dtype, "content": self._sha.hexdigest()}
        return fingerprint({"__type__": "FrameStream", **summary}, chars)


def frames_fingerprint(frames: np.ndarray | Iterable[np.ndarray], frame_ndim: int = 2, chunk: int = 64) -> str:
    """:class:`StreamingHash` digest of a frame stack, an iterable of frames or an iterable of chunks."""
    h = StreamingHash(frame_ndim)
    if isinstance(frames, np.ndarray):
        stack = frames if frames.ndim == frame_ndim + 1 else frames[None]
        for i in range(0, len(stack), chunk):
            h.update(stack[i : i + chunk])
    else:
        for item in frames:
            h.update(item)
    return h.hexdigest()


def library_versions() -> dict[str, str]:
    """Installed versions of the libraries whose changes can change the numbers (without importing them)."""
    versions = {"mincam_sim method": METHOD_VERSION}
    for dist in VERSIONED_LIBRARIES:
        try:
            versions[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            versions[dist] = "not installed"
    return versions


@dataclasses.dataclass(frozen=True)
class IdentityKind:
    """The content parts an identity of one kind holds (besides ``versions``, and ``variant`` where recorded).

    Attributes
    ----------
    parts : frozenset of str
        Parts every identity of the kind has.
    optional : frozenset of str
        Parts some have (e.g. the stratified estimator's options).
    variant : bool
        Whether the Mitsuba variant that computed the numbers is recorded (CUDA and LLVM differ in the last bits).
    """

    parts: frozenset[str]
    optional: frozenset[str] = frozenset()
    variant: bool = True


#: Every kind of stored identity and its parts. An identity's content is its parts, ``variant`` and ``versions``
#: only (the kind itself is not stored, so that output directories written before this table existed still
#: resume). Changing a kind's parts changes its identities: results stored before are then refused, never reused.
IDENTITY_KINDS: dict[str, IdentityKind] = {
    # identity.json of a render config's output directory (render_job)
    "render_config": IdentityKind(frozenset({"form", "seed", "budget", "mincam", "mixels", "masks", "screen",
                                             "frames"})),
    # identity.json of a world config's output directory (world_job)
    "world_config": IdentityKind(frozenset({"config", "files"})),
    # design_identity.json (design.run)
    "design": IdentityKind(frozenset({"task", "quick", "seed", "setup"}), variant=False),
    # the identity of a study's store (studies.runner)
    "study": IdentityKind(frozenset({"experiment", "dims", "points", "metrics", "seed", "replicates",
                                     "common_random_numbers", "quick"}), variant=False),
    # the one identity of a run (mincam_sim.runs.run.Run): the scene, the solver, the requested budget, the frames
    "run": IdentityKind(frozenset({"scene", "solver", "budget", "frames"})),
    # reproduce_identity.json (experiments.registry)
    "reproduce": IdentityKind(frozenset({"setup"})),
}

_NO_VARIANT = object()


def build_identity(kind: str, parts: Mapping[str, Any], variant: Any = _NO_VARIANT) -> dict:
    """The identity of a stored result: what determines its numbers. Every identity is built here.

    Parameters
    ----------
    kind : str
        One of :data:`IDENTITY_KINDS`; ``parts`` must hold exactly its parts (and any of its optional ones).
    parts : mapping
        Content fingerprints and numbers (anything :func:`canonical` accepts).
    variant : str, optional
        The Mitsuba variant, for kinds that record it (required for them, refused for the others).

    Returns
    -------
    dict
        ``parts``, then ``variant`` (where recorded) and ``versions`` (:func:`library_versions`).

    Raises
    ------
    ValueError
        An unknown kind, missing or unknown parts, or a variant given (or missing) against the kind.
    """
    spec = IDENTITY_KINDS.get(kind)
    if spec is None:
        raise ValueError(f"unknown identity kind {kind!r}; declare it in IDENTITY_KINDS: {', '.join(IDENTITY_KINDS)}")
    missing = sorted(spec.parts - set(parts))
    unknown = sorted(set(parts) - spec.parts - spec.optional)
    if missing or unknown:
        raise ValueError(f"a {kind!r} identity holds {sorted(spec.parts)} (optional {sorted(spec.optional)}); "
                         f"missing {missing}, unknown {unknown}")
    if spec.variant == (variant is _NO_VARIANT):
        need = "needs the Mitsuba variant (variant=...)" if spec.variant else "records no variant"
        raise ValueError(f"a {kind!r} identity {need}")
    identity = dict(parts)
    if spec.variant:
        identity["variant"] = variant
    identity["versions"] = library_versions()
    return identity


def _leaf(value: Any) -> str:
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= 24 else text[:21] + "..."


def diff_identities(old: Any, new: Any, depth: int = 2, prefix: str = "") -> list[str]:
    """What differs between two canonical identities, as short phrases (``"seed 0 -> 1"``, ``"masks"``).

    Parameters
    ----------
    old, new : object
        Canonical forms (:func:`canonical`) of two identities.
    depth : int
        How many levels of nested dicts to name (``budget.samples_per_texel``); deeper differences are named
        by their parent.
    """
    if old == new:
        return []
    if isinstance(old, dict) and isinstance(new, dict) and depth > 0:
        out = []
        for key in sorted(set(old) | set(new)):
            name = f"{prefix}{key}"
            if key not in old:
                out.append(f"{name} (new)")
            elif key not in new:
                out.append(f"{name} (gone)")
            else:
                out.extend(diff_identities(old[key], new[key], depth - 1, f"{name}."))
        return out
    name = prefix.rstrip(".") or "identity"
    scalar = (str, int, float, bool, type(None))
    if isinstance(old, scalar) and isinstance(new, scalar) and not (_digest_like(old) or _digest_like(new)):
        return [f"{name} {_leaf(old)} -> {_leaf(new)}"]
    return [name]


def _digest_like(value: Any) -> bool:
    return isinstance(value, str) and len(value) >= 16 and all(c in "0123456789abcdef" for c in value)


__all__ = [
    "FINGERPRINT_CHARS",
    "IDENTITY_KINDS",
    "IdentityKind",
    "StreamingHash",
    "array_bytes_digest",
    "mask_parts",
    "array_digest",
    "build_identity",
    "bytes_digest",
    "display_frames_identity",
    "canonical",
    "canonical_json",
    "diff_identities",
    "fingerprint",
    "frames_fingerprint",
    "library_versions",
    "run_identity",
    "run_key",
    "scene_file_digests",
    "updates_fingerprint",
]


# ---------------------------------------------------------------------------------------- hashers of the runs
def bytes_digest(data: bytes) -> str:
    """sha256 hex digest of raw bytes (a mask's transmission, a file's content)."""
    return hashlib.sha256(data).hexdigest()


def array_bytes_digest(array: np.ndarray) -> str:
    """sha256 hex digest of an array's C-ordered bytes only (no dtype or shape: what :func:`mask_parts` records
    as ``transmission_sha256``)."""
    return bytes_digest(np.ascontiguousarray(array).tobytes())


def mask_parts(mask: Mask) -> dict:
    """Everything that determines what ``mask`` transmits, compactly (its texels as one digest): the record of a
    mask in a scene's identity."""
    return {
        "transmission_sha256": array_bytes_digest(mask.transmission),
        "shape": list(mask.shape),
        "width_m": mask.width_m,
        "height_m": mask.height_m,
        "profile": None if mask.profile is None else mask.profile.describe(),
        "interpolation": mask.interpolation,
    }


def updates_fingerprint(updates) -> list:
    """``[n, digest]`` of a sequence of parameter-update dicts (keys in sorted order, values as float64)."""
    h = hashlib.sha256()
    for u in updates:
        for k in sorted(u):
            h.update(k.encode())
            h.update(np.ascontiguousarray(np.asarray(u[k], dtype=np.float64)).tobytes())
    return [len(updates), h.hexdigest()[:16]]


def display_frames_identity(frames, chunk_frames: int, check=None) -> dict:
    """What determines a display run's frames (a :class:`~mincam_sim.scene.display.FrameSource`): a generated
    source's description, or the content hashed as it streams, ``chunk_frames`` at a time (``check(chunk,
    indices)`` validates each chunk on the way)."""
    if frames.description is not None:
        return {"n": len(frames), "description": fingerprint(frames.description)}
    digest = StreamingHash()
    for lo in range(0, len(frames), chunk_frames):
        block = frames[lo : lo + chunk_frames]
        if check is not None:
            check(block, np.arange(lo, lo + len(block)))
        digest.update(block)
    return {"n": len(frames), "content_sha256": digest.hexdigest()}


_XML_FILE_ATTRIBUTES = ("filename", "value")


def scene_file_digests(path, _seen: dict | None = None, parameters: Mapping[str, str] | None = None
                       ) -> dict[str, str]:
    """sha256 of a Mitsuba XML scene file and of every file it names, recursively: ``<include>``d scene files,
    and meshes, textures and other files named by a ``filename`` or ``value`` attribute, also through a
    ``$parameter`` whose ``<default>`` (or the loader's ``parameters``, which override the defaults) names a file.
    Paths are resolved as Mitsuba does, from the naming file's folder. A file that does not exist is recorded as
    ``"missing"``."""
    import re
    import xml.etree.ElementTree as ET
    from pathlib import Path

    path = Path(path)
    seen = {} if _seen is None else _seen
    key = str(path.resolve())
    if key in seen:
        return seen
    if not path.is_file():
        seen[key] = "missing"
        return seen
    data = path.read_bytes()
    seen[key] = bytes_digest(data)
    if path.suffix.lower() != ".xml":
        return seen
    try:
        root = ET.fromstring(data)
    except ET.ParseError:
        return seen
    defaults = {e.get("name"): e.get("value") for e in root.iter("default") if e.get("name")}
    defaults.update(parameters or {})

    def resolve(text: str) -> str:
        return re.sub(r"\$(\w+)", lambda m: defaults.get(m.group(1), m.group(0)), text)

    for element in root.iter():
        if element.tag == "default":  # resolved where a $parameter names it
            continue
        for attribute in _XML_FILE_ATTRIBUTES:
            text = element.get(attribute)
            if not text:
                continue
            named = resolve(text)
            candidate = Path(named) if Path(named).is_absolute() else path.parent / named
            names_a_file = element.tag == "include" or attribute == "filename" or element.get("name") == "filename"
            if names_a_file or candidate.is_file():
                scene_file_digests(candidate, seen, parameters)
    return seen


def run_identity(scene: Mapping, solver: Mapping, budget: Mapping, frames: Any, variant: str) -> dict:
    """The one identity of a run (kind ``"run"``), from the simulation's ``identity``, the solver's
    ``identity``, the budget as requested (``Budget.describe``), the frames' identity and the Mitsuba
    variant; built by :class:`mincam_sim.runs.run.Run` only."""
    return build_identity("run", {"scene": scene, "solver": solver, "budget": budget, "frames": frames},
                          variant=variant)
