"""`rcbht closed-loop`'s experiment: draw failing and nominal worlds, run every policy on the
same worlds, and score them as Rodriguez et al. score abort-and-retry (success within k
attempts, expected time per success), with the unnecessary aborts on nominal trials."""

from __future__ import annotations

import functools
import math
import statistics
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from rcbht_introspection.closed_loop.run import TaskWorld, TrialRecord, run_trial
from rcbht_introspection.fleet import parallel_map
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.plan.planner import PolicyName
from rcbht_introspection.plan.recovery import RecoveryConfig
from rcbht_introspection.sim.episode import draw_world
from rcbht_introspection.sim.peg_config import PegConfig
from rcbht_introspection.sim.peg_episode import draw_peg_world
from rcbht_introspection.sim.tasks import TaskConfig, sim_task_of, trial_simulator
from rcbht_introspection.verify.config import VerifyConfig
from rcbht_introspection.verify.labels import label_of
from rcbht_introspection.verify.model_file import VerifierModel
from rcbht_introspection.verify.train import train_verifier

SEED_BLOCK = 100_000
"""Trial seeds of one experiment: failing seed * SEED_BLOCK + i, nominal + NOMINAL_OFFSET."""
NOMINAL_OFFSET = 50_000
TRAIN_OFFSET = 90_000
"""The default verifier's trials: the next seed's block from here (other seeds than any test)."""
MIN_PER_CLASS = 12
"""The default verifier's failures per class, at least."""
MIN_SUCCESSES = 40
"""The default verifier's nominal trials, at least."""
MAX_DRAWS_PER_FAILING = 3
"""Worlds drawn at most per failing trial asked for: a class whose draws all seat is counted."""
Progress = Callable[[int], object]


@dataclass(frozen=True)
class Worlds:
    """The worlds every policy runs: failing ones, nominal ones, and the draws that did not
    fail per requested class (the arm seated them uncorrected)."""

    failing: list[TaskWorld]
    nominal: list[TaskWorld]
    not_failing: dict[str, int]


def _draw(config: TaskConfig, item: tuple[int, str | None]) -> TaskWorld:
    if isinstance(config, PegConfig):
        return draw_peg_world(config, item[0], item[1])
    return draw_world(config, item[0], item[1])


def draw_worlds(
    config: TaskConfig,
    classes: Sequence[str],
    n_failing: int,
    n_nominal: int,
    seed: int,
    jobs: int = 1,
) -> Worlds:
    """`n_failing` worlds cycling through `classes` (a draw that seats uncorrected is skipped
    and counted) and `n_nominal` worlds that seat."""
    draw = functools.partial(_draw, config)
    base = seed * SEED_BLOCK
    failing: list[TaskWorld] = []
    not_failing: dict[str, int] = {}
    i = 0
    while len(failing) < n_failing and i < MAX_DRAWS_PER_FAILING * n_failing:
        ask = n_failing - len(failing)
        batch = [(base + k, classes[k % len(classes)]) for k in range(i, i + ask)]
        i += len(batch)
        for world in parallel_map(draw, batch, jobs):
            if world.failing:
                failing.append(world)
            else:
                key = world.failure or ""
                not_failing[key] = not_failing.get(key, 0) + 1
    nominal_items = [(base + NOMINAL_OFFSET + j, None) for j in range(n_nominal)]
    nominal = [w for w in parallel_map(draw, nominal_items, jobs) if not w.failing]
    return Worlds(failing[:n_failing], nominal, not_failing)


def _run(
    config: TaskConfig,
    recovery: RecoveryConfig,
    verifier: VerifierModel | None,
    item: tuple[TaskWorld, PolicyName],
) -> TrialRecord:
    return run_trial(config, item[0], item[1], recovery, verifier)


def run_policies(
    config: TaskConfig,
    worlds: Worlds,
    policies: Sequence[PolicyName],
    recovery: RecoveryConfig,
    verifier: VerifierModel | None,
    jobs: int = 1,
    progress: Progress | None = None,
) -> dict[str, list[TrialRecord]]:
    """Every policy on every world (failing first, then nominal), in parallel over pairs."""
    items = [(w, p) for p in policies for w in (*worlds.failing, *worlds.nominal)]
    run = functools.partial(_run, config, recovery, verifier)
    out: dict[str, list[TrialRecord]] = {p: [] for p in policies}
    for record in parallel_map(run, items, jobs, progress):
        out[record.policy].append(record)
    return out


