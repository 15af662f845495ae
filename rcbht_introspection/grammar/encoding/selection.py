"""Feature selection of the compact encoding: ANOVA F rankings taken per pair of classes."""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
from sklearn.feature_selection import f_classif


def pairwise_selection(matrix: np.ndarray, labels: Sequence[str], k: int) -> np.ndarray:
    """Indices of k columns taken in turn from each pair of classes' ANOVA F ranking.

    A single multi-class F ranking is dominated by the easiest contrast (e.g. the 5 ms rotation
    samples against everything); ranking per class pair keeps features for every contrast.
    """
    labels_arr = np.asarray(labels)
    classes = sorted(set(labels))
    rankings = []
    for i, a in enumerate(classes):
        for b in classes[i + 1 :]:
            rows = (labels_arr == a) | (labels_arr == b)
            with np.errstate(divide="ignore", invalid="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                scores, _ = f_classif(matrix[rows], labels_arr[rows])
            scores = np.nan_to_num(scores, nan=0.0, posinf=np.finfo(float).max)
            rankings.append(np.argsort(-scores, kind="stable"))
    chosen: list[int] = []
    seen: set[int] = set()
    depth = 0
    while len(chosen) < min(k, matrix.shape[1]):
        for ranking in rankings:
            column = int(ranking[depth])
            if column not in seen and len(chosen) < k:
                seen.add(column)
                chosen.append(column)
        depth += 1
    return np.asarray(sorted(chosen), dtype=int)
