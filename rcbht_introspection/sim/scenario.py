"""Scenarios: which arms exist, which one holds the housing, which wrenches are recorded."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from rcbht_introspection.errors import InputError

ScenarioName = Literal["one-arm", "two-arm"]


@dataclass(frozen=True)
class Scenario:
    """A scenario: its name, whether a second (left) arm holds the housing, the arms recorded."""

    name: ScenarioName
    two_arm: bool
    arms: tuple[str, ...]


SCENARIOS: dict[ScenarioName, Scenario] = {
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
