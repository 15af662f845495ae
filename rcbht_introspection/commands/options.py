"""Options several subcommands share: which taxonomy profile labels the trials."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rcbht_introspection.taxonomy.config import TaxonomyConfig


def add_taxonomy_options(parser: argparse.ArgumentParser) -> None:
    """--profile NAME and --taxonomy-config FILE (e.g. the output of `rcbht calibrate`)."""
    parser.add_argument(
        "--profile",
        default=None,
        metavar="NAME",
        help="taxonomy profile: of config/rcbht.yaml (default reference), or of "
        "--taxonomy-config (default: its only profile)",
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
