"""The client side of classifier_node's ~/teach service (the `rcbht teach` CLI, the replay
harness, tests): one request, re-sent until answered, taught once (its request_id)."""

from __future__ import annotations

import time
import uuid
from typing import Any

from rcbht_interfaces.srv import Teach
from rclpy.client import Client
from rclpy.node import Node

from rcbht_introspection.errors import InputError
from rcbht_introspection.waiting import wait_until

RESEND_S = 2.0
"""A request unanswered this long is sent again: Fast DDS may drop the response of a service
whose response writer has not matched this client's reader yet (right after discovery)."""


def teach_client(node: Node, classifier: str = "/classifier_node") -> Client:
    """A client of `<classifier>/teach`."""
    return node.create_client(Teach, f"{classifier.rstrip('/')}/teach")


def teach_request(label: str, start: float | None = None, end: float | None = None) -> Any:
    """A Teach request: [start, end] in stream seconds, or (both None) the last sub-task."""
    request = Teach.Request()
    request.label = label
    request.last = start is None
    request.start = float(start or 0.0)
    request.end = float(end or 0.0)
    request.request_id = uuid.uuid4().hex
    return request


def call_teach(client: Client, request: Any, timeout: float = 20.0) -> Any:
    """The response to `request`, re-sent every RESEND_S until one arrives (the request_id
    makes a repeat harmless); InputError when the service does not answer within `timeout`."""
    deadline = time.monotonic() + timeout
    if not client.wait_for_service(timeout_sec=timeout):
        raise InputError(f"no service {client.srv_name} within {timeout:g} s")
    futures = []
    while time.monotonic() < deadline:
        futures.append(client.call_async(request))
        left = deadline - time.monotonic()
        # rclpy's Future is untyped
        if wait_until(lambda: any(f.done() for f in futures), max(0.0, min(RESEND_S, left))):  # type: ignore[no-untyped-call]
            return next(f for f in futures if f.done()).result()  # type: ignore[no-untyped-call]
    raise InputError(f"no response from {client.srv_name} within {timeout:g} s")


def response_text(response: Any) -> str:
    """One line: what the classifier answered."""
    return (
        f"{'accepted' if response.accepted else 'refused'}: {response.message or '-'} "
        f"(pending {response.pending}, taught windows {response.taught_windows}, "
        f"model version {response.model_version}, errors {response.errors})"
    )
