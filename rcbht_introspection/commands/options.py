"""Options several subcommands share: which taxonomy profile labels the trials, and the
/task_state rule of the classifier (live-eval, replay-eval)."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rcbht_introspection.live.state import TaskStateConfig
    from rcbht_introspection.taxonomy.config import TaxonomyConfig


def add_taxonomy_options(parser: argparse.ArgumentParser, with_model: bool = False) -> None:
    """--profile NAME and --taxonomy-config FILE (e.g. the output of `rcbht calibrate`);
    `with_model`: neither given, a --model file's own profile labels the words."""
    model = "; with --model neither is needed: the model file carries its profile"
    parser.add_argument(
        "--profile",
        default=None,
        metavar="NAME",
        help="taxonomy profile: of config/rcbht.yaml (default reference), or of "
        f"--taxonomy-config (default: its only profile){model if with_model else ''}",
    )
    parser.add_argument(
        "--taxonomy-config",
        type=Path,
        default=None,
        metavar="FILE",
        help="YAML file of taxonomy profiles, e.g. written by `rcbht calibrate`",
    )


def taxonomy_from_args(args: argparse.Namespace) -> TaxonomyConfig | None:
    """The profile the options name, or None when neither option was given."""
    if args.profile is None and args.taxonomy_config is None:
        return None
    from rcbht_introspection.taxonomy.config import load_taxonomy_config

    return load_taxonomy_config(args.profile, args.taxonomy_config)


def taxonomy_or_default(args: argparse.Namespace) -> TaxonomyConfig:
    """The profile the options name, else the reference profile."""
    from rcbht_introspection.taxonomy.config import default_config

    return taxonomy_from_args(args) or default_config()


STATE_OPTIONS = {
    "min_probability": "a new /task_state needs at least this probability",
    "min_log_ratio": "... and this log ratio over the current state's probability",
    "evidence_bound": "... and this sum of log-odds over the successive beliefs it leads",
    "min_words": "... from a window of at least this many words",
    "hold_s": "... held this long (stream s)",
}
"""The /task_state rule's fields (live/state.py TaskStateConfig) as --state-<name> options."""


def add_state_options(parser: argparse.ArgumentParser) -> None:
    """--state-min-probability, --state-min-log-ratio, --state-evidence-bound, --state-min-words,
    --state-hold-s: classifier_node's `state.*` parameters (default: config/classifier.yaml's)."""
    for name, text in STATE_OPTIONS.items():
        parser.add_argument(
            "--state-" + name.replace("_", "-"),
            dest="state_" + name,
            type=int if name == "min_words" else float,
            default=None,
            help=f"classifier_node's state.{name}: {text} (default: docs/live-belief.md)",
        )


def state_from_args(args: argparse.Namespace) -> TaskStateConfig:
    """The /task_state rule: config/classifier.yaml's `state` (the node's own defaults) with the
    given --state-* options."""
    from rcbht_introspection.configure.params import ClassifierConfig, load_node_config
    from rcbht_introspection.errors import InputError
    from rcbht_introspection.live.state import check_task_state

    given = {k: getattr(args, "state_" + k) for k in STATE_OPTIONS}
    config = dataclasses.replace(
        load_node_config(ClassifierConfig).state,
        **{k: v for k, v in given.items() if v is not None},
    )
    try:
        check_task_state(config)
    except InputError as exc:
        raise InputError(exc.message, field="--state-" + str(exc.field).replace("_", "-")) from None
    return config
