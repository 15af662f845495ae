"""From words to sub-task samples: state split and encodings."""

ENCODINGS: tuple[str, ...] = ("compact", "paper")
"""Encoding names; here (not in encoding/) so the CLI lists them without importing scikit-learn."""
