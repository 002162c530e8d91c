"""Randomised quasi-Monte Carlo points: an Owen-scrambled Sobol sequence in Dr.Jit ``UInt32`` arithmetic.

Point ``i`` of the sequence scrambled by ``seed`` (Burley 2020, "Practical Hash-based Owen Scrambling"): the
index is shuffled by a nested uniform scramble (a base-2 Owen scramble of its bits), the Sobol point of the
shuffled index is computed from the direction numbers of Joe and Kuo (``new-joe-kuo-6.21201``, the first
:data:`DIMENSIONS` dimensions), and every coordinate gets a nested uniform scramble of its own. The scrambles are
Laine-Karras hashes of the bit-reversed value (each output bit depends only on the bits above it, as an Owen
scramble's does), so

* every point is uniform on ``[0, 1)^d`` over the seed (an estimate from the points is unbiased);
* the first ``2^m`` points of one seed are a scrambled aligned block of the Sobol sequence, a ``(t, m, d)``-net:
  every 1D projection has one point in each interval of length ``2^-m``, and the projection on the first two
  dimensions one point in each ``2^-k x 2^-(m-k)`` box;
* different seeds give (to the hash's quality) independent point sets, so estimates from independent seeds are
  independent and their spread is an honest standard error.

Everything is plain ``UInt32`` arithmetic on Dr.Jit arrays (products wrap modulo ``2^32``), with only constants
baked in: a frozen launch replays it, and any subset of indices draws what the full set draws there.
"""

from __future__ import annotations

import numpy as np

DIMENSIONS = 5
BITS = 32
# (degree s, coefficients a, initial direction numbers m) of Joe-Kuo dimensions 2 .. DIMENSIONS; dimension 1 is
# the van der Corput sequence (the bit reversal of the index)
_JOE_KUO = ((1, 0, (1,)), (2, 1, (1, 3)), (3, 1, (1, 3, 1)), (3, 2, (1, 1, 1)))
_DIM_SALT = (0x9E3779B9, 0x7F4A7C15, 0xF39CC060, 0x5CEDC834, 0x2BA9E4A1)  # distinct constants per dimension


def direction_numbers() -> np.ndarray:
    """(DIMENSIONS, BITS) Sobol direction numbers as 32-bit integers (column ``b`` is the contribution of
    index bit ``b``)."""
    out = np.zeros((DIMENSIONS, BITS), dtype=np.uint64)
    out[0] = [1 << (BITS - 1 - b) for b in range(BITS)]
    for dim, (s, a, m) in enumerate(_JOE_KUO, start=1):
        v = [int(m[i]) << (BITS - 1 - i) for i in range(s)]
        for i in range(s, BITS):
            value = v[i - s] ^ (v[i - s] >> s)
            for k in range(1, s):
                if (a >> (s - 1 - k)) & 1:
                    value ^= v[i - k]
            v.append(value)
        out[dim] = v
    return out.astype(np.uint32)


_V = direction_numbers()


def _reverse_bits(x):
    """The 32 bits of each entry in reverse order."""
    x = ((x >> 1) & 0x55555555) | ((x & 0x55555555) << 1)
    x = ((x >> 2) & 0x33333333) | ((x & 0x33333333) << 2)
    x = ((x >> 4) & 0x0F0F0F0F) | ((x & 0x0F0F0F0F) << 4)
    x = ((x >> 8) & 0x00FF00FF) | ((x & 0x00FF00FF) << 8)
    return (x >> 16) | (x << 16)


def _laine_karras(x, seed):
    """Burley's improved Laine-Karras permutation: output bit ``b`` depends only on input bits ``<= b`` (pure:
    the arguments are not changed)."""
    x = x ^ (x * 0x3D20ADEA)
    x = x + seed
    x = x * ((seed >> 16) | 1)
    x = x ^ (x * 0x05526C56)
    return x ^ (x * 0x53A22864)


def nested_uniform_scramble(x, seed):
    """A base-2 Owen scramble of ``x`` (``UInt32``) drawn by ``seed``: each bit flipped as a hash of the bits
    above it and the seed."""
    return _reverse_bits(_laine_karras(_reverse_bits(x), seed))


def hash_u32(x):
    """A well-mixing 32-bit integer hash (Wellons' ``lowbias32``)."""
    x = x ^ (x >> 16)
    x = x * 0x7FEB352D
    x = x ^ (x >> 15)
    x = x * 0x846CA68B
    return x ^ (x >> 16)


def sobol_u32(index, dim: int):
    """Coordinate ``dim`` of Sobol point ``index`` (``UInt32``), unscrambled, as a 32-bit fraction."""
    x = index & 0  # zeros of the index's type
    for b in range(BITS):
        x = x ^ (((index >> b) & 1) * int(_V[dim, b]))
    return x


def owen_sobol(index, seed, dims: int = DIMENSIONS) -> list:
    """Coordinates ``0 .. dims - 1`` (``Float`` in ``[0, 1)``, 24 bits) of point ``index`` of the Sobol sequence
    Owen-scrambled by ``seed`` (both ``UInt32`` arrays, one entry per lane, or broadcastable).

    Raises a ``ValueError`` beyond :data:`DIMENSIONS` dimensions."""
    if not 1 <= dims <= DIMENSIONS:
        raise ValueError(f"dims (coordinates of an Owen-scrambled Sobol point) must be 1 .. {DIMENSIONS}, got {dims}")
    from mincam_sim.render import backend

    mi = backend.mitsuba()
    shuffled = nested_uniform_scramble(index, hash_u32(seed))
    points = []
    for dim in range(dims):
        x = nested_uniform_scramble(sobol_u32(shuffled, dim), hash_u32(seed ^ _DIM_SALT[dim]))
        points.append(mi.Float(x >> 8) * (1.0 / (1 << 24)))
    return points


__all__ = ["BITS", "DIMENSIONS", "direction_numbers", "hash_u32", "nested_uniform_scramble", "owen_sobol",
           "sobol_u32"]
