"""Property-based fuzzing of the config loader: any document loads, or raises ConfigError -- nothing else.

Documents are TOML-like dicts built from the schema's sections and keys, junk keys, and values of random types
(numbers of every kind, booleans, strings that are sometimes valid choices, arrays, nested tables). Frame stacks
stay small: the screen resolution and counts come from small ranges (plus a few huge values the loader must
refuse before allocating anything).
"""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mincam_sim.configuration.config import _FRAME_KINDS, _MIXEL_KEYS, _SCHEMA, ConfigError, RenderConfig, load_config

HUGE = [10**9, 2**31, 2**62, -(2**63), 2**63 - 1]
WORDS = ["pair", "cross", "custom", "response_map", "fast", "reference", "line_sweep", "grid_sweep", "npy",
         "ramp:x", "ramp:1-y", "ramp:z", "constant:0.5", "constant:2", "constant:", "file:", "file:nope.png",
         "sinusoid", "llvm_ad_mono", "scalar_rgb", "cuda_ad_mono", "", "2mm", "0.5", "out", "x", "nan", "\x00"]

small_ints = st.integers(-3, 40)
ints = st.one_of(small_ints, small_ints, st.sampled_from(HUGE))
floats = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                   st.floats(-1.0, 1.0), st.sampled_from([0.0, -0.0, 1e-300, 1e300, 0.002, 0.5, 2.5]))
scalars = st.one_of(ints, floats, st.booleans(), st.sampled_from(WORDS), st.text(max_size=8))


def vectors(n: int):
    return st.lists(st.one_of(st.floats(-1, 1), small_ints), min_size=n, max_size=n)


sinusoid = st.fixed_dictionaries(
    {"kind": st.sampled_from(["sinusoid", "sine", 3])},
    optional={"omega_rad_per_m": st.one_of(floats, ints, st.text(max_size=3)), "a0": scalars, "a1": scalars,
              "phase_rad": scalars, "direction_deg": scalars, "junk": scalars},
)

values = st.recursive(
    st.one_of(scalars, vectors(2), vectors(3), sinusoid),
    lambda children: st.one_of(st.lists(children, max_size=4), st.dictionaries(st.text(max_size=5), children,
                                                                                max_size=3)),
    max_leaves=8,
)


def section(keys: list[str], special: dict | None = None):
    """A table with some schema keys (random values; ``special`` strategies for some keys) and junk keys."""
    special = special or {}
    known = {k: special.get(k, values) for k in keys}
    table = st.fixed_dictionaries({}, optional=known)
    junk = st.dictionaries(st.sampled_from(["junk", "spp_count", "colour", "extra"]), values, max_size=1)
    combined = st.builds(lambda a, b: {**a, **b}, table, st.one_of(st.just({}), st.just({}), junk))
    return st.one_of(combined, combined, combined, values)  # sometimes not a table at all


resolutions = st.one_of(st.lists(st.integers(1, 24), min_size=2, max_size=2),
                        st.lists(st.integers(1, 24), min_size=2, max_size=2), values,
                        st.sampled_from([[10**6, 10**6], [2.5, 9], [16, 9.0], "16x9"]))
screen = st.builds(
    lambda extra, res: {**(extra if isinstance(extra, dict) else {}), "resolution": res},
    section(list(_SCHEMA["screen"])), resolutions,
)
counts = st.one_of(small_ints, st.sampled_from(HUGE), values)
frames = section(list(_SCHEMA["frames"]), {"kind": st.one_of(st.sampled_from(_FRAME_KINDS), values), "n": counts,
                                           "nx": counts, "ny": counts})
mincam = section(list(_SCHEMA["mincam"]), {"layout": st.one_of(st.sampled_from(["pair", "cross", "custom"]), values),
                                           "mask_resolution": counts})
run = section(list(_SCHEMA["run"]))
mixel_table = section(list(_MIXEL_KEYS), {"mask": st.one_of(st.sampled_from(WORDS), sinusoid, values)})
mixels = st.one_of(st.lists(mixel_table, max_size=3), values)

documents = st.fixed_dictionaries(
    {"screen": screen},
    optional={"run": run, "mincam": mincam, "frames": frames, "mixel": mixels,
              "junk": values, "Run": values},
)


def _check(doc, tmp_path) -> None:
    try:
        cfg = load_config(doc, base_dir=tmp_path)
    except ConfigError as err:
        assert str(err)
        return
    assert isinstance(cfg, RenderConfig)
    assert len(cfg.frames.shape) == 3 and len(cfg.frames) >= 1
    assert all(math.isfinite(v) for v in cfg.frames[0].reshape(-1)[:10])


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture,
                                                                  HealthCheck.data_too_large])
@given(doc=documents)
def test_fuzzed_documents_load_or_raise_config_error(doc, tmp_path):
    _check(doc, tmp_path)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=st.one_of(st.text(max_size=60),
                      st.builds(lambda a, b: f"[{a}]\n{b} = 1\n", st.sampled_from(["run", "screen", "x"]),
                                st.text(min_size=1, max_size=5))))
def test_fuzzed_text_loads_or_raises_config_error(text, tmp_path):
    try:
        load_config(text, base_dir=tmp_path)
    except ConfigError:
        pass


@pytest.mark.parametrize(
    "doc",
    [
        {"run": 5},
        {"run": {"out_dir": 5}},
        {"mincam": {"d_f_m": "2mm"}},
        {"mincam": {"layout": "custom"}, "mixel": [{"mask": "ramp:x", "d_f_m": "2mm"}]},
        {"run": {"seed": True}},
        {"screen": {"resolution": [256.5, 144]}},
        {"screen": {"resolution": [16.0, 9]}},
        {"mincam": {"layout": "custom"}, "mixel": {"mask": "ramp:x"}},
        {"mincam": {"layout": "custom"}, "mixel": [1, "x"]},
        {"mincam": {"layout": "custom"}, "mixel": [{"mask": {"kind": "sinusoid", "omega_rad_per_m": "x"}}]},
        {"mincam": {"layout": "custom"}, "mixel": [{"mask": {"kind": "sinusoid", "omega_rad_per_m": 1.0,
                                                             1: 2}}]},
        {"frames": {"n": 10**9}},
        {"frames": {"kind": "grid_sweep", "nx": 10**5, "ny": 10**5}},
        {"mincam": {"mask_resolution": 10**9}},
        {"run": {"replicates": True}},
        {"run": {"target_rel_stderr": float("nan")}},
        {"frames": {"start_m": [float("inf"), 0]}},
        {"frames": {"path": 5, "kind": "npy"}},
        {"run": {"out_dir": "a\x00b"}},
        {1: {}},
        {"run": {2: 3}},
        {"mincam": {"layout": "custom"}, "mixel": [{"name": ["a"], "mask": "ramp:x"}]},
    ],
)
def test_known_bad_documents(doc, tmp_path):
    with pytest.raises(ConfigError):
        load_config(doc, base_dir=tmp_path)
