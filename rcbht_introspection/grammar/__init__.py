"""From words to sub-task samples: state split and encodings."""

ENCODINGS: tuple[str, ...] = ("compact", "paper")
"""Encoding names; here (not in encoding.py) so the CLI lists them without importing scikit-learn."""
