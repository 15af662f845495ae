"""Scenarios: which arms exist, which one holds the housing, which wrenches are recorded."""

from __future__ import annotations

from dataclasses import dataclass

from rcbht_introspection.errors import InputError


@dataclass(frozen=True)
class Scenario:
    """A scenario: its name, whether a second (left) arm holds the housing, the arms recorded."""

    name: str
    two_arm: bool
    arms: tuple[str, ...]


SCENARIOS: dict[str, Scenario] = {
    "one-arm": Scenario("one-arm", two_arm=False, arms=("R",)),
    "two-arm": Scenario("two-arm", two_arm=True, arms=("L", "R")),
}


def get_scenario(name: str) -> Scenario:
    """The named scenario, or a one-line error listing the known ones."""
    try:
        return SCENARIOS[name]
    except KeyError:
        raise InputError(
            f"unknown scenario {name!r} (known: {', '.join(SCENARIOS)})", field="scenario"
        ) from None
