"""`rcbht verify-train` and `rcbht verify-eval`: failure detection and characterisation."""

from __future__ import annotations

import argparse
import functools
import json
import sys
from pathlib import Path
from typing import Any

from rcbht_introspection.commands.sensor import add_strict, report_dropped
from rcbht_introspection.errors import InputError
from rcbht_introspection.fleet import BadInputs, add_parallel_options, backend, jobs_from_args


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the `verify-train` and `verify-eval` subcommands."""
    tr = subparsers.add_parser(
        "verify-train",
        help="train a verifier (failure detector + characteriser) from labelled trials",
        description="Fit the detector on the successful trials and the failure characteriser on "
        "the failed ones (docs/verification.md); writes a safe verifier file.",
    )
    _common(tr)
    tr.add_argument("--out", type=Path, required=True, help="verifier file to write")
    tr.set_defaults(func=cmd_verify_train)
    ev = subparsers.add_parser(
        "verify-eval",
        help="score failure detection and characterisation (alarm gate, false alarms, classes)",
        description="Grouped k-fold (or leave-one-trial-out, or train-on/test-on) evaluation of "
        "the verifier beside a raw-wrench and a timing-only baseline; an alarm counts only "
        "within 1 s after the labelled onset, any alarm on a nominal run is a false positive.",
    )
    _common(ev)
    ev.add_argument("--json", type=Path, default=None, metavar="OUT", help="write the results")
    ev.add_argument("--folds", type=int, default=5, help="stratified folds over trials (default 5)")
    ev.add_argument("--loo", action="store_true", help="leave one trial out instead of folds")
    ev.add_argument(
        "--train", nargs="+", default=[], metavar="DATA", help="train on these, test on DATA"
    )
    ev.add_argument("--plots", type=Path, default=None, metavar="DIR", help="failure timelines")
    ev.add_argument(
        "--model",
        type=Path,
        default=None,
        metavar="FILE",
        help="sub-task model (rcbht train; trained on other trials): also score the verifier "
        "with the mismatch signal, from this classifier's final verdicts as the node gives them",
    )
    ev.add_argument("--seed", type=int, default=0)
    ev.add_argument(
        "--no-peers",
        action="store_true",
        help="leave out the anchors' methods (hmm, minirocket: the peers extra)",
    )
    add_parallel_options(ev, "trials' features and the folds")
    ev.set_defaults(func=cmd_verify_eval)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("data", nargs="+", help="trial folders, dataset folders or bags")
    p.add_argument("--labels", type=Path, default=None, help="labels CSV (docs/verification.md)")
    p.add_argument("--config", type=Path, default=None, help="verify config (config/verify.yaml)")
    add_strict(p, ", or a labels row for a trial not given")


def _load(paths: list[str], bad: BadInputs, strict: bool = False) -> list[Any]:
    """The trials of `paths`: unique names (a name twice is an error naming both paths), one arm
    set; state times after the data or out of order dropped (`strict`: an error); a trial that
    cannot be read counted in `bad` and left out (`strict`: an error)."""
    from rcbht_introspection.learn.data import find_inputs

    pairs = bad.collect(functools.partial(_read_named, strict), find_inputs(paths), strict=strict)
    trials = [trial for _, trial in pairs]
    first: dict[str, Path] = {}
    for path, trial in pairs:
        if trial.name in first:
            raise InputError(
                f"two trials are named {trial.name!r}: {first[trial.name]} and {path}", path
            )
        first[trial.name] = path
    if len({t.arms for t in trials}) != 1:
        raise InputError(
            f"trials mix arm sets {sorted({t.arms for t in trials})}", ", ".join(paths)
        )
    return trials


def _read_named(strict: bool, path: Path) -> tuple[Path, Any]:
    """(path, the trial read from it): the path names the trial in a duplicate-name error."""
    from rcbht_introspection.learn.data import read_any_trial

    return path, read_any_trial(path, strict=strict)


def _labels(
    labels_file: Path | None, *sets: list[Any], strict: bool = False, command: str = ""
) -> tuple[list[dict[str, Any]], int]:
    """Per set of trials, each trial's label: its row of the labels file, else its metadata's;
    and how many rows named none of the trials (a warning on stderr; `strict`: an error)."""
    from rcbht_introspection.verify.labels import check_labels_cover, label_of, read_labels

    given = read_labels(labels_file) if labels_file is not None else {}
    not_given: list[str] = []
    if labels_file is not None:
        every = [t for trials in sets for t in trials]
        not_given = check_labels_cover(labels_file, given, every, strict)
    if not_given:
        shown = ", ".join(not_given[:3]) + (" ..." if len(not_given) > 3 else "")
        print(
            f"rcbht {command}: warning: {labels_file}: {len(not_given)} of {len(given)} rows "
            f"name trials not given ({shown}); --strict makes this an error",
            file=sys.stderr,
        )
    labels = [{t.name: given.get(t.name) or label_of(t) for t in trials} for trials in sets]
    return labels, len(not_given)


def _input_record(
    command: str, trials: list[Any], train: list[Any], labels_not_given: int
) -> dict[str, Any]:
    """The JSON's `input` record: the state times dropped from the trials (training trials of
    --train as train:<name>; one summary line on stderr) and the labels rows not used."""
    from rcbht_introspection.io.hiro import dropped_state_times
    from rcbht_introspection.verify.evaluate import TRAIN_PREFIX

    counts = {t.name: dropped_state_times(t) for t in trials}
    counts.update({TRAIN_PREFIX + t.name: dropped_state_times(t) for t in train})
    return {
        "dropped_state_times": report_dropped(command, counts),
        "labels_rows_not_given": labels_not_given,
    }


def cmd_verify_train(args: argparse.Namespace) -> int:
    from rcbht_introspection.verify.config import load_verify_config
    from rcbht_introspection.verify.model_file import save_verifier
    from rcbht_introspection.verify.train import train_verifier

    bad = BadInputs("verify-train")
    trials = _load(args.data, bad, args.strict)
    (labels,), not_given = _labels(args.labels, trials, strict=args.strict, command="verify-train")
    read = _input_record("verify-train", trials, [], not_given)
    if sum(not lb.failed for lb in labels.values()) < 2:
        raise InputError("need at least 2 successful trials to calibrate the detector")
    try:
        model = train_verifier(trials, labels, load_verify_config(args.config))
    except ValueError as exc:
        raise InputError(str(exc)) from None
    model.trained_on["input"] = read  # stored in the verifier file's header too
    model.trained_on["bad_inputs"] = bad.to_dict()
    save_verifier(model, args.out)
    print(f"{args.out}: {json.dumps(model.trained_on)}")
    return bad.finish(args.strict)


def cmd_verify_eval(args: argparse.Namespace) -> int:
    from rcbht_introspection.verify.config import load_verify_config
    from rcbht_introspection.verify.evaluate import summarise, verify_runs

    config = load_verify_config(args.config)
    bad = BadInputs("verify-eval")
    trials = _load(args.data, bad, args.strict)
    train = _load(args.train, bad, args.strict) if args.train else []
    (labels, train_labels), not_given = _labels(
        args.labels, trials, train, strict=args.strict, command="verify-eval"
    )
    read = _input_record("verify-eval", trials, train, not_given)
    folds = None if args.loo else args.folds
    if not train and folds is not None and not 2 <= folds <= len(trials):
        raise InputError(f"--folds must be 2..{len(trials)} (the trials), got {folds}")
    if train and train[0].arms != trials[0].arms:
        raise InputError(f"--train trials have arms {train[0].arms}, the others {trials[0].arms}")
    n_nominal = sum(not (train_labels or labels)[t.name].failed for t in (train or trials))
    if n_nominal < 3:
        raise InputError("need at least 3 successful trials to train and calibrate on")
    contradictions = _contradictions(args.model, trials, config) if args.model else None
    jobs = jobs_from_args(args)
    try:
        with backend(args.scheduler):
            runs = verify_runs(
                trials,
                labels,
                config,
                folds,
                args.seed,
                train,
                progress=lambda s: print(s, file=sys.stderr),
                train_labels=train_labels,
                contradictions=contradictions,
                peers=not args.no_peers,
                jobs=jobs,
            )
    except ValueError as exc:  # e.g. successes without sub-task events to calibrate on
        raise InputError(str(exc)) from None
    protocol = "transfer" if train else ("leave-one-trial-out" if folds is None else str(folds))
    summary, records = summarise(runs, config, protocol)
    summary["input"] = read
    summary["bad_inputs"] = bad.to_dict()
    _print(summary)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({**summary, "records": records}, indent=2))
    if args.plots:
        _plots(args.plots, trials, labels, runs["verifier"])
    return bad.finish(args.strict)


def _contradictions(model_file: Path, trials: list[Any], config: Any) -> dict[str, Any]:
    """Per trial, the contradicting final verdicts `model_file`'s classifier gives live."""
    from rcbht_introspection.commands.progress import progress_bar
    from rcbht_introspection.learn.live import load_live_config, stream_factory
    from rcbht_introspection.learn.model_file import load_model, model_taxonomy
    from rcbht_introspection.verify.mismatch import trial_contradictions

    model = load_model(model_file)
    factory = stream_factory(load_live_config(), model_taxonomy(model, path=model_file))
    p = config.mismatch_min_probability
    out = {}
    bar = progress_bar(len(trials), "classifier verdicts", "trial")
    try:
        for t in trials:
            out[t.name] = trial_contradictions(t, model, factory, p)
            bar.update(1)
    finally:
        bar.close()
    return out


