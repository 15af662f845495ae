"""From words to sub-task samples: state split and encodings."""

from typing import Literal, get_args

EncodingName = Literal["words-wrench", "compact", "paper"]
"""Encoding names; here (not in encoding/) so the CLI lists them without importing scikit-learn."""
ENCODINGS: tuple[str, ...] = get_args(EncodingName)
