"""Wrench summaries beside the words: block means of each arm's wrench on the stream clock."""

from rcbht_introspection.summaries.blocks import (
    BLOCK_S,
    BlockMeans,
    WrenchBlock,
    WrenchTrack,
    trial_tracks,
)

__all__ = ["BLOCK_S", "BlockMeans", "WrenchBlock", "WrenchTrack", "trial_tracks"]
