"""The `rcbht` command: each subcommand is registered by the module that owns it.

A subcommand module exposes `register(subparsers)`, which adds its parser and sets
`func=<callable(args) -> int>` as the default. The dispatcher only routes and turns
`InputError` into a one-line message with exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from rcbht_introspection.errors import InputError

# Modules that register subcommands, in help order. Each owns its subcommands.
COMMAND_MODULES: tuple[str, ...] = (
    "rcbht_introspection.commands.taxonomy",  # label, conformance, plot
    "rcbht_introspection.commands.calibrate",  # calibrate
    "rcbht_introspection.commands.learn",  # train, evaluate
    "rcbht_introspection.commands.audit",  # audit (data quality before training)
    "rcbht_introspection.commands.live",  # live-eval (offline live /task_state replay)
    "rcbht_introspection.commands.sim",  # sim, sim-report
    "rcbht_introspection.commands.ros",  # bag, replay-eval
    "rcbht_introspection.commands.teach",  # teach (a running classifier_node)
    "rcbht_introspection.commands.verify",  # verify-train, verify-eval
    "rcbht_introspection.commands.closed_loop",  # closed-loop (planner + verifier + simulator)
    "rcbht_introspection.commands.demo",  # demo
)


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser from every command module."""
    parser = argparse.ArgumentParser(prog="rcbht", description=__doc__.splitlines()[0])
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `rcbht` console script."""
    command = "rcbht"
    try:
        args = build_parser().parse_args(argv)
        command = f"rcbht {args.command}"
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"{command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C (also while starting): finally blocks have cleaned up
        print(f"{command}: interrupted", file=sys.stderr)
        return 0


if __name__ == "__main__":
    sys.exit(main())
