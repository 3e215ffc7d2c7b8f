"""tools/std_scales.py: the constant factors on a published std that would meet the honesty targets."""
import json
import sys

import numpy as np
import pytest

from canest.apps.evaluate import pool
from tests.conftest import ROOT

sys.path.insert(0, str(ROOT / "tools"))
import honesty  # noqa: E402
import std_scales  # noqa: E402

TARGETS = (honesty.WITHIN_TWO_STD_TARGET, honesty.NEES_TARGET, honesty.VALID_BUT_WRONG_TARGET)
TICKS = 200_000


def feasible(error, std, wrong_above) -> list:
    return std_scales.ranges(std_scales.meets_targets(std_scales.scale_sums(error, std, wrong_above), *TARGETS))


def test_a_gaussian_error_meets_the_targets_at_its_own_std_and_within_the_band_s_factors():
    """Where the valid-but-wrong threshold binds, a Gaussian error's targets hold for k std with 2 k from the 90 %
    quantile (1.645) to the 98 % one (2.326): k 0.82-1.16."""
    error = np.abs(np.random.default_rng(1).normal(size=TICKS))
    ((first, last),) = feasible(error, np.ones(TICKS), wrong_above=10.0)
    assert first == pytest.approx(0.82, abs=0.015) and last == pytest.approx(1.16, abs=0.015)


def test_a_std_twice_too_wide_is_mended_by_a_half():
    error = np.abs(np.random.default_rng(2).normal(size=TICKS))
    ((first, last),) = feasible(error, np.full(TICKS, 2.0), wrong_above=10.0)
    assert first <= 0.5 <= last and last < 1.0


def test_where_every_error_counts_as_wrong_even_a_gaussian_leaves_a_narrow_band():
    """With no threshold, 0.1 % beyond 3 k std needs 3 k >= 3.29 (the 99.9 % quantile): k 1.10-1.16."""
    error = np.abs(np.random.default_rng(3).normal(size=TICKS))
    ((first, last),) = feasible(error, np.ones(TICKS), wrong_above=0.0)
    assert first == pytest.approx(1.10, abs=0.015) and last == pytest.approx(1.16, abs=0.015)


def test_no_factor_meets_the_targets_on_errors_with_a_laplace_tail():
    """0.1 % beyond 3 k std needs k >= 2.30 Laplace scales, under which 99.0 % are within 2 k std."""
    error = np.abs(np.random.default_rng(4).laplace(size=TICKS))
    assert feasible(error, np.ones(TICKS), wrong_above=0.0) == []


def test_the_sums_pool_over_runs_as_over_their_ticks():
    rng = np.random.default_rng(5)
    error, std = np.abs(rng.normal(size=1000)), rng.uniform(0.5, 2.0, 1000)
    halves = pool([std_scales.scale_sums(error[:400], std[:400], 1.0), std_scales.scale_sums(error[400:], std[400:], 1.0)])
    whole = std_scales.scale_sums(error, std, 1.0)
    assert all(np.allclose(halves[key], whole[key]) for key in whole)


def test_grids_needing_different_factors_have_none_in_common(tmp_path, capsys):
    error = np.abs(np.random.default_rng(6).normal(size=TICKS))
    exact = {"ckf": {"beta": feasible(error, np.full(TICKS, 2.0), 10.0)}}  # too wide: a factor near 0.5
    drawn = {"ckf": {"beta": feasible(error, np.ones(TICKS), 10.0)}}  # right as published
    paths = []
    for label, scales in (("exact", exact), ("drawn", drawn)):
        paths.append(tmp_path / f"{label}.json")
        paths[-1].write_text(json.dumps({"scales": scales}))
    ((name, state, runs, both),) = std_scales.common([exact, drawn])
    assert (name, state, both) == ("ckf", "beta", []) and runs[1][0][0] <= 1.0 <= runs[1][0][1]
    assert std_scales.main([str(p) for p in paths]) == 0
    row = capsys.readouterr().out.splitlines()[-1]
    assert row.startswith("| ckf | beta |") and row.endswith("| none |") and " * |" in row


def test_a_file_that_is_not_a_scales_output_is_named(tmp_path, capsys):
    path = tmp_path / "plain.json"
    path.write_text(json.dumps({"ckf": {}}))
    assert std_scales.main([str(path)]) == 2
    assert str(path) in capsys.readouterr().err


def test_a_state_never_valid_is_not_judged():
    """As in honesty.outside_targets: dckf's frictions, never valid, get no factors, rather than 'none'."""
    rng = np.random.default_rng(7)
    error = np.abs(rng.normal(size=500))
    runs = [{"scales": {"dckf": {"vx": std_scales.scale_sums(error, np.ones(500), 10.0),
                                 "mu_fl": std_scales.scale_sums(np.array([]), np.array([]), 0.1)}}}]
    scales = honesty.pooled_scales(runs, ["dckf"])
    assert list(scales["dckf"]) == ["vx"] and std_scales.includes_published(scales["dckf"]["vx"])