def _train_trial(config: TaskConfig, item: tuple[int, str | None]) -> Trial:
    seed, failure = item
    simulate = trial_simulator(sim_task_of(config), config, "one-arm", config.sensor.rate_hz)
    return simulate(seed, failure, f"TRAIN-{seed}-{failure or 'S'}")


def calibration_successes(false_alarm_rate: float) -> int:
    """Nominal trials a verifier needs for its conformal threshold to reach `false_alarm_rate`
    (with n successes the rate cannot go below 1 / (n + 1)), at least MIN_SUCCESSES."""
    return max(MIN_SUCCESSES, math.ceil(1.0 / false_alarm_rate))


def train_default_verifier(
    config: TaskConfig,
    classes: Sequence[str],
    verify_config: VerifyConfig,
    seed: int,
    per_class: int | None = None,
    successes: int | None = None,
    jobs: int = 1,
) -> VerifierModel:
    """A verifier trained on simulated trials of the same config on other seeds than any
    experiment of `seed` runs: `successes` nominal ones (None: what its false-alarm rate needs)
    and `per_class` of each class (None: MIN_PER_CLASS, and at least as many failures in all as
    successes, so a task of few classes learns its directions from as many trials as its
    detector learns the nominal from)."""
    if successes is None:
        successes = calibration_successes(verify_config.false_alarm_rate)
    if per_class is None:
        per_class = max(MIN_PER_CLASS, math.ceil(successes / max(1, len(classes))))
    base = (seed + 1) * SEED_BLOCK + TRAIN_OFFSET
    items: list[tuple[int, str | None]] = [(base + i, None) for i in range(successes)]
    items += [
        (base + successes + k, cls)
        for k, cls in enumerate(c for c in classes for _ in range(per_class))
    ]
    trials = parallel_map(functools.partial(_train_trial, config), items, jobs)
    labels = {t.name: label_of(t) for t in trials}
    return train_verifier(trials, labels, verify_config, seed=seed)


def policy_summary(records: Sequence[TrialRecord], max_attempts: int) -> dict[str, object]:
    """One policy's figures: success within k attempts and time per success over the failing
    trials, unnecessary aborts and mean time over the nominal ones, per class, per trial."""
    failing = [r for r in records if r.failure]
    nominal = [r for r in records if not r.failure]
    successes = sum(r.success for r in failing)
    classes = sorted({r.failure for r in failing})
    return {
        "success_within_attempts": {
            str(k): _share(sum(r.success and len(r.attempts) <= k for r in failing), len(failing))
            for k in range(1, max_attempts + 1)
        },
        "time_per_success_s": (
            round(sum(r.time_s for r in failing) / successes, 4) if successes else None
        ),
        "unnecessary_aborts_per_nominal_trial": _share(
            sum(r.aborts for r in nominal), len(nominal)
        ),
        "nominal_success": _share(sum(r.success for r in nominal), len(nominal)),
        "nominal_mean_time_s": (
            round(statistics.fmean(r.time_s for r in nominal), 4) if nominal else None
        ),
        "by_class": {
            c: {
                "trials": sum(r.failure == c for r in failing),
                "success": _share(
                    sum(r.success for r in failing if r.failure == c),
                    sum(r.failure == c for r in failing),
                ),
            }
            for c in classes
        },
        "trials": [r.to_dict() for r in records],
    }


def _share(count: int, total: int) -> float | None:
    return round(count / total, 4) if total else None


ABORT_TIME_TOLERANCE_S = 0.5
"""Over DDS an abort lands later than in-process (the verdict's and the cancel's transport):
decision timelines agree when each abort is this close to the offline one."""


def stop_success(timelines: Sequence[Sequence[Mapping[str, Any]]]) -> float | None:
    """Share of trials whose last decision stops them as seated (the arm's own check)."""
    ends = [t[-1]["reason"] == "seated" for t in timelines if t]
    return round(sum(ends) / len(ends), 4) if ends else None


def compare_decisions(a: Sequence[Mapping[str, Any]], b: Sequence[Mapping[str, Any]]) -> bool:
    """Two decision timelines agree: the same kinds, attempts, classes and corrections in the
    same order, abort times within ABORT_TIME_TOLERANCE_S."""
    if len(a) != len(b):
        return False
    for x, y in zip(a, b, strict=True):
        same = (x["kind"], x["attempt"], x["failure_class"]) == (
            y["kind"], y["attempt"], y["failure_class"]
        )  # fmt: skip
        close = all(abs(x["correction"][k] - y["correction"][k]) < 1e-6 for k in x["correction"])
        timely = x["kind"] != "abort" or abs(x["time"] - y["time"]) <= ABORT_TIME_TOLERANCE_S
        if not (same and close and timely):
            return False
    return True
