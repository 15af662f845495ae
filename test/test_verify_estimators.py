"""The verifier's heads keep scikit-learn's conventions: check_estimator for the forest head and
the characteriser (class names as y), the parameter checks for the shape head, whose input is a
collection of variable-length windows rather than a table."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.utils.estimator_checks import (
    check_estimator,
    check_get_params_invariance,
    check_no_attributes_set_in_init,
    check_parameters_default_constructible,
    check_set_params,
)

from rcbht_introspection.learn.forest import ForestHead
from rcbht_introspection.verify.characterise import LABEL_COLUMNS, Characteriser
from rcbht_introspection.verify.shape import ShapeHead

ENVIRONMENT_SKIPS = {"check_array_api_input", "check_classifier_data_not_an_array"}
"""Checks that skip for what is not installed (array API, pandas), never for the estimator."""


@pytest.mark.parametrize(
    "estimator",
    [ForestHead(n_estimators=10), Characteriser(n_estimators=10)],
    ids=lambda e: type(e).__name__,
)
def test_the_heads_pass_scikit_learn_s_estimator_checks(estimator: Any) -> None:
    results = check_estimator(estimator, on_fail=None)
    failed = [
        (r["check_name"], str(r["exception"])[:200]) for r in results if r["status"] == "failed"
    ]
    assert not failed
    assert {r["check_name"] for r in results if r["status"] == "skipped"} <= ENVIRONMENT_SKIPS


@pytest.mark.parametrize(
    "check",
    [
        check_parameters_default_constructible,
        check_no_attributes_set_in_init,
        check_get_params_invariance,
        check_set_params,
    ],
)
def test_the_shape_head_keeps_the_parameter_conventions(check: Any) -> None:
    check("ShapeHead", ShapeHead())


def test_the_characteriser_learns_directions_from_label_rows() -> None:
    """y as rows of LABEL_COLUMNS: the direction heads learn the signs; predict and
    predict_proba name the class as characterise does, row by row."""
    rng = np.random.default_rng(1)
    X = rng.normal(size=(60, 3))
    cls = np.where(X[:, 0] > 0, "slip_x", "slip_y")
    y = np.array(
        [[c, "+" if c == "slip_x" else "0", "+" if c == "slip_y" else "0", "0"] for c in cls]
    )
    assert y.shape[1] == len(LABEL_COLUMNS)
    ch = Characteriser(n_estimators=20).fit(X, y)
    proba = ch.predict_proba(X)
    assert proba.shape == (60, 2) and np.allclose(proba.sum(axis=1), 1.0)
    assert list(ch.predict(X)) == [ch.characterise(x)[0] for x in X]
    assert np.mean(ch.predict(X) == cls) > 0.9
    assert ch.characterise(np.array([3.0, 0.0, 0.0]))[2] == {"x": "+", "y": "0", "r": "0"}
    assert clone(ch).get_params() == ch.get_params()
    with pytest.raises(ValueError):
        ch.predict(X[:, :2])
