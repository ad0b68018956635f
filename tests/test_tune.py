"""The tuning procedure (companion.apps.tune): seeded random search through the runner."""

import math

import pytest

from companion.apps import tune
from companion.params import Params


def test_tuning_is_seeded_and_keeps_the_best_candidate():
    first = tune.tune("vsm", Params(), budget=4, seed=1, workers=2)
    again = tune.tune("vsm", Params(), budget=4, seed=1, workers=1)
    assert first == again                                   # same seed, any worker count
    assert first.best_score <= first.start_score
    assert first.start_score == pytest.approx(
        tune.score("vsm", Params(), tune.tuning_scenarios()), rel=1e-12)
    tuned = tune.apply(Params(), first.dims, first.best)
    assert tune.current(tuned, first.dims) == pytest.approx(list(first.best))
    assert tune.score("vsm", tuned, tune.tuning_scenarios()) == pytest.approx(first.best_score)


def test_a_case_that_comes_too_close_is_penalised():
    good = {"rmse_rho_m": 0.01, "rmse_alpha_rad": 0.01, "finite": True,
            "min_person_distance_m": 0.9}
    assert tune.case_score(good) == pytest.approx(0.4)
    assert tune.case_score({**good, "min_person_distance_m": 0.4}) == pytest.approx(100.4)
    assert tune.case_score({**good, "rmse_rho_m": math.nan}) == 100.0