def _fmt(v: Any) -> str:
    return "-" if v is None else f"{v:.3f}" if isinstance(v, float) else str(v)


def _print(summary: dict[str, Any]) -> None:
    rows = [("verifier", summary), *summary["baselines"].items()]
    if "verifier_mismatch" in summary:
        rows.insert(1, ("+mismatch", summary["verifier_mismatch"]))
    keys = (
        "roc_auc",
        "detection_accuracy",
        "precision",
        "recall",
        "false_alarms_per_nominal_run",
        "class_accuracy",
        "class_accuracy_given_onset",
    )
    print("method        " + "  ".join(f"{k[:18]:>18}" for k in (*keys, "delay p50 (s)")))
    for name, m in rows:
        cells = [_fmt(m.get(k)) for k in keys] + [_fmt(m["detection_delay_s"]["p50"])]
        print(f"{name:<13} " + "  ".join(f"{c:>18}" for c in cells))
    src = summary["protocol"]["onset_source"]
    print(f"runs {summary['runs']} ({summary['nominal_runs']} nominal); onsets from: {src}")


def _plots(out: Path, trials: list[Any], labels: dict[str, Any], runs: list[Any]) -> None:
    """A timeline for two nominal runs and the first run of each failure class."""
    from rcbht_introspection.plots.failure_timeline import plot_failure_timeline
    from rcbht_introspection.taxonomy.batch import label_trial

    by_name = {t.name: t for t in trials}
    chosen: list[tuple[str, Any]] = []
    for r in runs:
        key = r.label.failure_class if r.label.failed else "success"
        if sum(k == key for k, _ in chosen) < (2 if key == "success" else 1):
            chosen.append((key, r))
    for _, r in chosen:
        trial = by_name[r.trial]
        path = plot_failure_timeline(
            trial,
            label_trial(trial),
            r.times,
            r.score,
            r.alarm,
            r.onset_estimate,
            r.classes_over_time,
            r.label.failure_class or "success",
            r.onset,
            out / f"{r.trial}.png",
        )
        print(f"wrote {path}")
