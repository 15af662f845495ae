"""`rcbht calibrate`: a taxonomy profile for a new sensor and rate, measured on its own trials.

Writes the profile (config/rcbht.yaml's form) and prints, per axis, primitives per window and
the 'cons' share under the reference profile and under the calibrated one, with words per second
and the label agreement of the two (taxonomy/calibration.py, docs/taxonomy.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rcbht_introspection.commands.sensor import add_repeated_stamps, repeated_policy, warn
from rcbht_introspection.errors import InputError
from rcbht_introspection.fleet import (
    BadInputs,
    add_parallel_options,
    add_strict_inputs,
    backend,
    jobs_from_args,
)

if TYPE_CHECKING:
    from rcbht_introspection.io.sensor_checks import RepeatedPolicy
    from rcbht_introspection.io.trial import Trial
    from rcbht_introspection.taxonomy.calibration import Calibration, Comparison


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the calibrate subcommand."""
    p = subparsers.add_parser(
        "calibrate",
        help="measure a taxonomy profile (window, noise floor, gradient spectra) on trials",
        description="Fit the taxonomy's segmentation and gradient thresholds to a sensor and "
        "rate from its trials (trial folders, dataset folders or bags) and write the profile; "
        "prints the before/after table (docs/taxonomy.md, 'Calibrating for a new sensor').",
    )
    p.add_argument("inputs", nargs="+", type=Path, metavar="BAG_OR_TRIAL_DIR")
    p.add_argument("--out", type=Path, required=True, metavar="FILE.yaml")
    p.add_argument("--name", default=None, help="profile name (default: the --out file's stem)")
    p.add_argument("--report", type=Path, default=None, metavar="FILE.json")
    add_repeated_stamps(p)
    add_strict_inputs(p, "trial")
    add_parallel_options(p, "trials' reading")
    p.set_defaults(func=run_calibrate)


def run_calibrate(args: argparse.Namespace) -> int:
    from rcbht_introspection.learn.data import find_inputs
    from rcbht_introspection.taxonomy.calibration import calibrate_profile, compare_profiles
    from rcbht_introspection.taxonomy.config import default_config, write_taxonomy_config

    name = args.name or args.out.stem
    if not name:
        raise InputError("empty profile name", field="--name")
    jobs = jobs_from_args(args)
    found = find_inputs(args.inputs)
    bad = BadInputs("calibrate")
    with backend(args.scheduler):
        read = functools.partial(_read_checked, repeated_policy(args))
        checked = bad.collect(read, found, jobs)
    paths = [path for path, _, _ in checked]
    trials = [trial for _, trial, _ in checked]
    for path, _, findings in checked:
        # a frozen stretch drags the measured noise floor towards 0: the user must know
        warn("calibrate", path.name, findings)
    if not any(len(t.time) > 1 for t in trials):
        raise InputError("no input has two samples or more", ", ".join(map(str, args.inputs)))
    calibration = calibrate_profile(trials, name)
    config = calibration.config
    header = (
        f"Taxonomy profile {name!r}, written by `rcbht calibrate` from {len(paths)} input(s) "
        f"at {calibration.rate_hz:.4g} Hz (docs/taxonomy.md, 'Calibrating for a new sensor').\n"
        f"rcbht label/train/evaluate: --taxonomy-config {args.out.name}; a model trained with "
        "it carries it (replay-eval, live-eval, segmenter_node's taxonomy_model_file)"
    )
    write_taxonomy_config(config, args.out, header=header)
    comparison = compare_profiles(trials, default_config(), config)
    print(table(calibration, comparison))
    for note in calibration.notes:
        print(f"note: {note}")
    print(f"wrote profile {name!r} to {args.out}")
    if args.report is not None:
        report = report_dict(calibration, comparison, [str(p) for p in paths], args.out)
        report["bad_inputs"] = bad.to_dict()
        args.report.parent.mkdir(parents=True, exist_ok=True)
        args.report.write_text(json.dumps(report, indent=2))
        print(f"wrote {args.report}")
    return bad.finish(args.strict)


def _read_checked(policy: RepeatedPolicy | None, path: Path) -> tuple[Path, Trial, tuple[str, ...]]:
    """One input read (on any worker), with its frozen-sensor findings."""
    from rcbht_introspection.io.sensor_checks import trial_findings
    from rcbht_introspection.learn.data import read_any_trial
    from rcbht_introspection.live.intake import load_intake_config

    trial = read_any_trial(path, policy)
    checks = load_intake_config()
    return path, trial, tuple(trial_findings(trial, checks.frozen_samples, checks.frozen_s))


def table(calibration: Calibration, comparison: Comparison) -> str:
    """The before/after table the command prints."""
    from rcbht_introspection.taxonomy.calibration import MAX_CUT_FRACTION
    from rcbht_introspection.taxonomy.words import AXES, LEVELS

    before, after = comparison.before, comparison.after
    floors = calibration.config.fit_noise_floor or {}
    lines = [
        f"{calibration.rate_hz:.4g} Hz; window {before.window} -> {after.window} samples; "
        f"target: at most {MAX_CUT_FRACTION} primitives per window",
        f"before: profile {before.profile!r}, after: profile {after.profile!r}",
        f"{'':6} {'primitives per window':>21}   {'cons share':>17}   {'noise floor':>11}",
        f"{'axis':6} {'before':>10} {'after':>10}   {'before':>8} {'after':>8}   {'factor':>11}",
    ]
    for axis in AXES:
        lines.append(
            f"{axis:6} {before.primitives_per_window[axis]:10.3f} "
            f"{after.primitives_per_window[axis]:10.3f}   {before.const_share[axis]:8.3f} "
            f"{after.const_share[axis]:8.3f}   {calibration.floor_factor[axis]:11.3g}"
            + ("" if axis in floors else " (none)")
        )
    rates = "; ".join(
        f"{key} {before.words_per_second[key]:.1f} -> {after.words_per_second[key]:.1f}"
        for key in ("all", *(level.value for level in LEVELS))
    )
    lines.append(f"words per second: {rates}")
    agreement = ", ".join(f"{k} {v:.3f}" for k, v in comparison.agreement.items())
    lines.append(f"label agreement with {before.profile} (share of samples): {agreement}")
    return "\n".join(lines)


def report_dict(
    calibration: Calibration, comparison: Comparison, inputs: list[str], out: Path
) -> dict[str, Any]:
    """The JSON report: what was measured, the profile's new values and the table."""
    from rcbht_introspection.taxonomy.calibration import MAX_CUT_FRACTION

    config = calibration.config
    return {
        "profile": config.profile,
        "out": str(out),
        "inputs": inputs,
        "rate_hz": calibration.rate_hz,
        "window": config.window,
        "target_primitives_per_window": MAX_CUT_FRACTION,
        "noise_variance": calibration.noise_variance,
        "floor_factor": calibration.floor_factor,
        "fit_noise_floor": config.fit_noise_floor,
        "limits": {
            k: {"largest": v[0], "near_constant": v[1]} for k, v in calibration.limits.items()
        },
        "calibrated_thresholds": {
            k: list(v) for k, v in (config.calibrated_thresholds or {}).items()
        },
        "domains": calibration.domains,
        "notes": calibration.notes,
        "before": dataclasses.asdict(comparison.before),
        "after": dataclasses.asdict(comparison.after),
        "agreement": comparison.agreement,
    }
