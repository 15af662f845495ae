"""The draining spin (`spin: draining`): the one place that uses rclpy's private API (checked
against rclpy 7.1.6); nodes use rclpy's executor where `unavailable()` says why it cannot run.

rclpy's executor rebuilds a wait set over every entity of the node (parameter and lifecycle
services, QoS events, ...) on each wake-up: ~0.3 ms of CPU per 1 kHz sample. `spin_draining`
waits on the high-rate subscriptions (those in a DrainedGroup) and the timers with one small wait
set, as rclpy's own `wait_for_message` does, and lets the node take whole bursts in `drain()`.
Timers, services and QoS events still run through the executor, when a timer is due and at least
every HOUSEKEEPING_S. test/test_draining.py pins the rclpy version this was verified with.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol, runtime_checkable

from rclpy.callback_groups import CallbackGroup
from rclpy.context import Context
from rclpy.executors import Executor, ShutdownException, TimeoutException
from rclpy.node import Node
from rclpy.subscription import Subscription
from rclpy.timer import Timer

from rcbht_introspection.nodes.lifetime import StopSignal

try:  # private: absent or changed in another rclpy, where nodes fall back to the executor
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
except ImportError:  # pragma: no cover - depends on the rclpy build
    _rclpy = None

VERIFIED_RCLPY = "7.1.6"
"""The rclpy release whose private WaitSet / take_message API this module was verified with."""
HOUSEKEEPING_S = 0.02
"""How often a draining node's other entities (services, QoS events) are served; also the
longest a stop request waits to be seen."""
HOUSEKEEPING_CALLBACKS = 16
"""Most executor callbacks served per housekeeping round (the hot inputs must not wait long)."""


def unavailable() -> str | None:
    """Why the draining spin cannot run with this rclpy (None: it can): the private wait set
    and take_message it uses must exist."""
    if _rclpy is None:
        return "rclpy has no rclpy_implementation module"
    for owner, name in (("", "WaitSet"), ("Subscription", "take_message")):
        holder = getattr(_rclpy, owner, None) if owner else _rclpy
        if holder is None or not hasattr(holder, name):
            return f"rclpy's private API has no {'.'.join(filter(None, (owner, name)))}"
    return None


class DrainedGroup(CallbackGroup):
    """Callback group of subscriptions that `spin_draining` takes itself; the executor skips them.

    Their QoS-event handlers (incompatible QoS, lost messages) still run through the executor.
    """

    def can_execute(self, entity: object) -> bool:
        return not isinstance(entity, Subscription)

    def beginning_execution(self, entity: object) -> bool:
        return not isinstance(entity, Subscription)

    def ending_execution(self, entity: object) -> None:
        pass


@runtime_checkable
class Draining(Protocol):
    """A node whose high-rate inputs (subscriptions in a DrainedGroup) are taken by `drain`."""

    def drain(self) -> None:
        """Take and handle every message already delivered on the drained subscriptions."""


def take(sub: Subscription) -> tuple[Any, Any] | None:
    """The next delivered message of `sub` as (message, info), or None: what drain() loops on."""
    with sub.handle:
        taken: tuple[Any, Any] | None = sub.handle.take_message(sub.msg_type, sub.raw)
    return taken


MAX_BURST = 1000
"""Most samples per arm taken in one executor wake-up."""


def take_bursts(
    subs: Sequence[tuple[str, Subscription]],
    handle: Callable[[str, Any, Any], None],
    limit: int = MAX_BURST,
) -> None:
    """Hand `handle(arm, message, info)` the messages already delivered on each arm's
    subscription, one per arm in turn (so the arms stay interleaved), until none is left or
    `limit` rounds: bounded, so the node's timers still run between bursts."""
    for _ in range(limit):
        taken = False
        for arm, sub in subs:
            got = take(sub)
            if got is not None:
                handle(arm, *got)
                taken = True
        if not taken:
            return


def serve_ready(executor: Executor, limit: int) -> int:
    """Run up to `limit` callbacks the executor finds ready now, without blocking; how many ran.

    One call serves at most one wake-up's worth (a message per subscription): call again while
    it returns more than 0 to take a whole backlog.
    """
    for done in range(limit):
        try:
            handler, _, _ = executor.wait_for_ready_callbacks(timeout_sec=0)
        except (TimeoutException, ShutdownException):
            return done
        handler()
        error = handler.exception()  # type: ignore[no-untyped-call]  # rclpy's Task is untyped
        if error is not None:
            raise error
    return limit


def _entities(node: Node) -> tuple[tuple[Subscription, ...], tuple[Timer, ...]]:
    """The drained subscriptions and the timers of `node` now (lifecycle transitions change them)."""
    subs = tuple(s for s in node.subscriptions if isinstance(s.callback_group, DrainedGroup))
    return subs, tuple(node.timers)


def _hold(
    handles: contextlib.ExitStack[bool | None],
    entities: tuple[tuple[Subscription, ...], tuple[Timer, ...]],
    context: Context,
) -> Any:
    """Hold the handles of `entities` (releasing those held so far) and make a wait set sized
    for them: rclpy's WaitSet needs its entities' handles held while it waits on them."""
    handles.close()
    subs, timers = entities
    for sub in subs:
        handles.enter_context(sub.handle)
    for timer in timers:
        handles.enter_context(timer.handle)
    return _rclpy.WaitSet(len(subs), 0, len(timers), 0, 0, 0, context.handle)


def _wait(
    wait_set: Any,
    entities: tuple[tuple[Subscription, ...], tuple[Timer, ...]],
    stop: StopSignal,
    timeout_ns: int,
) -> None:
    """Wait up to `timeout_ns` for a message on the drained subscriptions or a due timer."""
    subs, timers = entities
    wait_set.clear_entities()
    for sub in subs:
        wait_set.add_subscription(sub.handle)
    for timer in timers:
        wait_set.add_timer(timer.handle)
    if subs or timers:
        wait_set.wait(timeout_ns)
    else:  # rcl refuses an empty wait set
        stop.wait(HOUSEKEEPING_S)


def spin_draining(
    executor: Executor, node: Node, stop: StopSignal, keep: Callable[[], bool] = lambda: True
) -> None:
    """Spin `node` until `stop` is requested, the context shuts down or `keep()` turns false
    (a reconfigured node that no longer drains); drain on each wake-up."""
    context = executor.context
    if not isinstance(node, Draining):
        raise TypeError(f"{type(node).__name__} has no drain()")
    timeout_ns = int(HOUSEKEEPING_S * 1e9)
    due = time.monotonic()
    entities: tuple[tuple[Subscription, ...], tuple[Timer, ...]] | None = None
    with contextlib.ExitStack() as outer:
        handles = outer.enter_context(contextlib.ExitStack())
        wait_set = None
        while context.ok() and not stop.requested and keep():
            now_entities = _entities(node)
            if now_entities != entities:
                # activate/deactivate created or destroyed subscriptions: a new wait set; the
                # handles held so far are released (a destroyed entity goes away now)
                entities = now_entities
                wait_set = _hold(handles, entities, context)
            assert wait_set is not None
            subs, timers = entities
            _wait(wait_set, entities, stop, timeout_ns)
            if stop.requested or not context.ok():
                break
            if subs:
                node.drain()
            now = time.monotonic()
            if now >= due or (timers and wait_set.get_ready_entities("timer")):
                due = now + HOUSEKEEPING_S
                serve_ready(executor, HOUSEKEEPING_CALLBACKS)
