"""Study files and case expansion: counts, reproducible samples, keys, and errors that name the problem."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twin.config import small_config
from twin.studies.cases import case_key, expand, grid_points, mc_samples
from twin.studies.distributions import Integers, Normal
from twin.studies.spec import MonteCarlo, StudyError, load_study, parse_study

UNIFORM = {"dist": "uniform", "low": -0.3, "high": 0.3}
NORMAL = {"dist": "normal", "mean": 0.0, "std": 0.03, "low": -0.1, "high": 0.1}


@pytest.fixture(scope="module")
def cfg():
    return small_config()


def _study(**kw):
    doc: dict = {"base": {"oscillation": {"enabled": True}},
           "grid": {"oscillation.period": [6.0, 12.0, 18.0], "oscillation.amplitude": [0.016, 0.032]},
           "monte_carlo": {"n": 4, "seed": 1, "mismatch.alpha": UNIFORM, "mismatch.emissivity": NORMAL}}
    doc.update(kw)
    return parse_study(doc)


def test_grid_times_monte_carlo_counts_and_order(cfg):
    cases = expand(_study(), cfg)
    assert len(cases) == 3 * 2 * 4
    assert [c.index for c in cases] == list(range(24))
    # grid in file order, the last path fastest; each grid point runs every sample
    first = [(c.params["oscillation.period"], c.params["oscillation.amplitude"], c.sample) for c in cases[:5]]
    assert first == [(6.0, 0.016, 0), (6.0, 0.016, 1), (6.0, 0.016, 2), (6.0, 0.016, 3), (6.0, 0.032, 0)]
    assert {c.grid_point for c in cases} == set(range(6)) and {c.sample for c in cases} == set(range(4))
    c = cases[5]
    assert c.scenario.oscillation.period == 6.0 and c.scenario.oscillation.amplitude == 0.032
    assert c.scenario.mismatch.alpha == c.params["mismatch.alpha"]
    assert c.scenario.seed == c.params["seed"]  # seeds = "per_sample" by default
    assert set(c.params) == {"oscillation.period", "oscillation.amplitude", "mismatch.alpha",
                             "mismatch.emissivity", "seed"}
    assert len({c.key for c in cases}) == 24


def test_only_grid_or_only_monte_carlo(cfg):
    grid_only = expand(_study(monte_carlo=None), cfg)
    assert len(grid_only) == 6 and all(c.sample is None and c.scenario.seed == 0 for c in grid_only)
    mc_only = expand(_study(grid={}), cfg)
    assert len(mc_only) == 4 and all(c.grid_point is None for c in mc_only)


def test_samples_are_reproducible_for_a_seed_and_common_across_grid_points(cfg):
    a, b = expand(_study(), cfg), expand(_study(), cfg)
    assert [c.params for c in a] == [c.params for c in b]
    assert [c.key for c in a] == [c.key for c in b]
    other = expand(_study(monte_carlo={"n": 4, "seed": 2, "mismatch.alpha": UNIFORM,
                                       "mismatch.emissivity": NORMAL}), cfg)
    assert [c.params["mismatch.alpha"] for c in other] != [c.params["mismatch.alpha"] for c in a]
    # common random numbers: sample i is the same at every grid point
    alphas = {(c.grid_point, c.sample): c.params["mismatch.alpha"] for c in a}
    assert all(alphas[(g, s)] == alphas[(0, s)] for g in range(6) for s in range(4))
    assert len({alphas[(0, s)] for s in range(4)}) == 4


def test_a_fields_samples_do_not_move_when_another_field_is_added():
    one = mc_samples(MonteCarlo.model_validate({"n": 5, "seed": 7, "mismatch.alpha": UNIFORM}))
    two = mc_samples(MonteCarlo.model_validate({"n": 5, "seed": 7, "tc_noise": UNIFORM | {"low": 0.5, "high": 2},
                                                "mismatch.alpha": UNIFORM}))
    assert [s["mismatch.alpha"] for s in one] == [s["mismatch.alpha"] for s in two]


def test_keys_follow_the_scenario_not_the_order_in_the_file(cfg):
    a = expand(parse_study({"grid": {"tc_noise": [0.5, 1.0], "seed": [1, 2]}}), cfg)
    b = expand(parse_study({"grid": {"seed": [2, 1], "tc_noise": [1.0, 0.5]}}), cfg)
    assert {c.key for c in a} == {c.key for c in b}
    other_furnace = cfg.with_overrides({"specimen.initial_temperature": 310.0})
    assert case_key(other_furnace.digest(), a[0].scenario) != a[0].key


def test_grid_points_full_factorial():
    pts = grid_points({"a": [1, 2], "b": ["x", "y", "z"]})
    assert len(pts) == 6 and pts[0] == {"a": 1, "b": "x"} and pts[-1] == {"a": 2, "b": "z"}
    assert grid_points({}) == [{}]


def test_truncated_normal_is_resampled_not_clipped():
    x = np.array(Normal(mean=0.0, std=1.0, low=-0.5, high=1.0).sample(np.random.default_rng(3), 4000))
    assert x.min() >= -0.5 and x.max() <= 1.0
    # clipping would pile about 31 % (P(z < -0.5)) onto -0.5; a truncated normal has no atom there
    assert np.mean(x == -0.5) == 0.0 and np.mean(x < -0.45) < 0.05


def test_integers_include_both_ends():
    x = Integers(low=3, high=5).sample(np.random.default_rng(0), 300)
    assert set(x) == {3, 4, 5}


@pytest.mark.parametrize(
    ("doc", "needle"),
    [
        ({"grid": {"oscillation.perod": [1.0]}}, "perod"),
        ({"grid": {"tc_noise": [-1.0]}}, "tc_noise"),
        ({"base": {"duration": 20.0}, "grid": {"duration.x": [1.0]}}, "duration is a value"),
        ({"grid": {"duration.x": [1.0]}}, "duration: Input should be a valid number"),
        ({"grid": {"tc_noise": []}}, "has no values"),
        ({"base": {"duration": -1}, "grid": {"tc_noise": [1.0]}}, "base"),
        ({"grid": {"tc_noise": [1.0]}, "monte_carlo": {"n": 2, "tc_noise": UNIFORM}}, "both"),
        ({"grid": {"seed": [1, 2]}, "monte_carlo": {"n": 2}}, 'seeds = "base"'),
        ({"monte_carlo": {"n": 2, "mismatch.alpha": {"dist": "uniform", "low": 1, "high": 0}}}, "high > low"),
        ({"monte_carlo": {"n": 2, "mismatch.alpha": {"dist": "gamma"}}}, "mismatch.alpha"),
        ({"monte_carlo": {"n": 0}}, "n"),
        ({"base": {}}, "needs a [grid]"),
        ({"grid": {"tc_noise": [1.0] * 1000, "seed": list(range(101))}}, "at most 100000"),
        ({"grid": {"tc_noise": [1.0]}, "colour": "red"}, "colour"),
    ],
)
def test_bad_studies_name_the_problem(doc, needle, cfg):
    with pytest.raises(StudyError) as exc:
        expand(parse_study(doc), cfg)  # the structure is checked on parsing, the paths with the furnace
    assert needle in str(exc.value)


def test_the_furnace_limits_and_defaults_apply(cfg):
    spec = parse_study({"base": {"oscillation": {"enabled": True}}, "grid": {"oscillation.amplitude": [0.02, 0.04]}})
    narrow = cfg.with_overrides({"oscillation.eta_max": 0.03})
    assert len(expand(spec, cfg)) == 2
    with pytest.raises(StudyError, match=r"'oscillation.amplitude' = 0.04: .*eta_max of furnace"):
        expand(spec, narrow)
    # a field the study leaves out takes the furnace's default: the amplitude 3 L_h capped at eta_max
    periods = expand(parse_study({"base": {"oscillation": {"enabled": True}}, "grid": {"oscillation.period": [9.0]}}),
                     narrow)
    assert periods[0].scenario.oscillation.amplitude == 0.03


def test_monte_carlo_values_out_of_a_fields_range_are_refused(cfg):
    spec = parse_study({"monte_carlo": {"n": 50, "seed": 0, "mismatch.emissivity": {"dist": "normal", "std": 0.3}}})
    with pytest.raises(StudyError, match=r"mismatch\.emissivity"):  # the schema allows -0.5 .. 0.1
        expand(spec, cfg)


def test_a_truncation_far_in_the_tail_is_a_study_error(cfg):
    spec = parse_study({"monte_carlo": {"n": 5, "mismatch.alpha": {"dist": "normal", "std": 0.01, "low": 0.5,
                                                                   "high": 0.6}}})
    with pytest.raises(StudyError, match="far in the tail"):
        expand(spec, cfg)


def test_study_file_toml(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text('furnace = "banded"\n[base]\nduration = 60.0\n[grid]\n"oscillation.period" = [6.0, 12.0]\n'
                 '[monte_carlo]\nn = 3\nseed = 4\n"mismatch.alpha" = {dist = "uniform", low = -0.3, high = 0.3}\n')
    spec = load_study(f)
    assert spec.furnace == "banded" and spec.n_cases == 6 and spec.monte_carlo.seed == 4
    assert parse_study(spec.document()) == spec  # the document round-trips (it is the REST body too)
    f.write_text("[grid\n")
    with pytest.raises(StudyError, match="not valid TOML"):
        load_study(f)
    with pytest.raises(StudyError, match="cannot read"):
        load_study(tmp_path / "missing.toml")


@pytest.mark.parametrize("path", sorted((Path(__file__).parents[2] / "studies").glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_study_expands_against_its_furnace(path):
    """The study files in studies/ (docs/studies.md's examples and the speed study) load and expand: every field
    path exists and every value is within the limits of the furnace the file names."""
    from twin.config import load_config

    spec = load_study(path)
    cases = expand(spec, load_config(spec.furnace))
    n_grid = int(np.prod([len(v) for v in spec.grid.values()])) if spec.grid else 1
    assert len(cases) == n_grid * (spec.monte_carlo.n if spec.monte_carlo else 1)


def test_monte_carlo_fields_that_are_not_a_table_are_a_study_error_not_a_crash():
    """schemathesis found ``"fields": [null, null]`` answered 500 (a TypeError in the block's field
    collection); any non-table ``fields`` is now a StudyError naming it (a 422 from the API)."""
    from twin.studies.spec import StudyError, parse_study

    for fields in ([None, None], "x", 3):
        with pytest.raises(StudyError, match="monte_carlo: fields: a table"):
            parse_study({"monte_carlo": {"n": 1, "fields": fields}})
