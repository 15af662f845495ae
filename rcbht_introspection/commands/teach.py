"""`rcbht teach`: label a window for a running classifier_node (its ~/teach service)."""

from __future__ import annotations

import argparse

from rcbht_introspection.errors import InputError


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the `teach` subcommand."""
    p = subparsers.add_parser(
        "teach",
        help="teach a running classifier_node a label for a window (~/teach service)",
        description="Label the sub-task that ended last (default) or a [start, end] window in "
        "stream seconds with a sub-task name or failure class; --status only asks where "
        "teaching stands. Needs a classifier_node with teach_enabled (docs/ros.md).",
    )
    p.add_argument("label", nargs="?", default="", help="sub-task name or failure class")
    p.add_argument("--last", action="store_true", help="the sub-task that ended last (default)")
    p.add_argument("--start", type=float, default=None, help="window start (stream seconds)")
    p.add_argument("--end", type=float, default=None, help="window end (stream seconds)")
    p.add_argument("--status", action="store_true", help="only print the teaching status")
    p.add_argument("--node", default="/classifier_node", help="the classifier node's name")
    p.add_argument("--timeout", type=float, default=20.0, help="seconds to wait for an answer")
    p.set_defaults(func=cmd_teach)


def cmd_teach(args: argparse.Namespace) -> int:
    """Send one request, print the answer; exit 1 when it was refused."""
    window = (args.start, args.end)
    if args.status:
        if args.label or args.last or window != (None, None):
            raise InputError("--status takes no label and no window")
    elif not args.label:
        raise InputError("give a LABEL (or --status)")
    elif (args.start is None) != (args.end is None):
        raise InputError("give both --start and --end, or neither (--last)")
    elif args.last and args.start is not None:
        raise InputError("--last and --start/--end exclude each other")
    from rcbht_introspection.rostools.session import RosSession
    from rcbht_introspection.rostools.teach_client import (
        call_teach,
        response_text,
        teach_client,
        teach_request,
    )

    with RosSession("rcbht_teach") as ros:
        client = teach_client(ros.node, args.node)
        label = "" if args.status else args.label
        response = call_teach(client, teach_request(label, *window), args.timeout)
    print(response_text(response))
    return 0 if response.accepted else 1
